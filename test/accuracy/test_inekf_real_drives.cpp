// The filters on real KITTI OXTS drives from ../shared (skipped loudly without it), under the
// evaluation protocol: GPS = OXTS lat/lon/alt + N(0, 1.5 m) h / N(0, 3 m) v, once a second,
// seed 1, config/inekf.yaml. Thresholds are the targets for a careful left-InEKF.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <vector>

#include "inekf_semantic_mapping/estimation/oxts_run.h"
#include "inekf_semantic_mapping/kitti/gps_degradation.h"
#include "inekf_semantic_mapping/kitti/mercator.h"
#include "inekf_semantic_mapping/lie/so3.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace estimation {
namespace {

std::string oxtsDir(const std::string& drive) {
  return "data/kitti_raw/" + drive.substr(0, 10) + "/" + drive + "_sync/oxts";
}

OxtsRunOptions protocol(FilterType type) {
  OxtsRunOptions options;
  options.config = LocalizationSessionConfig::fromYamlFile(test::repoPath("config/inekf.yaml"));
  options.config.localizer.filter_type = type;
  options.gps = protocolGps();
  return options;
}

struct Target {
  const char* drive;
  double ate_m, rotation_rmse_deg;
};

TEST(RealDrives, GyroSampleFitsTheIntervalBeforeIt) {
  ISM_REQUIRE_SHARED(oxtsDir("2011_09_30_drive_0027"));
  const auto frames = kitti::readOxtsFolder(test::sharedPath(oxtsDir("2011_09_30_drive_0027")));
  double backward = 0.0, forward = 0.0;
  int count = 0;
  for (std::size_t k = 1; k < frames.size(); ++k) {
    const auto& a = frames[k - 1].record;
    const auto& b = frames[k].record;
    if (a.posmode <= 0 || b.posmode <= 0) continue;
    const double dt = frames[k].stampSeconds() - frames[k - 1].stampSeconds();
    const Eigen::Matrix3d relative =
        kitti::rotationFromRollPitchYaw(a.roll, a.pitch, a.yaw).transpose() *
        kitti::rotationFromRollPitchYaw(b.roll, b.pitch, b.yaw);
    const Eigen::Vector3d wa(a.wx, a.wy, a.wz), wb(b.wx, b.wy, b.wz);
    backward += lie::logSO3(lie::expSO3(wb * dt).transpose() * relative).squaredNorm();
    forward += lie::logSO3(lie::expSO3(wa * dt).transpose() * relative).squaredNorm();
    ++count;
  }
  backward = std::sqrt(backward / count) * 180.0 / M_PI;
  forward = std::sqrt(forward / count) * 180.0 / M_PI;
  std::printf(
      "[ MEASURED ] 0027 rotation residual per step: sample k over (k-1,k] %.4f deg, "
      "over (k,k+1] %.4f deg\n",
      backward, forward);
  EXPECT_LT(backward, 0.3 * forward);
}

TEST(RealDrives, LeftInvariantEkfMeetsTheTargets) {
  const Target targets[] = {{"2011_09_30_drive_0027", 2.1, 0.85},
                            {"2011_09_26_drive_0036", 2.3, 0.85},
                            {"2011_09_30_drive_0018", 2.1, 1.7}};
  int ran = 0;
  for (const Target& target : targets) {
    const std::string dir = test::sharedPath(oxtsDir(target.drive));
    if (!std::filesystem::exists(dir)) {
      std::fprintf(stderr, "*** SKIPPED drive %s: %s not found\n", target.drive, dir.c_str());
      continue;
    }
    const OxtsRunResult run =
        runLocalizerOnOxts(kitti::readOxtsFolder(dir), protocol(FilterType::kLeftInvariant));
    const TrajectoryErrors errors = compareWithTruth(run);
    std::printf("[ ACCURACY ] %s left: ATE %.2f m (target %.2f), rotation RMSE %.2f deg (%.2f)\n",
                target.drive, errors.ate_m, target.ate_m, errors.rotation_rmse_deg,
                target.rotation_rmse_deg);
    EXPECT_LT(errors.ate_m, target.ate_m) << target.drive;
    EXPECT_LT(errors.rotation_rmse_deg, target.rotation_rmse_deg) << target.drive;
    EXPECT_EQ(run.statistics.filter.gps_rejected, 0) << target.drive;
    EXPECT_EQ(run.states.size(), run.truth.size());
    ++ran;
  }
  if (ran < 2) GTEST_SKIP() << "fewer than two real drives available in " << test::sharedDir();
}

// The Rauch-Tung-Striebel pass (inekf_offline --smooth) on the same runs: measured ATE 1.36 ->
// 1.02 m on 0027, 1.35 -> 0.92 m on 0018, 1.46 -> 0.98 m on 0036 (with KITTI's IMU mounting in
// the land-vehicle constraint; without it the filter was worse, 1.74 / 1.71 / 1.93 m, and the
// ratio lower); guarded at 0.85 of the filter's and 1.3 m.
TEST(RealDrives, SmoothingLowersTheAte) {
  int ran = 0;
  for (const char* drive :
       {"2011_09_30_drive_0027", "2011_09_30_drive_0018", "2011_09_26_drive_0036"}) {
    const std::string dir = test::sharedPath(oxtsDir(drive));
    if (!std::filesystem::exists(dir)) {
      std::fprintf(stderr, "*** SKIPPED drive %s: %s not found\n", drive, dir.c_str());
      continue;
    }
    const auto frames = kitti::readOxtsFolder(dir);
    OxtsRunOptions options = protocol(FilterType::kLeftInvariant);
    const TrajectoryErrors filtered = compareWithTruth(runLocalizerOnOxts(frames, options));
    options.smooth = true;
    const OxtsRunResult run = runLocalizerOnOxts(frames, options);
    const TrajectoryErrors smoothed = compareWithTruth(run);
    std::printf(
        "[ ACCURACY ] %s smoothed: ATE %.2f m (filter %.2f), rotation RMSE %.2f deg "
        "(filter %.2f)\n",
        drive, smoothed.ate_m, filtered.ate_m, smoothed.rotation_rmse_deg,
        filtered.rotation_rmse_deg);
    EXPECT_TRUE(run.smoothed);
    EXPECT_EQ(run.smoother_breaks, 0) << drive;
    EXPECT_LT(smoothed.ate_m, 0.85 * filtered.ate_m) << drive;
    EXPECT_LT(smoothed.ate_m, 1.3) << drive;
    EXPECT_LT(smoothed.rotation_rmse_deg, 1.2) << drive;
    ++ran;
  }
  if (ran < 2) GTEST_SKIP() << "fewer than two real drives available in " << test::sharedDir();
  // The smoother is the left-invariant error's: another filter is refused, not smoothed wrongly.
  OxtsRunOptions right = protocol(FilterType::kRightInvariant);
  right.smooth = true;
  const auto frames = kitti::readOxtsFolder(test::sharedPath(oxtsDir("2011_09_30_drive_0027")));
  EXPECT_THROW(runLocalizerOnOxts(frames, right), std::invalid_argument);
}

// The floor of the smoother's ATE (README): the mean error of the fixes it was given. Without
// noise it is zero (each fix sits at its own frame's truth: one frame off would be about 1 m at
// the drive's speed); with vertical noise only, it is the mean of the degrader's own draws,
// recomputed here from the altitudes it returns. Under the protocol on 0027 that mean is
// -0.76 m: the best-informed smoother of that run gets no better than about 1.8x the filter's
// ATE.
TEST(RealDrives, TheFixesMeanErrorIsTheirNoiseMean) {
  ISM_REQUIRE_SHARED(oxtsDir("2011_09_30_drive_0027"));
  const auto frames = kitti::readOxtsFolder(test::sharedPath(oxtsDir("2011_09_30_drive_0027")));
  OxtsRunOptions options = protocol(FilterType::kLeftInvariant);
  options.gps.sigma_horizontal_m = 0.0;
  options.gps.sigma_vertical_m = 0.0;
  const FixErrorMean exact = meanFixError(runLocalizerOnOxts(frames, options));
  EXPECT_GT(exact.fixes, 100);
  EXPECT_LT(exact.mean.norm(), 0.01);

  options.gps.sigma_vertical_m = 3.0;
  const OxtsRunResult run = runLocalizerOnOxts(frames, options);
  const FixErrorMean noisy = meanFixError(run);
  kitti::GpsDegrader degrader(options.gps);
  double altitude_noise = 0.0;
  int count = 0;
  const double t0 = frames.front().stampSeconds();
  for (std::size_t k = 0; k < frames.size(); ++k) {
    const auto fix = degrader.degrade(k, frames[k].stampSeconds() - t0, frames[k].record);
    // The start's own fix initializes the filter; OxtsRunResult::fixes are those after it.
    if (!fix || static_cast<int>(k) <= run.first_estimated_frame) continue;
    altitude_noise += fix->alt_m - frames[k].record.alt;
    ++count;
  }
  ASSERT_EQ(noisy.fixes, count);
  std::printf("[ ACCURACY ] 0027, 3 m vertical noise at seed 1: the fixes' mean error %.3f m up\n",
              noisy.mean.z());
  EXPECT_LT(noisy.mean.head<2>().norm(), 0.01);
  EXPECT_NEAR(noisy.mean.z(), altitude_noise / count, 1e-3);
  EXPECT_GT(std::abs(noisy.mean.z()), 0.05);
}

// KITTI's OXTS is mounted 0.65 deg pitched against the car's direction of travel. The smoothed
// run with no mounting configured finds it from GPS and IMU alone (median 0.81 deg on 0027; the
// OXTS reference solution says 0.73 on average), and configuring it lowers the filter's ATE (1.74
// -> 1.36 m): the constraint no longer tilts the attitude to explain the car's apparent vertical
// velocity.
TEST(RealDrives, TheSmootherFindsTheImuMountingAndTheFilterGainsFromIt) {
  ISM_REQUIRE_SHARED(oxtsDir("2011_09_30_drive_0027"));
  const auto frames = kitti::readOxtsFolder(test::sharedPath(oxtsDir("2011_09_30_drive_0027")));
  OxtsRunOptions unmounted = protocol(FilterType::kLeftInvariant);
  unmounted.config.localizer.nonholonomic_vehicle_pitch_deg = 0.0;
  unmounted.smooth = true;
  const OxtsRunResult smoothed = runLocalizerOnOxts(frames, unmounted);
  const TravelDirection direction = travelDirectionInImu(smoothed.states);
  std::printf(
      "[ MEASURED ] 0027 direction of travel in the IMU frame: pitch %.2f deg, yaw %.2f "
      "deg (%d states)\n",
      direction.pitch_deg, direction.yaw_deg, direction.samples);
  EXPECT_GT(direction.samples, 500);
  EXPECT_NEAR(direction.pitch_deg, 0.65, 0.25);
  EXPECT_NEAR(direction.yaw_deg, 0.0, 0.25);

  unmounted.smooth = false;
  const double ate_unmounted = compareWithTruth(runLocalizerOnOxts(frames, unmounted)).ate_m;
  const double ate_mounted =
      compareWithTruth(runLocalizerOnOxts(frames, protocol(FilterType::kLeftInvariant))).ate_m;
  std::printf("[ ACCURACY ] 0027 left: ATE %.2f m with the mounting, %.2f m without\n", ate_mounted,
              ate_unmounted);
  EXPECT_LT(ate_mounted, 0.85 * ate_unmounted);
}

TEST(RealDrives, LeftInvariantEkfRecoversFromA90DegreeYawErrorFasterThanTheEskf) {
  ISM_REQUIRE_SHARED(oxtsDir("2011_09_30_drive_0027"));
  const auto frames = kitti::readOxtsFolder(test::sharedPath(oxtsDir("2011_09_30_drive_0027")));
  const double t0 = frames.front().stampSeconds();
  auto worstYawAfter = [&](const OxtsRunResult& run, double after_s) {
    double worst = 0.0;
    for (std::size_t k = 0; k < frames.size(); ++k) {
      if (frames[k].stampSeconds() - t0 >= after_s) {
        worst = std::max(worst, std::abs(yawErrorDeg(run, static_cast<int>(k))));
      }
    }
    return worst;
  };
  // The filters' own error definitions are compared without the land-vehicle constraint: once
  // the heading is known to 10 deg it brings all three to the same heading. With it (the
  // default) none may settle on the reverse heading, which the constraint alone cannot tell.
  for (bool nonholonomic : {false, true}) {
    double worst_after_20s[3], worst_after_60s[3];
    int i = 0;
    for (FilterType type :
         {FilterType::kLeftInvariant, FilterType::kQuaternionEskf, FilterType::kRightInvariant}) {
      OxtsRunOptions options = protocol(type);
      options.init_yaw_error_deg = 90.0;
      options.config.localizer.initial_yaw_sigma_deg = 180.0;
      options.config.localizer.nonholonomic = nonholonomic;
      const OxtsRunResult run = runLocalizerOnOxts(frames, options);
      EXPECT_NEAR(std::abs(yawErrorDeg(run, 0)), 90.0, 1e-6);
      worst_after_20s[i] = worstYawAfter(run, 20.0);
      worst_after_60s[i] = worstYawAfter(run, 60.0);
      std::printf("[ YAW 90   ] %s%s: max |yaw error| after 20 s %.2f deg, after 60 s %.2f deg\n",
                  toString(type).c_str(), nonholonomic ? " + land-vehicle constraint" : "",
                  worst_after_20s[i], worst_after_60s[i]);
      ++i;
    }
    EXPECT_LT(worst_after_60s[0], 1.5);
    if (nonholonomic) {
      EXPECT_LT(worst_after_60s[1], 1.5);
      EXPECT_LT(worst_after_60s[2], 1.5);
    } else {
      EXPECT_LT(worst_after_20s[0], worst_after_20s[1]);  // left converges faster than the ESKF
      EXPECT_LE(worst_after_60s[0], worst_after_60s[1]);
    }
  }
}

// IMU + GPS only (the OXTS solution's attitude and velocity columns zeroed: an IMU without an
// INS), against the reference start (the OXTS attitude and velocity at the first fix).
struct HeadingFigures {
  double motion_s = -1.0;            // first frame at >= 3 m/s (truth), s since frame 0
  double converged_s = -1.0;         // after motion: first time |yaw error| < 2 deg for good
  double worst_after_30s_deg = 0.0;  // max |yaw error| from motion + 30 s on
  double first_after_30s_deg = 0.0;  // |yaw error| at motion + 30 s
  int first_frame_after_30s = 0;
};

HeadingFigures headingFigures(const std::vector<kitti::OxtsFrame>& frames, const OxtsRunResult& run,
                              int exclude_first = -1, int exclude_last = -1) {
  HeadingFigures h;
  const double t0 = frames.front().stampSeconds();
  for (const auto& frame : frames) {
    if (std::hypot(frame.record.vn, frame.record.ve) >= 3.0) {
      h.motion_s = frame.stampSeconds() - t0;
      break;
    }
  }
  h.first_frame_after_30s = static_cast<int>(frames.size());
  double last_bad_s = h.motion_s;
  for (std::size_t k = static_cast<std::size_t>(run.first_estimated_frame); k < frames.size();
       ++k) {
    const int frame = static_cast<int>(k);
    if (frame >= exclude_first && frame <= exclude_last) continue;
    const double t = frames[k].stampSeconds() - t0;
    const double error = std::abs(yawErrorDeg(run, frame));
    if (t < h.motion_s) continue;
    if (error >= 2.0) last_bad_s = t;
    if (t >= h.motion_s + 30.0) {
      if (frame < h.first_frame_after_30s) h.first_after_30s_deg = error;
      h.first_frame_after_30s = std::min(h.first_frame_after_30s, frame);
      h.worst_after_30s_deg = std::max(h.worst_after_30s_deg, error);
    }
  }
  h.converged_s = last_bad_s - h.motion_s;
  return h;
}

// Errors over [first, end) without 0028's bad-truth stretch.
TrajectoryErrors errorsWithout(const OxtsRunResult& run, int first, int exclude_first,
                               int exclude_last) {
  if (exclude_first < 0) return compareWithTruth(run, first);
  const TrajectoryErrors a = compareWithTruth(run, first, exclude_first);
  const TrajectoryErrors b = compareWithTruth(run, std::max(first, exclude_last + 1));
  const int na = std::max(0, exclude_first - std::max(first, run.first_estimated_frame));
  const int nb = static_cast<int>(run.states.size()) - std::max(first, exclude_last + 1);
  const auto mix = [&](double x, double y) {
    return std::sqrt((na * x * x + nb * y * y) / std::max(1, na + nb));
  };
  return {mix(a.ate_m, b.ate_m), mix(a.rotation_rmse_deg, b.rotation_rmse_deg),
          mix(a.yaw_rmse_deg, b.yaw_rmse_deg)};
}

struct LongDrive {
  const char* drive;
  int exclude_first, exclude_last;  // bad OXTS truth (0028), -1: none
};
constexpr LongDrive kLongDrives[] = {{"2011_09_30_drive_0027", -1, -1},
                                     {"2011_09_30_drive_0018", -1, -1},
                                     {"2011_09_30_drive_0028", 769, 1202}};

// The heading converges from the GPS track within 30 s of motion and stays within 2 deg; after
// that the ATE is within 10 % of the reference start's. The zeroed columns are detected as "no
// attitude" (the same run as --imu-gps-only), and the smoother gains on the same.
TEST(RealDrives, ImuAndGpsOnlyFindTheHeadingAndMatchTheReferenceStart) {
  int ran = 0;
  for (const LongDrive& d : kLongDrives) {
    const std::string dir = test::sharedPath(oxtsDir(d.drive));
    if (!std::filesystem::exists(dir)) {
      std::fprintf(stderr, "*** SKIPPED drive %s: %s not found\n", d.drive, dir.c_str());
      continue;
    }
    const auto frames = kitti::readOxtsFolder(dir);
    std::vector<kitti::OxtsFrame> zeroed = frames;
    for (auto& frame : zeroed) frame.record = kitti::withoutAttitude(frame.record);
    OxtsRunOptions options = protocol(FilterType::kLeftInvariant);
    const OxtsRunResult reference = runLocalizerOnOxts(frames, options);
    const OxtsRunResult imu_gps = runLocalizerOnOxts(zeroed, options);
    options.imu_gps_only = true;
    const OxtsRunResult flagged = runLocalizerOnOxts(frames, options);
    ASSERT_EQ(imu_gps.states.size(), flagged.states.size());
    EXPECT_LT((imu_gps.states.back().position_map - flagged.states.back().position_map).norm(),
              1e-9)
        << d.drive << ": zeroed columns and --imu-gps-only must be the same run";
    // The zeroed frames' own "truth" has no attitude: the figures come from the flagged run,
    // whose truth is the OXTS solution's (the same estimate, checked above).
    const HeadingFigures h = headingFigures(frames, flagged, d.exclude_first, d.exclude_last);
    // The reference start's own excursions (0018: 5.7 deg over its interpolated-gyro run at
    // frame 1500; 0028: 2.1 deg) bound what any start can do after convergence.
    const HeadingFigures r = headingFigures(frames, reference, d.exclude_first, d.exclude_last);
    const int after = h.first_frame_after_30s;
    const TrajectoryErrors ref_after =
        errorsWithout(reference, after, d.exclude_first, d.exclude_last);
    const TrajectoryErrors own_after =
        errorsWithout(flagged, after, d.exclude_first, d.exclude_last);
    std::printf(
        "[ IMU+GPS  ] %s: motion at %.1f s, heading within 2 deg for good %.1f s later, worst "
        "after 30 s %.2f deg; after that ATE %.2f m (reference start %.2f), rotation RMSE %.2f "
        "deg (%.2f)\n",
        d.drive, h.motion_s, h.converged_s, h.worst_after_30s_deg, own_after.ate_m, ref_after.ate_m,
        own_after.rotation_rmse_deg, ref_after.rotation_rmse_deg);
    EXPECT_LT(h.first_after_30s_deg, 2.0) << d.drive;
    EXPECT_LT(h.worst_after_30s_deg, std::max(2.0, r.worst_after_30s_deg + 0.5)) << d.drive;
    EXPECT_LT(own_after.ate_m, 1.1 * ref_after.ate_m) << d.drive;

    options.imu_gps_only = true;
    options.smooth = true;
    const OxtsRunResult smoothed = runLocalizerOnOxts(frames, options);
    options.imu_gps_only = false;
    const OxtsRunResult smoothed_reference = runLocalizerOnOxts(frames, options);
    const TrajectoryErrors s_own = errorsWithout(smoothed, 0, d.exclude_first, d.exclude_last);
    const TrajectoryErrors s_ref =
        errorsWithout(smoothed_reference, 0, d.exclude_first, d.exclude_last);
    std::printf(
        "[ IMU+GPS  ] %s smoothed: ATE %.2f m (reference start %.2f), rotation RMSE %.2f deg "
        "(%.2f)\n",
        d.drive, s_own.ate_m, s_ref.ate_m, s_own.rotation_rmse_deg, s_ref.rotation_rmse_deg);
    EXPECT_EQ(smoothed.smoother_breaks, 0) << d.drive;
    EXPECT_LT(s_own.ate_m, 1.1 * s_ref.ate_m) << d.drive;
    EXPECT_LT(s_own.rotation_rmse_deg, 0.5) << d.drive;
    ++ran;
  }
  if (ran < 2) GTEST_SKIP() << "fewer than two long real drives available in " << test::sharedDir();
}

// A reference heading 60, 120 or 180 deg off that claims 1 deg: the fixes disagree, the
// monitor re-initialises the heading from the GPS track (logged and counted), within 2 deg 30 s
// after motion and for good, and the ATE after that within 10 % of the right start's.
TEST(RealDrives, AWrongReferenceHeadingIsRecovered) {
  int ran = 0;
  for (const LongDrive& d : kLongDrives) {
    const std::string dir = test::sharedPath(oxtsDir(d.drive));
    if (!std::filesystem::exists(dir)) {
      std::fprintf(stderr, "*** SKIPPED drive %s: %s not found\n", d.drive, dir.c_str());
      continue;
    }
    const auto frames = kitti::readOxtsFolder(dir);
    OxtsRunOptions options = protocol(FilterType::kLeftInvariant);
    const OxtsRunResult reference = runLocalizerOnOxts(frames, options);
    const HeadingFigures r = headingFigures(frames, reference, d.exclude_first, d.exclude_last);
    for (double error_deg : {60.0, 120.0, 180.0}) {
      options.init_yaw_error_deg = error_deg;
      const OxtsRunResult run = runLocalizerOnOxts(frames, options);
      const auto& f = run.statistics.filter;
      const HeadingFigures h = headingFigures(frames, run, d.exclude_first, d.exclude_last);
      const int after = h.first_frame_after_30s;
      const TrajectoryErrors ref_after =
          errorsWithout(reference, after, d.exclude_first, d.exclude_last);
      const TrajectoryErrors own_after = errorsWithout(run, after, d.exclude_first, d.exclude_last);
      std::printf(
          "[ YAW OFF  ] %s %.0f deg: %lld recoveries, %lld re-opens, %lld alignments; heading "
          "within 2 deg for good %.1f s after motion, worst after 30 s %.2f deg; ATE after %.2f "
          "m (right start %.2f)\n",
          d.drive, error_deg, static_cast<long long>(f.heading_recoveries),
          static_cast<long long>(f.heading_reopens), static_cast<long long>(f.heading_alignments),
          h.converged_s, h.worst_after_30s_deg, own_after.ate_m, ref_after.ate_m);
      EXPECT_GE(f.heading_recoveries + f.heading_reopens, 1) << d.drive << " " << error_deg;
      EXPECT_LT(h.first_after_30s_deg, 2.0) << d.drive << " " << error_deg;
      EXPECT_LT(h.worst_after_30s_deg, std::max(2.0, r.worst_after_30s_deg + 0.5))
          << d.drive << " " << error_deg;
      EXPECT_LT(own_after.ate_m, 1.1 * ref_after.ate_m) << d.drive << " " << error_deg;
    }
    ++ran;
  }
  if (ran < 2) GTEST_SKIP() << "fewer than two long real drives available in " << test::sharedDir();
}

// The slow and the outage drives (0087: residential at 3-4 m/s, where a 2-s chord is worth ~25
// deg; 0071: city, 47 s without GPS): the heading is held out of the position update until the
// track, of chords at least 12 m long, aligns it. IMU + GPS only: within 2 deg for good within
// 30 s of motion and never above 10 deg after that; a reference heading 60 deg off claiming 1
// deg: within 2 deg for good within 60 s of motion.
TEST(RealDrives, OnTheSlowAndTheOutageDrivesTheHeadingIsFoundAndAWrongOneRecovered) {
  int ran = 0;
  for (const char* drive : {"2011_09_26_drive_0087", "2011_09_29_drive_0071"}) {
    const std::string dir = test::sharedPath(oxtsDir(drive));
    if (!std::filesystem::exists(dir)) {
      std::fprintf(stderr, "*** SKIPPED drive %s: %s not found\n", drive, dir.c_str());
      continue;
    }
    const auto frames = kitti::readOxtsFolder(dir);
    OxtsRunOptions options = protocol(FilterType::kLeftInvariant);
    options.imu_gps_only = true;
    const HeadingFigures h = headingFigures(frames, runLocalizerOnOxts(frames, options));
    options.imu_gps_only = false;
    options.init_yaw_error_deg = 60.0;
    const HeadingFigures off = headingFigures(frames, runLocalizerOnOxts(frames, options));
    std::printf(
        "[ SLOW     ] %s: IMU+GPS only within 2 deg for good %.1f s after motion, worst after 30 "
        "s %.2f deg; 60 deg off: %.1f s, worst after 30 s %.2f deg\n",
        drive, h.converged_s, h.worst_after_30s_deg, off.converged_s, off.worst_after_30s_deg);
    EXPECT_LT(h.converged_s, 30.0) << drive;
    EXPECT_LT(h.worst_after_30s_deg, 10.0) << drive;
    EXPECT_LT(off.converged_s, 60.0) << drive;
    ++ran;
  }
  if (ran == 0) GTEST_SKIP() << "neither drive available in " << test::sharedDir();
}

// An offline smoother knows the future: with a start of unknown heading, the second pass
// carries the heading from where it settled back to the start through the gyro, so that the
// whole smoothed drive, the frames before the alignment included, matches the reference start
// (the targets: ATE <= 1.15x, rotation RMSE <= 1.5x). The single pass is far off on the same
// drives (the frames before the alignment keep the unknown heading). On the 11 and 15 s drives
// the heading is known to only about 2 deg when the drive ends, against the OXTS solution's
// 0.1 deg: there the second pass is held to a large gain over the single one instead.
TEST(RealDrives, TheSecondPassGivesTheWholeSmoothedDriveTheHeading) {
  struct Drive {
    const char* name;
    bool short_drive;
  };
  int ran = 0;
  for (const Drive& d :
       {Drive{"2011_09_26_drive_0001", true}, Drive{"2011_09_26_drive_0005", true},
        Drive{"2011_09_26_drive_0009", false}, Drive{"2011_09_26_drive_0036", false},
        Drive{"2011_09_26_drive_0061", false}, Drive{"2011_09_26_drive_0087", false},
        Drive{"2011_09_29_drive_0071", false}}) {
    const std::string dir = test::sharedPath(oxtsDir(d.name));
    if (!std::filesystem::exists(dir)) {
      std::fprintf(stderr, "*** SKIPPED drive %s: %s not found\n", d.name, dir.c_str());
      continue;
    }
    const auto frames = kitti::readOxtsFolder(dir);
    OxtsRunOptions options = protocol(FilterType::kLeftInvariant);
    options.smooth = true;
    const TrajectoryErrors reference = compareWithTruth(runLocalizerOnOxts(frames, options));
    options.imu_gps_only = true;
    const OxtsRunResult two = runLocalizerOnOxts(frames, options);
    options.second_pass = false;
    const OxtsRunResult one = runLocalizerOnOxts(frames, options);
    const TrajectoryErrors e2 = compareWithTruth(two), e1 = compareWithTruth(one);
    std::printf(
        "[ 2ND PASS ] %s: smoothed IMU+GPS only ATE %.3f m, rotation RMSE %.3f deg (one pass "
        "%.3f / %.3f; reference start %.3f / %.3f); heading carried back from frame %d, start "
        "yaw sigma %.2f deg\n",
        d.name, e2.ate_m, e2.rotation_rmse_deg, e1.ate_m, e1.rotation_rmse_deg, reference.ate_m,
        reference.rotation_rmse_deg, two.second_pass_reference_frame,
        two.second_pass_yaw_sigma_deg);
    ASSERT_TRUE(two.second_pass) << d.name;
    EXPECT_FALSE(one.second_pass) << d.name;
    EXPECT_EQ(two.smoother_breaks, 0) << d.name;
    if (d.short_drive) {
      EXPECT_LT(e2.ate_m, 0.5 * e1.ate_m) << d.name;
      EXPECT_LT(e2.rotation_rmse_deg, 0.75 * e1.rotation_rmse_deg) << d.name;
    } else {
      EXPECT_LT(e2.ate_m, 1.15 * reference.ate_m) << d.name;
      EXPECT_LT(e2.rotation_rmse_deg, 1.5 * reference.rotation_rmse_deg) << d.name;
      EXPECT_LT(e2.ate_m, 0.9 * e1.ate_m) << d.name;
    }
    ++ran;
  }
  if (ran == 0) GTEST_SKIP() << "none of the drives available in " << test::sharedDir();
}

// A stated heading 90 deg off with a sigma that says it is not known (180 deg): the monitor
// replaces it, and the second pass carries the settled heading back. The check "the stated start
// agrees with the carried-back heading" took the stated sigma into its 3-sigma bound and agreed
// with any offset: the first pass was kept (rotation RMSE 5.4 deg; 0.7 with the second pass).
TEST(RealDrives, AnUnknownStatedHeadingGetsTheSecondPass) {
  const std::string dir = test::sharedPath(oxtsDir("2011_09_26_drive_0005"));
  ISM_REQUIRE_SHARED(oxtsDir("2011_09_26_drive_0005"));
  const auto frames = kitti::readOxtsFolder(dir);
  OxtsRunOptions options = protocol(FilterType::kLeftInvariant);
  options.smooth = true;
  options.init_yaw_error_deg = 90.0;
  options.config.localizer.initial_yaw_sigma_deg = 180.0;
  const OxtsRunResult run = runLocalizerOnOxts(frames, options);
  const TrajectoryErrors errors = compareWithTruth(run);
  std::printf(
      "[ MEASURED ] 0005, stated heading 90 deg off (sigma 180): second pass %d, ATE %.3f "
      "m, rotation RMSE %.3f deg\n",
      run.second_pass ? 1 : 0, errors.ate_m, errors.rotation_rmse_deg);
  EXPECT_TRUE(run.second_pass);
  EXPECT_LT(errors.rotation_rmse_deg, 2.0);
}

}  // namespace
}  // namespace estimation
}  // namespace inekf_semantic_mapping
