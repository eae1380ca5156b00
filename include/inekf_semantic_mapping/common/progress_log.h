// Progress of a long loop in a command-line tool: a line at most once per period (none for a
// loop that ends sooner), with what is done, the rate and the time left, e.g.
//   "evaluate_semantics: 05 labels: 300 of 2761 frames, 1.4 frames/s, about 29 min left".
//
//   common::ProgressLog progress("evaluate_semantics: 05 labels", frames.size(), "frames");
//   for (...) { ...; progress.update(done); }
//
// Header-only, standard library only.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdio>
#include <iostream>
#include <string>
#include <utility>

namespace inekf_semantic_mapping {
namespace common {

class ProgressLog {
 public:
  using Clock = std::chrono::steady_clock;

  // period_s: the least time between two lines (0: a line at every update).
  ProgressLog(std::string what, std::size_t total, std::string unit, double period_s = 30.0,
              std::ostream* out = &std::cout)
      : what_(std::move(what)),
        unit_(std::move(unit)),
        total_(total),
        period_s_(period_s),
        out_(out),
        start_(Clock::now()),
        last_(start_) {}

  // `done` items of the total are finished; prints a line when the period has passed since the
  // last one (or the start). Returns whether it printed.
  bool update(std::size_t done) {
    const Clock::time_point now = Clock::now();
    if (std::chrono::duration<double>(now - last_).count() < period_s_) return false;
    last_ = now;
    *out_ << line(done, std::chrono::duration<double>(now - start_).count()) << std::endl;
    return true;
  }

  // The line for `done` items after elapsed_s seconds.
  std::string line(std::size_t done, double elapsed_s) const {
    std::string text =
        what_ + ": " + std::to_string(done) + " of " + std::to_string(total_) + " " + unit_;
    if (done == 0 || !(elapsed_s > 0.0)) return text;
    const double rate = static_cast<double>(done) / elapsed_s;
    char figures[96];
    std::snprintf(figures, sizeof(figures), rate >= 10.0 ? ", %.0f %s/s" : ", %.2g %s/s", rate,
                  unit_.c_str());
    text += figures;
    if (done < total_) text += ", about " + duration((total_ - done) / rate) + " left";
    return text;
  }

 private:
  static std::string duration(double seconds) {
    char text[32];
    if (seconds < 90.0) {
      std::snprintf(text, sizeof(text), "%.0f s", seconds);
    } else if (seconds < 90.0 * 60.0) {
      std::snprintf(text, sizeof(text), "%.0f min", seconds / 60.0);
    } else {
      std::snprintf(text, sizeof(text), "%.1f h", seconds / 3600.0);
    }
    return text;
  }

  std::string what_;
  std::string unit_;
  std::size_t total_;
  double period_s_;
  std::ostream* out_;
  Clock::time_point start_;
  Clock::time_point last_;
};

}  // namespace common
}  // namespace inekf_semantic_mapping
