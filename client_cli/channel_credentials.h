// The channel's credentials from the client options: plaintext, TLS against a CA file, or mTLS
// with a client certificate and key.
#pragma once

#include <grpcpp/security/credentials.h>

#include <memory>

#include "client_cli/inspection_client.h"

namespace inspection::client {

// Always sets *credentials; INVALID_ARGUMENT naming the option when a file cannot be read or the
// certificate comes without its key (the client then answers every call with it).
grpc::Status ChannelCredentialsFor(const ClientOptions& options,
                                   std::shared_ptr<grpc::ChannelCredentials>* credentials);

}  // namespace inspection::client
