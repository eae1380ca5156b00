// The package's one map metric: evaluation::mapLabelAt and the evaluate_map tool, on a short
// synthetic drive mapped from its own true point labels (the score must be near perfect) and
// from poses shifted by a metre (it must drop), and the tool's errors on bad inputs; the listing
// of a SemanticKITTI sequence's frames.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "inekf_semantic_mapping/evaluation/semantic_evaluation.h"
#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/kitti/poses.h"
#include "inekf_semantic_mapping/kitti/velodyne.h"
#include "inekf_semantic_mapping/mapping/map_io.h"
#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"
#include "inekf_semantic_mapping/perception/cityscapes.h"
#include "inekf_semantic_mapping/synthetic/drive_generator.h"
#include "synthetic_kitti_drive.h"
#include "test_data.h"

namespace fs = std::filesystem;
namespace ism = inekf_semantic_mapping;
namespace cs = ism::cityscapes;

namespace {

double jsonNumber(const std::string& json, const std::string& key) {
  const std::size_t at = json.find("\"" + key + "\":");
  if (at == std::string::npos) return -1;
  return std::stod(json.substr(at + key.size() + 3));
}

class EvaluateMapTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ =
        (fs::temp_directory_path() / ("ism_evaluate_map_" + std::to_string(::getpid()))).string();
    ism::synthetic::DriveOptions options;
    options.output_dir = dir_;
    options.seed = 5;
    options.duration_s = 3.0;
    options.write_images = false;
    options.lidar.beams = 16;
    options.lidar.azimuth_step_deg = 0.8;
    drive_ = ism::synthetic::generateSyntheticDrive(options).sync_dir;
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }

  // A map of every other scan from the true per-point labels, placed with `poses` (T_map_imu).
  static std::string buildMap(const std::vector<Eigen::Isometry3d>& poses,
                              const std::string& name) {
    const Eigen::Isometry3d T_imu_velo =
        ism::kitti::readRawCalibration(fs::path(drive_).parent_path().string())
            .T_velo_imu.inverse();
    ism::mapping::SemanticMappingSession session{ism::mapping::SemanticMappingConfig{}};
    for (std::size_t frame = 0; frame < poses.size(); frame += 2) {
      char stem[24];  // room for any size_t
      std::snprintf(stem, sizeof(stem), "%010zu", frame);
      const auto scan =
          ism::kitti::readVelodyneBin(drive_ + "/velodyne_points/data/" + stem + ".bin");
      std::vector<std::uint32_t> labels =
          ism::kitti::readLabelFile(drive_ + "/ground_truth/velodyne_labels/" + stem + ".label");
      for (std::uint32_t& l : labels) l = ism::kitti::semanticClass(l);
      Eigen::Matrix3Xf points(3, static_cast<Eigen::Index>(scan.size()));
      for (std::size_t i = 0; i < scan.size(); ++i) {
        points.col(static_cast<Eigen::Index>(i)) << scan.point(i)[0], scan.point(i)[1],
            scan.point(i)[2];
      }
      session.insertScanWithPointLabels(points, poses[frame] * T_imu_velo, labels, cs::kUnlabeled);
    }
    const std::string path = dir_ + "/" + name + ".ot";
    session.save(path, ism::mapping::MapFormat::kSemanticOt);
    return path;
  }

  static std::string truePoses() { return drive_ + "/ground_truth/poses_imu_map.txt"; }

  static std::string dir_, drive_;
};
std::string EvaluateMapTest::dir_, EvaluateMapTest::drive_;

TEST_F(EvaluateMapTest, MapLabelAtIsTheVoxelsClassOrNone) {
  ism::mapping::SemanticMappingSession session{ism::mapping::SemanticMappingConfig{}};
  // A wall of "building" points 5 m ahead, seen from the origin.
  Eigen::Matrix3Xf wall(3, 121);
  for (int i = 0; i < 121; ++i)
    wall.col(i) << 5.0f, -1.0f + 0.2f * (i % 11), -1.0f + 0.2f * (i / 11);
  session.insertScanWithPointLabels(wall, Eigen::Isometry3d::Identity(),
                                    std::vector<std::uint32_t>(121, cs::kBuilding), cs::kUnlabeled);
  const auto& tree = session.tree();  // synced from the insertion grid when asked for
  EXPECT_EQ(ism::evaluation::mapLabelAt(tree, Eigen::Vector3f(5.0f, 0.0f, 0.0f)), cs::kBuilding);
  // Free space in front of the wall, unknown space behind it: no label.
  EXPECT_EQ(ism::evaluation::mapLabelAt(tree, Eigen::Vector3f(2.5f, 0.0f, 0.0f)), cs::kUnlabeled);
  EXPECT_EQ(ism::evaluation::mapLabelAt(tree, Eigen::Vector3f(9.0f, 0.0f, 0.0f)), cs::kUnlabeled);
  // An occupied voxel without class evidence covers nothing either.
  Eigen::Matrix3Xf post(3, 1);
  post << 0.0f, 6.0f, 0.0f;
  session.insertScanWithPointLabels(post, Eigen::Isometry3d::Identity(), {cs::kUnlabeled},
                                    cs::kUnlabeled);
  const auto& updated = session.tree();
  ASSERT_NE(updated.search(0.0, 6.0, 0.0), nullptr);
  EXPECT_EQ(ism::evaluation::mapLabelAt(updated, Eigen::Vector3f(0.0f, 6.0f, 0.0f)),
            cs::kUnlabeled);
}

TEST_F(EvaluateMapTest, AMapOfTheTrueLabelsScoresNearOneAndAShiftedOneLess) {
  const std::vector<Eigen::Isometry3d> poses = ism::kitti::readKittiPoses(truePoses());
  ASSERT_GE(poses.size(), 20u);
  const std::string exact = buildMap(poses, "exact");
  const auto [status, output] = ism::test::runCommand(std::string(EVALUATE_MAP_PATH) + " --map " +
                                                      exact + " --drive " + drive_);
  ASSERT_EQ(status, 0) << output;
  const std::string result = output.substr(output.rfind("RESULT "));
  EXPECT_GT(jsonNumber(result, "miou"), 0.9) << result;
  EXPECT_GT(jsonNumber(result, "accuracy"), 0.97) << result;
  EXPECT_GT(jsonNumber(result, "coverage"), 0.8) << result;
  EXPECT_GT(jsonNumber(result, "scans"), 9) << result;

  // Scored with poses 1 m off to the side, points land in the wrong voxels: narrow classes
  // (sidewalk, terrain, poles) are missed and fewer points find an occupied voxel.
  std::vector<Eigen::Isometry3d> shifted = poses;
  for (Eigen::Isometry3d& pose : shifted) pose.translation().y() += 1.0;
  const std::string shifted_poses = dir_ + "/shifted_poses.txt";
  {
    std::ofstream out(shifted_poses);
    for (const Eigen::Isometry3d& pose : shifted) {
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 4; ++c) out << pose.matrix()(r, c) << (r == 2 && c == 3 ? "\n" : " ");
      }
    }
  }
  const auto [shifted_status, shifted_output] =
      ism::test::runCommand(std::string(EVALUATE_MAP_PATH) + " --map " + exact + " --drive " +
                            drive_ + " --poses " + shifted_poses);
  ASSERT_EQ(shifted_status, 0) << shifted_output;
  const std::string shifted_result = shifted_output.substr(shifted_output.rfind("RESULT "));
  EXPECT_LT(jsonNumber(shifted_result, "miou"), jsonNumber(result, "miou") - 0.1)
      << shifted_result << "\nexact: " << result;
  EXPECT_LT(jsonNumber(shifted_result, "coverage"), jsonNumber(result, "coverage") - 0.1)
      << shifted_result << "\nexact: " << result;

  // --frames names the frame of each pose line: the first half of the poses, relabelled as the
  // second half's frames, place the scans wrongly too; a count that does not match is refused.
  const std::string frames = dir_ + "/frames.txt";
  {
    std::ofstream out(frames);
    for (std::size_t i = 0; i < poses.size(); ++i) out << i << "\n";
  }
  const auto [frames_status, frames_output] =
      ism::test::runCommand(std::string(EVALUATE_MAP_PATH) + " --map " + exact + " --drive " +
                            drive_ + " --poses " + truePoses() + " --frames " + frames);
  ASSERT_EQ(frames_status, 0) << frames_output;
  EXPECT_EQ(frames_output.substr(frames_output.rfind("RESULT ")), result);
  {
    std::ofstream out(frames, std::ios::app);
    out << poses.size() << "\n";
  }
  const auto [bad_status, bad_output] =
      ism::test::runCommand(std::string(EVALUATE_MAP_PATH) + " --map " + exact + " --drive " +
                            drive_ + " --poses " + truePoses() + " --frames " + frames);
  EXPECT_NE(bad_status, 0);
  EXPECT_NE(bad_output.find(frames), std::string::npos) << bad_output;

  // The drive folder with a trailing '/' (its parent is still the date folder), --camera 2 (the
  // default) and --all-points, which scores the whole sweep: more points than the camera sees.
  const auto [slash_status, slash_output] = ism::test::runCommand(
      std::string(EVALUATE_MAP_PATH) + " --map " + exact + " --drive " + drive_ + "/ --camera 2");
  ASSERT_EQ(slash_status, 0) << slash_output;
  EXPECT_EQ(slash_output.substr(slash_output.rfind("RESULT ")), result);
  const auto [all_status, all_output] = ism::test::runCommand(
      std::string(EVALUATE_MAP_PATH) + " --map " + exact + " --drive " + drive_ + " --all-points");
  ASSERT_EQ(all_status, 0) << all_output;
  const std::string all_result = all_output.substr(all_output.rfind("RESULT "));
  EXPECT_GT(jsonNumber(all_result, "scored"), 1.5 * jsonNumber(result, "scored"))
      << all_result << "\ncamera 2: " << result;
}

TEST_F(EvaluateMapTest, BadInputsNameTheFile) {
  const auto [status, output] = ism::test::runCommand(std::string(EVALUATE_MAP_PATH) + " --map " +
                                                      dir_ + "/missing.ot --drive " + drive_);
  EXPECT_NE(status, 0);
  EXPECT_NE(output.find("missing.ot"), std::string::npos) << output;
  const auto [usage_status, usage_output] =
      ism::test::runCommand(std::string(EVALUATE_MAP_PATH) + " --drive " + drive_);
  EXPECT_NE(usage_status, 0);
  EXPECT_NE(usage_output.find("--map"), std::string::npos) << usage_output;
  // A --json in a folder that is not there and a negative --max-range fail before the map is
  // read (the JSON's folder was found missing after the whole evaluation, -5 meant every point).
  const auto [json_status, json_output] =
      ism::test::runCommand(std::string(EVALUATE_MAP_PATH) + " --map " + dir_ +
                            "/missing.ot --drive " + drive_ + " --json " + dir_ + "/no_dir/x.json");
  EXPECT_NE(json_status, 0);
  EXPECT_NE(json_output.find(dir_ + "/no_dir/x.json"), std::string::npos) << json_output;
  EXPECT_EQ(json_output.find("missing.ot"), std::string::npos) << json_output;
  const auto [range_status, range_output] =
      ism::test::runCommand(std::string(EVALUATE_MAP_PATH) + " --map " + dir_ +
                            "/missing.ot --drive " + drive_ + " --max-range -5");
  EXPECT_NE(range_status, 0);
  EXPECT_NE(range_output.find("--max-range must be >= 0"), std::string::npos) << range_output;
}

// Labels the tool cannot score: SemanticKITTI's own ids scored nothing (or the wrong class where
// the ids overlap) and unlabelled points gave "mIoU nan", both with exit status 0.
TEST_F(EvaluateMapTest, LabelsItCannotScoreAreAnErrorNotANanScore) {
  const std::string map = buildMap(ism::kitti::readKittiPoses(truePoses()), "for_labels");
  const std::string truth_dir = drive_ + "/ground_truth/velodyne_labels";
  for (const auto& [name, label] :
       {std::pair<std::string, std::uint32_t>{"semantickitti", 40}, {"unlabelled", 0}}) {
    const std::string dir = dir_ + "/labels_" + name;
    fs::create_directories(dir);
    for (const auto& entry : fs::directory_iterator(truth_dir)) {
      std::vector<std::uint32_t> labels = ism::kitti::readLabelFile(entry.path().string());
      for (std::uint32_t& l : labels) l = (7u << 16) | label;  // an instance id above
      std::ofstream out(dir + "/" + entry.path().filename().string(), std::ios::binary);
      out.write(reinterpret_cast<const char*>(labels.data()),
                static_cast<std::streamsize>(labels.size() * sizeof(std::uint32_t)));
    }
    const auto [status, output] =
        ism::test::runCommand(std::string(EVALUATE_MAP_PATH) + " --map " + map + " --drive " +
                              drive_ + " --labels " + dir);
    EXPECT_NE(status, 0) << name << ": " << output;
    EXPECT_EQ(output.find("RESULT"), std::string::npos) << output;
    if (label == 40) {
      EXPECT_NE(output.find(dir + "/0000000000.label"), std::string::npos) << output;
      EXPECT_NE(output.find("has label 40, not a Cityscapes labelId"), std::string::npos) << output;
    } else {
      EXPECT_NE(output.find("nothing to score"), std::string::npos) << output;
    }
  }
}

TEST(SemanticKittiListing, NamesTheScansWithoutTheirLabelOrImage) {
  const fs::path dir =
      fs::temp_directory_path() / ("ism_semantickitti_listing_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const auto touch = [](const fs::path& path) { ism::test_drive::writeFile(path.string(), ""); };
  for (const char* name : {"000002", "000000", "000001"})
    touch(dir / "velodyne" / (std::string(name) + ".bin"));
  touch(dir / "velodyne" / "notes.txt");  // not a scan
  touch(dir / "labels" / "000000.label");
  touch(dir / "labels" / "000002.label");
  touch(dir / "image_2" / "000000.png");
  touch(dir / "image_2" / "000001.png");

  std::vector<std::string> incomplete;
  const std::vector<std::string> frames =
      ism::evaluation::listSemanticKittiFrames(dir.string(), &incomplete);
  EXPECT_EQ(frames, std::vector<std::string>{"000000"});
  EXPECT_EQ(incomplete, (std::vector<std::string>{"000001", "000002"}));

  fs::remove(dir / "labels" / "000000.label");
  try {
    ism::evaluation::listSemanticKittiFrames(dir.string());
    ADD_FAILURE() << "a sequence without one complete frame was listed";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(dir.string()), std::string::npos) << e.what();
  }
  // A scan whose name is not a frame number is named at once (it stopped a whole run at its end
  // with "stoul").
  touch(dir / "labels" / "000000.label");
  touch(dir / "velodyne" / "000000_copy.bin");
  try {
    ism::evaluation::listSemanticKittiFrames(dir.string());
    ADD_FAILURE() << "000000_copy.bin was listed";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("000000_copy.bin: not a frame"), std::string::npos)
        << e.what();
  }
  fs::remove_all(dir);
}

}  // namespace
