// HTTPS for inspectd's HTTP port, matching the gRPC port's transport security: the server
// certificate and key of the gRPC port and, when gRPC requires client certificates (mTLS), the
// same client CA. A client certificate is asked for and verified against that CA during the
// handshake (one from another CA, expired or otherwise invalid, ends the handshake); a request
// without one is answered 401 by HttpEndpoint, so a browser without a certificate gets a page
// saying why instead of a bare TLS error. The names a verified certificate carries - CN first,
// then the subject alternative names (DNS, e-mail, URI, IP), as gRPC's auth context lists them -
// are the identity the AccessPolicy maps to a role, exactly as on gRPC.
#pragma once

#include <openssl/ssl.h>

#include <string>
#include <vector>

namespace inspection {

struct HttpTlsFiles {
  std::string cert_file;       // PEM chain
  std::string key_file;        // PEM private key
  std::string client_ca_file;  // PEM CA bundle; empty = no client certificates asked for
};

// Configures `ctx` (fresh from cpp-httplib's SSLServer) for `files`: TLS 1.2 or newer, the
// certificate chain and matching key, and with a client CA the verification set-up above.
// False when a file cannot be used; `error` then names it.
bool ConfigureHttpTls(SSL_CTX& ctx, const HttpTlsFiles& files, std::string* error);

// The names of the client certificate `ssl` verified in its handshake: CN, then the SANs.
// Empty when there is none, or when the verification did not succeed.
std::vector<std::string> VerifiedClientCertificateNames(const SSL* ssl);

}  // namespace inspection
