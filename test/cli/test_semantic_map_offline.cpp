// semantic_map_offline on a small sequence written here: the .ot and .ply it writes, the grids,
// and the exit status on a missing flag or folder.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "inekf_semantic_mapping/kitti/mercator.h"
#include "inekf_semantic_mapping/kitti/oxts.h"
#include "inekf_semantic_mapping/kitti/poses.h"
#include "inekf_semantic_mapping/mapping/map_io.h"
#include "inekf_semantic_mapping/mapping/offline_mapping.h"
#include "inekf_semantic_mapping/mapping/semantic_octree.h"
#include "offline_mapping_fixture.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace mapping {
namespace {

// The CLI contract the evaluation uses: exact flags, .ot + PLY outputs, non-zero exit on errors.
TEST_F(OfflineMappingTest, CommandLineToolWritesOtAndPly) {
  const std::string command =
      std::string(SEMANTIC_MAP_OFFLINE_PATH) + " --scans " + dir_ + "/velodyne --labels " + dir_ +
      "/labels --poses " + dir_ + "/poses.txt --calib " + dir_ +
      "/calib.txt --resolution 0.1 --output " + dir_ + "/map.ot --export-ply " + dir_ +
      "/map.ply --max-range 30 --confusion 0.7 --max-scans 2 2>/dev/null";
  ASSERT_EQ(std::system(command.c_str()), 0) << command;
  std::unique_ptr<SemanticOcTree> loaded = loadSemanticOcTree(dir_ + "/map.ot");
  EXPECT_DOUBLE_EQ(loaded->fusionModel().correct_probability, 0.7);
  const SemanticOcTreeNode* node = loaded->search(13.05, -0.95, 0.05);
  ASSERT_NE(node, nullptr);
  EXPECT_EQ(loaded->mostLikelyLabel(*node, 0), 50u);
  std::ifstream ply(dir_ + "/map.ply");
  std::string first_line;
  std::getline(ply, first_line);
  EXPECT_EQ(first_line, "ply");

  const std::string missing_flag = std::string(SEMANTIC_MAP_OFFLINE_PATH) + " --scans " + dir_ +
                                   "/velodyne --output " + dir_ + "/x.ot 2>/dev/null";
  EXPECT_NE(std::system(missing_flag.c_str()), 0);
  const std::string bad_dir = std::string(SEMANTIC_MAP_OFFLINE_PATH) +
                              " --scans /nonexistent --labels /nonexistent --poses x --calib x "
                              "--resolution 0.2 --output " +
                              dir_ + "/y.ot 2>/dev/null";
  EXPECT_NE(std::system(bad_dir.c_str()), 0);
  EXPECT_FALSE(std::filesystem::exists(dir_ + "/y.ot"));

  // An output folder that is not there fails before any scan is read, naming the output (the
  // grids were found unwritable after the run, with the map already written).
  const auto [status, output] = test::runCommand(
      std::string(SEMANTIC_MAP_OFFLINE_PATH) + " --scans " + dir_ + "/velodyne --labels " + dir_ +
      "/labels --poses " + dir_ + "/poses.txt --calib " + dir_ + "/calib.txt --output " + dir_ +
      "/z.ot --grid " + dir_ + "/no_such_dir/grid");
  EXPECT_NE(status, 0);
  EXPECT_NE(output.find(dir_ + "/no_such_dir/grid"), std::string::npos) << output;
  EXPECT_EQ(output.find("inserted"), std::string::npos) << output;
  EXPECT_FALSE(std::filesystem::exists(dir_ + "/z.ot"));
}

// The label source decides the class set; a --config that says otherwise is named (it was
// overridden without a word, and a node configured with it then refused the map).
TEST_F(OfflineMappingTest, AConfigsClassSetOtherThanTheLabelSourcesIsNamed) {
  const std::string config = dir_ + "/cityscapes.yaml";
  std::ofstream(config) << "class_set: cityscapes\n";
  const auto [status, output] = test::runCommand(
      std::string(SEMANTIC_MAP_OFFLINE_PATH) + " --scans " + dir_ + "/velodyne --labels " + dir_ +
      "/labels --poses " + dir_ + "/poses.txt --calib " + dir_ + "/calib.txt --output " + dir_ +
      "/sk.ot --max-scans 1 --config " + config);
  ASSERT_EQ(status, 0) << output;
  EXPECT_NE(output.find(config + ": class_set cityscapes is not the label source's; the map uses "
                                 "semantickitti"),
            std::string::npos)
      << output;
  const ClassSet semantickitti = ClassSet::semanticKitti();
  ASSERT_NE(semantickitti.info(2).name, ClassSet::cityscapes().info(2).name);
  EXPECT_EQ(loadSemanticOcTree(dir_ + "/sk.ot")->classSet().info(2).name,
            semantickitti.info(2).name);
}

// The node's camera keys in --config are named, not dropped without a word (the tool's flags
// choose); the default values say nothing.
TEST_F(OfflineMappingTest, TheNodesCameraKeysInTheConfigAreNamed) {
  const std::string command = std::string(SEMANTIC_MAP_OFFLINE_PATH) + " --scans " + dir_ +
                              "/velodyne --labels " + dir_ + "/labels --poses " + dir_ +
                              "/poses.txt --calib " + dir_ + "/calib.txt --output " + dir_ +
                              "/sk.ot --max-scans 1 --config ";
  const std::string note = "calib_dir and camera_index are semantic_octomap_node's";
  std::ofstream(dir_ + "/camera3.yaml") << "class_set: semantickitti\ncamera_index: 3\n";
  const auto [status, output] = test::runCommand(command + dir_ + "/camera3.yaml");
  ASSERT_EQ(status, 0) << output;
  EXPECT_NE(output.find(dir_ + "/camera3.yaml: " + note), std::string::npos) << output;
  std::ofstream(dir_ + "/defaults.yaml")
      << "class_set: semantickitti\ncamera_index: 2\ncalib_dir: \"\"\n";
  const auto [default_status, default_output] = test::runCommand(command + dir_ + "/defaults.yaml");
  ASSERT_EQ(default_status, 0) << default_output;
  EXPECT_EQ(default_output.find(note), std::string::npos) << default_output;
}

// --grid: the node's two grids in map_server's format; the ground under the scans' lidar poses.
// The stem has " #" and ": " in it (found by review: the image name was written unquoted, and
// map_server's YAML read "grid" and a comment).
TEST_F(OfflineMappingTest, CommandLineToolWritesTheGrids) {
  std::vector<Eigen::Vector3d> origins;
  OfflineSequence sequence = options();
  sequence.on_scan_inserted = [&origins](const Eigen::Isometry3d& T_map_velo) {
    origins.push_back(T_map_velo.translation());
  };
  buildMap(sequence);
  ASSERT_EQ(origins.size(), 2u);
  EXPECT_GT((origins[1] - origins[0]).norm(), 1.0);  // the second pose moved 3 m

  const std::string command = std::string(SEMANTIC_MAP_OFFLINE_PATH) + " --scans " + dir_ +
                              "/velodyne --labels " + dir_ + "/labels --poses " + dir_ +
                              "/poses.txt --calib " + dir_ +
                              "/calib.txt --resolution 0.1 --output " + dir_ + "/map.ot --grid '" +
                              dir_ + "/grid #1: a' 2>/dev/null";
  ASSERT_EQ(std::system(command.c_str()), 0) << command;
  for (const char* name : {"projected", "drivable"}) {
    const std::string stem = dir_ + "/grid #1: a_" + name;
    const YAML::Node yaml = YAML::LoadFile(stem + ".yaml");
    EXPECT_EQ(yaml["image"].as<std::string>(), std::string("grid #1: a_") + name + ".pgm");
    EXPECT_DOUBLE_EQ(yaml["resolution"].as<double>(), 0.1);
    std::ifstream pgm(stem + ".pgm", std::ios::binary);
    std::string magic;
    int width = 0, height = 0, maxval = 0;
    pgm >> magic >> width >> height >> maxval;
    pgm.get();
    ASSERT_EQ(magic, "P5");
    std::vector<unsigned char> pixels(static_cast<std::size_t>(width) * height);
    pgm.read(reinterpret_cast<char*>(pixels.data()), static_cast<std::streamsize>(pixels.size()));
    ASSERT_TRUE(pgm) << stem;
    // The building point of scan 1 (1.78 m above the ground 1.73 m below its lidar) is an
    // obstacle in both grids; the image's top row is the largest y.
    const int ix = static_cast<int>(std::floor((13.05 - yaml["origin"][0].as<double>()) / 0.1));
    const int iy = static_cast<int>(std::floor((-0.95 - yaml["origin"][1].as<double>()) / 0.1));
    ASSERT_TRUE(ix >= 0 && ix < width && iy >= 0 && iy < height) << ix << " " << iy;
    EXPECT_EQ(pixels[static_cast<std::size_t>(height - 1 - iy) * width + ix], 0) << name;
  }
}

// A flag of the other input form, or one that needs --model, is refused before the run (each was
// ignored without a word: --labels with --drive even switched the class set).
TEST_F(OfflineMappingTest, FlagsOfTheOtherInputFormAreRefused) {
  const std::string tool = SEMANTIC_MAP_OFFLINE_PATH;
  const std::string scans = " --scans " + dir_ + "/velodyne --labels " + dir_ + "/labels --poses " +
                            dir_ + "/poses.txt --calib " + dir_ + "/calib.txt --output " + dir_ +
                            "/f.ot";
  const std::string drive =
      " --drive " + dir_ + "/2011_01_01/2011_01_01_drive_0001_sync --output " + dir_ + "/f.ot";
  const std::pair<std::string, std::string> cases[] = {
      {drive + " --labels " + dir_ + "/labels", "--labels goes with --scans, not --drive"},
      {drive + " --images " + dir_ + "/images", "--images goes with --scans, not --drive"},
      {drive + " --calib " + dir_ + "/calib.txt", "--calib goes with --scans, not --drive"},
      {scans + " --camera 3", "--camera goes with --drive, not --scans"},
      {scans + " --calib-dir " + dir_, "--calib-dir goes with --drive, not --scans"},
      {scans + " --threads 4", "--threads goes with --model"},
      {scans + " --model-card card.yaml", "--model-card goes with --model"},
      // The label source's class set, and each file in the format its name says.
      {scans + " --classes cityscapes", "--classes cityscapes does not go with --labels"},
      {drive + " --model m.onnx --classes semantickitti",
       "--classes semantickitti does not go with --model"},
      {scans + " --export-ply " + dir_ + "/f.bt", "--export-ply " + dir_ +
                                                      "/f.bt: the file is "
                                                      "written as .ply, its name ends in '.bt'"},
      {scans + " --color-ot " + dir_ + "/c.ply", "--color-ot " + dir_ +
                                                     "/c.ply: the file is "
                                                     "written as .ot"},
  };
  for (const auto& [flags, message] : cases) {
    const auto [status, output] = test::runCommand(tool + flags);
    EXPECT_NE(status, 0) << flags;
    EXPECT_NE(output.find(message), std::string::npos) << flags << "\n" << output;
  }
  EXPECT_FALSE(std::filesystem::exists(dir_ + "/f.ot"));
  const auto [status, output] = test::runCommand(tool + scans + "x.bt");  // --output f.otx.bt
  EXPECT_NE(status, 0);
  EXPECT_NE(output.find("the file is written as .ot, its name ends in '.bt'"), std::string::npos)
      << output;
}

// --model labels the scans from images: a folder that is not there, or holds none, is an error
// before the run (it gave an occupancy-only map with exit status 0), and .jpg images are read
// (only .png were: "no readable image" for every scan).
TEST_F(OfflineMappingTest, ModelImagesMustBeThereAndMayBeJpeg) {
  const std::string model = std::string(ISM_REPO_ROOT) + "/models/unet_synthetic.onnx";
  const std::string base = std::string(SEMANTIC_MAP_OFFLINE_PATH) + " --scans " + dir_ +
                           "/velodyne --poses " + dir_ + "/poses.txt --calib " + dir_ +
                           "/calib.txt --model " + model + " --output " + dir_ + "/m.ot";
  const auto [missing_status, missing] = test::runCommand(base + " --images " + dir_ + "/nope");
  EXPECT_NE(missing_status, 0);
  EXPECT_NE(missing.find(dir_ + "/nope: no such folder"), std::string::npos) << missing;
  std::filesystem::create_directories(dir_ + "/images");
  std::ofstream(dir_ + "/images/readme.txt") << "no images\n";
  const auto [empty_status, empty] = test::runCommand(base + " --images " + dir_ + "/images");
  EXPECT_NE(empty_status, 0);
  EXPECT_NE(empty.find("no .png, .jpg or .jpeg image in it"), std::string::npos) << empty;
  EXPECT_FALSE(std::filesystem::exists(dir_ + "/m.ot"));
  for (const char* stem : {"000000", "000001"}) {
    const cv::Mat gray(375, 1242, CV_8UC3, cv::Scalar(90, 110, 100));
    ASSERT_TRUE(cv::imwrite(dir_ + "/images/" + stem + ".jpg", gray));
  }
  const auto [status, output] = test::runCommand(base + " --images " + dir_ + "/images");
  EXPECT_EQ(status, 0) << output;
  EXPECT_EQ(output.find("no readable image"), std::string::npos) << output;
  EXPECT_NE(output.find("2 scans, 2 with class evidence"), std::string::npos) << output;
}

// Found by review: a copy named 000001_copy.bin went in as frame 1 a second time (the frame
// number was read from the leading digits), and a drive without scans was written out as an
// empty map. Both are errors naming the file or folder.
TEST_F(OfflineMappingTest, ScanNamesAreWholeFrameNumbersAndADriveNeedsScans) {
  std::filesystem::copy_file(dir_ + "/velodyne/000001.bin", dir_ + "/velodyne/000001_copy.bin");
  try {
    buildMap(options());
    ADD_FAILURE() << "000001_copy.bin was mapped";
  } catch (const std::runtime_error& error) {
    EXPECT_NE(std::string(error.what()).find("000001_copy.bin: scan name is not a frame number"),
              std::string::npos)
        << error.what();
  }

  // A raw drive with its calibration and an empty velodyne_points/ (poses from a file).
  const std::string date_dir = dir_ + "/2011_01_01";
  const std::string drive = date_dir + "/2011_01_01_drive_0001_sync";
  std::filesystem::create_directories(drive + "/velodyne_points/data");
  std::ofstream(drive + "/velodyne_points/timestamps.txt");
  std::ofstream(date_dir + "/calib_imu_to_velo.txt") << "R: 1 0 0 0 1 0 0 0 1\nT: 0 0 0\n";
  std::ofstream(date_dir + "/calib_velo_to_cam.txt") << "R: 0 -1 0 0 0 -1 1 0 0\nT: 0 0 0\n";
  std::ofstream(date_dir + "/calib_cam_to_cam.txt")
      << "S_02: 1392 512\nK_02: 700 0 600 0 700 180 0 0 1\nD_02: 0 0 0 0 0\n"
         "R_02: 1 0 0 0 1 0 0 0 1\nT_02: 0 0 0\nS_rect_02: 1242 375\n"
         "R_rect_02: 1 0 0 0 1 0 0 0 1\nP_rect_02: 700 0 600 0 0 700 180 0 0 0 1 0\n";
  OfflineRawDrive raw;
  raw.drive_dir = drive;
  raw.poses_path = dir_ + "/poses.txt";
  try {
    forEachRawDriveScan(raw, [](auto&&...) { ADD_FAILURE() << "a scan of an empty drive"; });
    ADD_FAILURE() << "an empty drive was mapped";
  } catch (const std::runtime_error& error) {
    EXPECT_NE(std::string(error.what()).find("velodyne_points: no scans"), std::string::npos)
        << error.what();
  }
}

// Found by review: 1.bin and 000001.bin were both mapped as frame 1, names were sorted as text
// ("10.bin" before "2.bin"), and --max-scans 0 wrote an empty map with exit status 0.
TEST_F(OfflineMappingTest, ScansAreInFrameOrderOncePerFrame) {
  const std::string names_dir = dir_ + "/names";
  std::filesystem::create_directories(names_dir);
  for (const char* name : {"10.bin", "2.bin", "0000000003.bin", "notes.txt"}) {
    std::ofstream(names_dir + "/" + name);
  }
  const std::vector<ScanFile> scans = listScanFiles(names_dir, -1);
  ASSERT_EQ(scans.size(), 3u);
  EXPECT_EQ(scans[0].frame, 2u);
  EXPECT_EQ(scans[1].frame, 3u);
  EXPECT_EQ(scans[2].frame, 10u);
  EXPECT_EQ(std::filesystem::path(scans[2].path).filename(), "10.bin");
  ASSERT_EQ(listScanFiles(names_dir, 2).size(), 2u);
  EXPECT_THROW(listScanFiles(names_dir, 0), std::invalid_argument);

  std::filesystem::copy_file(dir_ + "/velodyne/000001.bin", dir_ + "/velodyne/1.bin");
  try {
    buildMap(options());
    ADD_FAILURE() << "1.bin and 000001.bin were both mapped";
  } catch (const std::runtime_error& error) {
    EXPECT_NE(std::string(error.what()).find("are both frame 1"), std::string::npos)
        << error.what();
  }
  OfflineRawDrive none;
  none.drive_dir = dir_;
  none.max_scans = 0;
  EXPECT_THROW(forEachRawDriveScan(none, [](auto&&...) {}), std::invalid_argument);
}

}  // namespace
}  // namespace mapping
}  // namespace inekf_semantic_mapping
