// MetricsRegistry: counters, gauges and histograms with labels, rendered in the Prometheus text
// exposition format 0.0.4 (what inspectd's /metrics serves). No global registry: the server owns
// one, so tests and several servers in one process never share counts.
// Thread-safe: every update and Render take the registry's one mutex (updates are a map lookup
// and an add; scrapes are rare), which keeps a scrape consistent across series.
#pragma once

#include <map>
#include <mutex>
#include <string>
#include <string_view>
#include <vector>

namespace inspection {

// Label values in the order of the family's label names.
using LabelValues = std::vector<std::string>;

class MetricsRegistry;

// Handles to one metric family; cheap to copy, valid while the registry lives.
class Counter {
 public:
  // Adds `value` (>= 0; a negative value is ignored: counters only go up).
  void Add(const LabelValues& labels, double value = 1.0) const;
  double Value(const LabelValues& labels) const;  // 0 for a series never touched

 private:
  friend class MetricsRegistry;
  Counter(MetricsRegistry* registry, size_t family) : registry_(registry), family_(family) {}
  MetricsRegistry* registry_;
  size_t family_;
};

class Gauge {
 public:
  void Set(const LabelValues& labels, double value) const;
  double Value(const LabelValues& labels) const;

 private:
  friend class MetricsRegistry;
  Gauge(MetricsRegistry* registry, size_t family) : registry_(registry), family_(family) {}
  MetricsRegistry* registry_;
  size_t family_;
};

class Histogram {
 public:
  void Observe(const LabelValues& labels, double value) const;
  uint64_t Count(const LabelValues& labels) const;

 private:
  friend class MetricsRegistry;
  Histogram(MetricsRegistry* registry, size_t family) : registry_(registry), family_(family) {}
  MetricsRegistry* registry_;
  size_t family_;
};

class MetricsRegistry {
 public:
  MetricsRegistry() = default;
  MetricsRegistry(const MetricsRegistry&) = delete;
  MetricsRegistry& operator=(const MetricsRegistry&) = delete;

  // Declares a family. Names and label names must be valid Prometheus names (checked: a bad
  // name is a programming error and aborts at start-up, never at scrape time). Families render
  // in declaration order, series in label-value order.
  Counter AddCounter(std::string name, std::string help, std::vector<std::string> label_names = {});
  Gauge AddGauge(std::string name, std::string help, std::vector<std::string> label_names = {});
  // `upper_bounds` strictly increasing; the +Inf bucket is implicit.
  Histogram AddHistogram(std::string name, std::string help, std::vector<double> upper_bounds,
                         std::vector<std::string> label_names = {});

  // The whole registry in the text exposition format (Content-Type kContentType).
  std::string Render() const;

  static constexpr const char* kContentType = "text/plain; version=0.0.4; charset=utf-8";

 private:
  friend class Counter;
  friend class Gauge;
  friend class Histogram;

  enum class Type { kCounter, kGauge, kHistogram };
  struct Series {
    double value = 0.0;                   // counter, gauge
    std::vector<uint64_t> bucket_counts;  // histogram: per bucket, not cumulative
    double sum = 0.0;
    uint64_t count = 0;
  };
  struct Family {
    std::string name, help;
    Type type;
    std::vector<std::string> label_names;
    std::vector<double> upper_bounds;
    std::map<LabelValues, Series> series;
  };

  size_t Add(Family family);
  // The series for `labels` (created on first use). Caller holds mu_. A label count that does
  // not match the family is a programming error: the update goes to a series named by the
  // values given, padded or cut to the family's labels, so a scrape never fails over it.
  Series& SeriesLocked(size_t family, const LabelValues& labels);

  mutable std::mutex mu_;  // guards families_
  std::vector<Family> families_;
};

// Exposition helpers, public for the tests: a sample value ("3", "0.25", "+Inf", "NaN") and a
// label value with \\, \" and \n escaped.
std::string FormatMetricValue(double value);
std::string EscapeLabelValue(std::string_view value);

}  // namespace inspection
