// HttpEndpoint: inspectd's second port, HTTP/1.1 (cpp-httplib; HTTPS when gRPC has TLS) beside gRPC, for the
// Prometheus /metrics endpoint and the read-only web dashboard. Read-only by design: only GET
// routes exist, nothing here changes the rig or the jobs.
// Authentication follows the gRPC side, with the server's own AccessControl (the same identities,
// roles and SIGHUP reloads): when it is enabled, every data route needs an identity whose role may
// call `role_method` (GetRigStatus: viewer), else 401 (no or unknown credentials) or 403 (an
// identity the policy does not list, or a role too low). The identity is the bearer token's
// ("Authorization: Bearer <token>"), or, when gRPC requires client certificates (mTLS), the
// verified client certificate's (http_tls.h); with mTLS a request without a verified
// certificate is 401 whatever token it carries, as gRPC would refuse its handshake.
// Static assets (the dashboard's page, script and style, which hold no data) are served to
// anyone so a browser can load the page and then ask for the token.
#pragma once

#include <atomic>
#include <functional>
#include <memory>
#include <string>
#include <thread>

#include "core/util/status.h"
#include "server/security/access_control.h"

namespace httplib {
class Server;
struct Request;
struct Response;
}  // namespace httplib

namespace inspection {

struct HttpEndpointOptions {
  std::string listen_address;                   // host:port; port 0 picks a free port (see port())
  std::shared_ptr<const AccessControl> access;  // null = open (no authentication configured)
  // The gRPC method (full name, as the authorization table keys it) whose role the data routes need.
  std::string role_method = "/inspection.v1.InspectionService/GetRigStatus";
  // PEM files: with both, the port speaks HTTPS with the gRPC port's certificate, so a token
  // never crosses the network in clear when gRPC is protected by TLS.
  std::string tls_cert_file;
  std::string tls_key_file;
  // PEM CA bundle (gRPC's tls_client_ca): client certificates are verified against it and
  // required on data routes.
  std::string tls_client_ca_file;
};

class HttpEndpoint {
 public:
  using Handler = std::function<void(const httplib::Request&, httplib::Response&)>;

  explicit HttpEndpoint(HttpEndpointOptions options);
  ~HttpEndpoint();  // Stop()
  HttpEndpoint(const HttpEndpoint&) = delete;
  HttpEndpoint& operator=(const HttpEndpoint&) = delete;

  // Routes, before Start. `pattern` is a cpp-httplib regex matched against the whole path.
  // Data routes check credentials first; public routes do not.
  void AddDataRoute(const std::string& pattern, Handler handler);
  void AddPublicRoute(const std::string& pattern, Handler handler);

  // Binds and serves on a thread of its own. UNAVAILABLE naming the address when it cannot bind.
  Status Start();
  void Stop();  // idempotent; returns when the serving thread has ended

  int port() const { return port_; }
  std::string address() const;  // host:port actually bound

 private:
  // True when the call may proceed; otherwise `response` holds 401 (no or unknown credentials)
  // or 403 (identity not in the policy, role too low) with the reason.
  bool Authorized(const httplib::Request& request, httplib::Response& response) const;

  HttpEndpointOptions options_;
  std::string tls_error_;  // why the TLS set-up failed (Start reports it)
  std::unique_ptr<httplib::Server> server_;
  std::thread thread_;
  std::atomic<bool> thread_done_{false};
  std::string host_;
  int port_ = 0;
};

// "host:port" split; "[::1]:80" gives "::1". INVALID_ARGUMENT naming `setting` otherwise.
Status SplitHostPort(const std::string& address, const std::string& setting, std::string* host, int* port);

}  // namespace inspection
