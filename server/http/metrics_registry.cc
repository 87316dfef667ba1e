// inspectd's metrics on prometheus-cpp (metrics_registry.h): the families live in a
// prometheus::Registry; what this file adds is the label-value handles the server calls, the
// checks at declaration (so prometheus-cpp never throws at update or scrape time) and a stable
// exposition order.
#include "server/http/metrics_registry.h"

#include <prometheus/check_names.h>
#include <prometheus/counter.h>
#include <prometheus/family.h>
#include <prometheus/gauge.h>
#include <prometheus/histogram.h>
#include <prometheus/registry.h>
#include <prometheus/text_serializer.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <utility>

namespace inspection {

namespace {

[[noreturn]] void Die(const std::string& what) {
  std::fprintf(stderr, "MetricsRegistry: %s\n", what.c_str());
  std::abort();
}

// The family's labels for `values` in the order of its names. A count that does not match the
// family is a programming error: the update goes to a series named by the values given, padded
// with "" or cut to the family's labels, so a scrape never fails over it.
prometheus::Labels LabelsOf(const metrics_detail::FamilyInfo& info, const LabelValues& values) {
  prometheus::Labels labels;
  for (size_t i = 0; i < info.label_names.size(); ++i)
    labels.emplace(info.label_names[i], i < values.size() ? values[i] : std::string());
  return labels;
}

// HELP text as the exposition format wants it: backslash and newline escaped. prometheus-cpp
// 1.0.1 writes the help as given (a help with a newline came out as a stray line that breaks the
// scrape: MetricsRegistryTest), so it gets the escaped text.
std::string EscapeHelp(const std::string& help) {
  std::string out;
  for (char c : help) {
    if (c == '\\')
      out += "\\\\";
    else if (c == '\n')
      out += "\\n";
    else
      out += c;
  }
  return out;
}

}  // namespace

void Counter::Add(const LabelValues& labels, double value) const {
  if (!(value >= 0.0)) return;  // also NaN, which prometheus-cpp would add
  family_->Add(LabelsOf(*info_, labels)).Increment(value);
}

double Counter::Value(const LabelValues& labels) const {
  const prometheus::Labels l = LabelsOf(*info_, labels);
  return family_->Has(l) ? family_->Add(l).Value() : 0.0;
}

void Gauge::Set(const LabelValues& labels, double value) const { family_->Add(LabelsOf(*info_, labels)).Set(value); }

void Gauge::Remove(const LabelValues& labels) const {
  const prometheus::Labels l = LabelsOf(*info_, labels);
  if (family_->Has(l)) family_->Remove(&family_->Add(l));
}

double Gauge::Value(const LabelValues& labels) const {
  const prometheus::Labels l = LabelsOf(*info_, labels);
  return family_->Has(l) ? family_->Add(l).Value() : 0.0;
}

void Histogram::Observe(const LabelValues& labels, double value) const {
  family_->Add(LabelsOf(*info_, labels), info_->upper_bounds).Observe(value);
}

uint64_t Histogram::Count(const LabelValues& labels) const {
  const prometheus::Labels l = LabelsOf(*info_, labels);
  return family_->Has(l) ? family_->Add(l, info_->upper_bounds).Collect().histogram.sample_count : 0;
}

MetricsRegistry::MetricsRegistry() : registry_(std::make_unique<prometheus::Registry>()) {}
MetricsRegistry::~MetricsRegistry() = default;

const metrics_detail::FamilyInfo* MetricsRegistry::Declare(std::string name, std::vector<std::string> label_names,
                                                           std::vector<double> upper_bounds) {
  if (!prometheus::CheckMetricName(name)) Die("invalid metric name \"" + name + "\"");
  for (const auto& l : label_names) {
    if (!prometheus::CheckLabelName(l) || l == "le") Die("invalid label name \"" + l + "\" of " + name);
  }
  for (size_t i = 1; i < upper_bounds.size(); ++i) {
    if (!(upper_bounds[i] > upper_bounds[i - 1])) Die("bucket bounds of " + name + " must increase");
  }
  std::lock_guard<std::mutex> lock(mu_);
  if (by_name_.count(name)) Die("metric " + name + " declared twice");
  metrics_detail::FamilyInfo& info = infos_.emplace_back();
  info.name = std::move(name);
  info.label_names = std::move(label_names);
  info.upper_bounds = std::move(upper_bounds);
  info.order = infos_.size() - 1;
  by_name_[info.name] = &info;
  return &info;
}

Counter MetricsRegistry::AddCounter(std::string name, std::string help, std::vector<std::string> label_names) {
  const metrics_detail::FamilyInfo* info = Declare(name, std::move(label_names), {});
  auto& family = prometheus::BuildCounter().Name(info->name).Help(EscapeHelp(help)).Register(*registry_);
  if (info->label_names.empty()) family.Add({});
  return Counter(&family, info);
}

Gauge MetricsRegistry::AddGauge(std::string name, std::string help, std::vector<std::string> label_names) {
  const metrics_detail::FamilyInfo* info = Declare(name, std::move(label_names), {});
  auto& family = prometheus::BuildGauge().Name(info->name).Help(EscapeHelp(help)).Register(*registry_);
  if (info->label_names.empty()) family.Add({});
  return Gauge(&family, info);
}

Histogram MetricsRegistry::AddHistogram(std::string name, std::string help, std::vector<double> upper_bounds,
                                        std::vector<std::string> label_names) {
  const metrics_detail::FamilyInfo* info = Declare(name, std::move(label_names), std::move(upper_bounds));
  auto& family = prometheus::BuildHistogram().Name(info->name).Help(EscapeHelp(help)).Register(*registry_);
  if (info->label_names.empty()) family.Add({}, info->upper_bounds);
  return Histogram(&family, info);
}

std::string MetricsRegistry::Render() const {
  std::vector<prometheus::MetricFamily> families = registry_->Collect();
  {
    // prometheus-cpp collects by type and keeps a family's series in a hash map and their labels
    // sorted by name; the exposition keeps the declared orders instead, so two scrapes of the
    // same state are the same text and read like the declarations.
    std::lock_guard<std::mutex> lock(mu_);
    auto info_of = [&](const prometheus::MetricFamily& f) { return by_name_.at(f.name); };
    for (prometheus::MetricFamily& f : families) {
      const metrics_detail::FamilyInfo& info = *info_of(f);
      for (prometheus::ClientMetric& m : f.metric) {
        std::vector<prometheus::ClientMetric::Label> ordered;
        for (const std::string& name : info.label_names) {
          auto it = std::find_if(m.label.begin(), m.label.end(), [&](const auto& l) { return l.name == name; });
          if (it != m.label.end()) ordered.push_back(*it);
        }
        m.label = std::move(ordered);
      }
      std::stable_sort(f.metric.begin(), f.metric.end(), [](const auto& a, const auto& b) {
        return std::lexicographical_compare(a.label.begin(), a.label.end(), b.label.begin(), b.label.end(),
                                            [](const auto& x, const auto& y) { return x.value < y.value; });
      });
    }
    std::stable_sort(families.begin(), families.end(),
                     [&](const auto& a, const auto& b) { return info_of(a)->order < info_of(b)->order; });
  }
  return prometheus::TextSerializer().Serialize(families);
}

}  // namespace inspection
