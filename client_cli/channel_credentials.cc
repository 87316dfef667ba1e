// Channel credentials from the client options (channel_credentials.h).
#include "client_cli/channel_credentials.h"

#include "client_cli/stack_files.h"

namespace inspection::client {

grpc::Status ChannelCredentialsFor(const ClientOptions& options,
                                   std::shared_ptr<grpc::ChannelCredentials>* credentials) {
  grpc::Status status;
  if (options.tls_ca_file.empty()) {
    *credentials = grpc::InsecureChannelCredentials();
  } else {
    grpc::SslCredentialsOptions ssl;
    if (!ReadWholeFile(options.tls_ca_file, &ssl.pem_root_certs) || ssl.pem_root_certs.empty()) {
      status = grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "tls_ca_file: cannot read " + options.tls_ca_file);
    }
    // mTLS: a client certificate and key, both or neither.
    if (options.tls_client_cert_file.empty() != options.tls_client_key_file.empty()) {
      status =
          grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "tls_client_cert_file and tls_client_key_file go together");
    } else if (!options.tls_client_cert_file.empty()) {
      if (!ReadWholeFile(options.tls_client_cert_file, &ssl.pem_cert_chain) || ssl.pem_cert_chain.empty()) {
        status = grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                              "tls_client_cert_file: cannot read " + options.tls_client_cert_file);
      }
      if (!ReadWholeFile(options.tls_client_key_file, &ssl.pem_private_key) || ssl.pem_private_key.empty()) {
        status = grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                              "tls_client_key_file: cannot read " + options.tls_client_key_file);
      }
    }
    *credentials = grpc::SslCredentials(ssl);
  }
  return status;
}

}  // namespace inspection::client
