// OperationsHttp: everything inspectd offers operators beside gRPC - the Prometheus metrics
// (/metrics), the dashboard (/, /api/...), the interceptor that counts gRPC calls - owned by
// the InspectionServer as one part. Created before the JobManager (which feeds OnJobEvent from
// its first event), started after the gRPC server when an HTTP address is configured.
// Thread-safe.
#pragma once

#include <grpcpp/support/server_interceptor.h>

#include <filesystem>
#include <memory>
#include <string>

#include "server/http/dashboard.h"
#include "server/http/http_endpoint.h"
#include "server/http/server_metrics.h"

namespace inspection {

class OperationsHttp {
 public:
  explicit OperationsHttp(std::string server_version);
  ~OperationsHttp();

  // The JobManager's event observer (JobManagerOptions::on_event).
  void OnJobEvent(const v1::JobEvent& event);
  // For grpc::ServerBuilder::experimental().SetInterceptorCreators; this object must outlive
  // the gRPC server.
  std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface> NewInterceptorFactory();

  // Serves /metrics and the dashboard on `listen_address` (host:port, port 0 = any).
  // `endpoint` names the address, the access control and TLS files.
  Status Start(HttpEndpointOptions endpoint, DashboardSources sources, std::filesystem::path data_dir);
  void Stop();
  int port() const { return endpoint_ ? endpoint_->port() : 0; }
  std::string address() const { return endpoint_ ? endpoint_->address() : std::string(); }

  ServerMetrics& metrics() { return metrics_; }
  Dashboard& dashboard() { return dashboard_; }

  // /metrics body for the current state of `sources`.
  std::string MetricsText();

 private:
  ServerMetrics metrics_;
  Dashboard dashboard_;
  DashboardSources sources_;
  std::filesystem::path data_dir_;
  std::unique_ptr<HttpEndpoint> endpoint_;
};

}  // namespace inspection
