// libFuzzer target: the request validators of server/request_mapping (the first thing every
// client byte reaches after protobuf decoding). The input's first byte picks the request type,
// the rest is decoded as that message; each validator must answer a Status, never crash.
#include <cstddef>
#include <cstdint>
#include <string>

#include "server/api/request_mapping.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const char* body = reinterpret_cast<const char*>(data + 1);
  const int n = static_cast<int>(size - 1);
  namespace v1 = inspection::v1;
  switch (data[0] % 6) {
    case 0: {
      v1::ScanRequest r;
      if (r.ParseFromArray(body, n)) {
        (void)inspection::CheckRequestTextLimits(r);
        if (r.has_reconstruction()) (void)inspection::MapReconstructionOptions(r.reconstruction(), "reconstruction");
        (void)inspection::MapIlluminationMode(r.illumination());
        (void)inspection::MapIlluminationParameters(r.illumination_parameters());
      }
      break;
    }
    case 1: {
      v1::ReconstructRequest r;
      if (r.ParseFromArray(body, n)) {
        (void)inspection::CheckRequestTextLimits(r);
        if (r.has_start()) (void)inspection::MapReconstructSource(r.start(), int64_t(1) << 30);
        if (r.has_file_chunk()) (void)inspection::CheckUploadChunk(r.file_chunk());
      }
      break;
    }
    case 2: {
      v1::CalibrateRequest r;
      if (r.ParseFromArray(body, n)) {
        (void)inspection::CheckRequestTextLimits(r);
        (void)inspection::MapCalibrateRequest(r);
      }
      break;
    }
    case 3: {
      v1::ListJobsRequest r;
      if (r.ParseFromArray(body, n)) {
        (void)inspection::CheckRequestTextLimits(r);
        (void)inspection::MapListJobsRequest(r);
      }
      break;
    }
    case 4: {
      v1::DownloadArtifactRequest r;
      if (r.ParseFromArray(body, n)) {
        (void)inspection::CheckRequestTextLimits(r);
        (void)inspection::MapDownloadRequest(r);
      }
      break;
    }
    default: {
      v1::SetSpecimenRequest r;
      if (r.ParseFromArray(body, n)) {
        (void)inspection::CheckRequestTextLimits(r);
        (void)inspection::CheckSpecimenName(r.specimen());
      }
      break;
    }
  }
  return 0;
}
