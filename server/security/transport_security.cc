// TLS / mTLS server credentials with file-watching reload (see transport_security.h).
#include "server/security/transport_security.h"

#include <grpcpp/security/tls_certificate_provider.h>
#include <grpcpp/security/tls_credentials_options.h>
#include <spdlog/spdlog.h>

#include <fstream>

namespace inspection {

namespace {

Status CheckPemFile(const std::string& path, const char* flag, const char* marker) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::InvalidArgument(std::string(flag) + " '" + path + "' cannot be read");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (text.find(marker) == std::string::npos) {
    return Status::InvalidArgument(std::string(flag) + " '" + path + "' holds no PEM block (" + marker + ")");
  }
  return Status::Ok();
}

std::string HostOf(const std::string& address) {
  if (!address.empty() && address.front() == '[') {  // [::1]:50051
    const auto close = address.find(']');
    return close == std::string::npos ? address : address.substr(1, close - 1);
  }
  const auto colon = address.rfind(':');
  return colon == std::string::npos ? address : address.substr(0, colon);
}

}  // namespace

bool IsLoopbackListenAddress(const std::string& listen_address) {
  if (listen_address.rfind("unix:", 0) == 0) return true;
  const std::string host = HostOf(listen_address);
  if (host == "localhost" || host == "::1") return true;
  return host.rfind("127.", 0) == 0 && host.find_first_not_of("0123456789.") == std::string::npos;
}

StatusOr<std::shared_ptr<grpc::ServerCredentials>> MakeServerCredentials(const TransportSecurityOptions& o,
                                                                         const std::string& listen_address) {
  const bool tls = !o.tls_cert_file.empty() || !o.tls_key_file.empty();
  if (!tls) {
    if (!o.tls_client_ca_file.empty()) {
      return Status::InvalidArgument("--tls-client-ca needs --tls-cert and --tls-key (mTLS is TLS first)");
    }
    if (!IsLoopbackListenAddress(listen_address)) {
      if (!o.insecure) {
        return Status::InvalidArgument("plaintext listening on " + listen_address +
                                       " is allowed only on loopback: give --tls-cert/--tls-key, or --insecure");
      }
      spdlog::warn("listening on {} WITHOUT TLS (--insecure): credentials and images cross the network in clear",
                   listen_address);
    }
    return grpc::InsecureServerCredentials();
  }
  if (o.tls_cert_file.empty() || o.tls_key_file.empty()) {
    return Status::InvalidArgument("TLS needs both --tls-cert and --tls-key");
  }
  INSPECT_RETURN_IF_ERROR(CheckPemFile(o.tls_cert_file, "--tls-cert", "-----BEGIN CERTIFICATE-----"));
  INSPECT_RETURN_IF_ERROR(CheckPemFile(o.tls_key_file, "--tls-key", "PRIVATE KEY-----"));
  if (!o.tls_client_ca_file.empty()) {
    INSPECT_RETURN_IF_ERROR(CheckPemFile(o.tls_client_ca_file, "--tls-client-ca", "-----BEGIN CERTIFICATE-----"));
  }
  if (o.reload_interval_s < 1) return Status::InvalidArgument("TLS reload interval must be >= 1 s");
  auto provider = std::make_shared<grpc::experimental::FileWatcherCertificateProvider>(
      o.tls_key_file, o.tls_cert_file, o.tls_client_ca_file, o.reload_interval_s);
  grpc::experimental::TlsServerCredentialsOptions options(provider);
  options.watch_identity_key_cert_pairs();
  if (!o.tls_client_ca_file.empty()) {
    options.watch_root_certs();
    options.set_cert_request_type(GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY);
  } else {
    options.set_cert_request_type(GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE);
  }
  return grpc::experimental::TlsServerCredentials(options);
}

}  // namespace inspection
