// KITTI raw I/O on the real data in ../shared (skipped loudly when absent): timestamps, OXTS
// files and folders, raw and object calibration, velodyne scans and rings, SemanticKITTI labels,
// raw drive folders. The data-free cases: test/unit/test_kitti_io.cpp.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/kitti/drive_timeline.h"
#include "inekf_semantic_mapping/kitti/errors.h"
#include "inekf_semantic_mapping/kitti/mercator.h"
#include "inekf_semantic_mapping/kitti/oxts.h"
#include "inekf_semantic_mapping/kitti/poses.h"
#include "inekf_semantic_mapping/kitti/raw_drive.h"
#include "inekf_semantic_mapping/kitti/timestamps.h"
#include "inekf_semantic_mapping/kitti/velodyne.h"
#include "kitti_format_error.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace kitti {
namespace {

namespace fs = std::filesystem;
using test::makeTempDir;
using test::sharedPath;

const char kDrive0001[] = "data/kitti_raw/2011_09_26/2011_09_26_drive_0001_sync";
const char kDrive0005[] = "data/kitti_raw/2011_09_26/2011_09_26_drive_0005_sync";
const char kDate0926[] = "data/kitti_raw/2011_09_26";

using test::expectFormatError;
using test::writeFile;

TEST(KittiTimestamps, ReadsRealFileAndNamesBadLine) {
  ISM_REQUIRE_SHARED(kDrive0001);
  const auto stamps = readTimestampLines(sharedPath(kDrive0001) + "/oxts/timestamps.txt");
  ASSERT_EQ(stamps.size(), 108u);
  for (const auto& stamp : stamps) ASSERT_TRUE(stamp.has_value());
  EXPECT_EQ(*stamps[0], 1317042145964389445LL);
  EXPECT_EQ(*stamps[1] - *stamps[0], 109958171LL);  // 26.074347616 - 25.964389445
  for (std::size_t i = 1; i < stamps.size(); ++i) EXPECT_GT(*stamps[i], *stamps[i - 1]);

  const std::string dir = makeTempDir("kitti_ts");
  writeFile(dir + "/timestamps.txt", "2011-09-26 13:02:25.964389445\nnot a time\n");
  expectFormatError([&] { readTimestampLines(dir + "/timestamps.txt"); },
                    {dir + "/timestamps.txt:2"});
  expectFormatError([&] { readTimestampLines(dir + "/missing.txt"); }, {"missing.txt"});
  fs::remove_all(dir);
}

TEST(KittiOxts, RealFourteenDecimalFileWithoutGpsSolution) {
  ISM_REQUIRE_SHARED(kDrive0005);
  const OxtsRecord r = readOxtsFile(sharedPath(kDrive0005) + "/oxts/data/0000000096.txt");
  EXPECT_DOUBLE_EQ(r.lat, 49.01101238314250);
  EXPECT_DOUBLE_EQ(r.wz, -0.24245760150804);
  EXPECT_EQ(r.numsats, 9);
  EXPECT_EQ(r.posmode, -1);
}

TEST(KittiOxts, ReadsRealFolder) {
  ISM_REQUIRE_SHARED(kDrive0001);
  const auto frames = readOxtsFolder(sharedPath(kDrive0001) + "/oxts");
  ASSERT_EQ(frames.size(), 108u);
  EXPECT_DOUBLE_EQ(frames[1].record.lat, 49.014997147797);
  EXPECT_DOUBLE_EQ(frames[1].record.az, 10.078281781295);
  EXPECT_NEAR(frames[0].stampSeconds(), 1317042145.964389445, 1e-6);
}

// ---------------------------------------------------------------------------- calibration
TEST(KittiCalibration, ReadsRawCalibrationOf20110926) {
  ISM_REQUIRE_SHARED(kDate0926);
  const RawCalibration calib = readRawCalibration(sharedPath(kDate0926));
  EXPECT_NEAR(calib.T_velo_imu.translation().x(), -8.086759e-01, 1e-9);
  EXPECT_NEAR(calib.T_velo_imu.linear()(1, 2), -1.482298e-02, 1e-6);
  EXPECT_NEAR(calib.T_cam0_velo.translation().z(), -2.717806e-01, 1e-9);
  EXPECT_NEAR(calib.T_cam0_velo.linear()(0, 1), -9.999714e-01, 1e-6);
  for (int i = 0; i < 4; ++i) EXPECT_TRUE(calib.cameras[i].present) << i;
  const CameraCalibration& cam2 = calib.cameras[2];
  EXPECT_DOUBLE_EQ(cam2.P_rect(0, 3), 4.485728e+01);
  EXPECT_DOUBLE_EQ(cam2.P_rect(2, 3), 2.745884e-03);
  EXPECT_DOUBLE_EQ(cam2.K(1, 2), 2.241806e+02);
  EXPECT_DOUBLE_EQ(cam2.D[4], -6.770705e-02);
  EXPECT_DOUBLE_EQ(cam2.T.x(), 5.956621e-02);
  EXPECT_EQ(cam2.S_rect, Eigen::Vector2d(1242, 375));

  const CameraProjection projection = calib.projection(2);
  EXPECT_EQ(projection.width, 1242);
  EXPECT_EQ(projection.height, 375);
  // R_rect_00 for every camera (the devkit chain), not R_rect_02.
  EXPECT_DOUBLE_EQ(projection.R_rect(0, 1), 9.837760e-03);
  // A point 10 m ahead of the velodyne lands near the principal point, a bit right of it
  // (cam2 sits 6 cm left of cam0; the velodyne 27 cm behind the cameras).
  const Eigen::Vector3d h = projection.projectHomogeneous(Eigen::Vector3d(10, 0, 0));
  ASSERT_GT(h.z(), 0);
  EXPECT_NEAR(h.x() / h.z(), 609.6 + 721.5 * (0.06 + 0.0) / 10.3, 15.0);
  EXPECT_NEAR(h.y() / h.z(), 172.9, 15.0);
  // The tf chain must reproduce the devkit projection: K * (T_cam2_velo * x) == P_rect * ...
  const Eigen::Vector3d x_velo(12.0, -3.0, 0.5);
  const Eigen::Vector3d via_frame =
      projection.rectifiedIntrinsics() * (projection.T_rectified_camera_velo() * x_velo);
  const Eigen::Vector3d devkit = projection.projectHomogeneous(x_velo);
  EXPECT_NEAR(via_frame.x() / via_frame.z(), devkit.x() / devkit.z(), 1e-3);
  EXPECT_NEAR(via_frame.y() / via_frame.z(), devkit.y() / devkit.z(), 1e-3);
}

TEST(KittiCalibration, ReadsObjectCalibration) {
  const std::string path = "data/kitti_object/training/calib/000000.txt";
  ISM_REQUIRE_SHARED(path);
  const ObjectCalibration calib = readObjectCalibration(sharedPath(path));
  EXPECT_DOUBLE_EQ(calib.P[2](0, 3), 4.575831e+01);
  EXPECT_DOUBLE_EQ(calib.P[3](1, 3), 2.330660e+00);
  EXPECT_DOUBLE_EQ(calib.R0_rect(1, 0), -1.012729e-02);
  EXPECT_NEAR(calib.Tr_velo_to_cam.translation().z(), -3.321029e-01, 1e-12);
  ASSERT_TRUE(calib.has_imu_to_velo);
  EXPECT_NEAR(calib.Tr_imu_to_velo.translation().x(), -8.086759e-01, 1e-12);
  const CameraProjection projection = calib.projection(2, 1242, 375);
  EXPECT_EQ(projection.width, 1242);
  EXPECT_DOUBLE_EQ(projection.P_rect(0, 0), 7.070493e+02);
}

TEST(KittiVelodyne, ReadsRealScanAndRecoversRings) {
  const std::string path = "data/kitti_object/training/velodyne/000000.bin";
  ISM_REQUIRE_SHARED(path);
  const VelodyneScan scan = readVelodyneBin(sharedPath(path));
  EXPECT_EQ(scan.size() * 16, fs::file_size(sharedPath(path)));
  EXPECT_GT(scan.size(), 100000u);
  const auto rings = computeRings(scan);
  ASSERT_EQ(rings.size(), scan.size());
  EXPECT_EQ(*std::max_element(rings.begin(), rings.end()), 63);
  // Rings are in scan order and the HDL-64E writes them top laser first: the mean elevation
  // must fall from ring to ring (a ring detector that splits or merges lasers breaks this).
  std::vector<double> sum(64, 0.0);
  std::vector<int> count(64, 0);
  for (std::size_t i = 0; i < scan.size(); ++i) {
    const float* p = scan.point(i);
    sum[rings[i]] += std::atan2(p[2], std::hypot(p[0], p[1]));
    ++count[rings[i]];
    if (i > 0) {
      ASSERT_GE(rings[i], rings[i - 1]);
    }
  }
  int decreasing = 0;
  for (int k = 0; k + 1 < 64; ++k) {
    ASSERT_GT(count[k], 100) << "ring " << k;
    decreasing += sum[k] / count[k] > sum[k + 1] / count[k + 1];
  }
  EXPECT_GE(decreasing, 60);  // a few low rings see the ground at similar mean elevation
}

TEST(KittiVelodyne, ReadsSemanticKittiLabels) {
  const std::string labels = "data/semantickitti_format/sequences/00/labels/000000.label";
  ISM_REQUIRE_SHARED(labels);
  const auto raw = readLabelFile(sharedPath(labels));
  const VelodyneScan scan =
      readVelodyneBin(sharedPath("data/semantickitti_format/sequences/00/velodyne/000000.bin"));
  EXPECT_EQ(raw.size(), scan.size());
  for (std::uint32_t label : raw) EXPECT_LT(semanticClass(label), 260);  // SemanticKITTI ids
  EXPECT_EQ(semanticClass(0x00050028u), 40);
  EXPECT_EQ(instanceId(0x00050028u), 5);
}

// ---------------------------------------------------------------------------- raw drive
TEST(KittiRawDrive, OpensOxtsOnlyDriveWithCalibration) {
  ISM_REQUIRE_SHARED(kDrive0001);
  const RawDrive drive(sharedPath(kDrive0001));
  EXPECT_TRUE(drive.hasOxts());
  EXPECT_FALSE(drive.hasVelodyne());
  EXPECT_FALSE(drive.hasCamera(2));
  EXPECT_FALSE(drive.isExtract());
  EXPECT_EQ(drive.oxts().size(), 108u);
  EXPECT_EQ(drive.oxts().extension, ".txt");
  EXPECT_EQ(drive.oxts().framePath(7), sharedPath(kDrive0001) + "/oxts/data/0000000007.txt");
  EXPECT_TRUE(drive.hasCalibration());
  EXPECT_EQ(fs::canonical(drive.calibrationDir()), fs::canonical(sharedPath(kDate0926)));
  const auto missing = drive.missingParts();
  EXPECT_NE(std::find(missing.begin(), missing.end(), "velodyne_points"), missing.end());
  for (const auto& part : missing) EXPECT_EQ(part.find("calibration"), std::string::npos);
  const auto frames = drive.readOxts();
  ASSERT_EQ(frames.size(), 108u);
  EXPECT_EQ(frames[0].stamp_ns, drive.firstStampNs());
}

TEST(KittiRawDrive, DriveWithoutCalibrationAndMissingFolder) {
  ISM_REQUIRE_SHARED("data/kitti_raw/2011_09_29/2011_09_29_drive_0071_sync");
  const RawDrive drive(sharedPath("data/kitti_raw/2011_09_29/2011_09_29_drive_0071_sync"));
  EXPECT_FALSE(drive.hasCalibration());
  EXPECT_THROW(drive.readCalibration(), KittiFormatError);
  const auto missing = drive.missingParts();
  EXPECT_NE(missing.back().find("calibration (no calib_*.txt in"), std::string::npos);
  // Where some files are there, the warning names the ones that are not.
  const std::string partial = makeTempDir("partial_calibration");
  for (const char* name : {"calib_cam_to_cam.txt", "calib_imu_to_velo.txt"}) {
    fs::copy_file(sharedPath(kDate0926) + "/" + name, partial + "/" + name);
  }
  const auto partly = RawDrive(sharedPath(kDrive0001), partial).missingParts();
  EXPECT_EQ(partly.back(), "calibration (calib_velo_to_cam.txt missing in " + partial + ")");
  // An explicit calibration folder without the files is not fatal either.
  EXPECT_FALSE(RawDrive(sharedPath("data/kitti_raw/2011_09_29/2011_09_29_drive_0071_sync"),
                        sharedPath("data/kitti_raw/2011_09_29"))
                   .hasCalibration());
  expectFormatError([] { RawDrive("/nonexistent/2011_09_26_drive_0001_sync"); },
                    {"/nonexistent/2011_09_26_drive_0001_sync"});
}

}  // namespace
}  // namespace kitti
}  // namespace inekf_semantic_mapping
