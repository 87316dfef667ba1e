// Test helper shared by the JobManager tests: follows a job's event stream to its end.
#ifndef INSPECTION_TESTS_SERVER_JOBS_JOB_EVENTS_H_
#define INSPECTION_TESTS_SERVER_JOBS_JOB_EVENTS_H_

#include <gtest/gtest.h>

#include <chrono>
#include <memory>
#include <vector>

#include "server/jobs/job_manager.h"

namespace inspection {

// Every event of the job up to its terminal one; a failure (not a hang) when no new event comes
// within `deadline`.
inline std::vector<v1::JobEvent> WaitForJobEnd(const std::shared_ptr<JobRecord>& r,
                                               std::chrono::milliseconds deadline) {
  std::vector<v1::JobEvent> events;
  for (;;) {
    const size_t before = events.size();
    if (r->EventsSince(before, deadline, &events)) return events;
    if (events.size() == before) {
      ADD_FAILURE() << "job " << r->job_id() << " did not end";
      return events;
    }
  }
}

}  // namespace inspection

#endif  // INSPECTION_TESTS_SERVER_JOBS_JOB_EVENTS_H_
