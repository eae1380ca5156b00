// make_camera_labels: training labels for the camera from a SemanticKITTI sequence. Each frame's
// human-labelled lidar points are projected into the colour cameras (image_2 with P2, image_3
// with P3 of calib.txt); a point the camera cannot see (perception::rejectOccludedPoints, the
// mapping's occlusion test) labels nothing, and the nearest point wins a pixel. The output is
// the layout scripts/adapt_segmentation.sh trains on (`--sparse-root`):
//
//   OUT/image_2/<frame>.png    the frame's image, copied as it is
//   OUT/labels_2/<frame>.png   16-bit: the SemanticKITTI class of the point seen there, 0: none
//   OUT/image_3/..., OUT/labels_3/...   the same for the right camera, where image_3/ exists
//   OUT/calib.txt, poses.txt, times.txt  copied
//
//   make_camera_labels --sequence SEQ --output OUT/sequences/NN [--every N] [--max-frames N]
//                      [--cameras 2,3]
#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/common/atomic_file.h"
#include "inekf_semantic_mapping/common/cli_args.h"
#include "inekf_semantic_mapping/common/progress_log.h"
#include "inekf_semantic_mapping/evaluation/semantic_evaluation.h"
#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/kitti/velodyne.h"
#include "inekf_semantic_mapping/perception/projection.h"

namespace fs = std::filesystem;
namespace ism = inekf_semantic_mapping;
using ism::common::UsageError;

namespace {

constexpr char kUsage[] =
    "usage: make_camera_labels --sequence SEQ --output OUT [--every N] [--max-frames N]\n"
    "                          [--cameras 2,3]\n"
    "  --sequence    a SemanticKITTI sequence folder: velodyne/*.bin, labels/*.label,\n"
    "                image_2/*.png (image_3/*.png for the right camera), calib.txt\n"
    "  --output      the folder to write (OUT/sequences/NN for adapt_segmentation.sh\n"
    "                --sparse-root OUT): image_N/, labels_N/ (16-bit PNG, the SemanticKITTI\n"
    "                class of the lidar point the camera sees at that pixel, 0 where none),\n"
    "                calib.txt, poses.txt, times.txt\n"
    "  --every       every N-th frame (default 1; a whole sequence holds thousands of nearly\n"
    "                equal frames, and each training image holds about 14 MB of the\n"
    "                teacher's distributions while adapt_segmentation trains)\n"
    "  --max-frames  at most this many frames (after --every; default: all)\n"
    "  --cameras     2, 3 or 2,3 (default): camera 3 where image_3/ holds the frame\n";

std::vector<int> parseCameras(const std::string& text) {
  std::vector<int> cameras;
  std::stringstream list(text);
  std::string item;
  while (std::getline(list, item, ',')) {
    if (item != "2" && item != "3")
      throw UsageError("--cameras: expected 2, 3 or 2,3, got '" + text + "'");
    const int camera = item[0] - '0';
    if (std::find(cameras.begin(), cameras.end(), camera) == cameras.end())
      cameras.push_back(camera);
  }
  // getline drops a trailing empty item: "2," is refused as ",2" is.
  if (cameras.empty() || text.back() == ',') {
    throw UsageError("--cameras: expected 2, 3 or 2,3, got '" + text + "'");
  }
  return cameras;
}

void copyAtomically(const fs::path& from, const fs::path& to) {
  ism::common::commitFileAtomically(to.string(), [&](const std::string& tmp) {
    fs::copy_file(from, tmp, fs::copy_options::overwrite_existing);
  });
}

struct Totals {
  std::size_t images = 0;
  std::size_t labelled_pixels = 0;
  std::size_t points_in_view = 0;
  std::size_t hidden = 0;
  std::size_t missing_images = 0;       // frames without image_3/<frame>.png (camera 3 asked for)
  std::map<int, cv::Size> image_sizes;  // of each camera's first image
};

// One camera of one frame: the visible points' classes written as OUT/labels_N/<frame>.png.
void writeCameraLabels(const ism::kitti::VelodyneScan& scan,
                       const std::vector<std::uint32_t>& point_labels,
                       const ism::kitti::ObjectCalibration& calibration, int camera,
                       const fs::path& image_path, const fs::path& output, const std::string& frame,
                       Totals* totals) {
  namespace perception = ism::perception;
  const cv::Mat image = cv::imread(image_path.string(), cv::IMREAD_UNCHANGED);
  if (image.empty()) throw std::runtime_error("cannot read image " + image_path.string());
  // The training reads 8-bit colour; a 16-bit image was copied into the training set as it was.
  if (image.depth() != CV_8U) {
    throw std::runtime_error(image_path.string() + ": " + std::to_string(8 * image.elemSize1()) +
                             "-bit image: the camera images must be 8-bit");
  }
  const ism::kitti::CameraProjection projection =
      calibration.projection(camera, image.cols, image.rows);
  // The calibration is of the camera's own image size: an image of another size (resized) was
  // labelled through it, the labels in the wrong pixels, with exit status 0.
  const double cx = projection.P_rect(0, 2), cy = projection.P_rect(1, 2);
  if (!(cx > 0.25 * image.cols && cx < 0.75 * image.cols && cy > 0.25 * image.rows &&
        cy < 0.75 * image.rows)) {
    char text[200];
    std::snprintf(text, sizeof text,
                  ": %dx%d, but the calibration's principal point (%.0f, %.0f) is not near its "
                  "middle: the image is not of the calibrated size (resized?)",
                  image.cols, image.rows, cx, cy);
    throw std::runtime_error(image_path.string() + text);
  }
  if (totals->image_sizes.count(camera) &&
      totals->image_sizes.at(camera) != cv::Size(image.cols, image.rows)) {
    const cv::Size first = totals->image_sizes.at(camera);
    throw std::runtime_error(image_path.string() + ": " + std::to_string(image.cols) + "x" +
                             std::to_string(image.rows) + ", the camera's other images are " +
                             std::to_string(first.width) + "x" + std::to_string(first.height));
  }
  totals->image_sizes[camera] = cv::Size(image.cols, image.rows);
  const perception::PointProjector projector(projection.P_rect, projection.R_rect,
                                             projection.T_cam0_velo, image.cols, image.rows);
  const Eigen::Map<const Eigen::Matrix<float, 4, Eigen::Dynamic>> xyzi(
      scan.xyzi.data(), 4, static_cast<Eigen::Index>(scan.size()));
  perception::ProjectedPoints projected;
  projector.project(xyzi.topRows<3>(), &projected);

  // Hidden points are passed over: the nearest point the camera sees takes the pixel, whatever
  // its class (an unlabelled point in front still hides a labelled one behind it).
  constexpr std::uint32_t kHidden = 0xFFFFFFFFu;
  std::vector<std::uint32_t> classes(scan.size());
  for (std::size_t i = 0; i < scan.size(); ++i)
    classes[i] = ism::kitti::semanticClass(point_labels[i]);
  std::size_t hidden = 0;
  perception::rejectOccludedPoints(projected, image.cols, image.rows,
                                   perception::OcclusionOptions(), kHidden, &classes, &hidden);
  std::vector<std::uint32_t> pixels;
  perception::rasterizePointLabels(projected, classes, image.cols, image.rows, kHidden, 0, &pixels);
  cv::Mat labels(image.rows, image.cols, CV_16UC1);
  std::size_t labelled = 0;
  for (int row = 0; row < image.rows; ++row) {
    auto* out = labels.ptr<std::uint16_t>(row);
    for (int col = 0; col < image.cols; ++col) {
      out[col] =
          static_cast<std::uint16_t>(pixels[static_cast<std::size_t>(row) * image.cols + col]);
      if (out[col] != 0) ++labelled;
    }
  }

  const std::string suffix = std::to_string(camera);
  fs::create_directories(output / ("image_" + suffix));
  fs::create_directories(output / ("labels_" + suffix));
  copyAtomically(image_path, output / ("image_" + suffix) / image_path.filename());
  const std::string label_path = (output / ("labels_" + suffix) / (frame + ".png")).string();
  ism::common::commitFileAtomically(label_path, [&](const std::string& tmp) {
    if (!cv::imwrite(tmp, labels)) throw std::runtime_error("cannot encode " + tmp);
  });
  ++totals->images;
  totals->labelled_pixels += labelled;
  totals->points_in_view += projected.validCount();
  totals->hidden += hidden;
}

// The file an output folder of this tool holds: a later run replaces only such a folder.
constexpr char kOutputMarker[] = ".make_camera_labels";

// Whether `folder` holds nothing but what this tool writes (an earlier version wrote no marker).
bool holdsOnlyCameraLabels(const fs::path& folder) {
  for (const fs::directory_entry& entry : fs::directory_iterator(folder)) {
    const std::string name = entry.path().filename().string();
    const bool ours =
        name == "calib.txt" || name == "poses.txt" || name == "times.txt" ||
        (entry.is_directory() && (name.rfind("image_", 0) == 0 || name.rfind("labels_", 0) == 0));
    if (!ours) return false;
  }
  return true;
}

// The output folder, absolute, without a trailing '/' (its ".partial" sibling went inside it),
// through a link to the folder itself: new, empty, or an earlier run's (its marker file, or only
// this tool's files). Anything else is refused: it is replaced whole at the end, and a user's
// folder (holding the sequence itself) was deleted. A mount point is refused before the work: it
// cannot be renamed.
fs::path outputFolder(const fs::path& output, const fs::path& sequence) {
  fs::path target = fs::absolute(output).lexically_normal();
  if (target.filename().empty()) target = target.parent_path();
  if (!fs::exists(target)) return target;
  target = fs::canonical(target);
  if (!fs::is_directory(target)) throw std::runtime_error(target.string() + ": not a folder");
  const fs::path input = fs::canonical(sequence);
  if (std::mismatch(target.begin(), target.end(), input.begin(), input.end()).first ==
      target.end()) {
    throw std::runtime_error(target.string() + ": holds the input sequence " + sequence.string() +
                             ": give a folder of its own");
  }
  if (!fs::is_empty(target) && !fs::exists(target / kOutputMarker) &&
      !holdsOnlyCameraLabels(target)) {
    throw std::runtime_error(
        target.string() + ": exists and is not a make_camera_labels output (no " + kOutputMarker +
        "): give a new or empty folder (it is replaced whole)");
  }
  struct stat own {
  }, parent{};
  if (::stat(target.c_str(), &own) == 0 && ::stat(target.parent_path().c_str(), &parent) == 0 &&
      own.st_dev != parent.st_dev) {
    throw std::runtime_error(target.string() +
                             ": a mount point, which cannot be replaced: give a folder inside it");
  }
  return target;
}

// Removes a folder when it goes out of scope, unless its path was cleared (the run finished).
struct RemoveOnExit {
  fs::path path;
  ~RemoveOnExit() {
    std::error_code ignored;
    if (!path.empty()) fs::remove_all(path, ignored);
  }
};

int run(const ism::common::CommandLine& cli) {
  const fs::path sequence(cli.require("--sequence"));
  const fs::path output(cli.require("--output"));
  const int every = cli.getInt("--every", 1);
  const int max_frames = cli.getInt("--max-frames", 0);
  if (every < 1) throw UsageError("--every must be >= 1");
  if (max_frames < 0) throw UsageError("--max-frames must be >= 0");
  const std::vector<int> cameras = parseCameras(cli.get("--cameras", "2,3"));

  std::vector<std::string> incomplete;
  const std::vector<std::string> all =
      ism::evaluation::listSemanticKittiFrames(sequence.string(), &incomplete);
  if (!incomplete.empty()) {
    std::fprintf(stderr,
                 "make_camera_labels: %zu scans of %s lack their labels/*.label or "
                 "image_2/*.png (first: %s): left out\n",
                 incomplete.size(), sequence.c_str(), incomplete.front().c_str());
  }
  std::vector<std::string> frames;
  for (std::size_t i = 0; i < all.size(); i += static_cast<std::size_t>(every)) {
    if (max_frames > 0 && static_cast<int>(frames.size()) >= max_frames) break;
    frames.push_back(all[i]);
  }
  const ism::kitti::ObjectCalibration calibration =
      ism::kitti::readObjectCalibration((sequence / "calib.txt").string());
  ism::common::checkOutputsAreNotInputs({output.string()}, {sequence.string()});
  ism::common::checkOutputFolderIsNotInAnInput(output.string(), {sequence.string()});
  const fs::path target = outputFolder(output, sequence);
  fs::create_directories(target.parent_path());
  ism::common::checkOutputDirectory(target.string());
  // Written beside the output and renamed onto it at the end: a run that fails half-way (a
  // truncated .label) left a folder whose poses listed frames it had no images for, which a
  // training run would read.
  const fs::path partial = target.string() + ".partial";
  fs::remove_all(partial);
  fs::create_directories(partial);
  RemoveOnExit partial_cleanup{partial};
  std::ofstream(partial / kOutputMarker) << "written by make_camera_labels: a later run into this "
                                            "folder replaces it whole\n";
  for (const char* name : {"calib.txt", "poses.txt", "times.txt"}) {
    if (fs::exists(sequence / name)) copyAtomically(sequence / name, partial / name);
  }
  std::printf("make_camera_labels: %zu of %zu frames of %s (every %d), cameras %s -> %s\n",
              frames.size(), all.size(), sequence.c_str(), every,
              cli.get("--cameras", "2,3").c_str(), output.c_str());
  std::fflush(stdout);

  const auto start = std::chrono::steady_clock::now();
  ism::common::ProgressLog progress("make_camera_labels", frames.size(), "frames");
  Totals totals;
  for (std::size_t f = 0; f < frames.size(); ++f) {
    const std::string& frame = frames[f];
    const ism::kitti::VelodyneScan scan =
        ism::kitti::readVelodyneBin((sequence / "velodyne" / (frame + ".bin")).string());
    const std::string label_path = (sequence / "labels" / (frame + ".label")).string();
    const std::vector<std::uint32_t> point_labels = ism::kitti::readLabelFile(label_path);
    if (point_labels.size() != scan.size()) {
      throw std::runtime_error(label_path + " has " + std::to_string(point_labels.size()) +
                               " labels for the " + std::to_string(scan.size()) +
                               " points of its scan");
    }
    for (const int camera : cameras) {
      const fs::path image_path = sequence / ("image_" + std::to_string(camera)) / (frame + ".png");
      if (camera == 3 && !fs::exists(image_path)) {
        ++totals.missing_images;
        continue;
      }
      writeCameraLabels(scan, point_labels, calibration, camera, image_path, partial, frame,
                        &totals);
    }
    progress.update(f + 1);
  }
  // The finished folder takes the output's place (an empty one, or an earlier run's: see
  // outputFolder).
  const fs::path earlier = partial.string() + ".earlier";
  fs::remove_all(earlier);
  if (fs::exists(target)) fs::rename(target, earlier);
  fs::rename(partial, target);
  fs::remove_all(earlier);
  partial_cleanup.path.clear();
  if (totals.missing_images > 0) {
    std::fprintf(stderr,
                 "make_camera_labels: %zu frames have no image_3/<frame>.png: camera 3 "
                 "left out for them\n",
                 totals.missing_images);
  }
  const double per_image =
      totals.images ? static_cast<double>(totals.labelled_pixels) / totals.images : 0.0;
  const double hidden_share =
      totals.points_in_view ? 100.0 * totals.hidden / totals.points_in_view : 0.0;
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf(
      "make_camera_labels: %zu label images, %.0f labelled pixels per image, %.1f %% of "
      "the points in view hidden from the camera, %.1f s\n",
      totals.images, per_image, hidden_share, seconds);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return ism::common::runCli("make_camera_labels", kUsage, [&] {
    const ism::common::CommandLine cli(
        argc, argv, {"--sequence", "--output", "--every", "--max-frames", "--cameras"}, {});
    if (cli.helpRequested()) return ism::common::printUsage(kUsage);
    return run(cli);
  });
}
