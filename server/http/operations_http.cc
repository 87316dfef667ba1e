// inspectd's HTTP side: metrics, dashboard and the gRPC call counter as one part (operations_http.h).
#include "server/http/operations_http.h"

#include <httplib.h>

#include "server/http/grpc_metrics_interceptor.h"
#include "server/jobs/rig_verification.h"

namespace inspection {

OperationsHttp::OperationsHttp(std::string server_version) : metrics_(std::move(server_version)) {}

OperationsHttp::~OperationsHttp() { Stop(); }

void OperationsHttp::OnJobEvent(const v1::JobEvent& event) {
  metrics_.OnJobEvent(event);
  dashboard_.OnJobEvent(event);
}

std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface> OperationsHttp::NewInterceptorFactory() {
  return std::make_unique<GrpcMetricsInterceptorFactory>(&metrics_);
}

std::string OperationsHttp::MetricsText() {
  ScrapeState state;
  if (sources_.rig) state.rig_state = sources_.rig->state();
  if (sources_.rig && sources_.store && sources_.calibrations) {
    const google::protobuf::Timestamp now = CurrentTimestamp();
    if (StatusOr<RigVerification> v = ReadRigVerification(*sources_.store, sources_.calibrations->active_id(), now);
        v.ok()) {
      state.verification_state = v->state;
      if (v->full) {
        for (const v1::VerificationCharacteristic& c : v->full->characteristics()) {
          state.verified_characteristics[c.name()] = {c.value(), c.expanded_uncertainty()};
        }
        state.full_verification_age_days = DaysBetween(v->full->finish_time(), now);
      }
    }
  }
  if (sources_.jobs) {
    state.queued_rig_jobs = sources_.jobs->queued_rig_jobs();
    state.rig_job_running = !sources_.jobs->running_rig_job().empty();
    state.reconstruct_queue_depth = sources_.jobs->reconstruct_queue_depth();
  }
  std::error_code ec;
  const std::filesystem::space_info space = std::filesystem::space(data_dir_, ec);
  if (!ec) state.data_disk_free_bytes = space.available;
  return metrics_.Render(state);
}

Status OperationsHttp::Start(HttpEndpointOptions options, DashboardSources sources, std::filesystem::path data_dir) {
  sources_ = sources;
  data_dir_ = std::move(data_dir);
  dashboard_.SetSources(std::move(sources));
  endpoint_ = std::make_unique<HttpEndpoint>(std::move(options));
  endpoint_->AddDataRoute("/metrics", [this](const httplib::Request&, httplib::Response& res) {
    res.set_content(MetricsText(), MetricsRegistry::kContentType);
  });
  dashboard_.AddRoutes(*endpoint_);
  Status s = endpoint_->Start();
  if (!s.ok()) endpoint_.reset();
  return s;
}

void OperationsHttp::Stop() {
  if (endpoint_) endpoint_->Stop();
}

}  // namespace inspection
