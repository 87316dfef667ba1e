// MetricsRegistry: counters, gauges and histograms with labels, kept and rendered in the
// Prometheus text exposition format 0.0.4 (what inspectd's /metrics serves) by prometheus-cpp
// (Debian prometheus-cpp-dev, its core library only: the HTTP side is inspectd's own port).
// No global registry: the server owns one, so tests and several servers in one process never
// share counts.
// Thread-safe: prometheus-cpp's families and metrics are (a label lookup takes the family's mutex,
// updates are atomic); a scrape reads each series once.
#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace prometheus {
class Registry;
class Counter;
class Gauge;
class Histogram;
template <typename T>
class Family;
}  // namespace prometheus

namespace inspection {

// Label values in the order of the family's label names.
using LabelValues = std::vector<std::string>;

class MetricsRegistry;

namespace metrics_detail {
// What the registry keeps of a family beside prometheus-cpp's: its label names in declaration
// order (prometheus-cpp keeps labels in a name-sorted map) and its place in the exposition.
struct FamilyInfo {
  std::string name;
  std::vector<std::string> label_names;
  std::vector<double> upper_bounds;  // histograms
  size_t order = 0;
};
}  // namespace metrics_detail

// Handles to one metric family; cheap to copy, valid while the registry lives.
class Counter {
 public:
  // Adds `value` (>= 0; a negative value is ignored: counters only go up).
  void Add(const LabelValues& labels, double value = 1.0) const;
  double Value(const LabelValues& labels) const;  // 0 for a series never touched (not created)

 private:
  friend class MetricsRegistry;
  Counter(prometheus::Family<prometheus::Counter>* family, const metrics_detail::FamilyInfo* info)
      : family_(family), info_(info) {}
  prometheus::Family<prometheus::Counter>* family_;
  const metrics_detail::FamilyInfo* info_;
};

class Gauge {
 public:
  void Set(const LabelValues& labels, double value) const;
  double Value(const LabelValues& labels) const;  // 0 for a series never set (not created)
  // Drops the series (no sample until it is set again): for a value that no longer exists,
  // which a stale number would misreport. No-op for a series never set.
  void Remove(const LabelValues& labels) const;

 private:
  friend class MetricsRegistry;
  Gauge(prometheus::Family<prometheus::Gauge>* family, const metrics_detail::FamilyInfo* info)
      : family_(family), info_(info) {}
  prometheus::Family<prometheus::Gauge>* family_;
  const metrics_detail::FamilyInfo* info_;
};

class Histogram {
 public:
  void Observe(const LabelValues& labels, double value) const;
  uint64_t Count(const LabelValues& labels) const;  // 0 for a series never observed (not created)

 private:
  friend class MetricsRegistry;
  Histogram(prometheus::Family<prometheus::Histogram>* family, const metrics_detail::FamilyInfo* info)
      : family_(family), info_(info) {}
  prometheus::Family<prometheus::Histogram>* family_;
  const metrics_detail::FamilyInfo* info_;
};

class MetricsRegistry {
 public:
  MetricsRegistry();
  ~MetricsRegistry();
  MetricsRegistry(const MetricsRegistry&) = delete;
  MetricsRegistry& operator=(const MetricsRegistry&) = delete;

  // Declares a family. Names and label names must be valid Prometheus names (checked with
  // prometheus-cpp's rules, and "le" is reserved: a bad name is a programming error and aborts
  // at start-up, never at scrape time). A family without labels has its one series from the
  // start, so a scrape reports 0 rather than nothing before the first event; a labelled family
  // shows a series once it has been updated. Families render in declaration order, series in
  // label-value order, labels in the declared order.
  Counter AddCounter(std::string name, std::string help, std::vector<std::string> label_names = {});
  Gauge AddGauge(std::string name, std::string help, std::vector<std::string> label_names = {});
  // `upper_bounds` strictly increasing; the +Inf bucket is implicit. A value on a bound counts
  // in that bucket (le is <=).
  Histogram AddHistogram(std::string name, std::string help, std::vector<double> upper_bounds,
                         std::vector<std::string> label_names = {});

  // The whole registry in the text exposition format (Content-Type kContentType), as
  // prometheus-cpp's TextSerializer writes it.
  std::string Render() const;

  static constexpr const char* kContentType = "text/plain; version=0.0.4; charset=utf-8";

 private:
  const metrics_detail::FamilyInfo* Declare(std::string name, std::vector<std::string> label_names,
                                            std::vector<double> upper_bounds);

  std::unique_ptr<prometheus::Registry> registry_;
  mutable std::mutex mu_;                         // guards infos_ and by_name_
  std::deque<metrics_detail::FamilyInfo> infos_;  // stable addresses for the handles
  std::map<std::string, const metrics_detail::FamilyInfo*> by_name_;
};

}  // namespace inspection
