// A gRPC server interceptor that counts every finished call by method and status code into
// ServerMetrics (inspectd_grpc_calls_total), whatever service answers it (inspection,
// simulation, health, reflection). Seen at the moment the status is sent, so calls that fail
// before their handler runs (authentication, bad arguments) count too.
#pragma once

#include <grpcpp/support/server_interceptor.h>

#include <memory>

#include "server/http/server_metrics.h"

namespace inspection {

class GrpcMetricsInterceptorFactory final : public grpc::experimental::ServerInterceptorFactoryInterface {
 public:
  // `metrics` must outlive the gRPC server.
  explicit GrpcMetricsInterceptorFactory(ServerMetrics* metrics) : metrics_(metrics) {}
  grpc::experimental::Interceptor* CreateServerInterceptor(grpc::experimental::ServerRpcInfo* info) override;

 private:
  ServerMetrics* metrics_;
};

}  // namespace inspection
