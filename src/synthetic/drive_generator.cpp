#include "inekf_semantic_mapping/synthetic/drive_generator.h"

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <mutex>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <stdexcept>
#include <thread>
#include <vector>

#include "inekf_semantic_mapping/common/atomic_file.h"
#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/kitti/mercator.h"
#include "inekf_semantic_mapping/kitti/poses.h"
#include "inekf_semantic_mapping/kitti/timestamps.h"
#include "inekf_semantic_mapping/synthetic/route.h"
#include "inekf_semantic_mapping/synthetic/world.h"

namespace inekf_semantic_mapping {
namespace synthetic {
namespace fs = std::filesystem;
using common::writeBytesAtomically;
using common::writeTextAtomically;

namespace {

std::int64_t parseDateDays(const std::string& date) {
  int y, m, d;
  char tail;
  if (date.size() != 10 || std::sscanf(date.c_str(), "%4d_%2d_%2d%c", &y, &m, &d, &tail) != 3 ||
      m < 1 || m > 12 || d < 1 || d > 31) {
    throw std::invalid_argument("--date must be YYYY_MM_DD (e.g. 2011_09_26), got '" + date + "'");
  }
  char iso[32];
  std::snprintf(iso, sizeof(iso), "%04d-%02d-%02d 00:00:00", y, m, d);
  return kitti::parseKittiTimestampNs(iso) / (86400LL * 1000000000LL);
}

const char kDataFormat[] =
    "lat:   latitude of the oxts-unit (deg)\n"
    "lon:   longitude of the oxts-unit (deg)\n"
    "alt:   altitude of the oxts-unit (m)\n"
    "roll:  roll angle (rad),  0 = level, positive = left side up (-pi..pi)\n"
    "pitch: pitch angle (rad), 0 = level, positive = front down (-pi/2..pi/2)\n"
    "yaw:   heading (rad),     0 = east,  positive = counter clockwise (-pi..pi)\n"
    "vn:    velocity towards north (m/s)\n"
    "ve:    velocity towards east (m/s)\n"
    "vf:    forward velocity, parallel to the earth surface (m/s)\n"
    "vl:    leftward velocity, parallel to the earth surface (m/s)\n"
    "vu:    upward velocity, perpendicular to the earth surface (m/s)\n"
    "ax:    acceleration in x, the vehicle front direction (m/s^2)\n"
    "ay:    acceleration in y, the vehicle left direction (m/s^2)\n"
    "az:    acceleration in z, the vehicle top direction (m/s^2)\n"
    "af:    forward acceleration (m/s^2)\n"
    "al:    leftward acceleration (m/s^2)\n"
    "au:    upward acceleration (m/s^2)\n"
    "wx:    angular rate around x (rad/s)\n"
    "wy:    angular rate around y (rad/s)\n"
    "wz:    angular rate around z (rad/s)\n"
    "wf:    angular rate around the forward axis (rad/s)\n"
    "wl:    angular rate around the leftward axis (rad/s)\n"
    "wu:    angular rate around the upward axis (rad/s)\n"
    "pos_accuracy:  position accuracy (north/east in m)\n"
    "vel_accuracy:  velocity accuracy (north/east in m/s)\n"
    "navstat:       navigation status\n"
    "numsats:       number of satellites tracked by the primary GPS receiver\n"
    "posmode:       position mode of the primary GPS receiver\n"
    "velmode:       velocity mode of the primary GPS receiver\n"
    "orimode:       orientation mode of the primary GPS receiver\n";

std::string frameName(std::size_t index, const char* extension) {
  char name[32];
  std::snprintf(name, sizeof(name), "%010zu%s", index, extension);
  return name;
}

std::string timestampsText(const std::vector<std::int64_t>& stamps) {
  std::string text;
  for (std::int64_t s : stamps) text += kitti::formatKittiTimestamp(s) + "\n";
  return text;
}

std::uint64_t mixSeed(std::uint64_t seed, std::uint64_t stream, std::uint64_t index) {
  std::uint64_t h = seed * 0x9E3779B97F4A7C15ull ^ (stream + 1) * 0xC2B2AE3D27D4EB4Full ^
                    (index + 7) * 0x165667B19E3779F9ull;
  h ^= h >> 31;
  h *= 0xBF58476D1CE4E5B9ull;
  return h ^ (h >> 29);
}

// Fast PNG: level 1 with run-length matching costs less CPU than plain level 1 on these noisy
// frames, for somewhat larger colour files.
void writePng(const std::string& path, const cv::Mat& image) {
  std::vector<uchar> bytes;
  if (!cv::imencode(".png", image, bytes,
                    {cv::IMWRITE_PNG_COMPRESSION, 1, cv::IMWRITE_PNG_STRATEGY,
                     cv::IMWRITE_PNG_STRATEGY_RLE})) {
    throw std::runtime_error(path + ": PNG encoding failed");
  }
  writeBytesAtomically(path, bytes.data(), bytes.size());
}

Eigen::Isometry3d isometry(const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = R;
  T.translation() = t;
  return T;
}

// Writes the whole drive under options.output_dir (see generateSyntheticDrive).
DriveSummary generateInto(const DriveOptions& options) {
  const auto wall_start = std::chrono::steady_clock::now();
  validateDriveOptions(options);
  const std::int64_t day = parseDateDays(options.date);

  DriveSummary summary;
  SyntheticWorld world;
  {
    ScopedTimer timer("synthetic/world");
    world = SyntheticWorld::generateTown(options.seed);
  }
  const SyntheticRoute route = SyntheticRoute::forWorld(world);
  summary.loop_length_m = route.loopLength();
  summary.distance_m = route.distanceAt(options.duration_s);

  char drive_name[64];
  std::snprintf(drive_name, sizeof(drive_name), "%s_drive_%04d", options.date.c_str(),
                options.drive_number);
  summary.date_dir = (fs::path(options.output_dir) / options.date).string();
  summary.sync_dir = summary.date_dir + "/" + drive_name + "_sync";
  summary.extract_dir = summary.date_dir + "/" + drive_name + "_extract";
  const std::string gt_dir = summary.sync_dir + "/ground_truth";
  for (const std::string& dir :
       {summary.sync_dir + "/oxts/data", summary.extract_dir + "/oxts/data",
        summary.extract_dir + "/ground_truth", gt_dir}) {
    fs::create_directories(dir);
  }
  if (options.write_lidar) {
    fs::create_directories(summary.sync_dir + "/velodyne_points/data");
    fs::create_directories(gt_dir + "/velodyne_labels");
  }
  if (options.write_images) {
    fs::create_directories(summary.sync_dir + "/image_02/data");
    fs::create_directories(gt_dir + "/image_02_labels");
  }

  // Calibration: write the KITTI files, then simulate with what a reader gets back from them.
  const KittiRig rig = KittiRig::kitti2011_09_26();
  rig.writeRawCalibration(summary.date_dir, options.image_width, options.image_height);
  const kitti::RawCalibration calibration = kitti::readRawCalibration(summary.date_dir);
  const Eigen::Isometry3d T_imu_velo = calibration.T_velo_imu.inverse();
  const kitti::CameraProjection camera = calibration.projection(2);
  const Eigen::Isometry3d T_velo_camera = camera.T_rectified_camera_velo().inverse();
  const Eigen::Matrix3d K = camera.rectifiedIntrinsics();

  std::mt19937_64 timing_rng(mixSeed(options.seed, 1, 0));
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::normal_distribution<double> normal(0.0, 1.0);
  const std::int64_t start_ns =
      (day * 86400LL + 12 * 3600) * 1000000000LL +
      static_cast<std::int64_t>(std::llround(unit(timing_rng) * 3000.0 * 1e9));
  auto stamp = [&](double t) {
    return start_ns + static_cast<std::int64_t>(std::llround(t * 1e9));
  };

  // ---- OXTS at 100 Hz (the _extract stream) -------------------------------------------------
  std::vector<double> extract_times;
  std::vector<std::string> extract_lines;
  std::vector<VehicleState> extract_states;
  {
    ScopedTimer timer("synthetic/oxts");
    const int samples = static_cast<int>(std::ceil((options.duration_s + 0.15) / 0.01)) + 1;
    for (int i = 0; i < samples; ++i) {
      extract_times.push_back(i == 0 ? 0.0 : 0.01 * i + 0.0004 * (2 * unit(timing_rng) - 1));
    }
    const kitti::MercatorProjection mercator(options.origin_lat_deg, options.origin_lon_deg,
                                             options.origin_alt_m);
    const ImuNoiseModel& noise = options.imu_noise;
    std::mt19937_64 imu_rng(mixSeed(options.seed, 2, 0));
    auto gaussian3 = [&](double sigma) {
      // One statement per draw: argument evaluation order is unspecified in C++.
      Eigen::Vector3d v;
      v.x() = normal(imu_rng);
      v.y() = normal(imu_rng);
      v.z() = normal(imu_rng);
      return Eigen::Vector3d(v * sigma);
    };
    Eigen::Vector3d accel_bias = gaussian3(noise.accel_bias_initial_std);
    Eigen::Vector3d gyro_bias = gaussian3(noise.gyro_bias_initial_std);
    std::string previous_tail;
    for (int i = 0; i < samples; ++i) {
      const double t = extract_times[i];
      const VehicleState state = route.stateAt(t);
      extract_states.push_back(state);
      if (i > 0) {
        const double dt = t - extract_times[i - 1];
        accel_bias += gaussian3(noise.accel_bias_walk * std::sqrt(dt));
        gyro_bias += gaussian3(noise.gyro_bias_walk * std::sqrt(dt));
      }
      const Eigen::Vector3d f =
          state.specificForceBody() + accel_bias + gaussian3(noise.accel_noise_std);
      const Eigen::Vector3d w =
          state.angular_velocity_body + gyro_bias + gaussian3(noise.gyro_noise_std);
      // Levelled frame: rotated by yaw only (x forward along the heading, z up).
      const Eigen::Matrix3d R_level_body =
          Eigen::AngleAxisd(-state.yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
          state.rotation;
      const Eigen::Vector3d f_level = R_level_body * f;
      const Eigen::Vector3d w_level = R_level_body * w;
      const Eigen::Vector3d v_level =
          Eigen::AngleAxisd(-state.yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
          state.velocity;
      double lat, lon, alt;
      mercator.toGeodetic(state.position, &lat, &lon, &alt);
      const double pos_accuracy = 0.02 + 0.01 * std::abs(std::sin(0.05 * t + 0.3));
      const double vel_accuracy = 0.015 + 0.005 * std::abs(std::sin(0.07 * t + 1.0));
      const int numsats = 9 + static_cast<int>(3 * std::abs(std::sin(0.02 * t + options.seed)));
      char line[1024];
      std::snprintf(line, sizeof(line),
                    "%.14g %.14g %.14g %.14g %.14g %.14g %.14g %.14g %.14g %.14g %.14g %.14g "
                    "%.14g %.14g %.14g %.14g %.14g %.14g %.14g %.14g %.14g %.14g %.14g %.14g "
                    "%.14g %d %d %d %d %d\n",
                    lat, lon, alt, state.roll, state.pitch, state.yaw, state.velocity.y(),
                    state.velocity.x(), v_level.x(), v_level.y(), v_level.z(), f.x(), f.y(), f.z(),
                    f_level.x(), f_level.y(), f_level.z(), w.x(), w.y(), w.z(), w_level.x(),
                    w_level.y(), w_level.z(), pos_accuracy, vel_accuracy, 4, numsats, 4, 4, 4);
      extract_lines.push_back(line);
    }
    std::vector<std::int64_t> stamps;
    std::string poses;
    for (int i = 0; i < samples; ++i) {
      writeTextAtomically(summary.extract_dir + "/oxts/data/" + frameName(i, ".txt"),
                          extract_lines[i]);
      stamps.push_back(stamp(extract_times[i]));
      poses += kitti::kittiPoseLine(extract_states[i].rotation, extract_states[i].position);
    }
    writeTextAtomically(summary.extract_dir + "/oxts/timestamps.txt", timestampsText(stamps));
    writeTextAtomically(summary.extract_dir + "/oxts/dataformat.txt", kDataFormat);
    writeTextAtomically(summary.extract_dir + "/ground_truth/poses_imu_map.txt", poses);
    summary.extract_frames = samples;
  }

  // ---- 10 Hz frames: lidar sweep centre times, nearest OXTS sample, camera triggers -----------
  std::vector<double> sweep_times;
  for (double t = 0.001 + 0.003 * unit(timing_rng); t <= options.duration_s;) {
    sweep_times.push_back(t);
    double period = 0.1 + 0.002 * normal(timing_rng);
    if (unit(timing_rng) < 0.02) period += (unit(timing_rng) < 0.5 ? -1 : 1) * 0.02;
    t += std::clamp(period, 0.07, 0.13);
  }
  const std::size_t frames = sweep_times.size();
  {
    ScopedTimer timer("synthetic/oxts");
    std::vector<std::int64_t> stamps;
    std::string poses;
    std::size_t j = 0;
    for (std::size_t k = 0; k < frames; ++k) {
      while (j + 1 < extract_times.size() && std::abs(extract_times[j + 1] - sweep_times[k]) <=
                                                 std::abs(extract_times[j] - sweep_times[k])) {
        ++j;
      }
      writeTextAtomically(summary.sync_dir + "/oxts/data/" + frameName(k, ".txt"),
                          extract_lines[j]);
      stamps.push_back(stamp(extract_times[j]));
      poses += kitti::kittiPoseLine(extract_states[j].rotation, extract_states[j].position);
    }
    writeTextAtomically(summary.sync_dir + "/oxts/timestamps.txt", timestampsText(stamps));
    writeTextAtomically(summary.sync_dir + "/oxts/dataformat.txt", kDataFormat);
    writeTextAtomically(gt_dir + "/poses_imu_map.txt", poses);
    summary.oxts_frames = static_cast<int>(frames);
  }
  {
    ScopedTimer timer("synthetic/world_save");
    world.save(gt_dir + "/world.txt");
  }

  // ---- Lidar and camera, frames in parallel ---------------------------------------------------
  const int camera_every =
      std::max(1, static_cast<int>(std::lround(10.0 / options.camera_rate_hz)));
  std::vector<std::size_t> camera_frames;  // lidar frame index of each image
  std::vector<double> image_times;
  for (std::size_t k = 0; k < frames; k += camera_every) {
    camera_frames.push_back(k);
    image_times.push_back(sweep_times[k] + options.camera_delay_s);
  }
  std::atomic<std::size_t> next_task{0};
  std::atomic<std::size_t> lidar_points{0};
  std::mutex error_mutex, progress_mutex;
  std::size_t tasks_done = 0;  // under progress_mutex
  std::exception_ptr first_error;
  const std::size_t lidar_tasks = options.write_lidar ? frames : 0;
  const std::size_t image_tasks = options.write_images ? camera_frames.size() : 0;
  auto worker = [&]() {
    try {
      while (true) {
        const std::size_t task = next_task.fetch_add(1);
        if (task >= lidar_tasks + image_tasks) return;
        {
          std::lock_guard<std::mutex> lock(error_mutex);
          if (first_error) return;
        }
        if (task < lidar_tasks) {
          const std::size_t k = task;
          const VehicleState state = route.poseAt(sweep_times[k]);
          const Eigen::Isometry3d T_map_velo =
              isometry(state.rotation, state.position) * T_imu_velo;
          LidarScan scan;
          {
            ScopedTimer timer("synthetic/lidar_raycast");
            scan = simulateLidarScan(world, T_map_velo, options.lidar, mixSeed(options.seed, 3, k));
          }
          ScopedTimer timer("synthetic/lidar_write");
          writeBytesAtomically(summary.sync_dir + "/velodyne_points/data/" + frameName(k, ".bin"),
                               scan.xyzi.data(), scan.xyzi.size() * sizeof(float));
          writeBytesAtomically(gt_dir + "/velodyne_labels/" + frameName(k, ".label"),
                               scan.labels.data(), scan.labels.size() * sizeof(std::uint32_t));
          lidar_points += scan.size();
        } else {
          const std::size_t i = task - lidar_tasks;
          const VehicleState state = route.poseAt(image_times[i]);
          const Eigen::Isometry3d T_map_camera =
              isometry(state.rotation, state.position) * T_imu_velo * T_velo_camera;
          RenderOptions render;
          render.noise_seed = mixSeed(options.seed, 4, i);
          RenderedImage image;
          {
            ScopedTimer timer("synthetic/camera_render");
            image = renderCamera(world, T_map_camera, K, options.image_width, options.image_height,
                                 render, 1);
          }
          ScopedTimer timer("synthetic/camera_write");
          writePng(summary.sync_dir + "/image_02/data/" + frameName(i, ".png"),
                   cv::Mat(image.height, image.width, CV_8UC3, image.bgr.data()));
          writePng(gt_dir + "/image_02_labels/" + frameName(i, ".png"),
                   cv::Mat(image.height, image.width, CV_8UC1, image.labels.data()));
        }
        if (options.on_progress) {
          std::lock_guard<std::mutex> lock(progress_mutex);
          options.on_progress(++tasks_done, lidar_tasks + image_tasks);
        }
      }
    } catch (...) {
      std::lock_guard<std::mutex> lock(error_mutex);
      if (!first_error) first_error = std::current_exception();
    }
  };
  std::vector<std::thread> workers;
  for (int t = 0; t < options.threads; ++t) workers.emplace_back(worker);
  for (std::thread& w : workers) w.join();
  if (first_error) std::rethrow_exception(first_error);

  {
    // Exact sensor poses at their own capture times (the OXTS frame can be ~5 ms off).
    std::string velo_poses, camera_poses;
    for (double t : sweep_times) {
      const VehicleState state = route.poseAt(t);
      const Eigen::Isometry3d T = isometry(state.rotation, state.position) * T_imu_velo;
      velo_poses += kitti::kittiPoseLine(T.linear(), T.translation());
    }
    for (double t : image_times) {
      const VehicleState state = route.poseAt(t);
      const Eigen::Isometry3d T =
          isometry(state.rotation, state.position) * T_imu_velo * T_velo_camera;
      camera_poses += kitti::kittiPoseLine(T.linear(), T.translation());
    }
    if (options.write_lidar) writeTextAtomically(gt_dir + "/poses_velodyne_map.txt", velo_poses);
    if (options.write_images) writeTextAtomically(gt_dir + "/poses_image_02_map.txt", camera_poses);
  }
  if (options.write_lidar) {
    std::vector<std::int64_t> centre, start, end;
    for (double t : sweep_times) {
      centre.push_back(stamp(t));
      start.push_back(stamp(t - 0.0515));
      end.push_back(stamp(t + 0.0515));
    }
    writeTextAtomically(summary.sync_dir + "/velodyne_points/timestamps.txt",
                        timestampsText(centre));
    writeTextAtomically(summary.sync_dir + "/velodyne_points/timestamps_start.txt",
                        timestampsText(start));
    writeTextAtomically(summary.sync_dir + "/velodyne_points/timestamps_end.txt",
                        timestampsText(end));
    summary.scans = static_cast<int>(frames);
    summary.lidar_points = lidar_points;
  }
  if (options.write_images) {
    std::vector<std::int64_t> stamps;
    for (double t : image_times) stamps.push_back(stamp(t));
    writeTextAtomically(summary.sync_dir + "/image_02/timestamps.txt", timestampsText(stamps));
    summary.images = static_cast<int>(image_times.size());
  }
  summary.wall_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
  return summary;
}

}  // namespace

void validateDriveOptions(const DriveOptions& options) {
  if (options.output_dir.empty()) throw std::invalid_argument("--output must be given");
  if (!(options.duration_s > 0 && options.duration_s <= 3600)) {
    throw std::invalid_argument("--duration must be in (0, 3600] seconds");
  }
  if (options.image_width < 16 || options.image_height < 16) {
    throw std::invalid_argument("--image-size must be at least 16x16");
  }
  if (!(options.camera_rate_hz > 0 && options.camera_rate_hz <= 10.0)) {
    throw std::invalid_argument("--camera-rate-hz must be in (0, 10]");
  }
  if (options.lidar.beams < 1 || options.lidar.beams > 512) {
    throw std::invalid_argument("--lidar-beams must be in 1..512");
  }
  if (options.threads < 1) throw std::invalid_argument("--threads must be >= 1");
  if (options.drive_number < 0 || options.drive_number > 9999) {
    throw std::invalid_argument("--drive must be in 0..9999");
  }
  if (!(options.lidar.azimuth_step_deg >= 0.01 && options.lidar.azimuth_step_deg <= 10)) {
    throw std::invalid_argument("--azimuth-step-deg must be in [0.01, 10]");
  }
  if (!(options.lidar.range_noise_std_m >= 0 && options.imu_noise.accel_noise_std >= 0 &&
        options.imu_noise.gyro_noise_std >= 0 && options.imu_noise.accel_bias_walk >= 0 &&
        options.imu_noise.gyro_bias_walk >= 0)) {
    throw std::invalid_argument("noise levels must be >= 0");
  }
  parseDateDays(options.date);
}

DriveSummary generateSyntheticDrive(const DriveOptions& options) {
  if (options.output_dir.empty()) throw std::invalid_argument("--output must be given");
  if (fs::exists(options.output_dir) && !fs::is_directory(options.output_dir)) {
    throw std::invalid_argument("--output " + options.output_dir + ": not a folder");
  }
  // Written into a hidden staging folder beside the result and moved in when complete: a full
  // disk or any failure half way leaves no half drive that a reader would take for a whole one.
  const fs::path date_dir = fs::path(options.output_dir) / options.date;
  const fs::path staging =
      fs::path(options.output_dir) /
      ("." + options.date + "_drive_" + std::to_string(options.drive_number) + ".partial");
  DriveOptions staged = options;
  staged.output_dir = staging.string();
  DriveSummary summary;
  try {
    fs::remove_all(staging);
    summary = generateInto(staged);
    fs::create_directories(date_dir);
    const fs::path staged_date = staging / options.date;
    // Calibration first (each file replaced atomically by rename), then the drive folders.
    for (const auto& entry : fs::directory_iterator(staged_date)) {
      if (entry.is_regular_file()) fs::rename(entry.path(), date_dir / entry.path().filename());
    }
    for (std::string* dir : {&summary.sync_dir, &summary.extract_dir}) {
      const fs::path target = date_dir / fs::path(*dir).filename();
      fs::remove_all(target);  // a drive generated again replaces the old one
      fs::rename(*dir, target);
      *dir = target.string();
    }
    summary.date_dir = date_dir.string();
    fs::remove_all(staging);
  } catch (...) {
    std::error_code ignored;
    fs::remove_all(staging, ignored);
    throw;
  }
  return summary;
}

}  // namespace synthetic
}  // namespace inekf_semantic_mapping
