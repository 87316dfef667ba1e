// InspectionServer: the whole service in one object - data store, rig controller, calibration
// store, job manager with its procedure runner, gRPC services, health and reflection - as
// inspectd runs it and as the end-to-end tests start it on loopback.
#pragma once

#include <grpcpp/grpcpp.h>

#include <memory>
#include <optional>
#include <string>

#include "core/util/status.h"
#include "devices/rig.h"
#include "devices/sim/simulated_rig.h"
#include "server/security/access_control.h"
#include "server/security/audit_log.h"
#include "server/storage/calibration_store.h"
#include "server/storage/data_lifecycle.h"
#include "server/storage/data_store.h"
#include "server/http/operations_http.h"
#include "server/api/inspection_service.h"
#include "server/jobs/job_manager.h"
#include "server/api/no_rig_service.h"
#include "server/jobs/procedure_runner.h"
#include "server/results/result_feed.h"
#include "server/results/result_forwarder.h"
#include "server/jobs/retention_sweeper.h"
#include "server/jobs/rig_controller.h"
#include "server/plant/mqtt_publisher.h"

namespace inspection {

struct ServerOptions {
  std::string listen_address = "127.0.0.1:50051";  // port 0 picks a free port (see port())
  std::filesystem::path data_dir = "./inspection-data";
  // Where the job database lives (default: SQLite in data_dir; server/storage/data_store.h).
  DatabaseOptions database;
  // Site result feed: this rig's results forwarded to the site's store
  // (server/results/result_forwarder.h). Off while site.url is empty.
  ResultForwardingOptions site_forwarding;
  int rig_queue_capacity = 4;
  // gRPC server reflection; unset = on without authentication, off when any is configured
  // (reflection hands an unauthenticated scanner the whole API).
  std::optional<bool> reflection;
  std::string tls_cert_file;  // PEM; with tls_key_file enables TLS (files reloaded on change)
  std::string tls_key_file;
  std::string tls_client_ca_file;       // PEM CA bundle: client certificates mandatory (mTLS)
  bool insecure = false;                // allow plaintext on a non-loopback address
  unsigned tls_reload_interval_s = 10;  // how often the certificate files are checked for changes
  std::string auth_token;               // single bearer token (identity "token", admin); empty = none
  std::string token_file;               // named tokens, "identity token" per line (access_control.h)
  std::string policy_file;              // identities -> roles, JSON (access_control.h)
  std::filesystem::path scene_dir;      // simulated rig: user scenes by name; empty = built-ins only
  // Audit trail of mutating and denied calls (JSON Lines); empty = <data_dir>/audit/audit.jsonl.
  std::filesystem::path audit_log;
  // Data lifecycle: new scans and uploads are refused (RESOURCE_EXHAUSTED) below this much free
  // space on the data disk; 0 = no reserve.
  int64_t min_free_mb = 0;
  RetentionPolicy retention;       // enforced by a background sweeper; no limits = no sweeper
  int retention_interval_s = 600;  // how often the sweeper runs
  // A full instrument verification's validity: its record's next_full_due (rig_verification.h).
  int verification_interval_days = 30;
  SimulatedRigOptions simulation;  // used when no rig is given to Start
  // Reconstruct only (the scale-out pool): no rig is opened; rig calls answer FAILED_PRECONDITION.
  bool no_rig = false;
  // How reconstructions decode frames and write artifacts (server/jobs/job_work.h).
  ReconstructPipelineOptions reconstruct;
  // Prometheus /metrics and the web dashboard (host:port, port 0 = any); empty = no HTTP port.
  std::string http_listen_address;
  // Results and rig states to an MQTT broker (server/plant/mqtt_publisher.h); no host = off.
  // An empty sequence_file is <data_dir>/plant/mqtt_sequence.
  MqttOptions mqtt;
  // Reconstruct pool (replicas on one PostgreSQL database and one shared data folder): the
  // work queue's lease, workers and poll (server/jobs/job_manager.h). On when the store is shared.
  PoolOptions pool;
  // SIGTERM in a pool: how long the running jobs may take to finish before they are handed back.
  std::chrono::milliseconds drain_timeout{60000};
};

// Health service names: "" is SERVING while the process runs; this one is SERVING only while
// the rig can take jobs (not in Error or Initializing).
inline constexpr const char* kRigHealthService = "inspection.v1.InspectionService";

class InspectionServer {
 public:
  // rig: the rig to drive (nullptr = the simulated rig from options.simulation). rig_startup:
  // why the rig started degraded, if it did.
  static StatusOr<std::unique_ptr<InspectionServer>> Start(const ServerOptions& options,
                                                           std::unique_ptr<Rig> rig = nullptr,
                                                           Status rig_startup = Status::Ok());
  ~InspectionServer();
  // While inspectd waits for its database at start-up: a gRPC server on options.listen_address,
  // with the same transport security, that serves only the standard health service, NOT_SERVING
  // for "" and kRigHealthService, so probes and load balancers see a replica that is up but not
  // ready (not a connection refused). Shut it down before Start binds the same address.
  static StatusOr<std::unique_ptr<grpc::Server>> StartWaitingHealth(const ServerOptions& options,
                                                                    std::string* address);

  int port() const { return port_; }
  int http_port() const { return ops_->port(); }  // 0 without an HTTP port
  std::string http_address() const { return ops_->address(); }
  std::string address() const;  // host:port actually bound
  // Stops accepting calls, cancels jobs, waits for the workers.
  void Shutdown();
  // A pool replica's SIGTERM: health NOT_SERVING, no more work taken, the running jobs finish
  // (up to drain_timeout) or are handed back. Shutdown follows. No-op outside a pool.
  void Drain();
  void Wait();

  JobManager& jobs() { return *jobs_; }
  RigController& rig() { return *rig_; }  // not with no_rig
  OperationsHttp& operations() { return *ops_; }
  // Re-reads the policy and token files (SIGHUP); keeps the old policy if the new one is bad.
  Status ReloadAccessPolicy() { return access_->Reload(); }
  bool authentication_enabled() const { return access_->enabled(); }
  bool reflection_enabled() const { return reflection_; }
  const std::filesystem::path& audit_log_path() const { return audit_path_; }
  RetentionSweeper& retention() { return *sweeper_; }

 private:
  InspectionServer() = default;

  ServerOptions options_;
  std::unique_ptr<AccessControl> access_;  // outlives the services that ask it
  std::unique_ptr<AuditLog> audit_;        // outlives the gRPC server whose interceptor writes it
  std::filesystem::path audit_path_;
  bool reflection_ = false;
  std::unique_ptr<OperationsHttp> ops_;  // outlives the JobManager and the gRPC server that feed it
  std::unique_ptr<DataStore> store_;
  std::unique_ptr<RigController> rig_;
  std::unique_ptr<CalibrationStore> calibrations_;
  std::unique_ptr<ResultFeed> results_;  // written by scan jobs, read by WatchResults handlers
  std::unique_ptr<ResultForwarder> forwarder_;  // reads the store's results; stopped before it closes
  std::unique_ptr<ProcedureRunner> runner_;
  std::unique_ptr<JobManager> jobs_;  // declared after what its jobs use: destroyed (joined) first
  std::unique_ptr<DataJanitor> janitor_;
  std::unique_ptr<RetentionSweeper> sweeper_;  // destroyed (joined) before the jobs and the store
  std::unique_ptr<MqttPublisher> mqtt_;        // reads the feed and the rig: destroyed before them
  std::unique_ptr<InspectionServiceImpl> service_;
  std::unique_ptr<SimulationServiceImpl> sim_service_;
  std::unique_ptr<NoRigInspectionService> no_rig_service_;
  std::unique_ptr<NoRigSimulationService> no_rig_sim_service_;
  std::unique_ptr<grpc::Server> server_;
  int port_ = 0;
  bool shut_down_ = false;
};

}  // namespace inspection
