// project_cloud: projects a velodyne scan into camera 2 of a KITTI object-format calibration or
// of a raw drive's date folder.
//
//   project_cloud (--calib CALIB.txt | --calib-dir DATE_DIR) --velodyne SCAN.bin --image IMG.png
//                 --output POINTS.csv [--overlay OVERLAY.png]
// CSV: header `index,u,v,depth`, one row per point inside the image with depth > 0 (index = the
// point's row in the .bin, u/v in pixels, depth in metres). The image is read for its size and
// as the overlay's background (points colored by depth).
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include "inekf_semantic_mapping/common/atomic_file.h"
#include "inekf_semantic_mapping/common/cli_args.h"
#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/kitti/velodyne.h"
#include "inekf_semantic_mapping/perception/projection.h"

namespace {

constexpr char kUsage[] =
    "usage: project_cloud (--calib CALIB.txt | --calib-dir DATE_DIR) --velodyne SCAN.bin "
    "--image IMG.png --output POINTS.csv [--overlay OVERLAY.png]\n"
    "  --calib      an object or odometry calib.txt (P0..P3, Tr_velo_to_cam or Tr)\n"
    "  --calib-dir  a raw drive's date folder (calib_cam_to_cam.txt, calib_velo_to_cam.txt); the\n"
    "               image must have its rectified size (S_rect_02)\n";

// Camera 2 of the calibration the command line names, for an image of the given size.
inekf_semantic_mapping::kitti::CameraProjection cameraOf(
    const inekf_semantic_mapping::common::CommandLine& cli, const cv::Mat& image) {
  using namespace inekf_semantic_mapping;
  if (cli.has("--calib-dir")) {
    const kitti::CameraProjection camera =
        kitti::readRawCalibration(cli.get("--calib-dir")).projection(2);
    camera.checkRectifiedImageSize(cli.get("--image"), image.cols, image.rows);
    return camera;
  }
  const std::string calib = cli.get("--calib");
  const std::string name = std::filesystem::path(calib).filename().string();
  if (name == "calib_cam_to_cam.txt" || name == "calib_velo_to_cam.txt" ||
      name == "calib_imu_to_velo.txt") {
    throw std::invalid_argument(calib +
                                ": a raw drive's calibration file; give its folder with "
                                "--calib-dir (--calib reads an object or odometry calib.txt)");
  }
  return kitti::readObjectCalibration(calib).projection(2, image.cols, image.rows);
}

// The tool once the command line is read (errors propagate to runCli: exit 1).
int run(const inekf_semantic_mapping::common::CommandLine& cli) {
  using namespace inekf_semantic_mapping;
  cv::Mat image;
  {
    ScopedTimer timer("project_cloud/read");
    image = cv::imread(cli.get("--image"), cv::IMREAD_COLOR);
    if (image.empty()) throw std::runtime_error(cli.get("--image") + ": cannot read image");
  }
  const kitti::CameraProjection camera = cameraOf(cli, image);
  const kitti::VelodyneScan scan = kitti::readVelodyneBin(cli.get("--velodyne"));
  const perception::PointProjector projector(camera.P_rect, camera.R_rect, camera.T_cam0_velo,
                                             image.cols, image.rows);
  perception::ProjectedPoints projected;
  {
    ScopedTimer timer("project_cloud/project");
    Eigen::Map<const Eigen::Matrix<float, 4, Eigen::Dynamic>> buffer(
        scan.xyzi.data(), 4, static_cast<Eigen::Index>(scan.size()));
    projector.project(buffer.topRows<3>(), &projected);
  }
  // The CSV and the overlay appear together or not at all.
  common::AtomicFileSet outputs;
  {
    ScopedTimer timer("project_cloud/write_csv");
    outputs.addStream(cli.get("--output"), [&](std::ostream& csv) {
      csv << "index,u,v,depth\n";
      char line[96];
      for (std::size_t i = 0; i < projected.size(); ++i) {
        if (!projected.valid[i]) continue;
        std::snprintf(line, sizeof(line), "%zu,%.3f,%.3f,%.4f\n", i, projected.u[i], projected.v[i],
                      projected.depth[i]);
        csv << line;
      }
    });
  }
  if (cli.has("--overlay")) {
    ScopedTimer timer("project_cloud/overlay");
    cv::Mat overlay = image.clone();
    // Near = red, far (>= 50 m) = blue: OpenCV's JET colormap, computed once as a table.
    cv::Mat ramp(1, 256, CV_8UC1), jet;
    for (int k = 0; k < 256; ++k) ramp.at<std::uint8_t>(0, k) = static_cast<std::uint8_t>(k);
    cv::applyColorMap(ramp, jet, cv::COLORMAP_JET);
    for (std::size_t i = 0; i < projected.size(); ++i) {
      if (!projected.valid[i]) continue;
      const double scaled = std::min(1.0, projected.depth[i] / 50.0);
      const int level = static_cast<int>(255 * (1.0 - scaled));
      cv::circle(overlay,
                 cv::Point(static_cast<int>(projected.u[i]), static_cast<int>(projected.v[i])), 1,
                 cv::Scalar(jet.at<cv::Vec3b>(0, level)), cv::FILLED);
    }
    const std::string path = cli.get("--overlay");
    // imwrite picks the format from the temporary's extension: always PNG, as before.
    outputs.add(path, [&](const std::string& tmp) {
      const std::string png = tmp + ".png";
      const bool written = cv::imwrite(png, overlay);
      std::error_code error;
      if (written) std::filesystem::rename(png, tmp, error);
      if (!written || error) {
        std::filesystem::remove(png, error);
        throw std::runtime_error("cannot write '" + path + "'");
      }
    });
  }
  outputs.commit();
  std::cerr << "[project_cloud] " << projected.validCount() << " of " << scan.size()
            << " points inside the " << image.cols << "x" << image.rows << " image -> "
            << cli.get("--output") << "\n";
  if (cli.has("--overlay"))
    std::cerr << "[project_cloud] overlay -> " << cli.get("--overlay") << "\n";
  std::cerr << TimingRegistry::instance().report();
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace inekf_semantic_mapping;
  return common::runCli("project_cloud", kUsage, [&] {
    const common::CommandLine cli(
        argc, argv, {"--calib", "--calib-dir", "--velodyne", "--image", "--output", "--overlay"});
    if (cli.helpRequested()) return common::printUsage(kUsage);
    if (cli.has("--calib") == cli.has("--calib-dir")) {
      throw std::invalid_argument("give one of --calib (CALIB.txt) and --calib-dir (DATE_DIR)");
    }
    for (const char* flag : {"--velodyne", "--image", "--output"}) cli.require(flag);
    const std::vector<std::string> outputs = cli.valuesOf({"--output", "--overlay"});
    common::checkOutputPaths(outputs);
    common::checkOutputsAreNotInputs(outputs, cli.valuesOf({"--calib", "--velodyne", "--image"}));
    return run(cli);
  });
}
