// The reader of LocalizerConfig: its YAML keys, each checked as it is read.
#include "inekf_semantic_mapping/estimation/localizer_config.h"

#include <cmath>
#include <exception>
#include <string>

#include "inekf_semantic_mapping/common/yaml_reader.h"

namespace inekf_semantic_mapping {
namespace estimation {

LocalizerConfig LocalizerConfig::fromYamlFile(const std::string& path) {
  common::YamlReader reader = common::YamlReader::fromFile(path);
  LocalizerConfig config = fromYaml(&reader);
  reader.allow("node.*");
  reader.allow("session.*");
  reader.rejectUnknown();
  return config;
}

LocalizerConfig LocalizerConfig::fromYaml(common::YamlReader* reader) {
  LocalizerConfig config;
  // Up to 1e6: the filter squares these (and sums them over steps); 1e200 passed as finite and
  // made every state non-finite. Angles of a heading or a rotation: beyond 180 deg they mean
  // nothing more.
  const auto positive = [reader](const std::string& key, double* out) {
    reader->readInRange(key, out, 0.0, 1e6, true);
  };
  const auto non_negative = [reader](const std::string& key, double* out) {
    reader->readInRange(key, out, 0.0, 1e6);
  };
  const auto angle = [reader](const std::string& key, double* out, bool zero_allowed) {
    reader->readInRange(key, out, 0.0, 180.0, !zero_allowed);
  };
  reader->readChoice("filter", filterTypeFromString, &config.filter_type);
  ImuNoise& n = config.imu_noise;
  positive("imu_noise.gyro_noise_density", &n.gyro_noise_density);
  positive("imu_noise.accel_noise_density", &n.accel_noise_density);
  non_negative("imu_noise.gyro_bias_random_walk", &n.gyro_bias_random_walk);
  non_negative("imu_noise.accel_bias_random_walk", &n.accel_bias_random_walk);
  positive("imu_noise.gravity_mps2", &n.gravity_mps2);
  angle("initial_sigma.rotation_deg", &config.initial_rotation_sigma_deg, false);
  angle("initial_sigma.yaw_deg", &config.initial_yaw_sigma_deg, false);
  positive("initial_sigma.velocity_mps", &config.initial_velocity_sigma_mps);
  positive("initial_sigma.unknown_velocity_horizontal_mps",
           &config.unknown_velocity_sigma_horizontal_mps);
  positive("initial_sigma.unknown_velocity_vertical_mps",
           &config.unknown_velocity_sigma_vertical_mps);
  angle("initial_sigma.unknown_yaw_deg", &config.unknown_yaw_sigma_deg, false);
  positive("initial_sigma.position_m", &config.initial_position_sigma_m);
  positive("initial_sigma.gyro_bias_radps", &config.initial_gyro_bias_sigma_radps);
  positive("initial_sigma.accel_bias_mps2", &config.initial_accel_bias_sigma_mps2);
  positive("gps.gate_mahalanobis_squared", &config.gps_gate_mahalanobis_squared);
  non_negative("gps.min_sigma_m", &config.min_gps_sigma_m);
  non_negative("gps.max_fix_age_s", &config.max_fix_age_s);
  non_negative("gps.fix_history_s", &config.fix_history_s);
  reader->readInRange("gps.max_consecutive_rejected_fixes", &config.max_consecutive_rejected_fixes,
                      0, 1000000);
  positive("gps.max_reacquisition_speed_mps", &config.max_reacquisition_speed_mps);
  positive("imu.max_angular_rate_radps", &config.max_angular_rate_radps);
  positive("imu.max_specific_force_mps2", &config.max_specific_force_mps2);
  positive("imu.max_gap_s", &config.max_imu_gap_s);
  positive("imu.gap_noise_scale", &config.gap_noise_scale);
  non_negative("imu.gap_gyro_noise_scale_per_s", &config.gap_gyro_noise_scale_per_s);
  non_negative("imu.interpolated_gyro_noise_scale_per_s",
               &config.interpolated_gyro_noise_scale_per_s);
  positive("imu.interpolated_accel_noise_scale", &config.interpolated_accel_noise_scale);
  reader->read("nonholonomic.enabled", &config.nonholonomic);
  positive("nonholonomic.lateral_sigma_mps", &config.nonholonomic_lateral_sigma_mps);
  positive("nonholonomic.vertical_sigma_mps", &config.nonholonomic_vertical_sigma_mps);
  non_negative("nonholonomic.min_step_s", &config.nonholonomic_min_step_s);
  positive("nonholonomic.gate_mahalanobis_squared", &config.nonholonomic_gate_mahalanobis_squared);
  angle("nonholonomic.max_heading_sigma_deg", &config.nonholonomic_max_heading_sigma_deg, false);
  // A mounting error, not another axis convention: an IMU turned further is described by tf
  // (base_link -> its frame), which inekf_node reads (Localizer::setImuMounting).
  const auto mounting_angle = [&](const char* key, double* out) {
    reader->read(key, out);
    if (!(std::abs(*out) <= 30.0)) {
      reader->fail(key,
                   "must be in [-30, 30] deg (a small mounting error; an IMU mounted turned is "
                   "described by the tf base_link -> its frame, which inekf_node reads)");
    }
  };
  mounting_angle("nonholonomic.vehicle_pitch_deg", &config.nonholonomic_vehicle_pitch_deg);
  mounting_angle("nonholonomic.vehicle_yaw_deg", &config.nonholonomic_vehicle_yaw_deg);
  StandstillOptions& still = config.standstill;
  reader->read("standstill.enabled", &still.enabled);
  positive("standstill.window_s", &still.window_s);
  positive("standstill.max_acceleration_mps2", &still.max_acceleration_mps2);
  angle("standstill.max_rate_degps", &still.max_rate_degps, false);
  positive("standstill.max_speed_mps", &still.max_speed_mps);
  positive("standstill.velocity_sigma_mps", &still.velocity_sigma_mps);
  positive("standstill.update_interval_s", &still.update_interval_s);
  positive("standstill.gate_mahalanobis_squared", &still.gate_mahalanobis_squared);
  LocalizerConfig::WheelSpeedOptions& wheel = config.wheel_speed;
  reader->read("wheel_speed.enabled", &wheel.enabled);
  positive("wheel_speed.default_sigma_mps", &wheel.default_sigma_mps);
  positive("wheel_speed.min_sigma_mps", &wheel.min_sigma_mps);
  non_negative("wheel_speed.scale_sigma", &wheel.scale_sigma);
  non_negative("wheel_speed.min_interval_s", &wheel.min_interval_s);
  non_negative("wheel_speed.max_age_s", &wheel.max_age_s);
  non_negative("wheel_speed.max_acceleration_mps2", &wheel.max_acceleration_mps2);
  positive("wheel_speed.gate_mahalanobis_squared", &wheel.gate_mahalanobis_squared);
  reader->readInRange("wheel_speed.max_rejected_in_a_row", &wheel.max_rejected_in_a_row, 0,
                      1000000);
  reader->read("init_orientation_from_reference", &config.init_orientation_from_reference);
  reader->read("heading.from_track", &config.heading_from_track);
  positive("heading.track_window_s", &config.heading_track_window_s);
  positive("heading.track_min_speed_mps", &config.heading_track_min_speed_mps);
  non_negative("heading.track_min_chord_m", &config.heading_track_min_chord_m);
  positive("heading.track_max_chord_s", &config.heading_track_max_chord_s);
  angle("heading.track_max_turn_deg", &config.heading_track_max_turn_deg, false);
  non_negative("heading.track_turn_weight", &config.heading_track_turn_weight);
  angle("heading.track_chord_floor_deg", &config.heading_track_chord_floor_deg, true);
  const auto count = [reader](const std::string& key, int* out, int min) {
    reader->readInRange(key, out, min, 1000000);
  };
  count("heading.track_min_chords", &config.heading_track_min_chords, 1);
  angle("heading.align_above_sigma_deg", &config.heading_align_above_sigma_deg, false);
  angle("heading.align_max_sigma_deg", &config.heading_align_max_sigma_deg, false);
  positive("heading.check_sigmas", &config.heading_check_sigmas);
  angle("heading.check_min_deg", &config.heading_check_min_deg, true);
  count("heading.reopen_after_rejected_fixes", &config.heading_reopen_after_rejected_fixes, 0);
  count("heading.nis_window_fixes", &config.heading_nis_window_fixes, 0);
  positive("heading.nis_window_max", &config.heading_nis_window_max);
  reader->read("heading.hold_unknown_yaw", &config.heading_hold_unknown_yaw);
  return config;
}

}  // namespace estimation
}  // namespace inekf_semantic_mapping
