// generate_synthetic_drive: writes a synthetic drive in the KITTI raw layout with full ground
// truth (see include/inekf_semantic_mapping/synthetic/drive_generator.h for the layout).
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <string>

#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/synthetic/drive_generator.h"

namespace {

const char kUsage[] =
    "usage: generate_synthetic_drive --output DIR [options]\n"
    "  --output DIR            where <date>/<date>_drive_<nnnn>_{sync,extract}/ are written\n"
    "  --seed S                world and noise seed (default 1)\n"
    "  --duration SECONDS      drive length (default 30)\n"
    "  --date YYYY_MM_DD       (default 2011_09_26)\n"
    "  --drive N               drive number (default 1)\n"
    "  --lidar-beams N         (default 64)\n"
    "  --azimuth-step-deg D    lidar horizontal resolution (default 0.1728)\n"
    "  --range-noise M         lidar range noise std (default 0.02)\n"
    "  --image-size WxH        rectified image size (default 1242x375)\n"
    "  --camera-rate-hz R      camera rate, <= 10 (default 10)\n"
    "  --no-images / --no-lidar\n"
    "  --noise-free            perfect IMU (no white noise, no bias)\n"
    "  --accel-noise S --gyro-noise S --accel-bias-walk S --gyro-bias-walk S\n"
    "                          IMU noise (m/s^2, rad/s per 100 Hz sample; per sqrt(s) for walks)\n"
    "  --threads N             worker threads (default 2)\n";

[[noreturn]] void usageError(const std::string& message) {
  std::cerr << "generate_synthetic_drive: " << message << "\n\n" << kUsage;
  std::exit(2);
}

double parseNumber(const std::string& flag, const std::string& text) {
  try {
    std::size_t used = 0;
    const double value = std::stod(text, &used);
    if (used != text.size()) throw std::invalid_argument("trailing characters");
    return value;
  } catch (const std::exception&) {
    usageError(flag + " expects a number, got '" + text + "'");
  }
}

int parseInt(const std::string& flag, const std::string& text) {
  const double value = parseNumber(flag, text);
  if (value != static_cast<int>(value))
    usageError(flag + " expects an integer, got '" + text + "'");
  return static_cast<int>(value);
}

}  // namespace

int main(int argc, char** argv) {
  using namespace inekf_semantic_mapping;
  synthetic::DriveOptions options;
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) usageError(flag + " needs a value");
      return argv[++i];
    };
    if (flag == "--help" || flag == "-h") {
      std::cout << kUsage;
      return 0;
    } else if (flag == "--output") {
      options.output_dir = value();
    } else if (flag == "--seed") {
      const std::string text = value();
      try {
        std::size_t used = 0;
        options.seed = std::stoull(text, &used);
        if (used != text.size()) throw std::invalid_argument("trailing");
      } catch (const std::exception&) {
        usageError("--seed expects a non-negative integer, got '" + text + "'");
      }
    } else if (flag == "--duration") {
      options.duration_s = parseNumber(flag, value());
    } else if (flag == "--date") {
      options.date = value();
    } else if (flag == "--drive") {
      options.drive_number = parseInt(flag, value());
    } else if (flag == "--lidar-beams") {
      options.lidar.beams = parseInt(flag, value());
    } else if (flag == "--azimuth-step-deg") {
      options.lidar.azimuth_step_deg = parseNumber(flag, value());
      if (!(options.lidar.azimuth_step_deg >= 0.01 && options.lidar.azimuth_step_deg <= 10)) {
        usageError("--azimuth-step-deg must be in [0.01, 10]");
      }
    } else if (flag == "--range-noise") {
      options.lidar.range_noise_std_m = parseNumber(flag, value());
    } else if (flag == "--image-size") {
      const std::string text = value();
      int w = 0, h = 0;
      char tail;
      if (std::sscanf(text.c_str(), "%dx%d%c", &w, &h, &tail) != 2) {
        usageError("--image-size expects WxH, e.g. 1242x375, got '" + text + "'");
      }
      options.image_width = w;
      options.image_height = h;
    } else if (flag == "--camera-rate-hz") {
      options.camera_rate_hz = parseNumber(flag, value());
    } else if (flag == "--no-images") {
      options.write_images = false;
    } else if (flag == "--no-lidar") {
      options.write_lidar = false;
    } else if (flag == "--noise-free") {
      options.imu_noise = synthetic::ImuNoiseModel::none();
    } else if (flag == "--accel-noise") {
      options.imu_noise.accel_noise_std = parseNumber(flag, value());
    } else if (flag == "--gyro-noise") {
      options.imu_noise.gyro_noise_std = parseNumber(flag, value());
    } else if (flag == "--accel-bias-walk") {
      options.imu_noise.accel_bias_walk = parseNumber(flag, value());
    } else if (flag == "--gyro-bias-walk") {
      options.imu_noise.gyro_bias_walk = parseNumber(flag, value());
    } else if (flag == "--threads") {
      options.threads = parseInt(flag, value());
    } else {
      usageError("unknown argument '" + flag + "'");
    }
  }
  if (options.output_dir.empty()) usageError("--output is required");
  if (options.lidar.range_noise_std_m < 0 || options.imu_noise.accel_noise_std < 0 ||
      options.imu_noise.gyro_noise_std < 0 || options.imu_noise.accel_bias_walk < 0 ||
      options.imu_noise.gyro_bias_walk < 0) {
    usageError("noise levels must be >= 0");
  }

  try {
    const synthetic::DriveSummary summary = synthetic::generateSyntheticDrive(options);
    std::printf(
        "wrote %s\n  %d OXTS frames (10 Hz), %d extract frames (100 Hz), %d scans "
        "(%zu points, %.0f per scan), %d images %dx%d\n",
        summary.sync_dir.c_str(), summary.oxts_frames, summary.extract_frames, summary.scans,
        summary.lidar_points,
        summary.scans ? static_cast<double>(summary.lidar_points) / summary.scans : 0.0,
        summary.images, options.image_width, options.image_height);
    std::printf(
        "  drove %.1f m (loop %.1f m) in %.1f s; generated in %.2f s wall with %d "
        "threads\n",
        summary.distance_m, summary.loop_length_m, options.duration_s, summary.wall_seconds,
        options.threads);
    std::printf("%s", TimingRegistry::instance().report().c_str());
  } catch (const std::exception& error) {
    std::cerr << "generate_synthetic_drive: " << error.what() << "\n";
    return 1;
  }
  return 0;
}
