#include "core/io/stack.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>

#include "core/io/colour.h"
#include "core/io/raw_frame_decode.h"

namespace inspection {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

Status Invalid(const std::string& msg) { return Status::InvalidArgument("stack.json: " + msg); }

// Rejects absolute paths and ".." so a manifest (possibly uploaded) cannot reach outside its folder.
Status CheckRelativeFile(const std::string& file, size_t index) {
  const std::string field = "frames[" + std::to_string(index) + "].file";
  if (file.empty()) return Invalid(field + " is empty");
  fs::path p(file);
  if (p.is_absolute()) return Invalid(field + " '" + file + "' must be relative to the stack folder");
  for (const auto& part : p) {
    if (part == "..") return Invalid(field + " '" + file + "' must not contain '..'");
  }
  return Status::Ok();
}

const char* const kAlignmentNames[] = {"none", "estimate", "calibrated"};
const char* const kAlignmentMethods[] = {"", "model", "chain"};

// A finite number at j[key] (required); errors name "alignment.<at><key>".
Status AlignmentNumber(const json& j, const std::string& at, const char* key, double* out) {
  if (!j.contains(key) || !j[key].is_number()) return Invalid("alignment." + at + key + " is missing or not a number");
  *out = j[key].get<double>();
  if (!std::isfinite(*out)) return Invalid("alignment." + at + key + " must be finite");
  return Status::Ok();
}

// stack.json "alignment" (StackAlignmentRecord): types, names and ranges, and one transform per
// frame when there are transforms. frame_count: the manifest's frames.
StatusOr<StackAlignmentRecord> ParseAlignmentRecord(const json& j, size_t frame_count) {
  if (!j.is_object()) return Invalid("alignment must be an object");
  StackAlignmentRecord r;
  if (!j.contains("alignment") || !j["alignment"].is_string()) return Invalid("alignment.alignment is missing or not a string");
  r.alignment = j["alignment"].get<std::string>();
  if (std::find(std::begin(kAlignmentNames), std::end(kAlignmentNames), r.alignment) == std::end(kAlignmentNames)) {
    return Invalid("alignment.alignment '" + r.alignment + "' is not one of none, estimate, calibrated");
  }
  if (j.contains("method")) {
    if (!j["method"].is_string()) return Invalid("alignment.method must be a string");
    r.method = j["method"].get<std::string>();
    if (std::find(std::begin(kAlignmentMethods), std::end(kAlignmentMethods), r.method) == std::end(kAlignmentMethods)) {
      return Invalid("alignment.method '" + r.method + "' is not one of model, chain or empty");
    }
  }
  if (j.contains("still")) {
    if (!j["still"].is_boolean()) return Invalid("alignment.still must be true or false");
    r.still = j["still"].get<bool>();
  }
  if (j.contains("fallback_reason")) {
    if (!j["fallback_reason"].is_string()) return Invalid("alignment.fallback_reason must be a string");
    r.fallback_reason = j["fallback_reason"].get<std::string>();
  }
  if (j.contains("reference_frame")) {
    if (!j["reference_frame"].is_number_integer()) return Invalid("alignment.reference_frame must be an integer");
    const int64_t ref = j["reference_frame"].get<int64_t>();
    if (ref < 0 || ref >= int64_t(frame_count)) {
      return Invalid("alignment.reference_frame " + std::to_string(ref) + " is not a frame of the stack (0.." +
                     std::to_string(frame_count - 1) + ")");
    }
    r.reference_frame = int(ref);
  }
  const std::pair<const char*, double*> figures[] = {
      {"max_scale_change_percent", &r.max_scale_change_percent},
      {"max_shift_px", &r.max_shift_px},
      {"seen_by_every_frame_percent", &r.seen_by_every_frame_percent},
      {"max_corner_displacement_px", &r.max_corner_displacement_px}};
  for (const auto& [key, out] : figures) {
    if (!j.contains(key)) continue;
    INSPECT_RETURN_IF_ERROR(AlignmentNumber(j, "", key, out));
    if (*out < 0) return Invalid(std::string("alignment.") + key + " must be >= 0");
  }
  if (!j.contains("frames")) return r;
  if (!j["frames"].is_array()) return Invalid("alignment.frames must be an array");
  const json& frames = j["frames"];
  if (!frames.empty() && frames.size() != frame_count) {
    return Invalid("alignment.frames has " + std::to_string(frames.size()) + " transforms for " +
                   std::to_string(frame_count) + " frames (one per frame, or none)");
  }
  for (size_t i = 0; i < frames.size(); ++i) {
    const json& f = frames[i];
    const std::string at = "frames[" + std::to_string(i) + "].";
    if (!f.is_object()) return Invalid("alignment.frames[" + std::to_string(i) + "] must be an object");
    StackFrameTransform t;
    if (!f.contains("frame") || !f["frame"].is_number_integer() || f["frame"].get<int64_t>() != int64_t(i)) {
      return Invalid("alignment." + at + "frame must be " + std::to_string(i) + " (z order)");
    }
    t.frame = int(i);
    INSPECT_RETURN_IF_ERROR(AlignmentNumber(f, at, "scale", &t.scale));
    if (!(t.scale > 0)) return Invalid("alignment." + at + "scale must be > 0");
    INSPECT_RETURN_IF_ERROR(AlignmentNumber(f, at, "rotation_deg", &t.rotation_deg));
    INSPECT_RETURN_IF_ERROR(AlignmentNumber(f, at, "shift_x_px", &t.shift_x_px));
    INSPECT_RETURN_IF_ERROR(AlignmentNumber(f, at, "shift_y_px", &t.shift_y_px));
    if (!f.contains("affine") || !f["affine"].is_array() || f["affine"].size() != 6) {
      return Invalid("alignment." + at + "affine must be an array of 6 numbers (row-major 2x3)");
    }
    for (size_t k = 0; k < 6; ++k) {
      const json& v = f["affine"][k];
      if (!v.is_number() || !std::isfinite(v.get<double>())) {
        return Invalid("alignment." + at + "affine[" + std::to_string(k) + "] must be a finite number");
      }
      t.affine[k] = v.get<double>();
    }
    r.frames.push_back(t);
  }
  return r;
}

json AlignmentRecordJson(const StackAlignmentRecord& r) {
  json j = {{"alignment", r.alignment},
            {"method", r.method},
            {"still", r.still},
            {"reference_frame", r.reference_frame},
            {"max_scale_change_percent", r.max_scale_change_percent},
            {"max_shift_px", r.max_shift_px},
            {"seen_by_every_frame_percent", r.seen_by_every_frame_percent},
            {"max_corner_displacement_px", r.max_corner_displacement_px}};
  if (!r.fallback_reason.empty()) j["fallback_reason"] = r.fallback_reason;
  j["frames"] = json::array();
  for (const StackFrameTransform& t : r.frames) {
    j["frames"].push_back({{"frame", t.frame},
                           {"scale", t.scale},
                           {"rotation_deg", t.rotation_deg},
                           {"shift_x_px", t.shift_x_px},
                           {"shift_y_px", t.shift_y_px},
                           {"affine", t.affine}});
  }
  return j;
}

}  // namespace

std::string FrameFileFormat(std::string_view file) {
  const size_t dot = file.rfind('.');
  if (dot == std::string_view::npos || file.find('/', dot) != std::string_view::npos) return "";
  std::string ext(file.substr(dot + 1));
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (ext == "png") return "PNG";
  if (ext == "tif" || ext == "tiff") return "TIFF";
  if (ext == "jpg" || ext == "jpeg") return "JPEG";
  if (IsRawFrameFile(file)) {
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::toupper(c)); });
    return "camera RAW (" + ext + ")";
  }
  return "";
}

Status CheckOneFrameFormat(const StackManifest& m) {
  // Mixed formats in one stack (a JPEG among PNGs, a NEF among DNGs) are almost always a stray
  // file in the folder; their grey values are not comparable (lossy coding, another camera's
  // processing) even when the sizes agree. Files without a known extension are decoded by their
  // content and not compared here.
  std::string first;
  size_t first_index = 0;
  for (size_t i = 0; i < m.frames.size(); ++i) {
    const std::string format = FrameFileFormat(m.frames[i].file);
    if (format.empty()) continue;
    if (first.empty()) {
      first = format;
      first_index = i;
    } else if (format != first) {
      return Invalid("frames[" + std::to_string(i) + "].file '" + m.frames[i].file + "' is " + format +
                     " but frames[" + std::to_string(first_index) + "].file '" + m.frames[first_index].file +
                     "' is " + first + "; the frames of a stack share one format");
    }
  }
  return Status::Ok();
}

Status CheckMonotonicZ(const std::vector<double>& z_um) {
  if (z_um.size() < 2) return Status::Ok();
  const bool increasing = z_um[1] > z_um[0];
  for (size_t i = 1; i < z_um.size(); ++i) {
    const double dz = z_um[i] - z_um[i - 1];
    if (dz == 0.0) {
      return Status::InvalidArgument("frames[" + std::to_string(i) + "].z_um " + std::to_string(z_um[i]) +
                                     " duplicates frames[" + std::to_string(i - 1) + "]");
    }
    if ((dz > 0) != increasing) {
      return Status::InvalidArgument("frames[" + std::to_string(i) + "].z_um " + std::to_string(z_um[i]) +
                                     " breaks the monotonic z order of the stack");
    }
  }
  return Status::Ok();
}

StatusOr<StackManifest> ParseStackManifest(const std::string& json_text) {
  json j = json::parse(json_text, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded()) return Invalid("not valid JSON");
  if (!j.is_object()) return Invalid("top level must be an object");

  StackManifest m;
  if (j.contains("version")) {
    if (!j["version"].is_number_integer()) return Invalid("version must be an integer");
    m.version = j["version"].get<int>();
    if (m.version != 1) return Invalid("version " + std::to_string(m.version) + " is not supported (expected 1)");
  }
  // Optional: stacks from other cameras often have no known scale. Missing = 0 = unknown (depth
  // stays in the z unit; lateral outputs count pixels); when given it must be a real size.
  if (j.contains("pixel_size_um")) {
    if (!j["pixel_size_um"].is_number()) return Invalid("pixel_size_um must be a number (or left out: unknown scale)");
    m.pixel_size_um = j["pixel_size_um"].get<double>();
    if (!(m.pixel_size_um > 0.0) || !std::isfinite(m.pixel_size_um)) {
      return Invalid("pixel_size_um must be > 0 (or left out: unknown scale)");
    }
  }
  if (j.contains("bit_depth")) {
    if (!j["bit_depth"].is_number_integer()) return Invalid("bit_depth must be an integer");
    m.bit_depth = j["bit_depth"].get<int>();
    if (m.bit_depth < 8 || m.bit_depth > 16) return Invalid("bit_depth must be between 8 and 16");
  }
  auto opt_string = [&](const char* key, std::string& out) -> Status {
    if (!j.contains(key) || j[key].is_null()) return Status::Ok();
    if (!j[key].is_string()) return Invalid(std::string(key) + " must be a string");
    out = j[key].get<std::string>();
    return Status::Ok();
  };
  INSPECT_RETURN_IF_ERROR(opt_string("specimen", m.specimen));
  INSPECT_RETURN_IF_ERROR(opt_string("calibration_id", m.calibration_id));
  INSPECT_RETURN_IF_ERROR(opt_string("illumination", m.illumination));
  INSPECT_RETURN_IF_ERROR(opt_string("illumination_decision", m.illumination_decision));

  if (!j.contains("frames") || !j["frames"].is_array()) return Invalid("frames is missing or not an array");
  const json& frames = j["frames"];
  if (frames.size() < 3)
    return Invalid("frames has " + std::to_string(frames.size()) + " entries; shape from focus needs at least 3");
  std::vector<double> z;
  for (size_t i = 0; i < frames.size(); ++i) {
    const json& f = frames[i];
    const std::string at = "frames[" + std::to_string(i) + "]";
    if (!f.is_object()) return Invalid(at + " must be an object");
    if (!f.contains("file") || !f["file"].is_string()) return Invalid(at + ".file is missing or not a string");
    if (!f.contains("z_um") || !f["z_um"].is_number()) return Invalid(at + ".z_um is missing or not a number");
    StackFrame sf;
    sf.file = f["file"].get<std::string>();
    INSPECT_RETURN_IF_ERROR(CheckRelativeFile(sf.file, i));
    sf.z_um = f["z_um"].get<double>();
    if (!std::isfinite(sf.z_um)) return Invalid(at + ".z_um must be finite");
    if (f.contains("exposure_us")) {
      if (!f["exposure_us"].is_number()) return Invalid(at + ".exposure_us must be a number");
      sf.exposure_us = f["exposure_us"].get<double>();
      if (sf.exposure_us < 0) return Invalid(at + ".exposure_us must be >= 0");
    }
    if (f.contains("pattern")) {
      if (!f["pattern"].is_string()) return Invalid(at + ".pattern must be a string");
      sf.pattern = f["pattern"].get<std::string>();
    }
    z.push_back(sf.z_um);
    m.frames.push_back(std::move(sf));
  }
  Status mono = CheckMonotonicZ(z);
  if (!mono.ok()) return Invalid(mono.message());
  INSPECT_RETURN_IF_ERROR(CheckOneFrameFormat(m));
  if (j.contains("alignment") && !j["alignment"].is_null()) {
    INSPECT_ASSIGN_OR_RETURN(m.alignment, ParseAlignmentRecord(j["alignment"], m.frames.size()));
  }
  return m;
}

StatusOr<StackManifest> ReadStackManifest(const fs::path& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return Status::InvalidArgument("stack folder '" + dir.string() + "' does not exist");
  const fs::path path = dir / kStackManifestName;
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::InvalidArgument("stack.json is missing in '" + dir.string() + "'");
  std::stringstream ss;
  ss << in.rdbuf();
  INSPECT_ASSIGN_OR_RETURN(StackManifest m, ParseStackManifest(ss.str()));
  for (size_t i = 0; i < m.frames.size(); ++i) {
    if (!fs::is_regular_file(dir / m.frames[i].file, ec)) {
      return Status::InvalidArgument("frame " + std::to_string(i) + " (" + m.frames[i].file + "): file is missing");
    }
  }
  return m;
}

Status WriteStackManifest(const fs::path& dir, const StackManifest& m) {
  json j;
  j["format"] = "inspection-stack";
  j["version"] = m.version;
  if (m.pixel_size_um > 0.0) j["pixel_size_um"] = m.pixel_size_um;  // 0 = unknown: left out
  j["bit_depth"] = m.bit_depth;
  if (!m.specimen.empty()) j["specimen"] = m.specimen;
  if (!m.calibration_id.empty()) j["calibration_id"] = m.calibration_id;
  if (!m.illumination.empty()) j["illumination"] = m.illumination;
  if (!m.illumination_decision.empty()) j["illumination_decision"] = m.illumination_decision;
  j["frames"] = json::array();
  for (const auto& f : m.frames) {
    json jf = {{"file", f.file}, {"z_um", f.z_um}, {"exposure_us", f.exposure_us}};
    if (!f.pattern.empty()) jf["pattern"] = f.pattern;
    j["frames"].push_back(std::move(jf));
  }
  if (const auto& r = m.z_range_search) {
    json jr = {{"window_start_um", r->window_start_um},
               {"window_end_um", r->window_end_um},
               {"coarse_step_um", r->coarse_step_um},
               {"margin_um", r->margin_um},
               {"focus_low_um", r->focus_low_um},
               {"focus_high_um", r->focus_high_um},
               {"resolved_percent", r->resolved_percent},
               {"settled_percent", r->settled_percent},
               {"stopped_early", r->stopped_early},
               {"z_start_um", r->z_start_um},
               {"z_end_um", r->z_end_um},
               {"search_seconds", r->search_seconds}};
    auto search_frames = [](const std::vector<StackFrame>& frames) {
      json list = json::array();
      for (const auto& f : frames) {
        list.push_back({{"file", f.file}, {"z_um", f.z_um}, {"exposure_us", f.exposure_us}, {"pattern", f.pattern}});
      }
      return list;
    };
    jr["coarse_frames"] = search_frames(r->coarse_frames);
    jr["refine_frames"] = search_frames(r->refine_frames);
    j["z_range_search"] = std::move(jr);
  }
  if (m.alignment) j["alignment"] = AlignmentRecordJson(*m.alignment);
  const fs::path tmp = dir / (std::string(kStackManifestName) + ".tmp");
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) return Status::Internal("cannot write " + tmp.string());
    out << j.dump(2) << "\n";
    if (!out.flush()) return Status::Internal("cannot write " + tmp.string());
  }
  std::error_code ec;
  fs::rename(tmp, dir / kStackManifestName, ec);
  if (ec) return Status::Internal("cannot rename " + tmp.string() + ": " + ec.message());
  return Status::Ok();
}

namespace {

std::string FrameName(const StackManifest& m, size_t index) {
  return "frame " + std::to_string(index) + " (" + m.frames[index].file + ")";
}

// The checks every decoded frame passes (a failed decode is an empty image): CV_8U or CV_16U, 1
// or 3 channels. Shared by the file and the in-memory decode, so their errors are the same.
StatusOr<cv::Mat> CheckDecodedFrame(const std::string& name, cv::Mat img) {
  if (img.empty()) return Status::InvalidArgument(name + ": cannot decode image (expected PNG, TIFF or JPEG)");
  if (img.channels() != 1 && img.channels() != 3) {
    return Status::InvalidArgument(name + ": has " + std::to_string(img.channels()) +
                                   " channels; frames must be grey (1 channel) or colour (3 channels)");
  }
  if (img.depth() != CV_8U && img.depth() != CV_16U) {
    return Status::InvalidArgument(name + ": pixel type must be 8- or 16-bit unsigned");
  }
  return img;
}

bool HasJpegSignature(std::string_view bytes) {
  return bytes.size() >= 3 && static_cast<unsigned char>(bytes[0]) == 0xFF &&
         static_cast<unsigned char>(bytes[1]) == 0xD8 && static_cast<unsigned char>(bytes[2]) == 0xFF;
}

// cv::IMREAD_UNCHANGED keeps depth and channels but ignores a JPEG's EXIF orientation; for JPEGs
// (never 16-bit, never with alpha) any depth and any colour keep the same pixels and apply the
// orientation, as a photo viewer shows the frame.
int ReadFlags(std::string_view signature) {
  return HasJpegSignature(signature) ? (cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR) : cv::IMREAD_UNCHANGED;
}

// Decodes a frame as stored: CV_8U or CV_16U, 1 or 3 channels; camera RAW through LibRaw.
StatusOr<cv::Mat> DecodeFrame(const fs::path& dir, const StackManifest& m, size_t index) {
  if (index >= m.frames.size()) return Status::OutOfRange("frame index " + std::to_string(index));
  const std::string name = FrameName(m, index);
  const fs::path path = dir / m.frames[index].file;
  if (IsRawFrameFile(m.frames[index].file)) {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat raw, DecodeRawFrameFile(path.string(), name));
    return CheckDecodedFrame(name, std::move(raw));
  }
  char signature[3] = {};
  {
    std::ifstream in(path, std::ios::binary);
    in.read(signature, sizeof signature);
  }
  cv::Mat img;
  try {
    img = cv::imread(path.string(), ReadFlags(std::string_view(signature, sizeof signature)));
  } catch (const cv::Exception& e) {
    return Status::InvalidArgument(name + ": cannot decode: " + e.what());
  }
  return CheckDecodedFrame(name, std::move(img));
}

const char* ChannelsName(int channels) { return channels == 3 ? "colour (3 channels)" : "grey"; }

}  // namespace

StatusOr<StackFrameImage> LoadStackFrameImage(const fs::path& dir, const StackManifest& m, size_t index) {
  INSPECT_ASSIGN_OR_RETURN(cv::Mat img, DecodeFrame(dir, m, index));
  StackFrameImage out;
  if (img.channels() == 3) {
    out.colour = img;
    INSPECT_ASSIGN_OR_RETURN(out.grey, LuminanceOf(img));
  } else {
    out.grey = img;
  }
  return out;
}

StatusOr<cv::Mat> LoadStackFrame(const fs::path& dir, const StackManifest& m, size_t index) {
  INSPECT_ASSIGN_OR_RETURN(cv::Mat img, DecodeFrame(dir, m, index));
  return LuminanceOf(img);  // grey frames as they are
}

StatusOr<cv::Mat> DecodeStackFrame(const fs::path& dir, const StackManifest& m, size_t index) {
  return DecodeFrame(dir, m, index);
}

StatusOr<cv::Mat> DecodeStackFrameBytes(std::string_view file, const StackManifest& m, size_t index) {
  if (index >= m.frames.size()) return Status::OutOfRange("frame index " + std::to_string(index));
  const std::string name = FrameName(m, index);
  if (IsRawFrameFile(m.frames[index].file)) {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat raw, DecodeRawFrame(file, name));
    return CheckDecodedFrame(name, std::move(raw));
  }
  cv::Mat img;
  try {
    // imdecode reads the buffer only; the header is a view, no copy.
    const cv::Mat buffer(1, int(file.size()), CV_8UC1, const_cast<char*>(file.data()));
    if (!file.empty()) img = cv::imdecode(buffer, ReadFlags(file));
  } catch (const cv::Exception& e) {
    return Status::InvalidArgument(name + ": cannot decode: " + e.what());
  }
  return CheckDecodedFrame(name, std::move(img));
}

Status CheckStackFrameShape(const StackManifest& m, size_t index, const StackFrameShape& first,
                            const StackFrameShape& shape) {
  if (index == 0) {
    if (m.bit_depth > 8 && shape.depth == CV_8U) {
      return Status::InvalidArgument(FrameName(m, 0) + ": 8-bit image but stack.json bit_depth is " +
                                     std::to_string(m.bit_depth));
    }
    return Status::Ok();
  }
  const std::string name = FrameName(m, index);
  if (shape.size != first.size) {
    return Status::InvalidArgument(name + ": size " + std::to_string(shape.size.width) + "x" +
                                   std::to_string(shape.size.height) + " differs from frame 0 (" +
                                   std::to_string(first.size.width) + "x" + std::to_string(first.size.height) + ")");
  }
  if (shape.channels != first.channels) {
    return Status::InvalidArgument(name + ": " + ChannelsName(shape.channels) + " differs from frame 0 (" +
                                   ChannelsName(first.channels) + ")");
  }
  if (shape.depth != first.depth) {
    return Status::InvalidArgument(name + ": bit depth " + (shape.depth == CV_8U ? "8" : "16") +
                                   " differs from frame 0 (" + (first.depth == CV_8U ? "8" : "16") + ")");
  }
  return Status::Ok();
}

Status ValidateStackFrames(const fs::path& dir, const StackManifest& m) {
  StackFrameShape first;
  for (size_t i = 0; i < m.frames.size(); ++i) {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat img, DecodeFrame(dir, m, i));
    const StackFrameShape shape = StackFrameShape::Of(img);
    if (i == 0) first = shape;
    INSPECT_RETURN_IF_ERROR(CheckStackFrameShape(m, i, first, shape));
  }
  return Status::Ok();
}

}  // namespace inspection
