// The dashboard's static files (server/http/assets/), compiled into inspectd by
// embed_assets.cmake so the binary serves them without files beside it or a CDN.
#pragma once

#include <string_view>
#include <vector>

namespace inspection {

struct DashboardAsset {
  std::string_view url_path;      // "/", "/dashboard.js", ...
  std::string_view content_type;  // "text/html; charset=utf-8", ...
  std::string_view body;
};

const std::vector<DashboardAsset>& DashboardAssets();

}  // namespace inspection
