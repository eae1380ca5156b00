// project_cloud on a real KITTI object scan of ../shared: the CSV it writes (the tool's contract).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <sstream>

#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/kitti/velodyne.h"
#include "inekf_semantic_mapping/perception/projection.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace perception {
namespace {

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
  const PointProjector projector = objectProjector(1224, 370);  // the PNG's size
  Eigen::Map<const Eigen::Matrix<float, 4, Eigen::Dynamic>> buffer(
      scan.xyzi.data(), 4, static_cast<Eigen::Index>(scan.size()));
  ProjectedPoints projected;
  projector.project(buffer.topRows<3>(), &projected);

  std::ifstream csv(dir + "/points.csv");
  std::string line;
  std::getline(csv, line);
  EXPECT_EQ(line, "index,u,v,depth");
  std::size_t rows = 0;
  while (std::getline(csv, line)) {
    std::istringstream fields(line);
    std::size_t index;
    char comma;
    double u, v, depth;
    ASSERT_TRUE(fields >> index >> comma >> u >> comma >> v >> comma >> depth) << line;
    ASSERT_LT(index, scan.size());
    ASSERT_TRUE(projected.valid[index]) << line;
    EXPECT_NEAR(u, projected.u[index], 2e-3);
    EXPECT_NEAR(v, projected.v[index], 2e-3);
    EXPECT_GT(depth, 0.0);
    // In the image: pixel k covers [k - 0.5, k + 0.5) (the CSV rounds to 1e-3).
    EXPECT_TRUE(u >= -0.5005 && u < 1223.5005 && v >= -0.5005 && v < 369.5005) << line;
    ++rows;
  }
  EXPECT_EQ(rows, projected.validCount());

  // An output that names an input is refused and the input kept (it was replaced by the CSV).
  std::filesystem::copy_file(base + "calib/000000.txt", dir + "/calib.txt");
  const std::string over_input = std::string(PROJECT_CLOUD_PATH) + " --calib " + dir +
                                 "/calib.txt --velodyne " + base + "velodyne/000000.bin --image " +
                                 base + "image_2/000000.png --output " + dir + "/calib.txt";
  const auto [status, output] = test::runCommand(over_input);
  EXPECT_NE(status, 0) << output;
  EXPECT_NE(output.find("is an input"), std::string::npos) << output;
  std::ifstream calib(dir + "/calib.txt");
  std::getline(calib, line);
  EXPECT_EQ(line.rfind("P0:", 0), 0u) << line;
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace perception
}  // namespace inekf_semantic_mapping
