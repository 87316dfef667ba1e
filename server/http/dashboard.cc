// The dashboard's JSON endpoints, thumbnails and static assets (dashboard.h).
#include "server/http/dashboard.h"

#include <google/protobuf/util/json_util.h>
#include <httplib.h>

#include <algorithm>
#include <charconv>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "server/http/dashboard_assets.h"
#include "server/jobs/rig_verification.h"

namespace inspection {
namespace fs = std::filesystem;

namespace {

using Json = nlohmann::ordered_json;

// A message as proto3 JSON (the gRPC API's field names in lowerCamelCase, enums by name), so
// the page reads the same fields as any client of the proto.
Json ProtoJson(const google::protobuf::Message& m) {
  std::string text;
  google::protobuf::util::JsonPrintOptions options;
  options.always_print_primitive_fields = true;
  if (!google::protobuf::util::MessageToJsonString(m, &text, options).ok()) return nullptr;
  return Json::parse(text, nullptr, /*allow_exceptions=*/false);
}

std::string FrameName(int index) {
  char name[32];
  std::snprintf(name, sizeof(name), "frame_%04d.png", index);
  return name;
}

void SendJson(httplib::Response& res, const std::string& body) {
  res.set_content(body, "application/json; charset=utf-8");
}

void SendError(httplib::Response& res, int status, const std::string& message) {
  res.status = status;
  res.set_content(message + "\n", "text/plain; charset=utf-8");
}

}  // namespace

std::string ThumbnailPng(const std::string& image_path, int max_width_px) {
  cv::Mat image = cv::imread(image_path, cv::IMREAD_UNCHANGED);
  if (image.empty()) return {};
  if (image.depth() == CV_16U) image.convertTo(image, CV_8U, 1.0 / 257.0);  // full 16-bit range onto 0..255
  if (image.cols > max_width_px) {
    const double scale = double(max_width_px) / image.cols;
    cv::resize(image, image, cv::Size(), scale, scale, cv::INTER_AREA);
  }
  std::vector<uchar> png;
  if (!cv::imencode(".png", image, png)) return {};
  return std::string(png.begin(), png.end());
}

void Dashboard::OnJobEvent(const v1::JobEvent& e) {
  std::lock_guard<std::mutex> lock(mu_);
  if (e.has_job()) {  // terminal: the job appears in /api/jobs from now on
    live_.erase(e.job_id());
    return;
  }
  LiveJob& j = live_[e.job_id()];
  j.last_event = e;
  if (e.has_frame()) {
    j.last_frame_event = e;
    ++j.frame_events;
  }
}

std::string Dashboard::StatusJson() {
  Json out;
  out["server_version"] = sources_.server_version;
  out["no_rig"] = sources_.rig == nullptr;
  if (sources_.rig) {
    v1::RigStatus st;
    sources_.rig->FillStatus(&st);
    if (sources_.calibrations) {
      st.set_active_calibration_id(sources_.calibrations->active_id());
      if (StatusOr<RigVerification> v =
              ReadRigVerification(*sources_.store, st.active_calibration_id(), CurrentTimestamp());
          v.ok()) {
        st.set_verification_state(v->state);
        st.set_verification_detail(v->detail);
      }
    }
    st.set_running_job_id(sources_.jobs->running_rig_job());
    st.set_queued_jobs(sources_.jobs->queued_rig_jobs());
    st.set_queue_capacity(sources_.jobs->rig_queue_capacity());
    st.set_server_version(sources_.server_version);
    out["rig"] = ProtoJson(st);
  } else {
    out["rig"] = nullptr;
  }
  // The queue: unfinished jobs oldest first, with their live state where it is fresher.
  Json queue = Json::array();
  auto unfinished = sources_.store->UnfinishedJobs();
  if (unfinished.ok()) {
    std::sort(unfinished->begin(), unfinished->end(), [](const v1::Job& a, const v1::Job& b) {
      return std::make_pair(a.create_time().seconds(), a.create_time().nanos()) <
             std::make_pair(b.create_time().seconds(), b.create_time().nanos());
    });
    for (const v1::Job& stored : *unfinished) {
      const std::shared_ptr<JobRecord> live = sources_.jobs->FindLive(stored.job_id());
      queue.push_back(ProtoJson(live ? live->Snapshot() : stored));
    }
  }
  out["queue"] = std::move(queue);
  return out.dump();
}

std::string Dashboard::LiveJson() {
  Json jobs = Json::array();
  std::lock_guard<std::mutex> lock(mu_);
  for (const auto& [id, j] : live_) {
    Json entry;
    entry["job_id"] = id;
    entry["frame_events"] = j.frame_events;
    entry["event"] = ProtoJson(j.last_event);
    entry["frame_event"] = j.frame_events > 0 ? ProtoJson(j.last_frame_event) : Json(nullptr);
    jobs.push_back(std::move(entry));
  }
  Json out;
  out["jobs"] = std::move(jobs);
  return out.dump();
}

std::string Dashboard::JobsJson(int limit) {
  Json jobs = Json::array();
  auto stored = sources_.store->ListJobs(v1::JOB_KIND_UNSPECIFIED, v1::JOB_STATE_UNSPECIFIED, limit, 0);
  if (stored.ok()) {
    for (const v1::Job& job : *stored) {
      const std::shared_ptr<JobRecord> live = sources_.jobs->FindLive(job.job_id());
      jobs.push_back(ProtoJson(live ? live->Snapshot() : job));
    }
  }
  Json out;
  out["jobs"] = std::move(jobs);
  return out.dump();
}

void Dashboard::AddRoutes(HttpEndpoint& endpoint) {
  for (const DashboardAsset& asset : DashboardAssets()) {
    endpoint.AddPublicRoute(std::string(asset.url_path), [&asset](const httplib::Request&, httplib::Response& res) {
      res.set_content(asset.body.data(), asset.body.size(), std::string(asset.content_type).c_str());
    });
  }
  endpoint.AddDataRoute("/api/status",
                        [this](const httplib::Request&, httplib::Response& res) { SendJson(res, StatusJson()); });
  endpoint.AddDataRoute("/api/live",
                        [this](const httplib::Request&, httplib::Response& res) { SendJson(res, LiveJson()); });
  endpoint.AddDataRoute("/api/jobs", [this](const httplib::Request& req, httplib::Response& res) {
    int limit = 20;
    if (req.has_param("limit")) {
      const std::string text = req.get_param_value("limit");
      const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), limit);
      if (ec != std::errc() || end != text.data() + text.size() || limit < 1 || limit > 100) {
        return SendError(res, 400, "limit must be a whole number 1..100");
      }
    }
    SendJson(res, JobsJson(limit));
  });
  // Job ids are letters, digits and '-' (data_store NewId): the pattern admits nothing that
  // could leave the data directory.
  endpoint.AddDataRoute(
      R"(/api/jobs/([A-Za-z0-9_-]+)/frame\.png)", [this](const httplib::Request& req, httplib::Response& res) {
        const std::string id = req.matches[1];
        int index = -1;
        {
          std::lock_guard<std::mutex> lock(mu_);
          auto it = live_.find(id);
          if (it == live_.end() || it->second.frame_events == 0) return SendError(res, 404, "no running scan " + id);
          const v1::JobEvent& f = it->second.last_frame_event;
          // During acquisition the reported frame is being captured and its file is written after
          // the event: the newest complete file is the one before it.
          const bool acquiring = it->second.last_event.phase() == v1::JOB_PHASE_ACQUIRING;
          index = f.frame().frame_index() - (acquiring ? 1 : 0);
        }
        if (index < 0) return SendError(res, 404, "no frame stored yet");
        for (const fs::path& dir : {sources_.store->tmp_dir() / (id + ".stack"), sources_.store->scans_dir() / id}) {
          std::string png = ThumbnailPng((dir / FrameName(index)).string(), 320);
          if (png.empty()) continue;
          res.set_header("X-Frame-Index", std::to_string(index));
          res.set_content(std::move(png), "image/png");
          return;
        }
        SendError(res, 404, "frame " + std::to_string(index) + " of " + id + " is not stored");
      });
  endpoint.AddDataRoute(
      R"(/api/jobs/([A-Za-z0-9_-]+)/preview\.png)", [this](const httplib::Request& req, httplib::Response& res) {
        auto record = sources_.jobs->Find(req.matches[1]);
        if (!record.ok()) return SendError(res, 404, record.status().message());
        const v1::Job job = (*record)->Snapshot();  // outlives the loop (a temporary's member would not)
        for (const v1::Artifact& a : job.result().artifacts()) {
          if (a.kind() != v1::ARTIFACT_KIND_DEPTH_PREVIEW_PNG) continue;
          auto stored = sources_.store->GetArtifact(a.artifact_id());
          if (!stored.ok()) break;
          std::string png = ThumbnailPng(stored->path.string(), 480);
          if (png.empty()) break;
          res.set_content(std::move(png), "image/png");
          return;
        }
        SendError(res, 404, "job has no depth preview");
      });
}

}  // namespace inspection
