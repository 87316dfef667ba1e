// TLS set-up of the HTTP port and the identity of a verified client certificate (http_tls.h).
#include "server/http/http_tls.h"

#include <arpa/inet.h>
#include <openssl/err.h>
#include <openssl/x509v3.h>

#include <memory>

namespace inspection {

namespace {

std::string OpenSslError() {
  const unsigned long code = ERR_get_error();
  ERR_clear_error();
  if (code == 0) return "unknown error";
  char text[256];
  ERR_error_string_n(code, text, sizeof(text));
  return text;
}

std::string Asn1Utf8(const ASN1_STRING* s) {
  unsigned char* utf8 = nullptr;
  const int n = ASN1_STRING_to_UTF8(&utf8, s);
  if (n < 0) return {};
  std::string out(reinterpret_cast<char*>(utf8), size_t(n));
  OPENSSL_free(utf8);
  return out;
}

// An IP SAN as text, as gRPC prints it ("127.0.0.1", "::1").
std::string IpText(const ASN1_OCTET_STRING* ip) {
  char text[INET6_ADDRSTRLEN] = {};
  const int len = ASN1_STRING_length(ip);
  const unsigned char* data = ASN1_STRING_get0_data(ip);
  if (len == 4 && inet_ntop(AF_INET, data, text, sizeof(text))) return text;
  if (len == 16 && inet_ntop(AF_INET6, data, text, sizeof(text))) return text;
  return {};
}

}  // namespace

bool ConfigureHttpTls(SSL_CTX& ctx, const HttpTlsFiles& files, std::string* error) {
  auto fail = [&](const std::string& what) {
    *error = what + ": " + OpenSslError();
    return false;
  };
  SSL_CTX_set_options(&ctx, SSL_OP_NO_COMPRESSION | SSL_OP_NO_SESSION_RESUMPTION_ON_RENEGOTIATION);
  SSL_CTX_set_min_proto_version(&ctx, TLS1_2_VERSION);
  if (SSL_CTX_use_certificate_chain_file(&ctx, files.cert_file.c_str()) != 1) {
    return fail("tls_cert '" + files.cert_file + "'");
  }
  if (SSL_CTX_use_PrivateKey_file(&ctx, files.key_file.c_str(), SSL_FILETYPE_PEM) != 1 ||
      SSL_CTX_check_private_key(&ctx) != 1) {
    return fail("tls_key '" + files.key_file + "'");
  }
  if (files.client_ca_file.empty()) return true;
  if (SSL_CTX_load_verify_locations(&ctx, files.client_ca_file.c_str(), nullptr) != 1) {
    return fail("tls_client_ca '" + files.client_ca_file + "'");
  }
  // Tells the client which CAs' certificates to offer (browsers pick from this list).
  STACK_OF(X509_NAME)* names = SSL_load_client_CA_file(files.client_ca_file.c_str());
  if (!names) return fail("tls_client_ca '" + files.client_ca_file + "'");
  SSL_CTX_set_client_CA_list(&ctx, names);
  // Asked for and verified, not demanded in the handshake: a request without a certificate is
  // refused with 401 (HttpEndpoint), which a person in a browser can read.
  SSL_CTX_set_verify(&ctx, SSL_VERIFY_PEER, nullptr);
  // Required by OpenSSL for resumed sessions when client certificates are verified.
  static const unsigned char kSessionContext[] = "inspectd-http";
  SSL_CTX_set_session_id_context(&ctx, kSessionContext, sizeof(kSessionContext) - 1);
  return true;
}

std::vector<std::string> VerifiedClientCertificateNames(const SSL* ssl) {
  std::vector<std::string> names;
  if (!ssl) return names;
  // The certificate stays owned by the session (get0): valid while `ssl` is.
  X509* cert = SSL_get0_peer_certificate(ssl);
  if (!cert || SSL_get_verify_result(ssl) != X509_V_OK) return names;
  const X509_NAME* subject = X509_get_subject_name(cert);
  for (int i = X509_NAME_get_index_by_NID(subject, NID_commonName, -1); i >= 0;
       i = X509_NAME_get_index_by_NID(subject, NID_commonName, i)) {
    std::string cn = Asn1Utf8(X509_NAME_ENTRY_get_data(X509_NAME_get_entry(subject, i)));
    if (!cn.empty()) names.push_back(std::move(cn));
  }
  std::unique_ptr<GENERAL_NAMES, decltype(&GENERAL_NAMES_free)> sans(
      static_cast<GENERAL_NAMES*>(X509_get_ext_d2i(cert, NID_subject_alt_name, nullptr, nullptr)), &GENERAL_NAMES_free);
  if (!sans) return names;
  for (int i = 0; i < sk_GENERAL_NAME_num(sans.get()); ++i) {
    const GENERAL_NAME* san = sk_GENERAL_NAME_value(sans.get(), i);
    std::string name;
    switch (san->type) {
      case GEN_DNS:
      case GEN_EMAIL:
      case GEN_URI:
        name = Asn1Utf8(san->d.ia5);
        break;
      case GEN_IPADD:
        name = IpText(san->d.iPAddress);
        break;
      default:
        break;
    }
    if (!name.empty()) names.push_back(std::move(name));
  }
  return names;
}

}  // namespace inspection
