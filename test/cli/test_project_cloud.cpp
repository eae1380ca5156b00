// project_cloud on a real KITTI object scan of ../shared: the CSV it writes (the tool's contract).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <sstream>

#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/kitti/velodyne.h"
#include "inekf_semantic_mapping/perception/projection.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace perception {
namespace {

// Checks project_cloud's CSV against the library's projection of `scan` (header, one row per
// point inside the width x height image with depth > 0, values within the CSV's rounding);
// returns the rows.
std::size_t checkCsv(const std::string& csv_path, const kitti::VelodyneScan& scan,
                     const PointProjector& projector, int width, int height) {
  Eigen::Map<const Eigen::Matrix<float, 4, Eigen::Dynamic>> buffer(
      scan.xyzi.data(), 4, static_cast<Eigen::Index>(scan.size()));
  ProjectedPoints projected;
  projector.project(buffer.topRows<3>(), &projected);
  std::ifstream csv(csv_path);
  std::string line;
  std::getline(csv, line);
  EXPECT_EQ(line, "index,u,v,depth");
  std::size_t rows = 0;
  while (std::getline(csv, line)) {
    std::istringstream fields(line);
    std::size_t index;
    char comma;
    double u, v, depth;
    if (!(fields >> index >> comma >> u >> comma >> v >> comma >> depth) || index >= scan.size() ||
        !projected.valid[index]) {
      ADD_FAILURE() << "not a row of a projected point: " << line;
      return rows;
    }
    EXPECT_NEAR(u, projected.u[index], 2e-3);
    EXPECT_NEAR(v, projected.v[index], 2e-3);
    EXPECT_GT(depth, 0.0);
    // In the image: pixel k covers [k - 0.5, k + 0.5) (the CSV rounds to 1e-3).
    EXPECT_TRUE(u >= -0.5005 && u < width - 0.4995 && v >= -0.5005 && v < height - 0.4995) << line;
    ++rows;
  }
  EXPECT_EQ(rows, projected.validCount());
  return rows;
}

// A 1226x370 PNG (another day's size) in dir, for a calibration of 1242x375.
std::string croppedImage(const std::string& dir) {
  const std::string path = dir + "/cropped.png";
  cv::imwrite(path, cv::Mat(370, 1226, CV_8UC3, cv::Scalar(40, 50, 60)));
  return path;
}

PointProjector objectProjector(int width, int height) {
  const std::string calib_path = test::sharedPath("data/kitti_object/training/calib/000000.txt");
  const kitti::CameraProjection camera =
      kitti::readObjectCalibration(calib_path).projection(2, width, height);
  return PointProjector(camera.P_rect, camera.R_rect, camera.T_cam0_velo, width, height);
}

// project_cloud's CSV contract on the real frame: header, one row per point inside the image with
// depth > 0, index = row in the .bin, values equal to the library's projection.
TEST(Projection, ProjectCloudToolWritesTheCsvContract) {
  ISM_REQUIRE_SHARED("data/kitti_object/training/velodyne/000000.bin");
  const std::string base = test::sharedPath("data/kitti_object/training/");
  const std::string dir = test::makeTempDir("project_cloud");
  const std::string command =
      std::string(PROJECT_CLOUD_PATH) + " --calib " + base + "calib/000000.txt --velodyne " + base +
      "velodyne/000000.bin --image " + base + "image_2/000000.png --output " + dir +
      "/points.csv --overlay " + dir + "/overlay.png 2>/dev/null";
  ASSERT_EQ(std::system(command.c_str()), 0) << command;
  EXPECT_TRUE(std::filesystem::exists(dir + "/overlay.png"));

  const kitti::VelodyneScan scan = kitti::readVelodyneBin(base + "velodyne/000000.bin");
  // The PNG's size.
  EXPECT_GT(checkCsv(dir + "/points.csv", scan, objectProjector(1224, 370), 1224, 370), 0u);

  // An output that names an input is refused and the input kept (it was replaced by the CSV).
  std::filesystem::copy_file(base + "calib/000000.txt", dir + "/calib.txt");
  const std::string over_input = std::string(PROJECT_CLOUD_PATH) + " --calib " + dir +
                                 "/calib.txt --velodyne " + base + "velodyne/000000.bin --image " +
                                 base + "image_2/000000.png --output " + dir + "/calib.txt";
  const auto [status, output] = test::runCommand(over_input);
  EXPECT_NE(status, 0) << output;
  EXPECT_NE(output.find("is an input"), std::string::npos) << output;
  std::ifstream calib(dir + "/calib.txt");
  std::string line;
  std::getline(calib, line);
  EXPECT_EQ(line.rfind("P0:", 0), 0u) << line;
  std::filesystem::remove_all(dir);
}

// A raw drive's calibration (found by review: project_cloud read only object-format files and
// said "missing key 'P0'" for a calib_cam_to_cam.txt): --calib-dir takes the date folder, checks
// the image against its rectified size, and gives the library's projection.
TEST(Projection, ProjectCloudToolTakesARawDrivesDateFolder) {
  ISM_REQUIRE_SHARED("data/kitti_raw/2011_09_26/2011_09_26_drive_0013_sync/velodyne_points");
  const std::string date_dir = test::sharedPath("data/kitti_raw/2011_09_26");
  const std::string drive = date_dir + "/2011_09_26_drive_0013_sync";
  const std::string scan_path = drive + "/velodyne_points/data/0000000000.bin";
  const std::string image_path = drive + "/image_02/data/0000000000.png";
  const std::string dir = test::makeTempDir("project_cloud_raw");
  const auto [status, output] = test::runCommand(
      std::string(PROJECT_CLOUD_PATH) + " --calib-dir " + date_dir + " --velodyne " + scan_path +
      " --image " + image_path + " --output " + dir + "/points.csv");
  ASSERT_EQ(status, 0) << output;
  const kitti::CameraProjection camera = kitti::readRawCalibration(date_dir).projection(2);
  const PointProjector projector(camera.P_rect, camera.R_rect, camera.T_cam0_velo, 1242, 375);
  EXPECT_GT(checkCsv(dir + "/points.csv", kitti::readVelodyneBin(scan_path), projector, 1242, 375),
            10000u);

  // An image of another size than S_rect_02, and a raw file given to --calib: refused, named.
  const std::string other_size = std::string(PROJECT_CLOUD_PATH) + " --calib-dir " + date_dir +
                                 " --velodyne " + scan_path + " --image " + croppedImage(dir) +
                                 " --output " + dir + "/other.csv";
  const auto [size_status, size_output] = test::runCommand(other_size);
  EXPECT_NE(size_status, 0) << size_output;
  EXPECT_NE(size_output.find("the calibration's rectified size (S_rect) says 1242x375"),
            std::string::npos)
      << size_output;
  const auto [file_status, file_output] = test::runCommand(
      std::string(PROJECT_CLOUD_PATH) + " --calib " + date_dir + "/calib_cam_to_cam.txt" +
      " --velodyne " + scan_path + " --image " + image_path + " --output " + dir + "/file.csv");
  EXPECT_NE(file_status, 0) << file_output;
  EXPECT_NE(file_output.find("a raw drive's calibration file; give its folder with --calib-dir"),
            std::string::npos)
      << file_output;
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace perception
}  // namespace inekf_semantic_mapping
