// semantic_map_offline: builds a semantic OctoMap from a SemanticKITTI-layout sequence through
// the same SemanticMappingSession as semantic_octomap_node, and saves it as .ot (+ PLY). Class
// evidence from per-point labels (ground truth or a network's per-point predictions), or from
// the camera: each scan's image segmented with the same Segmenter as segmentation_node.
//
//   semantic_map_offline --scans DIR --poses POSES.txt --calib CALIB.txt --output MAP.ot
//       [--labels DIR | --images DIR --model MODEL [--model-card CARD.yaml]]
//   semantic_map_offline --drive <date>/<date>_drive_NNNN_sync --output MAP.ot
//       [--model MODEL [--model-card CARD.yaml]] [--poses IMU_POSES.txt] [--camera N]
//       [--config semantic_mapping.yaml] [--resolution R] [--max-range M] [--confusion P]
//       [--fusion bayes|dirichlet] [--classes semantickitti|cityscapes] [--prob-hit P]
//       [--prob-miss P] [--grazing-truncation VOXELS] [--max-scans N] [--export-ply MAP.ply]
//       [--color-ot MAP_COLOR.ot] [--threads N] [--grid STEM]
//       [--label-images DIR [--label-min-probability P]]
#include <octomap/OcTree.h>
#include <time.h>
#include <yaml-cpp/yaml.h>

#include <chrono>
#include <filesystem>
#include <iostream>
#include <memory>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <utility>
#include <vector>

#include "inekf_semantic_mapping/common/atomic_file.h"
#include "inekf_semantic_mapping/common/cli_args.h"
#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/common/yaml_reader.h"
#include "inekf_semantic_mapping/mapping/grid_projection.h"
#include "inekf_semantic_mapping/mapping/map_io.h"
#include "inekf_semantic_mapping/mapping/map_label_images.h"
#include "inekf_semantic_mapping/mapping/offline_mapping.h"
#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"
#include "inekf_semantic_mapping/perception/model_card.h"
#include "inekf_semantic_mapping/perception/segmenter.h"

namespace {

namespace ism = inekf_semantic_mapping;
using ism::common::UsageError;

// --grid STEM writes STEM_projected.{pgm,yaml} and STEM_drivable.{pgm,yaml}.
constexpr const char* kGridNames[] = {"projected", "drivable"};
std::string gridStem(const ism::common::CommandLine& cli, const char* name) {
  return cli.get("--grid") + "_" + name;
}

constexpr char kUsage[] =
    "usage: semantic_map_offline --scans DIR --poses POSES.txt --calib CALIB.txt --output MAP.ot\n"
    "         [--labels DIR | --images DIR --model MODEL [--model-card CARD.yaml]]\n"
    "       semantic_map_offline --drive DRIVE_SYNC_DIR --output MAP.ot [--model MODEL\n"
    "         [--model-card CARD.yaml]] [--poses IMU_POSES.txt] [--calib-dir DIR] [--camera 2]\n"
    "     both [--config semantic_mapping.yaml] [--resolution R] [--max-range M]\n"
    "         [--confusion P] [--fusion bayes|dirichlet] [--classes semantickitti|cityscapes]\n"
    "         [--prob-hit P] [--prob-miss P] [--grazing-truncation VOXELS (1; 0: plain octomap)]\n"
    "         [--max-scans N] [--export-ply MAP.ply] [--color-ot MAP_COLOR.ot]\n"
    "         [--grid STEM] [--insertion octree|hashed_grid] [--early-termination N]\n"
    "         [--octomap-reference]\n"
    "       with --model: [--model-card CARD.yaml] [--threads N (2: the network's)]\n"
    "       with --drive: [--label-images DIR [--label-min-probability P (0)]]\n"
    "  --labels   per-point labels DIR/NNNNNN.label (SemanticKITTI ids; default classes\n"
    "             semantickitti)\n"
    "  --images   camera images DIR/NNNNNN.png, segmented with MODEL (Cityscapes labelIds;\n"
    "             default classes cityscapes); calib.txt's P2 projects the scans into them\n"
    "  --drive    a KITTI raw drive: velodyne_points/, oxts/, image_0N/ (N = --camera), the\n"
    "             calibration in its date folder; poses: --poses (IMU in the map frame per frame,\n"
    "             inekf_offline --output-kitti) or the OXTS RTK/INS solution; with --model the\n"
    "             scans are labelled from image_0N; the map frame is east-north-up at the\n"
    "             first OXTS frame (inekf_offline's), saved with the map for a node resuming it\n"
    "  --config   the node's YAML (config/semantic_mapping.yaml); flags override its values\n"
    "  --grid     the node's projected and drivable maps (its grid.* keys, the ground under\n"
    "             the scans' lidar poses) in map_server's format: STEM_projected.pgm/.yaml and\n"
    "             STEM_drivable.pgm/.yaml\n"
    "  --insertion, --early-termination  the config's insertion and\n"
    "             early_ray_termination_voxels\n"
    "  --octomap-reference  after the run, inserts every scan as inserted (map frame, same\n"
    "             origin, max range and resolution) into a plain octomap::OcTree with\n"
    "             insertPointCloud and prints the whole run's time against that reference's\n"
    "             (the benchmark's ratio; the scans are kept in memory meanwhile)\n"
    "  --label-images  after the map is built, the map's classes at each frame's lidar points\n"
    "             as the camera sees them (occlusion test, nearest point per pixel): "
    "DIR/<frame>.png,\n"
    "             8-bit labelIds of the map's class set, 0 where none (pseudo-labels for\n"
    "             training the camera: scripts/adapt_segmentation.sh --pseudo-labels); voxels\n"
    "             whose class posterior is below --label-min-probability label nothing\n";

// The session config: the YAML file if given, then the flags.
ism::mapping::SemanticMappingConfig configFrom(const ism::common::CommandLine& cli) {
  namespace mapping = ism::mapping;
  mapping::SemanticMappingConfig config;
  if (cli.has("--config")) {
    config = mapping::loadSemanticMappingConfig(cli.get("--config"));
  }
  // The label ids come from the label source (SemanticKITTI's in --labels, a Cityscapes model's
  // otherwise): its class set, not the node's YAML, says what they mean.
  const mapping::MapClassSet from_config = config.class_set;
  config.class_set = cli.has("--labels") ? mapping::MapClassSet::kSemanticKitti
                                         : mapping::MapClassSet::kCityscapes;
  if (cli.has("--config") && !cli.has("--classes") && from_config != config.class_set) {
    std::cerr << "[semantic_map_offline] " << cli.get("--config") << ": class_set "
              << mapping::mapClassSetName(from_config) << " is not the label source's; the map "
              << "uses " << mapping::mapClassSetName(config.class_set)
              << " (--classes chooses; a node must be configured with the map's set to load it)"
              << std::endl;
  }
  // The node's camera keys: the tool has its own flags (found by review: a camera_index: 3 in the
  // YAML was dropped without a word).
  if (cli.has("--config")) {
    const YAML::Node yaml = ism::common::loadYamlFile(cli.get("--config"));
    const bool calib_dir_set = yaml["calib_dir"] && !yaml["calib_dir"].as<std::string>("").empty();
    const bool camera_set = yaml["camera_index"] && yaml["camera_index"].as<int>(2) != 2;
    if (calib_dir_set || camera_set) {
      std::cerr << "[semantic_map_offline] " << cli.get("--config") << ": calib_dir and "
                << "camera_index are semantic_octomap_node's; here --calib-dir and --camera "
                << "choose (the drive's date folder and camera 2 by default)" << std::endl;
    }
  }
  config.resolution_m = cli.getDouble("--resolution", config.resolution_m);
  config.max_range_m = cli.getDouble("--max-range", config.max_range_m);
  config.fusion.correct_probability =
      cli.getDouble("--confusion", config.fusion.correct_probability);
  config.occupancy.prob_hit = cli.getDouble("--prob-hit", config.occupancy.prob_hit);
  config.occupancy.prob_miss = cli.getDouble("--prob-miss", config.occupancy.prob_miss);
  config.grazing_ray_truncation_voxels =
      cli.getDouble("--grazing-truncation", config.grazing_ray_truncation_voxels);
  config.early_ray_termination_voxels =
      cli.getInt("--early-termination", config.early_ray_termination_voxels);
  const auto choice = [&cli](const std::string& flag, auto parse, auto* out) {
    if (!cli.has(flag)) return;
    try {
      *out = parse(cli.get(flag));
    } catch (const std::invalid_argument& error) {
      throw UsageError(flag + ": " + error.what());
    }
  };
  choice("--classes", mapping::parseMapClassSet, &config.class_set);
  choice("--insertion", mapping::parseInsertionStructure, &config.insertion);
  choice("--fusion", mapping::parseFusionRule, &config.fusion.rule);
  try {
    config.validate();
  } catch (const std::invalid_argument& error) {
    throw UsageError(error.what());
  }
  return config;
}

constexpr const char* kImageExtensions[] = {".png", ".jpg", ".jpeg"};

// DIR/<stem> with the first image extension that exists (.png unless only another does).
std::string imagePath(const std::string& dir, const std::string& stem) {
  for (const char* extension : kImageExtensions) {
    const std::string path = dir + "/" + stem + extension;
    if (std::filesystem::exists(path)) return path;
  }
  return dir + "/" + stem + kImageExtensions[0];
}

// --model labels nothing without images: a missing camera folder (a grayscale-only download, a
// mistyped --images) gave an occupancy-only map, a warning per scan and exit status 0.
void checkImageFolder(const std::string& dir, const std::string& flag, const std::string& hint) {
  namespace fs = std::filesystem;
  if (!fs::is_directory(dir)) {
    throw std::runtime_error(dir + ": no such folder (" + flag + " labels the scans from its " +
                             "images)" + hint);
  }
  for (const auto& entry : fs::directory_iterator(dir)) {
    for (const char* extension : kImageExtensions) {
      if (entry.path().extension() == extension) return;
    }
  }
  throw std::runtime_error(dir + ": no .png, .jpg or .jpeg image in it (" + flag +
                           " labels the scans from its images)" + hint);
}

// The camera folders a raw drive has, for the error when the one asked for is missing.
std::string otherCamerasHint(const std::string& drive_dir) {
  std::string present;
  for (int camera = 0; camera < 4; ++camera) {
    if (std::filesystem::is_directory(drive_dir + "/image_0" + std::to_string(camera) + "/data")) {
      present += (present.empty() ? "" : ", ") + std::string("image_0") + std::to_string(camera);
    }
  }
  return present.empty() ? "; the drive has no camera folder: map without --model"
                         : "; the drive has " + present + ": --camera N picks one";
}

// Segments DIR/<stem>.png (or .jpg) for each scan (the segmentation_node's Segmenter).
ism::mapping::CameraLabelSource segmentingSource(const std::string& images_dir,
                                                 std::shared_ptr<ism::perception::Segmenter> net) {
  return [images_dir, net](const std::string& stem, ism::mapping::OwnedLabelImage* out) {
    const std::string path = imagePath(images_dir, stem);
    const cv::Mat image = cv::imread(path, cv::IMREAD_COLOR);
    if (image.empty()) {
      std::cerr << "[semantic_map_offline] " << path << ": no readable image, scan mapped "
                << "without class evidence\n";
      return false;
    }
    const ism::perception::Segmentation segmentation = net->segment(image);
    // The same label filter as segmentation_node (the model card's).
    cv::Mat labels = ism::perception::filterLabels(segmentation, net->card().label_filter);
    if (!labels.isContinuous()) labels = labels.clone();
    out->width = labels.cols;
    out->height = labels.rows;
    out->pixels.assign(labels.data, labels.data + labels.total());
    return true;
  };
}

// --label-images: the finished map's classes in each frame's camera, DIR/<stem>.png named as
// the image they label.
void writeMapLabelImages(const ism::mapping::SemanticOcTree& tree,
                         const ism::mapping::OfflineRawDrive& drive, const std::string& dir,
                         const ism::mapping::MapLabelImageOptions& options) {
  namespace mapping = ism::mapping;
  std::filesystem::create_directories(dir);
  const std::string images = drive.drive_dir + "/image_" + (drive.camera_index < 10 ? "0" : "") +
                             std::to_string(drive.camera_index) + "/data";
  std::size_t frames = 0, labelled = 0, in_view = 0, hidden = 0;
  ism::ScopedTimer timer("semantic_map/label_images");
  mapping::forEachRawDriveScan(drive, [&](const mapping::RawDriveScan& scan) {
    // The image's size is the calibration's rectified one (checked), or the calibration says none.
    if (scan.image_stem.empty()) {
      std::cerr << "[semantic_map_offline] velodyne frame " << scan.stem << ": no camera image "
                << "at its stamp in " << images << ", no label image for it\n";
      return;
    }
    const std::string& image_path = scan.image_path;
    const cv::Mat image = cv::imread(image_path, cv::IMREAD_UNCHANGED);
    if (image.empty()) {
      std::cerr << "[semantic_map_offline] " << image_path << ": no readable image, no label "
                << "image for it\n";
      return;
    }
    scan.camera.checkRectifiedImageSize(image_path, image.cols, image.rows);
    const mapping::CameraModel camera{scan.camera.P_rect, scan.camera.R_rect,
                                      scan.camera.T_cam0_velo, image.cols, image.rows};
    mapping::MapLabelImageStats stats;
    const mapping::OwnedLabelImage labels =
        mapping::mapLabelImage(tree, scan.points, scan.T_map_velo, camera, options, &stats);
    const cv::Mat view(labels.height, labels.width, CV_8UC1,
                       const_cast<std::uint8_t*>(labels.pixels.data()));
    const std::string path = dir + "/" + scan.image_stem + ".png";
    ism::common::commitFileAtomically(path, [&](const std::string& tmp) {
      if (!cv::imwrite(tmp, view)) throw std::runtime_error(path + ": cannot write PNG");
    });
    ++frames;
    labelled += stats.labelled;
    in_view += stats.points_in_view;
    hidden += stats.hidden;
  });
  std::cerr << "[semantic_map_offline] wrote " << frames << " label images in " << dir << " ("
            << (frames ? labelled / frames : 0) << " labelled pixels per image; of " << in_view
            << " points in view, " << hidden << " hidden from the camera)\n";
}

}  // namespace

int main(int argc, char** argv) {
  namespace mapping = ism::mapping;
  return ism::common::runCli("semantic_map_offline", kUsage, [&] {
    const ism::common::CommandLine cli(argc, argv,
                                       {"--scans",
                                        "--drive",
                                        "--calib-dir",
                                        "--camera",
                                        "--labels",
                                        "--images",
                                        "--model",
                                        "--model-card",
                                        "--poses",
                                        "--calib",
                                        "--config",
                                        "--resolution",
                                        "--output",
                                        "--export-ply",
                                        "--max-range",
                                        "--confusion",
                                        "--fusion",
                                        "--max-scans",
                                        "--classes",
                                        "--color-ot",
                                        "--prob-hit",
                                        "--prob-miss",
                                        "--grazing-truncation",
                                        "--threads",
                                        "--grid",
                                        "--insertion",
                                        "--early-termination",
                                        "--label-images",
                                        "--label-min-probability"},
                                       {"--octomap-reference"});
    if (cli.helpRequested()) return ism::common::printUsage(kUsage);
    const int max_scans = cli.getInt("--max-scans", -1);
    if (cli.has("--max-scans") && max_scans < 1) {
      throw ism::common::UsageError("--max-scans must be at least 1 (without it: every scan)");
    }
    const bool raw_drive = cli.has("--drive");
    if (raw_drive == cli.has("--scans")) throw UsageError("give --scans or --drive");
    if (cli.has("--labels") && (cli.has("--images") || cli.has("--model"))) {
      throw UsageError("give --labels or --images/--model, not both");
    }
    if (!raw_drive && cli.has("--images") != cli.has("--model")) {
      throw UsageError("--images and --model go together");
    }
    // A flag of the other input's form would be ignored without a word (--labels with --drive
    // even changed the class set and then read no label).
    const std::vector<std::string> other_form =
        raw_drive ? std::vector<std::string>{"--labels", "--images", "--calib"}
                  : std::vector<std::string>{"--calib-dir", "--camera"};
    for (const std::string& flag : other_form) {
      if (cli.has(flag)) {
        throw UsageError(flag + " goes with " + (raw_drive ? "--scans" : "--drive") + ", not " +
                         (raw_drive ? "--drive" : "--scans"));
      }
    }
    for (const char* flag : {"--model-card", "--threads"}) {
      if (cli.has(flag) && !cli.has("--model")) {
        throw UsageError(std::string(flag) + " goes with --model");
      }
    }
    if (cli.has("--threads") && cli.getInt("--threads", 1) < 1) {
      throw UsageError("--threads must be at least 1");
    }
    // The class set is the label source's: read as another set's, the ids made a wrong map (car
    // as "rail track") with exit 0.
    if (cli.has("--classes") && (cli.has("--labels") || cli.has("--model"))) {
      const bool lidar_labels = cli.has("--labels");
      const std::string own = lidar_labels ? "semantickitti" : "cityscapes";
      if (cli.get("--classes") != own) {
        throw UsageError("--classes " + cli.get("--classes") + " does not go with " +
                         (lidar_labels ? "--labels (SemanticKITTI label ids)"
                                       : "--model (Cityscapes labelIds)") +
                         ": their ids would be read as another class set's (leave --classes out)");
      }
    }
    const std::string output = cli.require("--output");
    // Each file in the format its name says: a semantic octree under .bt (octomap's own binary
    // format) was written, and octomap's tools failed to read it.
    for (const auto& [flag, extension] :
         {std::pair{"--output", ".ot"}, {"--color-ot", ".ot"}, {"--export-ply", ".ply"}}) {
      if (!cli.has(flag)) continue;
      const std::string given = std::filesystem::path(cli.get(flag)).extension().string();
      if (given != extension) {
        throw UsageError(std::string(flag) + " " + cli.get(flag) + ": the file is written as " +
                         extension + ", its name ends in '" + given + "'");
      }
    }
    if (cli.has("--label-images") && !raw_drive) throw UsageError("--label-images needs --drive");
    if (cli.has("--label-min-probability") && !cli.has("--label-images")) {
      throw UsageError("--label-min-probability goes with --label-images");
    }
    // Every output's place is checked before the run (a mistyped folder failed after it, with
    // the map written and the grids not).
    std::vector<std::string> output_paths{output};
    for (const char* flag : {"--export-ply", "--color-ot"}) {
      if (cli.has(flag)) output_paths.push_back(cli.get(flag));
    }
    if (cli.has("--grid")) {
      for (const char* name : kGridNames) {
        for (const std::string& path : mapping::mapServerGridPaths(gridStem(cli, name))) {
          output_paths.push_back(path);
        }
      }
    }
    ism::common::checkOutputPaths(output_paths);
    ism::common::checkOutputsAreNotInputs(
        output_paths, cli.valuesOf({"--scans", "--drive", "--calib-dir", "--labels", "--images",
                                    "--model", "--model-card", "--poses", "--calib", "--config"}));
    if (cli.has("--label-images")) {  // not inside the drive (its image folders are read)
      ism::common::checkOutputDirectory(cli.get("--label-images"));
      ism::common::checkOutputFolderIsNotInAnInput(cli.get("--label-images"),
                                                   cli.valuesOf({"--drive"}));
    }
    mapping::SemanticMappingSession session(configFrom(cli));
    mapping::GridProjectionConfig grid_config;
    if (cli.has("--config")) {
      grid_config = mapping::readGridProjectionConfig(
          ism::common::loadYamlFile(cli.get("--config")), cli.get("--config"));
    }
    mapping::GroundTrace ground_trace(grid_config.sensor_height);
    // --octomap-reference: the scans as inserted (map frame) are kept and go into a plain
    // octomap::OcTree after the run, timed apart (not interleaved: each run keeps its caches).
    const bool octomap_reference = cli.has("--octomap-reference");
    std::vector<std::pair<octomap::Pointcloud, octomap::point3d>> reference_scans;
    const auto thread_cpu_s = [] {
      timespec ts{};
      clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
      return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
    };
    double keep_wall_s = 0, keep_cpu_s = 0;  // copying the scans: not the run's time
    const auto run_start = std::chrono::steady_clock::now();
    const double run_cpu_start = thread_cpu_s();
    const auto on_scan_inserted = [&](const Eigen::Isometry3d& T_map_velo) {
      ground_trace.addSensorOrigin(T_map_velo.translation());
      if (!octomap_reference) return;
      const auto start = std::chrono::steady_clock::now();
      const double cpu_start = thread_cpu_s();
      const mapping::LabeledScan& scan = session.lastInsertedScan();
      octomap::Pointcloud cloud;
      cloud.reserve(static_cast<std::size_t>(scan.points_map.cols()));
      for (Eigen::Index i = 0; i < scan.points_map.cols(); ++i) {
        cloud.push_back(scan.points_map(0, i), scan.points_map(1, i), scan.points_map(2, i));
      }
      const Eigen::Vector3f& o = scan.sensor_origin_map;
      reference_scans.emplace_back(std::move(cloud), octomap::point3d(o.x(), o.y(), o.z()));
      keep_wall_s +=
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      keep_cpu_s += thread_cpu_s() - cpu_start;
    };

    mapping::CameraLabelSource camera_labels;
    if (cli.has("--model")) {
      const std::string model = cli.get("--model");
      const ism::perception::ModelCard card =
          cli.has("--model-card") ? ism::perception::loadModelCard(cli.get("--model-card"))
                                  : ism::perception::defaultModelCardFor(model);
      auto net =
          std::make_shared<ism::perception::Segmenter>(model, card, cli.getInt("--threads", 2));
      const std::string images = raw_drive ? cli.get("--drive") + "/image_" +
                                                 (cli.getInt("--camera", 2) < 10 ? "0" : "") +
                                                 std::to_string(cli.getInt("--camera", 2)) + "/data"
                                           : cli.get("--images");
      checkImageFolder(images, raw_drive ? "--model" : "--images",
                       raw_drive ? otherCamerasHint(cli.get("--drive")) : "");
      std::cerr << "[semantic_map_offline] segmenting " << images << " with " << model << " (card "
                << card.source << ")\n";
      camera_labels = segmentingSource(images, net);
    }
    const mapping::CameraLabelSource* labels_source = camera_labels ? &camera_labels : nullptr;
    mapping::OfflineRawDrive drive;
    if (raw_drive) {
      drive.drive_dir = cli.get("--drive");
      drive.calib_dir = cli.get("--calib-dir");
      drive.poses_path = cli.get("--poses");
      drive.camera_index = cli.getInt("--camera", 2);
      drive.max_scans = max_scans;
      drive.on_scan_inserted = on_scan_inserted;
      mapping::mapRawDrive(drive, &session, labels_source, &std::cerr);
    } else {
      mapping::OfflineSequence sequence;
      sequence.scans_dir = cli.require("--scans");
      sequence.poses_path = cli.require("--poses");
      sequence.calib_path = cli.require("--calib");
      sequence.labels_dir = cli.get("--labels");
      sequence.max_scans = max_scans;
      sequence.on_scan_inserted = on_scan_inserted;
      mapping::mapSequence(sequence, &session, labels_source, &std::cerr);
    }

    const mapping::MappingStatistics& stats = session.statistics();
    std::cerr << "[semantic_map_offline] " << stats.scans_inserted << " scans, "
              << stats.scans_with_labels << " with class evidence, " << stats.points_with_class
              << " of " << stats.points_inserted << " inserted points labelled\n";
    const std::size_t scans_inserted = stats.scans_inserted;
    const std::size_t scans_with_labels = stats.scans_with_labels;
    // The map and its exports appear together or not at all.
    std::vector<std::pair<std::string, mapping::MapFormat>> outputs{
        {output, mapping::MapFormat::kSemanticOt}};
    if (cli.has("--export-ply"))
      outputs.emplace_back(cli.get("--export-ply"), mapping::MapFormat::kPly);
    if (cli.has("--color-ot")) {
      outputs.emplace_back(cli.get("--color-ot"), mapping::MapFormat::kColorOt);
    }
    // The grids too: the map, its exports and the grids appear together or not at all.
    mapping::ProjectedGrids grids;
    const std::pair<const char*, const mapping::Grid2D*> grid_outputs[] = {
        {kGridNames[0], &grids.occupancy}, {kGridNames[1], &grids.drivable}};
    std::vector<std::vector<std::string>> grid_paths;
    if (cli.has("--grid")) {
      ism::ScopedTimer timer("semantic_map/grids");
      session.tree().updateInnerOccupancy();
      grids = mapping::projectGrids(session.tree(), grid_config, ground_trace.samples());
    }
    std::vector<std::size_t> counts;
    {
      ism::ScopedTimer timer("semantic_map/save");
      counts = mapping::saveMaps(session.tree(), outputs, [&](ism::common::AtomicFileSet* files) {
        if (!cli.has("--grid")) return;
        for (const auto& [name, grid] : grid_outputs) {
          grid_paths.push_back(mapping::addMapServerGrid(*grid, gridStem(cli, name), files));
        }
      });
    }
    // The insertion grid's figures were printed when its map moved into the tree (mapRawDrive,
    // mapSequence): the session holds the tree alone now.
    std::cerr << "[semantic_map_offline] wrote " << output << " (" << session.tree().size()
              << " nodes, " << counts[0] << " occupied voxels, " << session.tree().classSet().size()
              << " classes, " << session.tree().memoryUsage() / 1e6
              << " MB in memory; the session's map structures " << session.mapMemoryUsage() / 1e6
              << " MB)\n";
    for (std::size_t i = 1; i < outputs.size(); ++i) {
      std::cerr << "[semantic_map_offline] wrote " << outputs[i].first << "\n";
    }
    for (std::size_t g = 0; g < grid_paths.size(); ++g) {
      const auto& [name, grid] = grid_outputs[g];
      std::size_t cell_counts[3] = {0, 0, 0};  // free, occupied, unknown
      for (std::int8_t cell : grid->cells) {
        ++cell_counts[cell == mapping::kGridFree ? 0 : cell == mapping::kGridOccupied ? 1 : 2];
      }
      std::cerr << "[semantic_map_offline] wrote " << grid_paths[g][0] << " and "
                << grid_paths[g][1] << " (" << name << ": " << grid->width << " x " << grid->height
                << " cells, " << cell_counts[0] << " free, " << cell_counts[1] << " occupied, "
                << cell_counts[2] << " unknown)\n";
    }
    if (cli.has("--label-images")) {
      ism::mapping::MapLabelImageOptions options;
      options.min_class_probability = cli.getDouble("--label-min-probability", 0.0);
      drive.on_scan_inserted = nullptr;
      writeMapLabelImages(session.tree(), drive, cli.get("--label-images"), options);
    }
    if (octomap_reference) {
      const double wall_s =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - run_start).count() -
          keep_wall_s;
      const double cpu_s = thread_cpu_s() - run_cpu_start - keep_cpu_s;
      octomap::OcTree reference(session.config().resolution_m);
      const auto start = std::chrono::steady_clock::now();
      const double cpu_start = thread_cpu_s();
      for (const auto& [cloud, origin] : reference_scans) {
        reference.insertPointCloud(
            cloud, origin, session.config().max_range_m > 0 ? session.config().max_range_m : -1.0);
      }
      const double reference_wall_s =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      const double reference_cpu_s = thread_cpu_s() - cpu_start;
      const double scans = static_cast<double>(std::max<std::size_t>(1, stats.scans_inserted));
      std::cerr << "[semantic_map_offline] whole run ("
                << mapping::insertionStructureName(session.config().insertion)
                << " insertion, reading, mapping, save) per scan: wall " << 1e3 * wall_s / scans
                << " ms, CPU " << 1e3 * cpu_s / scans
                << " ms; octomap insertPointCloud of the same scans per scan: wall "
                << 1e3 * reference_wall_s / scans << " ms, CPU " << 1e3 * reference_cpu_s / scans
                << " ms; ratio wall " << wall_s / reference_wall_s << "x, CPU "
                << cpu_s / reference_cpu_s << "x (octomap map: " << reference.size() << " nodes)\n";
    }
    std::cerr << ism::TimingRegistry::instance().report();
    if (camera_labels && scans_with_labels == 0) {
      // Written (nothing mapped is lost), but not what --model asked for.
      throw std::runtime_error("none of the " + std::to_string(scans_inserted) +
                               " scans got class evidence from the camera (the warnings above "
                               "say why): the map written holds occupancy only");
    }
    return 0;
  });
}
