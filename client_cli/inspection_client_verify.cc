// InspectionClient: the instrument verification RPC.
#include "client_cli/inspection_client.h"

namespace inspection::client {

grpc::Status InspectionClient::Verify(const v1::VerifyRequest& request, const EventCallback& on_event, v1::Job* job) {
  if (!init_status_.ok()) return init_status_;
  grpc::ClientContext ctx;
  Prepare(&ctx);
  auto reader = stub_->Verify(&ctx, request);
  return FollowStream(reader.get(), on_event, job);
}

}  // namespace inspection::client
