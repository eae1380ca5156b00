// What every node shares for /diagnostics (diagnostic_msgs/DiagnosticArray): diagnostic_updater
// driven by a 1 Hz WALL timer (a paused or absent /clock must not silence a node's health), and
// sliding windows for rates and latency percentiles. Each node adds its own tasks; the status
// names start with the node's resolved name ("/ns/inekf_node: localization"), so pipelines under
// different namespaces stay apart on the one /diagnostics topic.
// ROS-facing (src/ros): only nodes include this header.
#pragma once

#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/node_handle.h>
#include <ros/timer.h>

#include <cstddef>
#include <deque>
#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <vector>

namespace inekf_semantic_mapping {
namespace ros_conversions {

// Times (seconds, of data or of the wall clock) of recent events, kept for `window_s` behind the
// newest one.
class EventWindow {
 public:
  explicit EventWindow(double window_s = 10.0) : window_s_(window_s) {}
  void add(double time_s, double value = 0.0);
  // Forgets events older than now_s - window_s (for a window on the wall clock).
  void expire(double now_s);
  void clear() { events_.clear(); }
  std::size_t count() const { return events_.size(); }
  // Events per second: (count - 1) over the span of their times; 0 with fewer than 2 events.
  double rateHz() const;
  // Events per second over the whole window ending at now_s (a wall-clock rate that falls to 0
  // when events stop).
  double rateOverWindowHz(double now_s) const;
  double newest() const { return events_.empty() ? 0.0 : events_.back().first; }
  // Mean and percentiles (0..1, nearest rank) of the events' values; 0 when empty.
  double mean() const;
  double percentile(double q) const;
  double window() const { return window_s_; }

 private:
  double window_s_;
  std::deque<std::pair<double, double>> events_;  // (time, value)
};

double wallNow();  // ros::WallTime::now() in seconds

// The health of a data source (kitti_player, kitti_bag_adapter): how fast its data clock runs
// against the wall clock, what it published and dropped. Thread-safe (a player publishes on
// its main thread, diagnostics run on the spinner's).
class PlaybackMonitor {
 public:
  // `counters` start at 0 (shown before anything happened).
  explicit PlaybackMonitor(double window_s = 10.0, const std::vector<std::string>& counters = {});
  // The data clock reached data_s at wall time wall_s (with a message counted as `counted`).
  void noteData(double data_s, double wall_s, const char* counted = nullptr);
  // Adds n to a counter ("published imu", "dropped velocity": names that start with "dropped"
  // are losses, and any in the window turns the status WARN).
  void count(const std::string& name, double wall_s, std::size_t n = 1);
  // Data seconds per wall second over the window (0 until the data clock moved).
  double playRate(double wall_s);
  // Level and summary (a loss in the window: WARN; requested_rate > 0 and the data clock slower
  // than 0.8 of it over a full window: WARN, falling behind; no data yet: OK, waiting), the play
  // rate and every counter.
  void fill(double wall_s, double requested_rate,
            diagnostic_updater::DiagnosticStatusWrapper* status);

 private:
  std::mutex mutex_;
  double window_s_;
  std::deque<std::pair<double, double>> clock_;  // (wall, data)
  EventWindow losses_;                           // wall times of drops
  std::map<std::string, std::size_t> counts_;
};

// diagnostic_updater::Updater published on the wall clock (~diagnostic_period, 1 s by default). The
// statuses' prefix and the hardware id are the node's name (its private namespace: a nodelet's own
// name, not its manager's).
class NodeDiagnostics {
 public:
  using Task = std::function<void(diagnostic_updater::DiagnosticStatusWrapper&)>;
  // Published every ~diagnostic_period seconds (diagnostic_updater's parameter, default 1 s, also
  // followed when set while running); throws std::invalid_argument when it is not positive at
  // the start.
  NodeDiagnostics(ros::NodeHandle& nh, ros::NodeHandle& private_nh);
  void add(const std::string& name, Task task);
  void forceUpdate() { updater_.force_update(); }

 private:
  void publish();

  diagnostic_updater::Updater updater_;
  ros::WallTimer timer_;
  double timer_period_s_ = 1.0;
};

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
