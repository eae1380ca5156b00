// The synthetic drive's rig against the real KITTI calibration of 2011_09_26 in ../shared.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <sstream>

#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/kitti/mercator.h"
#include "inekf_semantic_mapping/kitti/oxts.h"
#include "inekf_semantic_mapping/kitti/raw_drive.h"
#include "inekf_semantic_mapping/kitti/timestamps.h"
#include "inekf_semantic_mapping/kitti/velodyne.h"
#include "inekf_semantic_mapping/perception/cityscapes.h"
#include "inekf_semantic_mapping/synthetic/drive_generator.h"
#include "inekf_semantic_mapping/synthetic/route.h"
#include "inekf_semantic_mapping/synthetic/world.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace synthetic {
namespace {
namespace fs = std::filesystem;

constexpr int kWidth = 621, kHeight = 188;

class SyntheticDrive : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    output_ = new std::string(test::makeTempDir("synthetic_drive"));
    DriveOptions options;
    options.output_dir = *output_;
    options.seed = 42;
    options.duration_s = 3.0;
    options.image_width = kWidth;
    options.image_height = kHeight;
    options.lidar.azimuth_step_deg = 0.4;  // fewer rays: the test stays fast
    options.imu_noise = ImuNoiseModel::none();
    options.threads = 2;
    summary_ = new DriveSummary(generateSyntheticDrive(options));
  }
  static void TearDownTestSuite() {
    fs::remove_all(*output_);
    delete summary_;
    delete output_;
  }
  static std::string* output_;
  static DriveSummary* summary_;
};
std::string* SyntheticDrive::output_ = nullptr;
DriveSummary* SyntheticDrive::summary_ = nullptr;

TEST(SyntheticRig, MatchesTheRealKittiCalibrationOf2011_09_26) {
  ISM_REQUIRE_SHARED("data/kitti_raw/2011_09_26/calib_cam_to_cam.txt");
  const kitti::RawCalibration real =
      kitti::readRawCalibration(test::sharedPath("data/kitti_raw/2011_09_26"));
  const KittiRig rig = KittiRig::kitti2011_09_26();
  EXPECT_LT((real.T_velo_imu.translation() - rig.t_velo_imu).norm(), 1e-9);
  EXPECT_LT((real.T_cam0_velo.translation() - rig.t_cam0_velo).norm(), 1e-9);
  EXPECT_LT((real.T_cam0_velo.linear() - rig.R_cam0_velo).cwiseAbs().maxCoeff(), 1e-6);
  for (int i = 0; i < 4; ++i) {
    const kitti::CameraProjection p = real.projection(i);
    EXPECT_LT((p.P_rect - rig.cameras[i].P_rect).cwiseAbs().maxCoeff(), 1e-9) << "camera " << i;
    EXPECT_EQ(p.width, KittiRig::kNominalWidth);
  }
}

}  // namespace
}  // namespace synthetic
}  // namespace inekf_semantic_mapping
