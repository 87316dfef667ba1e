// Transport security of the listening port: TLS with certificates that reload from disk while
// the server runs, optional mandatory client certificates (mTLS), and the rule that plaintext
// is allowed only on loopback unless the admin says --insecure.
#pragma once

#include <grpcpp/security/server_credentials.h>

#include <memory>
#include <string>

#include "core/util/status.h"

namespace inspection {

struct TransportSecurityOptions {
  std::string tls_cert_file;       // PEM certificate chain; with tls_key_file enables TLS
  std::string tls_key_file;        // PEM private key
  std::string tls_client_ca_file;  // PEM CA bundle: client certificates become mandatory (mTLS)
  bool insecure = false;           // allow plaintext on a non-loopback address
  // How often the certificate files are checked for changes. gRPC re-reads them in the
  // background and new handshakes use the new files; calls in flight keep their connection.
  unsigned reload_interval_s = 10;
};

// True for 127.0.0.0/8, [::1], localhost and unix sockets.
bool IsLoopbackListenAddress(const std::string& listen_address);

// Credentials for grpc::ServerBuilder::AddListeningPort. INVALID_ARGUMENT when files are missing
// or unreadable, when only one of cert/key is given, when a client CA comes without a server
// certificate, or when plaintext would listen beyond loopback without `insecure`.
StatusOr<std::shared_ptr<grpc::ServerCredentials>> MakeServerCredentials(const TransportSecurityOptions& options,
                                                                         const std::string& listen_address);

}  // namespace inspection
