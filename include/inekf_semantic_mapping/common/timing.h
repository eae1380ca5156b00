// Lightweight stage timing (the voxblox timing::Timer idea): ScopedTimer adds the elapsed wall
// time of a scope to a named accumulator; tools print TimingRegistry::instance().report() and
// nodes publish it. Thread-safe; costs two clock reads and one short lock per measurement.
#pragma once

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <limits>
#include <map>
#include <mutex>
#include <string>

namespace inekf_semantic_mapping {

struct TimingStatistics {
  std::size_t count = 0;
  double total_s = 0.0;
  double min_s = std::numeric_limits<double>::infinity();
  double max_s = 0.0;
  double meanSeconds() const { return count ? total_s / static_cast<double>(count) : 0.0; }
};

class TimingRegistry {
 public:
  static TimingRegistry& instance() {
    static TimingRegistry registry;
    return registry;
  }

  void add(const std::string& name, double seconds) {
    std::lock_guard<std::mutex> lock(mutex_);
    TimingStatistics& s = stats_[name];
    ++s.count;
    s.total_s += seconds;
    s.min_s = std::min(s.min_s, seconds);
    s.max_s = std::max(s.max_s, seconds);
  }

  std::map<std::string, TimingStatistics> snapshot() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return stats_;
  }

  void reset() {
    std::lock_guard<std::mutex> lock(mutex_);
    stats_.clear();
  }

  // One line per stage: name, count, mean / min / max in milliseconds, total in seconds.
  std::string report() const {
    std::string out =
        "stage                              count    mean_ms     min_ms     max_ms   total_s\n";
    char line[256];
    for (const auto& [name, s] : snapshot()) {
      std::snprintf(line, sizeof(line), "%-32s %7zu %10.3f %10.3f %10.3f %9.3f\n", name.c_str(),
                    s.count, 1e3 * s.meanSeconds(), 1e3 * (s.count ? s.min_s : 0.0), 1e3 * s.max_s,
                    s.total_s);
      out += line;
    }
    return out;
  }

 private:
  mutable std::mutex mutex_;
  std::map<std::string, TimingStatistics> stats_;
};

class ScopedTimer {
 public:
  explicit ScopedTimer(std::string name)
      : name_(std::move(name)), start_(std::chrono::steady_clock::now()) {}
  ~ScopedTimer() {
    const std::chrono::duration<double> elapsed = std::chrono::steady_clock::now() - start_;
    TimingRegistry::instance().add(name_, elapsed.count());
  }
  ScopedTimer(const ScopedTimer&) = delete;
  ScopedTimer& operator=(const ScopedTimer&) = delete;

 private:
  std::string name_;
  std::chrono::steady_clock::time_point start_;
};

}  // namespace inekf_semantic_mapping
