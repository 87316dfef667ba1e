// inspectd's HTTP port: routing, credential checks and the serving thread (http_endpoint.h).
#include "server/http/http_endpoint.h"

#include <httplib.h>
#include <spdlog/spdlog.h>

#include <charconv>

#include "server/http/http_tls.h"

namespace inspection {

Status SplitHostPort(const std::string& address, const std::string& setting, std::string* host, int* port) {
  const auto colon = address.rfind(':');
  auto bad = [&] {
    return Status::InvalidArgument(setting + " '" + address + "' must be host:port, e.g. 127.0.0.1:9464");
  };
  if (colon == std::string::npos || colon == 0 || colon + 1 == address.size()) return bad();
  std::string h = address.substr(0, colon);
  if (h.size() >= 2 && h.front() == '[' && h.back() == ']') h = h.substr(1, h.size() - 2);
  int p = -1;
  const char* begin = address.data() + colon + 1;
  const char* end = address.data() + address.size();
  auto [ptr, ec] = std::from_chars(begin, end, p);
  if (ec != std::errc() || ptr != end || p < 0 || p > 65535 || h.empty()) return bad();
  *host = h;
  *port = p;
  return Status::Ok();
}

HttpEndpoint::HttpEndpoint(HttpEndpointOptions options) : options_(std::move(options)) {
  if (!options_.tls_cert_file.empty()) {
    const HttpTlsFiles files{options_.tls_cert_file, options_.tls_key_file, options_.tls_client_ca_file};
    server_ = std::make_unique<httplib::SSLServer>(
        [this, files](SSL_CTX& ctx) { return ConfigureHttpTls(ctx, files, &tls_error_); });
  } else {
    server_ = std::make_unique<httplib::Server>();
  }
  // Dashboard polls and scrapes are small; nothing here should be cached by a proxy, and the
  // page must not be framed by another site.
  server_->set_default_headers(
      {{"Cache-Control", "no-store"}, {"X-Content-Type-Options", "nosniff"}, {"X-Frame-Options", "DENY"}});
}

HttpEndpoint::~HttpEndpoint() { Stop(); }

bool HttpEndpoint::Authorized(const httplib::Request& request, httplib::Response& response) const {
  if (!options_.access || !options_.access->enabled()) return true;
  CallerCredentials credentials;
  const std::string header = request.get_header_value("Authorization");
  static const std::string kBearer = "Bearer ";
  if (header.compare(0, kBearer.size(), kBearer) == 0) credentials.bearer_token = header.substr(kBearer.size());
  credentials.peer = "http:" + request.remote_addr + ":" + std::to_string(request.remote_port);
  if (!options_.tls_client_ca_file.empty()) {
    // mTLS: the certificate is mandatory, as in gRPC's handshake; a token may add to it.
    credentials.cert_names = VerifiedClientCertificateNames(request.ssl);
    if (credentials.cert_names.empty()) {
      response.status = 401;
      response.set_content(
          "client certificate required: this server accepts only clients with a certificate "
          "from its client CA (as on its gRPC port)\n",
          "text/plain; charset=utf-8");
      return false;
    }
  }
  auto identity = options_.access->Authorize(credentials, options_.role_method);
  if (identity.ok()) return true;
  const bool denied = identity.status().code() == StatusCode::kPermissionDenied;
  response.status = denied ? 403 : 401;
  if (!denied) response.set_header("WWW-Authenticate", "Bearer realm=\"inspectd\"");
  response.set_content(identity.status().message() + "\n", "text/plain; charset=utf-8");
  return false;
}

void HttpEndpoint::AddDataRoute(const std::string& pattern, Handler handler) {
  server_->Get(pattern, [this, handler = std::move(handler)](const httplib::Request& req, httplib::Response& res) {
    if (Authorized(req, res)) handler(req, res);
  });
}

void HttpEndpoint::AddPublicRoute(const std::string& pattern, Handler handler) {
  server_->Get(pattern, std::move(handler));
}

Status HttpEndpoint::Start() {
  int requested = 0;
  INSPECT_RETURN_IF_ERROR(SplitHostPort(options_.listen_address, "http_listen", &host_, &requested));
  if (!server_->is_valid()) {
    return Status::InvalidArgument("HTTPS: " + (tls_error_.empty() ? "cannot set up TLS" : tls_error_));
  }
  if (requested == 0) {
    port_ = server_->bind_to_any_port(host_);
  } else if (server_->bind_to_port(host_, requested)) {
    port_ = requested;
  }
  if (port_ <= 0) {
    port_ = 0;
    return Status::Unavailable("cannot listen for HTTP on " + options_.listen_address);
  }
  thread_ = std::thread([this] {
    if (!server_->listen_after_bind()) spdlog::error("HTTP endpoint on {} stopped with an error", address());
    thread_done_ = true;
  });
  return Status::Ok();
}

void HttpEndpoint::Stop() {
  if (!thread_.joinable()) return;
  // httplib's stop() does nothing until the serving loop has started: wait for it (or for its
  // failure) first, or a Stop right after Start would leave the thread serving forever.
  while (!server_->is_running() && !thread_done_) std::this_thread::yield();
  server_->stop();
  thread_.join();
}

std::string HttpEndpoint::address() const {
  const bool v6 = host_.find(':') != std::string::npos;
  return (v6 ? "[" + host_ + "]" : host_) + ":" + std::to_string(port_);
}

}  // namespace inspection
