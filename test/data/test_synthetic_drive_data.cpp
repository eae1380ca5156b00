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
