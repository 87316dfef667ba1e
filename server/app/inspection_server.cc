#include "server/app/inspection_server.h"

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>
#include <spdlog/spdlog.h>

#include <algorithm>

#include "server/security/access_control.h"
#include "server/security/call_authorization.h"
#include "server/security/audit_interceptor.h"
#include "server/security/log_identity_interceptor.h"
#include "server/security/transport_security.h"
#include "server/api/stack_transfer.h"

namespace inspection {

namespace {

// Adds or removes the reflection service for one server. (grpc's InitProtoReflectionServerBuilderPlugin
// is process-wide: once called, every later server of the process would offer reflection.)
class ReflectionOption final : public grpc::ServerBuilderOption {
 public:
  explicit ReflectionOption(bool on) : on_(on) {}
  void UpdateArguments(grpc::ChannelArguments*) override {}
  void UpdatePlugins(std::vector<std::unique_ptr<grpc::ServerBuilderPlugin>>* plugins) override {
    auto is_reflection = [](const std::unique_ptr<grpc::ServerBuilderPlugin>& p) {
      return p->name() == "proto_server_reflection";
    };
    plugins->erase(std::remove_if(plugins->begin(), plugins->end(), is_reflection), plugins->end());
    if (on_) plugins->push_back(std::make_unique<grpc::reflection::ProtoServerReflectionPlugin>());
  }

 private:
  bool on_;
};

// The access policy from the options: a single token, named tokens and/or client certificates
// with a policy file, or none (every caller anonymous admin, as before authentication existed).
StatusOr<std::unique_ptr<AccessControl>> MakeAccessControl(const ServerOptions& o) {
  const bool mtls = !o.tls_client_ca_file.empty();
  if (!o.auth_token.empty() && !o.token_file.empty()) {
    return Status::InvalidArgument("give either auth_token_file (one token) or token_file (named tokens), not both");
  }
  if (!o.policy_file.empty() && o.token_file.empty() && !mtls) {
    return Status::InvalidArgument("policy_file needs identities: token_file or tls_client_ca (client certificates)");
  }
  if (!o.auth_token.empty()) {
    INSPECT_ASSIGN_OR_RETURN(AccessPolicy p, AccessPolicy::Parse("", o.auth_token, mtls));
    return std::make_unique<AccessControl>(std::move(p));
  }
  if (o.token_file.empty() && o.policy_file.empty() && !mtls) {
    return std::make_unique<AccessControl>(AccessPolicy::Open());
  }
  INSPECT_ASSIGN_OR_RETURN(AccessPolicy p, AccessPolicy::Load(o.policy_file, o.token_file, mtls));
  auto access = std::make_unique<AccessControl>(std::move(p));
  access->SetSource(o.policy_file, o.token_file, mtls);
  return access;
}

// host:port actually bound: the listen address's host with the port the server got.
std::string BoundAddress(const std::string& listen, int port) {
  const auto colon = listen.rfind(':');
  return (colon == std::string::npos ? listen : listen.substr(0, colon)) + ":" + std::to_string(port);
}

StatusOr<std::shared_ptr<grpc::ServerCredentials>> MakeCredentials(const ServerOptions& o) {
  TransportSecurityOptions tso;
  tso.tls_cert_file = o.tls_cert_file;
  tso.tls_key_file = o.tls_key_file;
  tso.tls_client_ca_file = o.tls_client_ca_file;
  tso.insecure = o.insecure;
  tso.reload_interval_s = o.tls_reload_interval_s;
  return MakeServerCredentials(tso, o.listen_address);
}

}  // namespace

StatusOr<std::unique_ptr<grpc::Server>> InspectionServer::StartWaitingHealth(const ServerOptions& options,
                                                                              std::string* address) {
  INSPECT_ASSIGN_OR_RETURN(std::shared_ptr<grpc::ServerCredentials> creds, MakeCredentials(options));
  grpc::EnableDefaultHealthCheckService(true);
  grpc::ServerBuilder builder;
  int port = 0;
  builder.AddListeningPort(options.listen_address, creds, &port);
  std::unique_ptr<grpc::Server> server = builder.BuildAndStart();
  if (!server || port == 0) return Status::Unavailable("cannot listen on " + options.listen_address);
  grpc::HealthCheckServiceInterface* health = server->GetHealthCheckService();
  health->SetServingStatus("", false);
  health->SetServingStatus(kRigHealthService, false);
  if (address) *address = BoundAddress(options.listen_address, port);
  return server;
}

StatusOr<std::unique_ptr<InspectionServer>> InspectionServer::Start(const ServerOptions& options,
                                                                    std::unique_ptr<Rig> rig, Status rig_startup) {
  std::unique_ptr<InspectionServer> s(new InspectionServer());
  s->options_ = options;
  if (options.rig_queue_capacity < 0) return Status::InvalidArgument("queue capacity must be >= 0");
  if (options.min_free_mb < 0) return Status::InvalidArgument("min_free_mb must be >= 0");
  if (options.retention_interval_s < 1) return Status::InvalidArgument("retention_interval_s must be >= 1");
  INSPECT_RETURN_IF_ERROR(options.retention.Validate());
  // Who may call, and over what transport: settled before anything starts.
  INSPECT_ASSIGN_OR_RETURN(s->access_, MakeAccessControl(options));
  INSPECT_ASSIGN_OR_RETURN(std::shared_ptr<grpc::ServerCredentials> creds, MakeCredentials(options));
  s->reflection_ = options.reflection.value_or(!s->access_->enabled());
  AuditLogOptions audit;
  audit.path = options.audit_log.empty() ? options.data_dir / "audit" / "audit.jsonl" : options.audit_log;
  s->audit_path_ = audit.path;
  INSPECT_ASSIGN_OR_RETURN(s->audit_, AuditLog::Open(audit));

  s->ops_ = std::make_unique<OperationsHttp>(INSPECT_VERSION);
  INSPECT_ASSIGN_OR_RETURN(s->store_, DataStore::Open(options.data_dir, options.database));
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
  s->results_ = std::make_unique<ResultFeed>(s->store_.get());
  if (!options.site_forwarding.site.url.empty()) {
    INSPECT_RETURN_IF_ERROR(ValidateResultForwardingOptions(options.site_forwarding));
    s->forwarder_ = std::make_unique<ResultForwarder>(s->store_.get(), options.site_forwarding);
    s->results_->SetAppendListener([f = s->forwarder_.get()] { f->Notify(); });
  }
  s->runner_ =
      std::make_unique<ProcedureRunner>(s->store_.get(), s->rig_.get(), s->calibrations_.get(), s->results_.get(),
                                        options.reconstruct);
  JobManagerOptions jo;
  jo.rig_queue_capacity = options.rig_queue_capacity;
  jo.on_event = [ops = s->ops_.get()](const v1::JobEvent& e) { ops->OnJobEvent(e); };
  // "Full" for a failed job's write: below the reserve, or below what one default scan needs
  // (~38 MiB for its stack, as much again for the archive and the depth files).
  const int64_t min_free_bytes = options.min_free_mb << 20;
  jo.disk_full = [dir = options.data_dir, full_below = std::max<int64_t>(min_free_bytes, int64_t(64) << 20)] {
    auto free_bytes = FreeDiskBytes(dir);
    return free_bytes.ok() && *free_bytes < full_below;
  };
  // A shared store (PostgreSQL) makes this server a pool replica: reconstructions go through the
  // store's work queue and any replica runs them, from their input on the shared data folder.
  jo.pool = options.pool;
  jo.pool.enabled = s->store_->shared();
  jo.pool.restore = [store = s->store_.get(), pipeline = options.reconstruct](const QueuedWork& w,
                                                                             const std::filesystem::path& dir) {
    return RestoreReconstructWork(*store, pipeline, w, dir);
  };
  s->jobs_ = std::make_unique<JobManager>(jo, s->store_.get(), s->runner_.get());
  INSPECT_RETURN_IF_ERROR(s->jobs_->Start());
  s->janitor_ = std::make_unique<DataJanitor>(s->store_.get(), s->jobs_.get());
  s->sweeper_ = std::make_unique<RetentionSweeper>(s->janitor_.get(), options.retention,
                                                   std::chrono::seconds(options.retention_interval_s));

  ServiceOptions so;
  so.server_version = INSPECT_VERSION;
  so.scene_dir = options.scene_dir;
  so.janitor = s->janitor_.get();
  so.min_free_bytes = min_free_bytes;
  so.results = s->results_.get();
  so.reconstruct = options.reconstruct;
  so.verification_interval_days = options.verification_interval_days;
  s->service_ = std::make_unique<InspectionServiceImpl>(so, s->store_.get(), s->jobs_.get(), s->rig_.get(),
                                                        s->calibrations_.get());
  if (options.no_rig) {
    s->no_rig_service_ = std::make_unique<NoRigInspectionService>(so, s->service_.get());
    s->no_rig_sim_service_ = std::make_unique<NoRigSimulationService>(so);
  } else {
    s->sim_service_ = std::make_unique<SimulationServiceImpl>(so, s->rig_.get());
  }

  grpc::EnableDefaultHealthCheckService(true);
  grpc::ServerBuilder builder;
  builder.SetOption(std::make_unique<ReflectionOption>(s->reflection_));
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
  interceptors.push_back(std::make_unique<AuditInterceptorFactory>(s->audit_.get(), s->access_.get()));
  interceptors.push_back(std::make_unique<LogIdentityInterceptorFactory>(s->access_.get()));  // "identity" in logs
  // Who may call what, decided before any handler runs; without it every call is refused.
  interceptors.push_back(std::make_unique<AuthorizationInterceptorFactory>(s->access_.get()));
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
    http.tls_client_ca_file = options.tls_client_ca_file;  // mTLS on gRPC: client certificates here too
    // The gRPC side's access control itself (tokens, certificates, policy, SIGHUP reloads); not
    // owned: access_ outlives ops_.
    if (s->access_->enabled()) {
      http.access = std::shared_ptr<const AccessControl>(std::shared_ptr<void>(), s->access_.get());
    }
    DashboardSources sources{s->store_.get(), s->jobs_.get(), s->rig_.get(), s->calibrations_.get(), INSPECT_VERSION};
    if (Status hs = s->ops_->Start(std::move(http), sources, options.data_dir); !hs.ok()) {
      s->Shutdown();
      return hs;
    }
    spdlog::info("metrics and dashboard on {}://{}/", options.tls_cert_file.empty() ? "http" : "https",
                 s->ops_->address());
  }
  if (options.mqtt.enabled()) {
    MqttOptions mo = options.mqtt;
    if (mo.sequence_file.empty()) mo.sequence_file = options.data_dir / "plant" / "mqtt_sequence";
    std::function<RigStateSample()> state;
    if (s->rig_) state = [rig = s->rig_.get()] { return RigStateSample{rig->state(), rig->state_detail()}; };
    auto mqtt = MqttPublisher::Start(mo, s->results_.get(), s->store_.get(), std::move(state));
    if (!mqtt.ok()) {
      s->Shutdown();
      return mqtt.status();
    }
    s->mqtt_ = std::move(*mqtt);
  }
  s->sweeper_->Start();
  spdlog::info("inspectd listening on {} (data dir {}, rig {}, state {})", s->address(), options.data_dir.string(),
               !s->rig_               ? "none (reconstruct only)"
               : s->rig_->simulated() ? "simulated"
                                      : "configured",
               s->rig_ ? v1::RigState_Name(s->rig_->state()) : "-");
  return s;
}

std::string InspectionServer::address() const { return BoundAddress(options_.listen_address, port_); }

void InspectionServer::Shutdown() {
  if (shut_down_) return;
  shut_down_ = true;
  ops_->Stop();  // its handlers read the jobs and the store
  if (sweeper_) sweeper_->Stop();
  if (mqtt_) mqtt_->Stop();  // before the feed shuts down: what it has not sent waits in the store
  // Jobs first, so streaming handlers see terminal events and return; then the transport.
  jobs_->Shutdown();
  results_->Shutdown();  // open WatchResults streams end (UNAVAILABLE: resume elsewhere or later)
  if (forwarder_) forwarder_->Stop();  // what it did not forward stays in the outbox for the next start
  server_->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(2));
}

void InspectionServer::Drain() {
  if (shut_down_ || !jobs_->pool()) return;
  // Readiness drops first: the Service stops sending this replica new calls.
  grpc::HealthCheckServiceInterface* health = server_->GetHealthCheckService();
  health->SetServingStatus("", false);
  health->SetServingStatus(kRigHealthService, false);
  const int handed_back = jobs_->Drain(options_.drain_timeout);
  spdlog::info("drained ({} job(s) handed back to the pool)", handed_back);
}

void InspectionServer::Wait() { server_->Wait(); }

InspectionServer::~InspectionServer() {
  if (server_) Shutdown();
}

}  // namespace inspection
