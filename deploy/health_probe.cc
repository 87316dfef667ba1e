// inspect-health-probe: asks a gRPC server's standard health service (grpc.health.v1.Health/Check)
// whether a service is SERVING; the container HEALTHCHECK and Kubernetes exec probes run it.
// The two messages are one string and one enum field, so they are encoded by hand: no generated
// code, only libgrpc++. Built by deploy/Containerfile (g++ ... $(pkg-config --libs grpc++)).
//
// Exit codes (as grpc_health_probe): 0 SERVING, 1 bad usage, 2 no connection within the timeout,
// 3 the RPC failed (e.g. NOT_FOUND for an unknown service), 4 NOT_SERVING or UNKNOWN.
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>

namespace {

const char* kUsage =
    "usage: inspect-health-probe [--addr HOST:PORT] [--service NAME] [--timeout SECONDS]\n"
    "                            [--tls-ca FILE [--tls-server-name NAME]]\n"
    "  --addr       server address (default: $INSPECT_SERVER, else 127.0.0.1:50051)\n"
    "  --service    health service name (default \"\": the whole server; inspectd also has\n"
    "               inspection.v1.InspectionService, SERVING while the rig can take jobs)\n"
    "  --timeout    seconds for connecting and for the call (default 3)\n"
    "  --tls-ca     PEM CA of the server certificate: speak TLS (default: $INSPECT_TLS_CA,\n"
    "               else plaintext)\n"
    "  --tls-server-name  name to verify in the certificate (default: $INSPECT_TLS_SERVER_NAME,\n"
    "               else the host of --addr)\n"
    "The environment defaults let one HEALTHCHECK line serve a plaintext and a TLS container\n"
    "(INSPECT_SERVER and INSPECT_TLS_CA are also inspectctl's).\n";

// HealthCheckRequest { string service = 1; }: tag 0x0a, varint length, bytes.
std::string EncodeRequest(const std::string& service) {
  std::string bytes;
  if (service.empty()) return bytes;  // proto3 default: not encoded
  bytes.push_back(0x0a);
  for (size_t n = service.size();; n >>= 7) {
    if (n < 0x80) {
      bytes.push_back(char(n));
      break;
    }
    bytes.push_back(char(0x80 | (n & 0x7f)));
  }
  return bytes + service;
}

// HealthCheckResponse { ServingStatus status = 1; }: the status, 0 (UNKNOWN) when absent;
// -1 when the bytes are not that message. Other fields are skipped only if they are varints.
int DecodeStatus(const std::string& bytes) {
  int status = 0;
  size_t i = 0;
  while (i < bytes.size()) {
    unsigned tag = static_cast<unsigned char>(bytes[i++]);
    if ((tag & 7) != 0) return -1;  // only varint fields expected
    uint64_t value = 0;
    for (int shift = 0;; shift += 7) {
      if (i >= bytes.size() || shift > 63) return -1;
      unsigned char b = static_cast<unsigned char>(bytes[i++]);
      value |= uint64_t(b & 0x7f) << shift;
      if (!(b & 0x80)) break;
    }
    if ((tag >> 3) == 1) status = int(value);
  }
  return status;
}

const char* StatusName(int status) {
  switch (status) {
    case 0:
      return "UNKNOWN";
    case 1:
      return "SERVING";
    case 2:
      return "NOT_SERVING";
    case 3:
      return "SERVICE_UNKNOWN";
    default:
      return "INVALID";
  }
}

std::string Environment(const char* name, const char* fallback) {
  const char* v = std::getenv(name);
  return v && *v ? v : fallback;
}

}  // namespace

int main(int argc, char** argv) {
  std::string addr = Environment("INSPECT_SERVER", "127.0.0.1:50051"), service;
  std::string tls_ca = Environment("INSPECT_TLS_CA", ""), server_name = Environment("INSPECT_TLS_SERVER_NAME", "");
  double timeout_s = 3;
  for (int i = 1; i < argc; ++i) {
    std::string arg = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::cerr << "inspect-health-probe: " << arg << " needs a value\n" << kUsage;
        std::exit(1);
      }
      return argv[++i];
    };
    if (arg == "--addr")
      addr = value();
    else if (arg == "--service")
      service = value();
    else if (arg == "--tls-ca")
      tls_ca = value();
    else if (arg == "--tls-server-name")
      server_name = value();
    else if (arg == "--timeout") {
      std::string t = value();
      char* end = nullptr;
      timeout_s = std::strtod(t.c_str(), &end);
      if (end == t.c_str() || *end != '\0' || !(timeout_s > 0)) {
        std::cerr << "inspect-health-probe: --timeout '" << t << "' must be seconds > 0\n";
        return 1;
      }
    } else if (arg == "-h" || arg == "--help") {
      std::cout << kUsage;
      return 0;
    } else {
      std::cerr << "inspect-health-probe: unknown argument '" << arg << "'\n" << kUsage;
      return 1;
    }
  }

  std::shared_ptr<grpc::ChannelCredentials> credentials = grpc::InsecureChannelCredentials();
  grpc::ChannelArguments args;
  if (!tls_ca.empty()) {
    std::ifstream in(tls_ca);
    std::stringstream pem;
    pem << in.rdbuf();
    if (!in || pem.str().empty()) {
      std::cerr << "inspect-health-probe: --tls-ca '" << tls_ca << "' is unreadable or empty\n";
      return 1;
    }
    grpc::SslCredentialsOptions ssl;
    ssl.pem_root_certs = pem.str();
    credentials = grpc::SslCredentials(ssl);
    if (!server_name.empty()) args.SetSslTargetNameOverride(server_name);
  }
  auto deadline = std::chrono::system_clock::now() + std::chrono::microseconds(static_cast<int64_t>(timeout_s * 1e6));
  auto channel = grpc::CreateCustomChannel(addr, credentials, args);
  if (!channel->WaitForConnected(deadline)) {
    std::cerr << "inspect-health-probe: no connection to " << addr << " within " << timeout_s << " s\n";
    return 2;
  }

  grpc::GenericStub stub(channel);
  grpc::ClientContext context;
  context.set_deadline(deadline);
  std::string request_bytes = EncodeRequest(service);
  grpc::Slice slice(request_bytes);
  grpc::ByteBuffer request(&slice, 1);
  grpc::CompletionQueue cq;
  auto call = stub.PrepareUnaryCall(&context, "/grpc.health.v1.Health/Check", request, &cq);
  call->StartCall();
  grpc::ByteBuffer response;
  grpc::Status status;
  call->Finish(&response, &status, reinterpret_cast<void*>(1));
  void* tag = nullptr;
  bool ok = false;
  if (!cq.Next(&tag, &ok) || !ok) {
    std::cerr << "inspect-health-probe: the health call to " << addr << " did not complete\n";
    return 3;
  }
  if (!status.ok()) {
    std::cerr << "inspect-health-probe: health check of service '" << service << "' failed: code "
              << int(status.error_code()) << ": " << status.error_message() << "\n";
    return 3;
  }
  std::vector<grpc::Slice> slices;
  std::string bytes;
  if (response.Dump(&slices).ok()) {
    for (const auto& s : slices) bytes.append(reinterpret_cast<const char*>(s.begin()), s.size());
  }
  int serving = DecodeStatus(bytes);
  std::cout << "service '" << service << "': " << StatusName(serving) << "\n";
  return serving == 1 ? 0 : 4;
}
