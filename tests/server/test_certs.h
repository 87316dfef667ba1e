// Test PKI made at run time with OpenSSL's API: a CA, a server certificate for localhost /
// 127.0.0.1, and client certificates with a chosen CN and SANs. Written as PEM files so the
// server reads them exactly as it reads an admin's files. Header-only (tests are globbed).
#pragma once

#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/x509.h>
#include <openssl/x509v3.h>

#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

namespace inspection::testing {

struct KeyAndCert {
  std::string key_pem;
  std::string cert_pem;
};

namespace certs_detail {

inline std::string Pem(EVP_PKEY* key) {
  BIO* b = BIO_new(BIO_s_mem());
  PEM_write_bio_PrivateKey(b, key, nullptr, nullptr, 0, nullptr, nullptr);
  char* data = nullptr;
  const long n = BIO_get_mem_data(b, &data);
  std::string s(data, static_cast<size_t>(n));
  BIO_free(b);
  return s;
}

inline std::string Pem(X509* cert) {
  BIO* b = BIO_new(BIO_s_mem());
  PEM_write_bio_X509(b, cert);
  char* data = nullptr;
  const long n = BIO_get_mem_data(b, &data);
  std::string s(data, static_cast<size_t>(n));
  BIO_free(b);
  return s;
}

inline void AddExt(X509* cert, X509* issuer, int nid, const std::string& value) {
  X509V3_CTX ctx;
  X509V3_set_ctx_nodb(&ctx);
  X509V3_set_ctx(&ctx, issuer, cert, nullptr, nullptr, 0);
  X509_EXTENSION* ext = X509V3_EXT_conf_nid(nullptr, &ctx, nid, value.c_str());
  X509_add_ext(cert, ext, -1);
  X509_EXTENSION_free(ext);
}

}  // namespace certs_detail

// A self-signed CA, or a certificate signed by `issuer` (key + cert of the CA).
// sans: OpenSSL syntax, e.g. "DNS:localhost,IP:127.0.0.1".
inline KeyAndCert MakeCertificate(const std::string& common_name, const std::string& sans, const KeyAndCert* issuer,
                                  long serial) {
  using namespace certs_detail;
  EVP_PKEY* key = EVP_EC_gen("P-256");
  X509* cert = X509_new();
  X509_set_version(cert, 2);
  ASN1_INTEGER_set(X509_get_serialNumber(cert), serial);
  X509_gmtime_adj(X509_getm_notBefore(cert), -3600);
  X509_gmtime_adj(X509_getm_notAfter(cert), 24 * 3600);
  X509_set_pubkey(cert, key);
  X509_NAME* name = X509_get_subject_name(cert);
  X509_NAME_add_entry_by_txt(name, "CN", MBSTRING_ASC, reinterpret_cast<const unsigned char*>(common_name.c_str()), -1,
                             -1, 0);
  EVP_PKEY* sign_key = key;
  X509* issuer_cert = cert;
  if (issuer) {
    BIO* kb = BIO_new_mem_buf(issuer->key_pem.data(), static_cast<int>(issuer->key_pem.size()));
    sign_key = PEM_read_bio_PrivateKey(kb, nullptr, nullptr, nullptr);
    BIO_free(kb);
    BIO* cb = BIO_new_mem_buf(issuer->cert_pem.data(), static_cast<int>(issuer->cert_pem.size()));
    issuer_cert = PEM_read_bio_X509(cb, nullptr, nullptr, nullptr);
    BIO_free(cb);
    X509_set_issuer_name(cert, X509_get_subject_name(issuer_cert));
    AddExt(cert, issuer_cert, NID_basic_constraints, "critical,CA:FALSE");
    if (!sans.empty()) AddExt(cert, issuer_cert, NID_subject_alt_name, sans);
  } else {
    X509_set_issuer_name(cert, name);
    AddExt(cert, cert, NID_basic_constraints, "critical,CA:TRUE");
    AddExt(cert, cert, NID_key_usage, "critical,keyCertSign,cRLSign");
  }
  X509_sign(cert, sign_key, EVP_sha256());
  KeyAndCert out{Pem(key), Pem(cert)};
  if (issuer) {
    EVP_PKEY_free(sign_key);
    X509_free(issuer_cert);
  }
  X509_free(cert);
  EVP_PKEY_free(key);
  return out;
}

inline void WriteText(const std::filesystem::path& p, const std::string& text) {
  std::ofstream(p, std::ios::binary | std::ios::trunc) << text;
}

}  // namespace inspection::testing
