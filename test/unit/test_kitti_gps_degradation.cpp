// GpsDegrader: rate, outages, frames without a GPS solution, noise statistics, determinism.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "inekf_semantic_mapping/kitti/gps_degradation.h"
#include "inekf_semantic_mapping/kitti/mercator.h"

namespace inekf_semantic_mapping {
namespace kitti {
namespace {

OxtsRecord goodRecord() {
  OxtsRecord r;
  r.lat = 49.015003823272;
  r.lon = 8.4342971002335;
  r.alt = 116.43;
  r.posmode = 6;
  r.pos_accuracy = 0.03;
  return r;
}

TEST(GpsDegradation, DefaultsKeepEveryFixUnchanged) {
  GpsDegrader degrader{GpsDegradationOptions{}};
  const OxtsRecord r = goodRecord();
  for (std::size_t i = 0; i < 5; ++i) {
    const auto fix = degrader.degrade(i, 0.1 * i, r);
    ASSERT_TRUE(fix.has_value());
    EXPECT_EQ(fix->lat_deg, r.lat);
    EXPECT_EQ(fix->lon_deg, r.lon);
    EXPECT_EQ(fix->alt_m, r.alt);
    EXPECT_EQ(fix->sigma_horizontal_m, 0.03);  // the receiver's own accuracy
  }
}

TEST(GpsDegradation, RateOutageAndNoSolutionFrames) {
  GpsDegradationOptions options;
  options.every_n_frames = 3;
  options.outages_s = {GpsDegradationOptions::parseOutage("1.0:0.5")};
  GpsDegrader degrader(options);
  OxtsRecord r = goodRecord();
  std::vector<std::size_t> produced;
  for (std::size_t i = 0; i < 30; ++i) {
    if (degrader.degrade(i, 0.1 * static_cast<double>(i), r)) produced.push_back(i);
  }
  // Every third frame, minus frames 12 (t = 1.2 s) in the outage [1.0, 1.5); 15 (t = 1.5) is
  // just past it.
  EXPECT_EQ(produced, (std::vector<std::size_t>{0, 3, 6, 9, 15, 18, 21, 24, 27}));
  r.posmode = 0;
  EXPECT_FALSE(degrader.degrade(0, 0.0, r));
  r.posmode = -1;
  EXPECT_FALSE(degrader.degrade(0, 0.0, r));
  r = goodRecord();
  r.alt = std::nan("");
  EXPECT_FALSE(degrader.degrade(0, 0.0, r));
}

TEST(GpsDegradation, ParseOutageRejectsBadText) {
  EXPECT_EQ(GpsDegradationOptions::parseOutage("12.5:3"), std::make_pair(12.5, 3.0));
  for (const char* bad : {"12.5", "a:3", "1:-2", "1:2x", ":3", ""}) {
    EXPECT_THROW(GpsDegradationOptions::parseOutage(bad), std::invalid_argument) << bad;
  }
  GpsDegradationOptions options;
  options.every_n_frames = 0;
  EXPECT_THROW(GpsDegrader{options}, std::invalid_argument);
  options.every_n_frames = 1;
  options.sigma_vertical_m = -1;
  EXPECT_THROW(GpsDegrader{options}, std::invalid_argument);
}

TEST(GpsDegradation, NoiseHasTheRequestedSigmaInTheMapFrame) {
  GpsDegradationOptions options;
  options.sigma_horizontal_m = 2.0;
  options.sigma_vertical_m = 5.0;
  options.seed = 42;
  GpsDegrader degrader(options);
  const OxtsRecord r = goodRecord();
  const MercatorProjection projection = MercatorProjection::atFirstFix(r);
  const int n = 20000;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero(), sum_sq = Eigen::Vector3d::Zero();
  double sum_east_north = 0;
  for (int i = 0; i < n; ++i) {
    const auto fix = degrader.degrade(static_cast<std::size_t>(i), 0.1 * i, r);
    ASSERT_TRUE(fix.has_value());
    EXPECT_EQ(fix->sigma_horizontal_m, 2.0);
    EXPECT_EQ(fix->sigma_vertical_m, 5.0);
    const Eigen::Vector3d e = projection.toMap(fix->lat_deg, fix->lon_deg, fix->alt_m);
    sum += e;
    sum_sq += e.cwiseProduct(e);
    sum_east_north += e.x() * e.y();
  }
  const Eigen::Vector3d mean = sum / n;
  const Eigen::Vector3d stddev = (sum_sq / n - mean.cwiseProduct(mean)).cwiseSqrt();
  // Sample std of 20000 draws is within ~1% (1 sigma) of the truth: 4% is a safe bound.
  EXPECT_NEAR(stddev.x(), 2.0, 0.08);
  EXPECT_NEAR(stddev.y(), 2.0, 0.08);
  EXPECT_NEAR(stddev.z(), 5.0, 0.2);
  EXPECT_NEAR(mean.x(), 0.0, 0.06);
  EXPECT_NEAR(mean.y(), 0.0, 0.06);
  EXPECT_NEAR(mean.z(), 0.0, 0.15);
  EXPECT_NEAR(sum_east_north / n / 4.0, 0.0, 0.03);  // east and north independent
}

TEST(GpsDegradation, DeterministicForASeed) {
  GpsDegradationOptions options;
  options.sigma_horizontal_m = 1.0;
  options.sigma_vertical_m = 1.0;
  options.seed = 7;
  GpsDegrader a(options), b(options);
  options.seed = 8;
  GpsDegrader c(options);
  const OxtsRecord r = goodRecord();
  bool any_difference_to_other_seed = false;
  for (std::size_t i = 0; i < 50; ++i) {
    const auto fa = a.degrade(i, 0.1 * i, r), fb = b.degrade(i, 0.1 * i, r),
               fc = c.degrade(i, 0.1 * i, r);
    EXPECT_EQ(fa->lat_deg, fb->lat_deg);
    EXPECT_EQ(fa->lon_deg, fb->lon_deg);
    EXPECT_EQ(fa->alt_m, fb->alt_m);
    any_difference_to_other_seed |= fa->lat_deg != fc->lat_deg;
  }
  EXPECT_TRUE(any_difference_to_other_seed);
}

}  // namespace
}  // namespace kitti
}  // namespace inekf_semantic_mapping
