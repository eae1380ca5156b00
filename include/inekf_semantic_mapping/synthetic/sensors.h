// Sensor models of the synthetic drive, with the KITTI rig geometry: the HDL-64E lidar and the
// rectified color camera, both by ray casting the SyntheticWorld, and the OXTS IMU error model.
#pragma once

#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/synthetic/world.h"

namespace inekf_semantic_mapping {
namespace synthetic {

// The KITTI raw rig of 2011_09_26 (values from its calib_*.txt; facts, not files), for writing
// calib_{cam_to_cam,imu_to_velo,velo_to_cam}.txt. The generator simulates with the values as
// read back from the written files, so that consumers and the simulation agree to the bit.
struct KittiRig {
  static constexpr int kNominalWidth = 1242, kNominalHeight = 375;

  Eigen::Matrix3d R_velo_imu;
  Eigen::Vector3d t_velo_imu;
  Eigen::Matrix3d R_cam0_velo;
  Eigen::Vector3d t_cam0_velo;
  struct Camera {
    Eigen::Matrix3d K;
    Eigen::Matrix<double, 5, 1> D;
    Eigen::Matrix3d R;
    Eigen::Vector3d T;
    Eigen::Matrix3d R_rect;
    Eigen::Matrix<double, 3, 4> P_rect;  // for the nominal 1242x375 image
  };
  std::array<Camera, 4> cameras;

  static KittiRig kitti2011_09_26();

  // P_rect_i for a width x height rectified image: rows 0 and 1 scaled by width/1242 and
  // height/375 (same field of view, other pixel size).
  Eigen::Matrix<double, 3, 4> scaledProjection(int camera_index, int width, int height) const;

  // Writes the three raw calibration files into date_dir in the KITTI text format (atomic).
  void writeRawCalibration(const std::string& date_dir, int width, int height) const;
};

// HDL-64E: 64 lasers in two blocks (+2 .. -8.33 deg by 1/3 deg, -8.83 .. -24.8 deg by ~1/2
// deg), one sweep per scan. Other beam counts are spread evenly over +2 .. -24.8 deg.
struct LidarModel {
  int beams = 64;
  double azimuth_step_deg = 0.1728;  // 2083 columns at 10 Hz
  double max_range_m = 120.0;
  double min_range_m = 0.9;
  double range_noise_std_m = 0.02;

  std::vector<double> elevationsRad() const;  // top laser first
  int columns() const;
};

struct LidarScan {
  std::vector<float> xyzi;            // N*4: x y z (velodyne frame) reflectance, KITTI .bin
  std::vector<std::uint32_t> labels;  // N: SemanticKITTI layout, lower 16 bits = labelId
  std::size_t size() const { return labels.size(); }
};

// One sweep from the pose T_map_velo (ego-motion during the 0.1 s sweep is ignored: every ray
// leaves from the same pose). Points are written as KITTI does: laser by laser from the top,
// each laser sweeping clockwise from the rear (azimuth +180 deg down to -180 deg).
// Deterministic for noise_seed.
LidarScan simulateLidarScan(const SyntheticWorld& world, const Eigen::Isometry3d& T_map_velo,
                            const LidarModel& model, std::uint64_t noise_seed);

struct RenderOptions {
  Eigen::Vector3d sun_direction = Eigen::Vector3d(-0.45, 0.35, 0.82).normalized();  // to sun
  double ambient = 0.42;
  double max_range_m = 250.0;
  double pixel_noise_std = 3.0;  // grey levels, per pixel and frame
  std::uint64_t noise_seed = 0;
};

struct RenderedImage {
  int width = 0, height = 0;
  std::vector<std::uint8_t> bgr;     // row-major, 3 bytes per pixel (OpenCV order)
  std::vector<std::uint8_t> labels;  // Cityscapes labelIds, sky = 23 where nothing is hit
  std::vector<float> range_m;        // distance from the optical centre, +inf for sky
};

// Renders a rectified pinhole camera by casting one ray per pixel centre: pixel (u, v) (integer
// column, row) looks along K^-1 (u, v, 1) in the camera optical frame (x right, y down, z
// forward) whose pose in the map is T_map_camera. `threads` split the rows.
RenderedImage renderCamera(const SyntheticWorld& world, const Eigen::Isometry3d& T_map_camera,
                           const Eigen::Matrix3d& K, int width, int height,
                           const RenderOptions& options, int threads);

// OXTS RT3003-like IMU errors, per 100 Hz sample: white noise and a bias random walk.
struct ImuNoiseModel {
  double accel_noise_std = 0.01;        // m/s^2, per sample
  double gyro_noise_std = 2e-4;         // rad/s, per sample
  double accel_bias_walk = 1e-4;        // m/s^2 / sqrt(s)
  double gyro_bias_walk = 1e-5;         // rad/s / sqrt(s)
  double accel_bias_initial_std = 0.0;  // m/s^2
  double gyro_bias_initial_std = 0.0;   // rad/s
  static ImuNoiseModel none() { return {0, 0, 0, 0, 0, 0}; }
};

}  // namespace synthetic
}  // namespace inekf_semantic_mapping
