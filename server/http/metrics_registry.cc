// Prometheus text exposition (format 0.0.4) of inspectd's metrics (metrics_registry.h).
#include "server/http/metrics_registry.h"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <utility>

namespace inspection {

namespace {

bool ValidName(std::string_view name, bool allow_colon) {
  if (name.empty()) return false;
  for (size_t i = 0; i < name.size(); ++i) {
    const char c = name[i];
    const bool letter = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || c == '_' || (allow_colon && c == ':');
    if (!letter && !(i > 0 && c >= '0' && c <= '9')) return false;
  }
  return true;
}

void CheckNames(const std::string& name, const std::vector<std::string>& labels) {
  bool ok = ValidName(name, true);
  for (const auto& l : labels) ok = ok && ValidName(l, false) && l != "le" && l.rfind("__", 0) != 0;
  if (!ok) {
    std::fprintf(stderr, "MetricsRegistry: invalid metric or label name in %s\n", name.c_str());
    std::abort();
  }
}

std::string EscapeHelp(std::string_view help) {
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

// {a="x",b="y"} plus an optional extra label (le for buckets); empty when there are none.
std::string LabelText(const std::vector<std::string>& names, const LabelValues& values,
                      std::string_view extra_name = {}, std::string_view extra_value = {}) {
  std::string out;
  for (size_t i = 0; i < names.size(); ++i) {
    out += out.empty() ? "{" : ",";
    out += names[i] + "=\"" + EscapeLabelValue(values[i]) + "\"";
  }
  if (!extra_name.empty()) {
    out += out.empty() ? "{" : ",";
    out += std::string(extra_name) + "=\"" + std::string(extra_value) + "\"";
  }
  if (!out.empty()) out += "}";
  return out;
}

}  // namespace

std::string FormatMetricValue(double v) {
  if (std::isnan(v)) return "NaN";
  if (std::isinf(v)) return v > 0 ? "+Inf" : "-Inf";
  // Whole numbers print without a fraction ("3", not "3.0"): counts stay readable and exact
  // up to 2^53, where doubles stop holding every integer.
  if (v == std::floor(v) && std::fabs(v) < 9007199254740992.0) {
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%lld", static_cast<long long>(v));
    return buf;
  }
  char buf[64];
  auto [end, ec] = std::to_chars(buf, buf + sizeof(buf), v);  // shortest text that reads back exactly
  return ec == std::errc() ? std::string(buf, end) : "NaN";
}

std::string EscapeLabelValue(std::string_view value) {
  std::string out;
  for (char c : value) {
    if (c == '\\')
      out += "\\\\";
    else if (c == '"')
      out += "\\\"";
    else if (c == '\n')
      out += "\\n";
    else
      out += c;
  }
  return out;
}

size_t MetricsRegistry::Add(Family family) {
  CheckNames(family.name, family.label_names);
  std::lock_guard<std::mutex> lock(mu_);
  families_.push_back(std::move(family));
  return families_.size() - 1;
}

Counter MetricsRegistry::AddCounter(std::string name, std::string help, std::vector<std::string> label_names) {
  return Counter(this, Add({std::move(name), std::move(help), Type::kCounter, std::move(label_names), {}, {}}));
}

Gauge MetricsRegistry::AddGauge(std::string name, std::string help, std::vector<std::string> label_names) {
  return Gauge(this, Add({std::move(name), std::move(help), Type::kGauge, std::move(label_names), {}, {}}));
}

Histogram MetricsRegistry::AddHistogram(std::string name, std::string help, std::vector<double> upper_bounds,
                                        std::vector<std::string> label_names) {
  for (size_t i = 1; i < upper_bounds.size(); ++i) {
    if (!(upper_bounds[i] > upper_bounds[i - 1])) {
      std::fprintf(stderr, "MetricsRegistry: bucket bounds of %s must increase\n", name.c_str());
      std::abort();
    }
  }
  return Histogram(
      this,
      Add({std::move(name), std::move(help), Type::kHistogram, std::move(label_names), std::move(upper_bounds), {}}));
}

MetricsRegistry::Series& MetricsRegistry::SeriesLocked(size_t family, const LabelValues& labels) {
  Family& f = families_[family];
  LabelValues key = labels;
  key.resize(f.label_names.size());
  auto [it, inserted] = f.series.try_emplace(std::move(key));
  if (inserted && f.type == Type::kHistogram) it->second.bucket_counts.assign(f.upper_bounds.size(), 0);
  return it->second;
}

void Counter::Add(const LabelValues& labels, double value) const {
  if (!(value >= 0.0)) return;
  std::lock_guard<std::mutex> lock(registry_->mu_);
  registry_->SeriesLocked(family_, labels).value += value;
}

double Counter::Value(const LabelValues& labels) const {
  std::lock_guard<std::mutex> lock(registry_->mu_);
  return registry_->SeriesLocked(family_, labels).value;
}

void Gauge::Set(const LabelValues& labels, double value) const {
  std::lock_guard<std::mutex> lock(registry_->mu_);
  registry_->SeriesLocked(family_, labels).value = value;
}

double Gauge::Value(const LabelValues& labels) const {
  std::lock_guard<std::mutex> lock(registry_->mu_);
  return registry_->SeriesLocked(family_, labels).value;
}

void Histogram::Observe(const LabelValues& labels, double value) const {
  std::lock_guard<std::mutex> lock(registry_->mu_);
  const auto& bounds = registry_->families_[family_].upper_bounds;
  MetricsRegistry::Series& s = registry_->SeriesLocked(family_, labels);
  for (size_t i = 0; i < bounds.size(); ++i) {
    if (value <= bounds[i]) {
      ++s.bucket_counts[i];
      break;
    }
  }
  s.sum += value;
  ++s.count;
}

uint64_t Histogram::Count(const LabelValues& labels) const {
  std::lock_guard<std::mutex> lock(registry_->mu_);
  return registry_->SeriesLocked(family_, labels).count;
}

std::string MetricsRegistry::Render() const {
  static const char* kTypeNames[] = {"counter", "gauge", "histogram"};
  std::lock_guard<std::mutex> lock(mu_);
  std::string out;
  for (const Family& f : families_) {
    out += "# HELP " + f.name + " " + EscapeHelp(f.help) + "\n";
    out += "# TYPE " + f.name + " " + kTypeNames[int(f.type)] + "\n";
    // A family without labels always shows its one series, so a scrape reports 0 rather than
    // nothing before the first event.
    if (f.series.empty() && f.label_names.empty()) {
      if (f.type != Type::kHistogram) {
        out += f.name + " 0\n";
      } else {
        for (double b : f.upper_bounds) out += f.name + "_bucket{le=\"" + FormatMetricValue(b) + "\"} 0\n";
        out += f.name + "_bucket{le=\"+Inf\"} 0\n" + f.name + "_sum 0\n" + f.name + "_count 0\n";
      }
      continue;
    }
    for (const auto& [values, s] : f.series) {
      if (f.type != Type::kHistogram) {
        out += f.name + LabelText(f.label_names, values) + " " + FormatMetricValue(s.value) + "\n";
        continue;
      }
      uint64_t cumulative = 0;
      for (size_t i = 0; i < f.upper_bounds.size(); ++i) {
        cumulative += s.bucket_counts[i];
        out += f.name + "_bucket" + LabelText(f.label_names, values, "le", FormatMetricValue(f.upper_bounds[i])) + " " +
               std::to_string(cumulative) + "\n";
      }
      out += f.name + "_bucket" + LabelText(f.label_names, values, "le", "+Inf") + " " + std::to_string(s.count) + "\n";
      out += f.name + "_sum" + LabelText(f.label_names, values) + " " + FormatMetricValue(s.sum) + "\n";
      out += f.name + "_count" + LabelText(f.label_names, values) + " " + std::to_string(s.count) + "\n";
    }
  }
  return out;
}

}  // namespace inspection
