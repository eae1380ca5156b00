#include "inekf_semantic_mapping/ros/diagnostics.h"

#include <ros/this_node.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>

namespace inekf_semantic_mapping {
namespace ros_conversions {

void EventWindow::add(double time_s, double value) {
  if (!events_.empty() && time_s < events_.back().first) events_.clear();  // time went back
  events_.emplace_back(time_s, value);
  expire(time_s);
}

void EventWindow::expire(double now_s) {
  while (!events_.empty() && events_.front().first < now_s - window_s_) events_.pop_front();
}

double EventWindow::rateHz() const {
  if (events_.size() < 2) return 0.0;
  const double span_s = events_.back().first - events_.front().first;
  return span_s > 0 ? static_cast<double>(events_.size() - 1) / span_s : 0.0;
}

double EventWindow::rateOverWindowHz(double now_s) const {
  std::size_t n = 0;
  for (const auto& event : events_) n += event.first >= now_s - window_s_;
  return window_s_ > 0 ? static_cast<double>(n) / window_s_ : 0.0;
}

double EventWindow::mean() const {
  if (events_.empty()) return 0.0;
  double sum = 0.0;
  for (const auto& event : events_) sum += event.second;
  return sum / static_cast<double>(events_.size());
}

double EventWindow::percentile(double q) const {
  if (events_.empty()) return 0.0;
  std::vector<double> values;
  values.reserve(events_.size());
  for (const auto& event : events_) values.push_back(event.second);
  const std::size_t rank =
      static_cast<std::size_t>(std::clamp(std::ceil(q * static_cast<double>(values.size())) - 1.0,
                                          0.0, static_cast<double>(values.size() - 1)));
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(rank),
                   values.end());
  return values[rank];
}

double wallNow() { return ros::WallTime::now().toSec(); }

PlaybackMonitor::PlaybackMonitor(double window_s, const std::vector<std::string>& counters)
    : window_s_(window_s), losses_(window_s) {
  for (const std::string& name : counters) counts_[name] = 0;
}

void PlaybackMonitor::noteData(double data_s, double wall_s, const char* counted) {
  if (counted) count(counted, wall_s);
  std::lock_guard<std::mutex> lock(mutex_);
  if (!clock_.empty() && data_s < clock_.back().second) clock_.clear();  // looped
  clock_.emplace_back(wall_s, data_s);
  while (clock_.size() > 2 && clock_.front().first < wall_s - window_s_) clock_.pop_front();
}

void PlaybackMonitor::count(const std::string& name, double wall_s, std::size_t n) {
  std::lock_guard<std::mutex> lock(mutex_);
  counts_[name] += n;
  if (n > 0 && name.rfind("dropped", 0) == 0) losses_.add(wall_s);
}

double PlaybackMonitor::playRate(double wall_s) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (clock_.size() < 2) return 0.0;
  const double wall_span_s = std::max(wall_s, clock_.back().first) - clock_.front().first;
  return wall_span_s > 0 ? (clock_.back().second - clock_.front().second) / wall_span_s : 0.0;
}

void PlaybackMonitor::fill(double wall_s, double requested_rate,
                           diagnostic_updater::DiagnosticStatusWrapper* status) {
  const double rate = playRate(wall_s);
  std::lock_guard<std::mutex> lock(mutex_);
  losses_.expire(wall_s);
  using diagnostic_msgs::DiagnosticStatus;
  const bool full_window = !clock_.empty() && wall_s - clock_.front().first >= 0.9 * window_s_;
  const double silent_s = clock_.empty() ? 0.0 : wall_s - clock_.back().first;
  if (clock_.empty()) {
    status->summary(DiagnosticStatus::OK, "waiting for data");
  } else if (losses_.count() > 0) {
    status->summary(DiagnosticStatus::WARN, std::to_string(losses_.count()) +
                                                " messages dropped in the last " +
                                                std::to_string(static_cast<int>(window_s_)) + " s");
  } else if (requested_rate > 0 && full_window && silent_s < 1.0 && rate < 0.8 * requested_rate) {
    status->summary(DiagnosticStatus::WARN, "falling behind the requested rate");
  } else if (silent_s > 2.0) {
    status->summary(DiagnosticStatus::OK,
                    "idle: no data for " + std::to_string(static_cast<int>(silent_s)) + " s");
  } else {
    status->summary(DiagnosticStatus::OK, "playing");
  }
  status->addf("play rate (x real time)", "%.2f", silent_s > 2.0 ? 0.0 : rate);
  if (requested_rate > 0) status->addf("requested rate (x real time)", "%.2f", requested_rate);
  status->addf("data time (s)", "%.1f", clock_.empty() ? 0.0 : clock_.back().second);
  for (const auto& [name, n] : counts_) status->add(name, n);
}

NodeDiagnostics::NodeDiagnostics(ros::NodeHandle& nh, ros::NodeHandle& private_nh)
    // The private namespace names the node, also for a nodelet (whose process is the manager).
    : updater_(nh, private_nh, private_nh.getNamespace()) {
  updater_.setHardwareID(private_nh.getNamespace());
  // The period is the updater's own ~diagnostic_period (1 s unless set), which it read above.
  const double period_s = updater_.getPeriod();
  if (!(period_s > 0.0) || !std::isfinite(period_s)) {
    throw std::invalid_argument(private_nh.resolveName("diagnostic_period") +
                                " must be a positive number of seconds, got " +
                                std::to_string(period_s));
  }
  timer_period_s_ = period_s;
  timer_ = nh.createWallTimer(ros::WallDuration(period_s),
                              [this](const ros::WallTimerEvent&) { publish(); });
}

void NodeDiagnostics::publish() {
  // force_update re-reads ~diagnostic_period (cached: rosparam set reaches it), so a period set
  // while running is followed from the next tick on. A bad one keeps the period there was.
  updater_.force_update();
  const double period_s = updater_.getPeriod();
  if (period_s == timer_period_s_) return;
  if (!(period_s > 0.0) || !std::isfinite(period_s)) {
    ROS_WARN_STREAM_THROTTLE(60.0,
                             "diagnostics: ~diagnostic_period must be a positive number of "
                             "seconds, got "
                                 << period_s << ": keeping " << timer_period_s_ << " s");
    return;
  }
  ROS_INFO_STREAM("diagnostics: now published every " << period_s << " s (~diagnostic_period)");
  timer_period_s_ = period_s;
  timer_.setPeriod(ros::WallDuration(period_s));
}

void NodeDiagnostics::add(const std::string& name, Task task) {
  updater_.add(name, std::move(task));
}

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
