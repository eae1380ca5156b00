// generate_synthetic_drive: writes a synthetic drive in the KITTI raw layout with full ground
// truth (see include/inekf_semantic_mapping/synthetic/drive_generator.h for the layout).
#include <cstdio>
#include <optional>
#include <string>

#include "inekf_semantic_mapping/common/cli_args.h"
#include "inekf_semantic_mapping/common/progress_log.h"
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

}  // namespace

int main(int argc, char** argv) {
  using namespace inekf_semantic_mapping;
  using common::UsageError;
  return common::runCli("generate_synthetic_drive", kUsage, [&] {
    const common::CommandLine cli(
        argc, argv,
        {"--output", "--seed", "--duration", "--date", "--drive", "--lidar-beams",
         "--azimuth-step-deg", "--range-noise", "--image-size", "--camera-rate-hz", "--accel-noise",
         "--gyro-noise", "--accel-bias-walk", "--gyro-bias-walk", "--threads"},
        {"--no-images", "--no-lidar", "--noise-free"});
    if (cli.helpRequested()) return common::printUsage(kUsage);

    synthetic::DriveOptions options;
    options.output_dir = cli.require("--output");
    options.seed = cli.getUint64("--seed", options.seed);
    options.duration_s = cli.getDouble("--duration", options.duration_s);
    options.date = cli.get("--date", options.date);
    options.drive_number = cli.getInt("--drive", options.drive_number);
    options.lidar.beams = cli.getInt("--lidar-beams", options.lidar.beams);
    options.lidar.azimuth_step_deg =
        cli.getDouble("--azimuth-step-deg", options.lidar.azimuth_step_deg);
    options.lidar.range_noise_std_m =
        cli.getDouble("--range-noise", options.lidar.range_noise_std_m);
    if (cli.has("--image-size")) {
      const std::string text = cli.get("--image-size");
      int w = 0, h = 0;
      char tail;
      if (std::sscanf(text.c_str(), "%dx%d%c", &w, &h, &tail) != 2) {
        throw UsageError("--image-size expects WxH, e.g. 1242x375, got '" + text + "'");
      }
      options.image_width = w;
      options.image_height = h;
    }
    options.camera_rate_hz = cli.getDouble("--camera-rate-hz", options.camera_rate_hz);
    if (cli.has("--no-images")) options.write_images = false;
    if (cli.has("--no-lidar")) options.write_lidar = false;
    // --noise-free first: explicit noise levels given with it still apply.
    if (cli.has("--noise-free")) options.imu_noise = synthetic::ImuNoiseModel::none();
    options.imu_noise.accel_noise_std =
        cli.getDouble("--accel-noise", options.imu_noise.accel_noise_std);
    options.imu_noise.gyro_noise_std =
        cli.getDouble("--gyro-noise", options.imu_noise.gyro_noise_std);
    options.imu_noise.accel_bias_walk =
        cli.getDouble("--accel-bias-walk", options.imu_noise.accel_bias_walk);
    options.imu_noise.gyro_bias_walk =
        cli.getDouble("--gyro-bias-walk", options.imu_noise.gyro_bias_walk);
    options.threads = cli.getInt("--threads", options.threads);
    try {  // every out-of-range option a usage error (exit status 2), before any work
      synthetic::validateDriveOptions(options);
    } catch (const std::invalid_argument& e) {
      throw UsageError(e.what());
    }

    // The sensors take most of the time (a minute or more for the default drive on 2 cores).
    std::optional<common::ProgressLog> progress;  // made at the first frame: its total
    options.on_progress = [&progress](std::size_t done, std::size_t total) {
      if (!progress) {
        progress.emplace("generate_synthetic_drive: lidar scans and images", total, "frames", 10.0);
      }
      progress->update(done);
    };
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
    return 0;
  });
}
