// inekf_offline: runs a filter over a KITTI raw oxts/ folder under the evaluation protocol and
// writes the trajectory (KITTI 12-number poses, TUM), the OXTS truth in the same format, and the
// per-frame states with the Euclidean pose covariance (for NEES): the filter's, the smoother's
// (--smooth) or the loop-closed one (--loop-closure), always in the same convention. The OXTS
// frames go through the same LocalizationSession as inekf_node's messages (start, origin, fix
// policy).
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <string>
#include <vector>

#include "gps_degradation_flags.h"
#include "inekf_semantic_mapping/common/atomic_file.h"
#include "inekf_semantic_mapping/common/cli_args.h"
#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/common/yaml_reader.h"
#include "inekf_semantic_mapping/estimation/loop_closure.h"
#include "inekf_semantic_mapping/estimation/oxts_run.h"
#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/kitti/oxts.h"
#include "inekf_semantic_mapping/kitti/poses.h"
#include "inekf_semantic_mapping/kitti/sensor_stream.h"
#include "inekf_semantic_mapping/registration/icp_registration.h"

namespace ism = inekf_semantic_mapping;
namespace estimation = inekf_semantic_mapping::estimation;

namespace {

constexpr char kUsage[] =
    "usage: inekf_offline --oxts OXTS_DIR --output-kitti POSES.txt [--output-tum TRAJ.txt]\n"
    "                     [--output-truth TRUTH_KITTI.txt] [--output-states STATES.csv]\n"
    "                     [--gps-every N] [--filter left|right|ekf] [--config FILE]\n"
    "                     [--init-yaw-sigma-deg DEG] [--init-yaw-error-deg DEG]\n"
    "                     [--gps-sigma-h M] [--gps-sigma-v M] [--gps-outage START:DURATION]...\n"
    "                     [--seed S] [--imu-gps-only] [--wheel-speed-sigma M]\n"
    "                     [--smooth [--single-pass]]\n"
    "                     [--loop-closure [--scans DIR] [--loop-config FILE]\n"
    "                     [--output-loops LOOPS.csv]]\n"
    "  --oxts            a KITTI raw oxts/ folder (data/%010d.txt + timestamps.txt)\n"
    "  --output-kitti    one IMU pose per OXTS frame in the map frame, 12 numbers (row-major "
    "3x4);\n"
    "                    the filter starts at the first fix (as inekf_node): frames before it\n"
    "                    repeat the start's pose and are left out of the ATE\n"
    "  --output-tum      'stamp_s x y z qx qy qz qw' per frame\n"
    "  --output-truth    the OXTS truth poses, same format as --output-kitti\n"
    "  --output-states   CSV: stamp, position, quaternion, velocity, biases, 6x6 pose covariance\n"
    "                    c00..c55 (row-major): [position error in the map frame (m), rotation\n"
    "                    error as a body-frame small angle, R_true = R Exp(d) (rad)]\n"
    "  --config          YAML as config/inekf.yaml (default: built-in defaults)\n"
    "  --filter          overrides the config's filter\n"
    "  --gps-*, --seed   degrade the OXTS fix before the filter sees it (default: unchanged)\n"
    "  --imu-gps-only    drop the OXTS solution's attitude and velocity columns: the filter\n"
    "                    starts levelled from gravity with an unknown yaw (as for a frame whose\n"
    "                    attitude and velocity columns are all zero) and the heading monitor\n"
    "                    aligns it from the GPS track\n"
    "  --wheel-speed-sigma  simulated wheel odometry: each frame's OXTS forward velocity vf\n"
    "                    plus N(0, M) as a wheel speed (what wheels would add; seeded by --seed)\n"
    "  --smooth          after the causal run, a Rauch-Tung-Striebel pass on the left-invariant\n"
    "                    error (filter left): every --output-* holds the smoothed estimate.\n"
    "                    A start without a known heading (--imu-gps-only, or a wrong one the\n"
    "                    monitor replaced) is run twice: the heading where it settled is carried\n"
    "                    back through the gyro to the start, and the second run starts there\n"
    "  --single-pass     with --smooth: one run only (the frames before the alignment keep the\n"
    "                    causal run's unknown heading)\n"
    "  --loop-closure    after --smooth: lidar loop closures (revisits by the smoothed estimate\n"
    "                    and its covariance, GICP of the two scans, robust loop factors on\n"
    "                    the smoothed run's own posterior over keyframes); every --output-*\n"
    "                    holds the loop-closed estimate, and the covariance columns its\n"
    "                    posterior covariance (see smoothed_posterior_graph.h); without an\n"
    "                    accepted loop the smoothed run, covariance included, stands\n"
    "  --scans           the scans, DIR/%010d.bin (or .txt) per OXTS frame (default: the\n"
    "                    drive's velodyne_points/data); the IMU-to-lidar calibration is\n"
    "                    calib_imu_to_velo.txt of the date folder (else of the drive folder)\n"
    "  --loop-config     YAML as config/loop_closure.yaml (default: built-in defaults)\n"
    "  --output-loops    CSV: one line per loop candidate, accepted or rejected and why\n";

// Adds one output to the run's set: written through a temporary file, and only renamed into
// place with the others once all are written (a reader never sees half a file or half a set).
void addOutput(ism::common::AtomicFileSet* outputs, const std::string& path,
               const std::function<void(std::ostream&)>& body) {
  outputs->addStream(path, [&](std::ostream& out) {
    out.precision(9);
    body(out);
  });
}

// The scan of each OXTS frame, for the loop search.
struct LoopScans {
  std::vector<std::string> paths;  // per OXTS frame; "" where it has none
  std::vector<bool> has_scan;
};

// A drive's scans (dir = velodyne_points/data beside its timestamps.txt) go with the OXTS frame
// nearest their stamp (within 50 ms): by file number, an _extract drive's 100 Hz OXTS frame k
// took scan k, ten times too early, and a frame the recorder dropped stopped the run. A folder
// of scans without timestamps pairs by file number (%010d.bin, else .txt). Frames without a scan
// take no part in the loop search.
LoopScans loopScans(const std::string& dir, const std::vector<ism::kitti::OxtsFrame>& frames) {
  namespace fs = std::filesystem;
  if (!fs::is_directory(dir)) {
    throw ism::common::UsageError("--loop-closure: the scan folder " + dir +
                                  " does not exist (give --scans DIR)");
  }
  LoopScans scans{std::vector<std::string>(frames.size()), std::vector<bool>(frames.size())};
  fs::path data_dir = fs::path(dir);
  if (!data_dir.has_filename()) data_dir = data_dir.parent_path();  // a trailing slash
  const fs::path stream_dir = data_dir.parent_path();
  if (data_dir.filename() == "data" && fs::is_regular_file(stream_dir / "timestamps.txt")) {
    const ism::kitti::SensorStream velodyne =
        ism::kitti::readSensorStream(stream_dir.string(), "velodyne_points");
    for (const std::string& warning : velodyne.warnings) {
      std::printf("inekf_offline: warning: %s\n", warning.c_str());
    }
    std::vector<std::int64_t> stamps_ns;
    for (const ism::kitti::OxtsFrame& frame : frames) stamps_ns.push_back(frame.stamp_ns);
    constexpr std::int64_t kScanToFrameMaxOffsetNs = 50'000'000;
    const std::vector<std::ptrdiff_t> scan_of =
        velodyne.framesAt(stamps_ns, kScanToFrameMaxOffsetNs);
    for (std::size_t k = 0; k < frames.size(); ++k) {
      if (scan_of[k] >= 0)
        scans.paths[k] = velodyne.framePath(static_cast<std::size_t>(scan_of[k]));
    }
  } else {
    for (std::size_t k = 0; k < frames.size(); ++k) {
      char name[32];
      std::snprintf(name, sizeof(name), "%010zu", frames[k].file_number);
      for (const char* extension : {".bin", ".txt"}) {
        const fs::path candidate = data_dir / (name + std::string(extension));
        if (fs::exists(candidate)) {
          scans.paths[k] = candidate.string();
          break;
        }
      }
    }
  }
  std::size_t without = 0;
  for (std::size_t k = 0; k < frames.size(); ++k) {
    scans.has_scan[k] = !scans.paths[k].empty();
    without += scans.has_scan[k] ? 0 : 1;
  }
  if (without == frames.size()) {
    throw std::runtime_error("--loop-closure: no OXTS frame has a scan in " + dir +
                             " (within 50 ms of its stamp, or of its file number without "
                             "timestamps)");
  }
  if (without > 0) {
    std::printf(
        "inekf_offline: warning: %zu of %zu OXTS frames have no scan in %s (frames the "
        "recorder dropped, or OXTS faster than the lidar): they take no part in the loop "
        "search\n",
        without, frames.size(), dir.c_str());
  }
  return scans;
}

}  // namespace

int main(int argc, char** argv) {
  using ism::common::UsageError;
  return ism::common::runCli("inekf_offline", kUsage, [&] {
    const ism::common::CommandLine cli(
        argc, argv,
        ism::tools::withGpsValueFlags({"--oxts", "--output-kitti", "--output-tum", "--output-truth",
                                       "--output-states", "--filter", "--config",
                                       "--init-yaw-sigma-deg", "--init-yaw-error-deg", "--scans",
                                       "--loop-config", "--output-loops", "--wheel-speed-sigma"}),
        {"--smooth", "--single-pass", "--loop-closure", "--imu-gps-only"},
        ism::tools::kGpsRepeatableFlags);
    if (cli.helpRequested()) return ism::common::printUsage(kUsage);
    if (!cli.has("--oxts") || !cli.has("--output-kitti")) {
      throw UsageError("--oxts and --output-kitti are required");
    }
    std::vector<std::string> output_paths;  // checked before the run
    for (const char* flag : {"--output-kitti", "--output-tum", "--output-truth", "--output-states",
                             "--output-loops"}) {
      if (cli.has(flag)) output_paths.push_back(cli.get(flag));
    }
    ism::common::checkOutputPaths(output_paths);
    ism::common::checkOutputsAreNotInputs(
        output_paths, cli.valuesOf({"--oxts", "--config", "--scans", "--loop-config"}));

    estimation::OxtsRunOptions options;
    const bool loop_closure = cli.has("--loop-closure");
    estimation::LoopClosureOptions loop_options;
    ism::registration::IcpOptions icp_options;
    if (!loop_closure &&
        (cli.has("--scans") || cli.has("--loop-config") || cli.has("--output-loops"))) {
      throw UsageError("--scans, --loop-config and --output-loops need --loop-closure");
    }
    if (loop_closure && !cli.has("--smooth")) {
      throw UsageError("--loop-closure runs on the smoothed estimate: add --smooth");
    }
    try {
      if (cli.has("--loop-config")) {
        ism::common::YamlReader reader =
            ism::common::YamlReader::fromFile(cli.get("--loop-config"));
        loop_options.read(&reader);
        icp_options.read(&reader);
        reader.rejectUnknown();
      }
      if (cli.has("--config")) {
        options.config = estimation::LocalizationSessionConfig::fromYamlFile(cli.get("--config"));
      }
      if (cli.has("--filter")) {
        options.config.localizer.filter_type =
            estimation::filterTypeFromString(cli.get("--filter"));
      }
      double& yaw_sigma_deg = options.config.localizer.initial_yaw_sigma_deg;
      yaw_sigma_deg = cli.getDouble("--init-yaw-sigma-deg", yaw_sigma_deg);
      if (cli.has("--init-yaw-sigma-deg") && !(yaw_sigma_deg > 0 && yaw_sigma_deg <= 180)) {
        throw UsageError("--init-yaw-sigma-deg must be in (0, 180]");
      }
      options.init_yaw_error_deg =
          cli.getDouble("--init-yaw-error-deg", options.init_yaw_error_deg);
      ism::tools::readGpsDegradationFlags(cli, &options.gps);
      options.smooth = cli.has("--smooth");
      options.imu_gps_only = cli.has("--imu-gps-only");
      options.wheel_speed_sigma_mps = cli.getDouble("--wheel-speed-sigma", 0.0);
      if (cli.has("--wheel-speed-sigma") &&
          !(options.wheel_speed_sigma_mps > 0.0 && std::isfinite(options.wheel_speed_sigma_mps))) {
        throw UsageError("--wheel-speed-sigma must be a positive number of m/s");
      }
      options.second_pass = !cli.has("--single-pass");
      if (cli.has("--single-pass") && !options.smooth) {
        throw UsageError("--single-pass applies to --smooth");
      }
      if (options.smooth &&
          options.config.localizer.filter_type != estimation::FilterType::kLeftInvariant) {
        throw UsageError("--smooth needs the left-invariant filter (--filter left)");
      }
    } catch (const UsageError&) {
      throw;
    } catch (const std::exception& e) {
      throw UsageError(e.what());  // a bad --config, --filter, --gps-outage or GPS option
    }

    std::vector<ism::kitti::OxtsFrame> frames;
    {
      ism::ScopedTimer timer("read_oxts");
      std::vector<std::string> warnings;
      frames = ism::kitti::readOxtsFolder(cli.get("--oxts"), &warnings);
      for (const std::string& warning : warnings) {
        std::printf("inekf_offline: warning: %s\n", warning.c_str());
      }
    }
    // The loop closure's inputs are checked before the (long) run.
    LoopScans loop_scans;
    Eigen::Isometry3d T_imu_velo = Eigen::Isometry3d::Identity();
    if (loop_closure) {
      namespace fs = std::filesystem;
      fs::path oxts_dir = fs::path(cli.get("--oxts"));
      if (!oxts_dir.has_filename()) oxts_dir = oxts_dir.parent_path();  // a trailing slash
      const fs::path drive_dir = oxts_dir.parent_path();
      const std::string scans_dir = cli.has("--scans")
                                        ? cli.get("--scans")
                                        : (drive_dir / "velodyne_points" / "data").string();
      loop_scans = loopScans(scans_dir, frames);
      // The raw calibration: the date folder's (KITTI's layout), else the drive folder's.
      std::string calib_dir;
      for (const fs::path& dir : {drive_dir.parent_path(), drive_dir}) {
        if (ism::kitti::hasRawCalibration(dir.string())) {
          calib_dir = dir.string();
          break;
        }
      }
      if (calib_dir.empty()) {
        throw std::runtime_error(
            "--loop-closure: no calib_imu_to_velo.txt (with the other raw "
            "calib_*.txt) in " +
            drive_dir.parent_path().string() + " or " + drive_dir.string());
      }
      T_imu_velo = ism::kitti::readRawCalibration(calib_dir).T_velo_imu.inverse();
    }
    estimation::OxtsRunResult run;
    {
      ism::ScopedTimer timer("filter_total");
      run = estimation::runLocalizerOnOxts(frames, options);
    }
    if (run.first_estimated_frame >= static_cast<int>(frames.size())) {
      // Written out, its start-state defaults would score as a perfect ATE of 0.
      throw std::runtime_error(
          cli.get("--oxts") + ": the filter never started (" + std::to_string(run.fixes_offered) +
          " of " + std::to_string(frames.size()) + " frames gave it a GPS fix): nothing written");
    }
    estimation::TrajectoryErrors smoothed_errors;
    estimation::LoopClosureResult loops;
    if (loop_closure) {
      smoothed_errors = estimation::compareWithTruth(run);
      ism::ScopedTimer timer("loop_closure");
      const ism::registration::IcpScanMatcher matcher(
          [&loop_scans](int frame) { return loop_scans.paths.at(frame); }, icp_options);
      loops = estimation::closeLoops(run, loop_scans.has_scan, T_imu_velo, matcher, loop_options);
      run.states = loops.states;
      run.pose_covariances = loops.pose_covariances;  // what --output-states writes
      for (const estimation::LoopRecord& loop : loops.loops) {
        std::printf(
            "inekf_offline: loop %d -> %d (%.1f s apart, %.2f m +- %.2f): %s, fitness "
            "%.4f m^2, correction %.2f m %.2f deg, chi2 %.1f / %.1f\n",
            loop.query_frame, loop.match_frame, loop.time_gap_s, loop.distance_m,
            loop.distance_sigma_m, loop.reason.c_str(), loop.fitness_m2, loop.correction_m,
            loop.correction_deg, loop.chi2_estimate, loop.chi2_final);
      }
    }
    ism::ScopedTimer write_timer("write_outputs");
    ism::common::AtomicFileSet outputs;
    // Each line is its frame's: a frame without an estimate of its own (before the start, held)
    // repeats the pose it is given but keeps its own stamp (TUM readers took the repeated stamps
    // as one pose); a misstamped frame keeps the estimate's, its own is the one that is wrong.
    std::vector<bool> misstamped(frames.size(), false);
    for (const int k : run.misstamped_frames) misstamped[static_cast<std::size_t>(k)] = true;
    const auto frameStamp = [&](std::size_t k) {
      return misstamped[k] ? run.states[k].stamp_s : frames[k].stampSeconds();
    };
    addOutput(&outputs, cli.get("--output-kitti"), [&](std::ostream& out) {
      for (const auto& s : run.states) out << ism::kitti::kittiPoseLine(s.rotation, s.position_map);
    });
    if (cli.has("--output-truth")) {
      addOutput(&outputs, cli.get("--output-truth"), [&](std::ostream& out) {
        for (const auto& t : run.truth) out << ism::kitti::kittiPoseLine(t);
      });
    }
    if (cli.has("--output-tum")) {
      addOutput(&outputs, cli.get("--output-tum"), [&](std::ostream& out) {
        out.precision(6);
        out << std::fixed;
        for (std::size_t k = 0; k < run.states.size(); ++k) {
          const auto& s = run.states[k];
          const Eigen::Quaterniond q(s.rotation);
          out << frameStamp(k) << ' ' << s.position_map.x() << ' ' << s.position_map.y() << ' '
              << s.position_map.z() << ' ' << q.x() << ' ' << q.y() << ' ' << q.z() << ' ' << q.w()
              << '\n';
        }
      });
    }
    if (cli.has("--output-states")) {
      addOutput(&outputs, cli.get("--output-states"), [&](std::ostream& out) {
        out << "stamp,px,py,pz,qx,qy,qz,qw,vx,vy,vz,bgx,bgy,bgz,bax,bay,baz";
        for (int r = 0; r < 6; ++r) {
          for (int c = 0; c < 6; ++c) out << ",c" << r << c;
        }
        out << '\n';
        for (std::size_t k = 0; k < run.states.size(); ++k) {
          const auto& s = run.states[k];
          const Eigen::Quaterniond q(s.rotation);
          char stamp[32];
          std::snprintf(stamp, sizeof(stamp), "%.6f", frameStamp(k));
          out << stamp << ',' << s.position_map.x() << ',' << s.position_map.y() << ','
              << s.position_map.z() << ',' << q.x() << ',' << q.y() << ',' << q.z() << ',' << q.w()
              << ',' << s.velocity_map.x() << ',' << s.velocity_map.y() << ',' << s.velocity_map.z()
              << ',' << s.gyro_bias.x() << ',' << s.gyro_bias.y() << ',' << s.gyro_bias.z() << ','
              << s.accel_bias.x() << ',' << s.accel_bias.y() << ',' << s.accel_bias.z();
          const auto& p = run.pose_covariances[k];
          for (int r = 0; r < 6; ++r) {
            for (int c = 0; c < 6; ++c) out << ',' << p(r, c);
          }
          out << '\n';
        }
      });
    }
    if (cli.has("--output-loops")) {
      addOutput(&outputs, cli.get("--output-loops"), [&](std::ostream& out) {
        out << estimation::loopCsvHeader() << '\n';
        for (const auto& loop : loops.loops) out << estimation::loopCsvLine(loop) << '\n';
      });
    }
    outputs.commit();
    const estimation::TrajectoryErrors errors = estimation::compareWithTruth(run);
    std::cout << ism::TimingRegistry::instance().report();
    std::printf(
        "inekf_offline: filter %s%s, %zu frames, imu used %lld dropped %lld, gps offered %d used "
        "%lld rejected %lld, ATE %.3f m, rotation RMSE %.3f deg, yaw RMSE %.3f deg\n",
        estimation::toString(options.config.localizer.filter_type).c_str(),
        run.smoothed ? (loop_closure ? " + RTS smoother + loop closure" : " + RTS smoother") : "",
        frames.size(), static_cast<long long>(run.statistics.filter.imu_used),
        static_cast<long long>(run.statistics.filter.imu_dropped), run.fixes_offered,
        static_cast<long long>(run.statistics.filter.gps_used),
        static_cast<long long>(run.statistics.filter.gps_rejected), errors.ate_m,
        errors.rotation_rmse_deg, errors.yaw_rmse_deg);
    const estimation::FixErrorMean fix_error = estimation::meanFixError(run);
    if (fix_error.fixes > 0 &&
        (options.gps.sigma_horizontal_m > 0 || options.gps.sigma_vertical_m > 0)) {
      // What the degraded fixes allow at best: their own mean error (README, smoothing).
      std::printf(
          "inekf_offline: the %d fixes' errors against the OXTS truth average (%.3f, %.3f, %.3f) m "
          "(east, north, up): an estimator that knew the car's relative motion exactly and took "
          "its "
          "position from these fixes would have an ATE of %.3f m\n",
          fix_error.fixes, fix_error.mean.x(), fix_error.mean.y(), fix_error.mean.z(),
          fix_error.mean.norm());
    }
    if (loop_closure) {
      std::printf(
          "inekf_offline: loop closure: %zu keyframes, %zu candidates, %d "
          "accepted, %d rejected; registration %.2f s, graph %.2f s (%d iterations), covariance "
          "%.3f s; ATE %.3f m -> %.3f m (smoothed -> loop-closed)\n",
          loops.keyframes.size(), loops.loops.size(), loops.accepted, loops.rejected,
          loops.seconds_registration, loops.seconds_optimization, loops.summary.iterations,
          loops.seconds_covariance, smoothed_errors.ate_m, errors.ate_m);
    }
    if (run.smoothed && options.config.localizer.nonholonomic) {
      // The smoothed velocity is GPS-aided and the constraint's vertical sigma loose, so its
      // direction shows the mounting; the causal estimate lags in pitch.
      constexpr double kMinSpeedMps = 3.0;
      const estimation::TravelDirection direction =
          estimation::travelDirectionInImu(run.states, kMinSpeedMps);
      if (direction.samples > 0) {
        std::printf(
            "inekf_offline: direction of travel in the IMU frame (median over %d smoothed states "
            "at >= %.0f m/s): pitch %.2f deg, yaw %.2f deg (nonholonomic.vehicle_pitch_deg / "
            "vehicle_yaw_deg: %.2f / %.2f)\n",
            direction.samples, kMinSpeedMps, direction.pitch_deg, direction.yaw_deg,
            options.config.localizer.nonholonomic_vehicle_pitch_deg,
            options.config.localizer.nonholonomic_vehicle_yaw_deg);
      }
    }
    for (const std::string& note : run.heading_notes) {
      std::printf("inekf_offline: %s\n", note.c_str());
    }
    {
      const auto& f = run.statistics.filter;
      std::printf(
          "inekf_offline: heading monitor: %lld aligned from the GPS track, %lld recovered, %lld "
          "re-opened; land-vehicle constraint %lld used / %lld skipped (heading unknown) / %lld "
          "suspended (fix rejected); standstill %lld used / %lld rejected\n",
          static_cast<long long>(f.heading_alignments),
          static_cast<long long>(f.heading_recoveries), static_cast<long long>(f.heading_reopens),
          static_cast<long long>(f.nonholonomic_used),
          static_cast<long long>(f.nonholonomic_skipped),
          static_cast<long long>(f.nonholonomic_suspended),
          static_cast<long long>(f.standstill_used), static_cast<long long>(f.standstill_rejected));
    }
    if (options.wheel_speed_sigma_mps > 0.0) {
      const auto& f = run.statistics.filter;
      std::printf(
          "inekf_offline: wheel speeds (simulated, sigma %.3f m/s): %lld used / %lld rejected / "
          "%lld stale / %lld ignored (before the start, while the heading or the filter's speed is "
          "too uncertain, or suspended)\n",
          options.wheel_speed_sigma_mps, static_cast<long long>(f.wheel_speed_used),
          static_cast<long long>(f.wheel_speed_rejected),
          static_cast<long long>(f.wheel_speed_stale),
          static_cast<long long>(f.wheel_speed_ignored));
    }
    if (run.smoother_breaks > 0) {
      std::printf("inekf_offline: the smoother restarted at %d IMU steps it could not reproduce\n",
                  run.smoother_breaks);
    }
    if (run.first_estimated_frame > 0) {
      std::printf("inekf_offline: no fix before frame %d: the filter started there\n",
                  run.first_estimated_frame);
    }
    if (run.statistics.messages_off_the_time_line > 0) {
      std::printf(
          "inekf_offline: %lld messages stamped more than session.time_jump_back_s off the newest "
          "were dropped: no second message confirmed their time jump\n",
          static_cast<long long>(run.statistics.messages_off_the_time_line));
    }
    if (!run.misstamped_frames.empty()) {
      std::printf(
          "inekf_offline: %zu frames (first %d) stamped off the frames around them (bad lines of "
          "timestamps.txt, warned above) left out of the filter\n",
          run.misstamped_frames.size(), run.misstamped_frames.front());
    }
    if (!run.held_frames.empty()) {
      std::printf(
          "inekf_offline: %zu frames (first %d) without an estimate of their own (after a reset "
          "until the next start, or their IMU sample dropped) repeat the last estimate and are "
          "not scored\n",
          run.held_frames.size(), run.held_frames.front());
    }
    return 0;
  });
}
