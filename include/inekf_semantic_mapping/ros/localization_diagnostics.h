// inekf_node's /diagnostics status: what the filter is doing (waiting, running, re-initialised),
// whether its inputs come at the rates they should, how long since a fix was accepted, how many
// were rejected and how consistent the accepted ones were, its uncertainty and its land-vehicle
// constraint and heading monitor counters. Times and rates are of DATA time (the messages'
// stamps), so a bag played at any rate reads the same; only "no IMU at all" is on the wall clock.
// ROS-facing (src/ros): only nodes and their tests include this header.
#pragma once

#include <diagnostic_updater/DiagnosticStatusWrapper.h>

#include <cstdint>
#include <string>

#include "inekf_semantic_mapping/common/yaml_reader.h"
#include "inekf_semantic_mapping/estimation/localization_session.h"
#include "inekf_semantic_mapping/ros/diagnostics.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

// config/inekf.yaml node.diagnostics.* (and inekf_node's ~diagnostics/* over them).
struct LocalizationDiagnosticsOptions {
  double expected_imu_rate_hz = 10.0;  // KITTI's OXTS
  double expected_fix_rate_hz = 1.0;   // the degraded-GPS protocol's
  double fix_warn_after_s = 5.0;       // data time without an accepted fix: WARN
  double fix_error_after_s = 15.0;     // ... ERROR
  double window_s = 10.0;              // rates, rejections and innovations over this data time
  double max_position_sigma_m = 10.0;  // horizontal 1-sigma above it: WARN
  double max_heading_sigma_deg = 10.0;
  double imu_stale_after_s = 2.0;  // WALL seconds without IMU after some came: WARN
};

// Reads `prefix` + the keys above (e.g. "node.diagnostics." of the config file, "diagnostics."
// of the private parameters) into *options; throws common::ConfigError for a bad value.
void readLocalizationDiagnosticsOptions(common::YamlReader* reader, const std::string& prefix,
                                        LocalizationDiagnosticsOptions* options);

class LocalizationMonitor {
 public:
  explicit LocalizationMonitor(LocalizationDiagnosticsOptions options);
  // After each IMU / fix event went through the session (data stamp of the message, wall time).
  void noteImu(double stamp_s, double wall_s, const estimation::LocalizationSession& session);
  void noteFix(double stamp_s, double wall_s, const estimation::LocalizationSession& session);
  // The status at wall time wall_s.
  void fill(const estimation::LocalizationSession& session, double wall_s,
            diagnostic_updater::DiagnosticStatusWrapper* status) const;
  const LocalizationDiagnosticsOptions& options() const { return options_; }

 private:
  void noteCounters(double stamp_s, const estimation::LocalizationSession& session);

  LocalizationDiagnosticsOptions options_;
  EventWindow imu_, fixes_, accepted_, rejected_;  // accepted_ values: NIS / dof
  double first_imu_s_ = 0.0, newest_s_ = 0.0, last_accepted_s_ = -1.0, last_imu_wall_s_ = -1.0;
  std::int64_t used_ = 0, rejected_count_ = 0, resets_ = 0;
};

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
