#include "server/inspection_server.h"

#include <fstream>
#include <sstream>

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>
#include <spdlog/spdlog.h>

namespace inspection {

namespace {
StatusOr<std::string> ReadFile(const std::string& path, const char* what) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::InvalidArgument(std::string(what) + " '" + path + "' cannot be read");
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}
}  // namespace

StatusOr<std::unique_ptr<InspectionServer>> InspectionServer::Start(const ServerOptions& options,
                                                                   std::unique_ptr<Rig> rig, Status rig_startup) {
  std::unique_ptr<InspectionServer> s(new InspectionServer());
  s->options_ = options;
  if (options.rig_queue_capacity < 0) return Status::InvalidArgument("queue capacity must be >= 0");
  INSPECT_ASSIGN_OR_RETURN(s->store_, DataStore::Open(options.data_dir));
  if (!rig) {
    INSPECT_ASSIGN_OR_RETURN(rig, CreateSimulatedRig(options.simulation));
  }
  s->rig_ = std::make_unique<RigController>(std::move(rig), rig_startup);
  s->calibrations_ = std::make_unique<CalibrationStore>(s->store_.get());
  s->calibrations_->LoadActive().IgnoreError();  // logged; the server still serves without it
  s->runner_ = std::make_unique<ProcedureRunner>(s->store_.get(), s->rig_.get(), s->calibrations_.get());
  JobManagerOptions jo;
  jo.rig_queue_capacity = options.rig_queue_capacity;
  s->jobs_ = std::make_unique<JobManager>(jo, s->store_.get(), s->runner_.get());
  INSPECT_RETURN_IF_ERROR(s->jobs_->Start());

  ServiceOptions so;
  so.server_version = INSPECT_VERSION;
  so.auth_token = options.auth_token;
  s->service_ = std::make_unique<InspectionServiceImpl>(so, s->store_.get(), s->jobs_.get(), s->rig_.get(),
                                                        s->calibrations_.get());
  s->sim_service_ = std::make_unique<SimulationServiceImpl>(so, s->rig_.get());

  grpc::EnableDefaultHealthCheckService(true);
  if (options.reflection) grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder builder;
  std::shared_ptr<grpc::ServerCredentials> creds;
  if (!options.tls_cert_file.empty() || !options.tls_key_file.empty()) {
    if (options.tls_cert_file.empty() || options.tls_key_file.empty()) {
      return Status::InvalidArgument("TLS needs both --tls-cert and --tls-key");
    }
    grpc::SslServerCredentialsOptions ssl;
    grpc::SslServerCredentialsOptions::PemKeyCertPair pair;
    INSPECT_ASSIGN_OR_RETURN(pair.private_key, ReadFile(options.tls_key_file, "--tls-key"));
    INSPECT_ASSIGN_OR_RETURN(pair.cert_chain, ReadFile(options.tls_cert_file, "--tls-cert"));
    ssl.pem_key_cert_pairs.push_back(pair);
    creds = grpc::SslServerCredentials(ssl);
  } else {
    creds = grpc::InsecureServerCredentials();
  }
  builder.AddListeningPort(options.listen_address, creds, &s->port_);
  builder.RegisterService(s->service_.get());
  builder.RegisterService(s->sim_service_.get());
  // Uploads arrive in 1 MiB chunks; keep headroom for the envelope.
  builder.SetMaxReceiveMessageSize(4 << 20);
  s->server_ = builder.BuildAndStart();
  if (!s->server_ || s->port_ == 0) {
    s->jobs_->Shutdown();
    return Status::Unavailable("cannot listen on " + options.listen_address);
  }
  grpc::HealthCheckServiceInterface* health = s->server_->GetHealthCheckService();
  health->SetServingStatus("", true);
  s->rig_->SetHealthCallback([health](bool serving) { health->SetServingStatus(kRigHealthService, serving); });
  spdlog::info("inspectd listening on {} (data dir {}, rig {}, state {})", s->address(), options.data_dir.string(),
               s->rig_->simulated() ? "simulated" : "configured", v1::RigState_Name(s->rig_->state()));
  return s;
}

std::string InspectionServer::address() const {
  const std::string& a = options_.listen_address;
  const auto colon = a.rfind(':');
  return (colon == std::string::npos ? a : a.substr(0, colon)) + ":" + std::to_string(port_);
}

void InspectionServer::Shutdown() {
  if (shut_down_) return;
  shut_down_ = true;
  // Jobs first, so streaming handlers see terminal events and return; then the transport.
  jobs_->Shutdown();
  server_->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(2));
}

void InspectionServer::Wait() { server_->Wait(); }

InspectionServer::~InspectionServer() {
  if (server_) Shutdown();
}

}  // namespace inspection
