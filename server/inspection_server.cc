#include "server/inspection_server.h"

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>
#include <spdlog/spdlog.h>

#include <fstream>
#include <sstream>

#include "server/access_control.h"

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
  s->ops_ = std::make_unique<OperationsHttp>(INSPECT_VERSION);
  INSPECT_ASSIGN_OR_RETURN(s->store_, DataStore::Open(options.data_dir));
  if (options.no_rig) {
    if (rig) return Status::InvalidArgument("a rig was given to a server started with no_rig");
  } else {
    if (!rig) {
      INSPECT_ASSIGN_OR_RETURN(rig, CreateSimulatedRig(options.simulation));
    }
    s->rig_ = std::make_unique<RigController>(std::move(rig), rig_startup);
  }
  s->calibrations_ = std::make_unique<CalibrationStore>(s->store_.get());
  s->calibrations_->LoadActive().IgnoreError();  // logged; the server still serves without it
  s->runner_ = std::make_unique<ProcedureRunner>(s->store_.get(), s->rig_.get(), s->calibrations_.get());
  JobManagerOptions jo;
  jo.rig_queue_capacity = options.rig_queue_capacity;
  jo.on_event = [ops = s->ops_.get()](const v1::JobEvent& e) { ops->OnJobEvent(e); };
  s->jobs_ = std::make_unique<JobManager>(jo, s->store_.get(), s->runner_.get());
  INSPECT_RETURN_IF_ERROR(s->jobs_->Start());

  ServiceOptions so;
  so.server_version = INSPECT_VERSION;
  so.auth_token = options.auth_token;
  s->service_ = std::make_unique<InspectionServiceImpl>(so, s->store_.get(), s->jobs_.get(), s->rig_.get(),
                                                        s->calibrations_.get());
  if (options.no_rig) {
    s->no_rig_service_ = std::make_unique<NoRigInspectionService>(so, s->service_.get());
    s->no_rig_sim_service_ = std::make_unique<NoRigSimulationService>(so);
  } else {
    s->sim_service_ = std::make_unique<SimulationServiceImpl>(so, s->rig_.get());
  }

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
  if (options.no_rig) {
    builder.RegisterService(s->no_rig_service_.get());
    builder.RegisterService(s->no_rig_sim_service_.get());
  } else {
    builder.RegisterService(s->service_.get());
    builder.RegisterService(s->sim_service_.get());
  }
  std::vector<std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>> interceptors;
  interceptors.push_back(s->ops_->NewInterceptorFactory());  // inspectd_grpc_calls_total
  builder.experimental().SetInterceptorCreators(std::move(interceptors));
  // Uploads arrive in 1 MiB chunks; keep headroom for the envelope.
  builder.SetMaxReceiveMessageSize(4 << 20);
  s->server_ = builder.BuildAndStart();
  if (!s->server_ || s->port_ == 0) {
    s->jobs_->Shutdown();
    return Status::Unavailable("cannot listen on " + options.listen_address);
  }
  grpc::HealthCheckServiceInterface* health = s->server_->GetHealthCheckService();
  health->SetServingStatus("", true);
  if (s->rig_) {
    s->rig_->SetHealthCallback([health](bool serving) { health->SetServingStatus(kRigHealthService, serving); });
  } else {
    health->SetServingStatus(kRigHealthService, true);  // without a rig, it can always take reconstructs
  }
  if (!options.http_listen_address.empty()) {
    HttpEndpointOptions http;
    http.listen_address = options.http_listen_address;
    http.tls_cert_file = options.tls_cert_file;  // HTTPS with the gRPC certificate when TLS is on
    http.tls_key_file = options.tls_key_file;
    if (!options.auth_token.empty()) {
      // The same bearer token as gRPC; a bare token line is one identity with every role.
      INSPECT_ASSIGN_OR_RETURN(AccessPolicy policy, AccessPolicy::Parse("", options.auth_token, false));
      http.access = std::make_shared<const AccessControl>(std::move(policy));
    }
    DashboardSources sources{s->store_.get(), s->jobs_.get(), s->rig_.get(), s->calibrations_.get(), INSPECT_VERSION};
    if (Status hs = s->ops_->Start(std::move(http), sources, options.data_dir); !hs.ok()) {
      s->Shutdown();
      return hs;
    }
    spdlog::info("metrics and dashboard on {}://{}/", options.tls_cert_file.empty() ? "http" : "https",
                 s->ops_->address());
  }
  spdlog::info("inspectd listening on {} (data dir {}, rig {}, state {})", s->address(), options.data_dir.string(),
               !s->rig_               ? "none (reconstruct only)"
               : s->rig_->simulated() ? "simulated"
                                      : "configured",
               s->rig_ ? v1::RigState_Name(s->rig_->state()) : "-");
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
  ops_->Stop();  // its handlers read the jobs and the store
  // Jobs first, so streaming handlers see terminal events and return; then the transport.
  jobs_->Shutdown();
  server_->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(2));
}

void InspectionServer::Wait() { server_->Wait(); }

InspectionServer::~InspectionServer() {
  if (server_) Shutdown();
}

}  // namespace inspection
