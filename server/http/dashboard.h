// Dashboard: inspectd's read-only web view on the HTTP port. The page (assets/, compiled in)
// polls JSON endpoints, so it refreshes without a reload:
//   GET /api/status                rig state and devices (null with --no-rig), queue and running jobs
//   GET /api/live                  latest event of each unfinished job (frame counter, z, frame statistics)
//   GET /api/jobs?limit=N          recent jobs, newest first, with result summaries (N <= 100, default 20)
//   GET /api/jobs/ID/frame.png     thumbnail of the newest stored frame of a running scan
//   GET /api/jobs/ID/preview.png   depth preview (colour map) of a finished job
// Jobs and results are the same protobuf messages as on gRPC, as proto3 JSON.
// Thread-safe: the JSON handlers run on the HTTP server's threads, OnJobEvent on job threads.
#pragma once

#include <map>
#include <mutex>
#include <string>

#include "inspection/v1/inspection.pb.h"
#include "server/storage/calibration_store.h"
#include "server/storage/data_store.h"
#include "server/http/http_endpoint.h"
#include "server/jobs/job_manager.h"
#include "server/jobs/rig_controller.h"

namespace inspection {

struct DashboardSources {
  DataStore* store = nullptr;
  JobManager* jobs = nullptr;
  RigController* rig = nullptr;  // null with --no-rig
  CalibrationStore* calibrations = nullptr;
  std::string server_version;
};

class Dashboard {
 public:
  Dashboard() = default;
  // Before AddRoutes: the server's parts exist only after the JobManager, which already feeds
  // OnJobEvent.
  void SetSources(DashboardSources sources) { sources_ = std::move(sources); }

  // Every job event as the JobManager records it (see ServerMetrics::OnJobEvent).
  void OnJobEvent(const v1::JobEvent& event);
  // Adds the page, its assets and the /api routes.
  void AddRoutes(HttpEndpoint& endpoint);

  // The handlers' bodies, public for tests.
  std::string StatusJson();
  std::string LiveJson();
  std::string JobsJson(int limit);

 private:
  DashboardSources sources_;

  struct LiveJob {
    v1::JobEvent last_event;        // without the job (terminal events end the entry)
    v1::JobEvent last_frame_event;  // the newest event with frame progress
    int64_t frame_events = 0;       // frame events so far: the live view's advancing counter
  };
  std::mutex mu_;  // guards live_
  std::map<std::string, LiveJob> live_;
};

// A frame image scaled to at most `max_width_px` wide, 8-bit, as PNG bytes; empty on failure.
std::string ThumbnailPng(const std::string& image_path, int max_width_px);

}  // namespace inspection
