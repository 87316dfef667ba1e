// The one place where core's Status becomes a gRPC status.
#pragma once

#include <grpcpp/support/status.h>

#include "core/util/status.h"

namespace inspection {

inline grpc::Status ToGrpcStatus(const Status& s) {
  if (s.ok()) return grpc::Status::OK;
  return grpc::Status(static_cast<grpc::StatusCode>(static_cast<int>(s.code())), s.message());
}

}  // namespace inspection
