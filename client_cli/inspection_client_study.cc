// InspectionClient: the Type-1 gauge study RPCs.
#include "client_cli/inspection_client.h"

namespace inspection::client {

grpc::Status InspectionClient::StartStudy(const v1::StartStudyRequest& request, const EventCallback& on_event,
                                          v1::Job* job) {
  if (!init_status_.ok()) return init_status_;
  grpc::ClientContext ctx;
  Prepare(&ctx);
  auto reader = stub_->StartStudy(&ctx, request);
  return FollowStream(reader.get(), on_event, job);
}

grpc::Status InspectionClient::GetStudy(const std::string& study_id, v1::Study* study) {
  v1::GetStudyRequest request;
  request.set_study_id(study_id);
  return Unary(&v1::InspectionService::Stub::GetStudy, request, study);
}

grpc::Status InspectionClient::ListStudies(const v1::ListStudiesRequest& request, v1::ListStudiesResponse* response) {
  return Unary(&v1::InspectionService::Stub::ListStudies, request, response);
}

}  // namespace inspection::client
