// Camera RAW frames (DNG, CR2, CR3, NEF, ARW, RAF, ORF, RW2, PEF, ...) through LibRaw.
//
// What a RAW frame becomes: linear 16-bit colour after demosaicing (LibRaw's AHD), with the
// camera's white balance, sRGB primaries, no gamma and no automatic brightening, in the camera's
// orientation (the file's orientation flag). Why not the luminance of the raw mosaic: on a
// coloured specimen the colour filter array leaves a 2-pixel pattern in the mosaic whose
// amplitude depends on the colour, not on focus, and every gradient focus measure (thesis 3.1.3)
// reads it as texture that is sharp at every z; binning each 2x2 cell instead would halve the
// lateral resolution. Demosaiced, the frame is an ordinary 16-bit colour frame: focus is measured
// on its luminance (core/io/colour.h, here of linear values, proportional to the irradiance as
// the thesis' grey values are) and the all-in-focus image keeps the colour. Linear and unscaled,
// so frames of one stack keep their relative exposure (no per-frame auto-brightness).
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <string_view>

#include "core/util/status.h"

namespace inspection {

// True when the file name's extension is a camera RAW format LibRaw reads (case-insensitive).
bool IsRawFrameFile(std::string_view file_name);

// Decodes a RAW file's bytes: CV_16UC3, BGR (OpenCV's order), linear, as described above.
// INVALID_ARGUMENT naming `name` when LibRaw cannot open, unpack or process it.
StatusOr<cv::Mat> DecodeRawFrame(std::string_view bytes, const std::string& name);
// The same from a file.
StatusOr<cv::Mat> DecodeRawFrameFile(const std::string& path, const std::string& name);

}  // namespace inspection
