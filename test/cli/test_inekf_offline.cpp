// inekf_offline on a short synthetic drive: it localizes and writes what it is asked for; a drive
// whose frames carry no GPS solution is an error, not a perfect score; one file named for two
// outputs is refused with nothing written.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/kitti/timestamps.h"
#include "inekf_semantic_mapping/synthetic/drive_generator.h"
#include "test_data.h"

namespace fs = std::filesystem;
namespace ism = inekf_semantic_mapping;

namespace {

class InekfOfflineTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = ism::test::makeTempDir("inekf_offline_cli");
    ism::synthetic::DriveOptions options;
    options.output_dir = dir_;
    options.seed = 3;
    options.duration_s = 5.0;
    options.write_images = false;
    options.lidar.beams = 4;
    options.lidar.azimuth_step_deg = 2.0;
    oxts_ = ism::synthetic::generateSyntheticDrive(options).sync_dir + "/oxts";
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }

  static std::pair<int, std::string> run(const std::string& arguments) {
    return ism::test::runCommand(std::string(INEKF_OFFLINE_PATH) + " " + arguments);
  }

  static std::size_t lineCount(const std::string& path) {
    std::ifstream in(path);
    std::size_t lines = 0;
    for (std::string line; std::getline(in, line);) ++lines;
    return lines;
  }

  static std::string dir_, oxts_;
};
std::string InekfOfflineTest::dir_, InekfOfflineTest::oxts_;

TEST_F(InekfOfflineTest, LocalizesASyntheticDrive) {
  const std::string poses = dir_ + "/poses.txt";
  const auto [status, output] = run("--oxts " + oxts_ + " --output-kitti " + poses);
  ASSERT_EQ(status, 0) << output;
  EXPECT_EQ(lineCount(poses), lineCount(oxts_ + "/timestamps.txt"));
  const std::size_t at = output.find("ATE ");
  ASSERT_NE(at, std::string::npos) << output;
  EXPECT_LT(std::stod(output.substr(at + 4)), 3.0) << output;
}

// Each line of --output-tum and --output-states carries its own frame's stamp, also the frames
// before the start (without the OXTS attitude the filter starts at the first fix, later): they
// repeated the start's stamp, and TUM readers saw one pose three times.
TEST_F(InekfOfflineTest, EveryOutputLineCarriesItsFramesStamp) {
  const std::string tum = dir_ + "/poses.tum", states = dir_ + "/states.csv";
  const auto [status, output] =
      run("--oxts " + oxts_ + " --output-kitti " + dir_ + "/poses_tum.txt --output-tum " + tum +
          " --output-states " + states + " --imu-gps-only");
  ASSERT_EQ(status, 0) << output;
  std::vector<std::int64_t> truth_ns;
  for (const auto& stamp : ism::kitti::readTimestampLines(oxts_ + "/timestamps.txt")) {
    ASSERT_TRUE(stamp.has_value());
    truth_ns.push_back(*stamp);
  }
  std::ifstream tum_in(tum), states_in(states);
  std::string header;
  std::getline(states_in, header);
  std::size_t k = 0;
  for (std::string line, row; std::getline(tum_in, line) && std::getline(states_in, row); ++k) {
    ASSERT_LT(k, truth_ns.size());
    const double expected = static_cast<double>(truth_ns[k]) * 1e-9;
    EXPECT_NEAR(std::stod(line.substr(0, line.find(' '))), expected, 2e-6) << "frame " << k;
    EXPECT_NEAR(std::stod(row.substr(0, row.find(','))), expected, 2e-6) << "frame " << k;
  }
  EXPECT_EQ(k, truth_ns.size());
}

// Every frame without a GPS solution (posmode 0): the filter never starts. It used to write the
// unstarted defaults for every frame and print "ATE 0.000 m".
// Simulated wheel odometry: the speeds are used once the heading is known and said in the log;
// a sigma that is not a positive number is refused.
TEST_F(InekfOfflineTest, SimulatedWheelSpeedsAreUsedAndCounted) {
  const std::string poses = dir_ + "/poses_wheels.txt";
  const auto [status, output] =
      run("--oxts " + oxts_ + " --output-kitti " + poses + " --wheel-speed-sigma 0.1");
  ASSERT_EQ(status, 0) << output;
  const std::size_t at = output.find("wheel speeds (simulated, sigma 0.100 m/s): ");
  ASSERT_NE(at, std::string::npos) << output;
  const int used = std::stoi(output.substr(at + 43));
  EXPECT_GT(used, 0.6 * static_cast<double>(lineCount(oxts_ + "/timestamps.txt"))) << output;
  for (const char* bad : {"0", "-1", "nan"}) {
    const auto [bad_status, bad_output] =
        run("--oxts " + oxts_ + " --output-kitti " + poses + " --wheel-speed-sigma " + bad);
    EXPECT_NE(bad_status, 0) << bad;
    EXPECT_NE(bad_output.find("--wheel-speed-sigma"), std::string::npos) << bad_output;
  }
}

TEST_F(InekfOfflineTest, ADriveWithoutAnyGpsFixIsAnError) {
  const fs::path no_fix = fs::path(dir_) / "no_fix" / "oxts";
  fs::create_directories(no_fix.parent_path());
  fs::copy(oxts_, no_fix, fs::copy_options::recursive);
  for (const fs::directory_entry& entry : fs::directory_iterator(no_fix / "data")) {
    std::ifstream in(entry.path());
    std::vector<std::string> fields;
    for (std::string field; in >> field;) fields.push_back(field);
    ASSERT_EQ(fields.size(), 30u) << entry.path();
    fields[27] = "0";  // posmode
    std::ofstream out(entry.path());
    for (std::size_t i = 0; i < fields.size(); ++i) out << (i ? " " : "") << fields[i];
    out << "\n";
  }
  const std::string poses = dir_ + "/no_fix_poses.txt";
  const auto [status, output] = run("--oxts " + no_fix.string() + " --output-kitti " + poses);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find(no_fix.string()), std::string::npos) << output;
  EXPECT_NE(output.find("never started"), std::string::npos) << output;
  EXPECT_EQ(output.find("ATE "), std::string::npos) << output;
  EXPECT_FALSE(fs::exists(poses));
}

// Line 3 of timestamps.txt an hour back: named by file and line; the frame is one glitch, its
// messages dropped (it was taken for a jump back and forth, and the filter started over twice),
// and the drive localizes as without it.
TEST_F(InekfOfflineTest, AStampThatGoesBackIsNamedAndTheRunGoesOn) {
  const fs::path jumped = fs::path(dir_) / "jumped" / "oxts";
  fs::create_directories(jumped.parent_path());
  fs::copy(oxts_, jumped, fs::copy_options::recursive);
  std::vector<std::string> lines;
  {
    std::ifstream in(jumped / "timestamps.txt");
    for (std::string line; std::getline(in, line);) lines.push_back(line);
  }
  ASSERT_GT(lines.size(), 10u);
  lines[2] = ism::kitti::formatKittiTimestamp(ism::kitti::parseKittiTimestampNs(lines[2]) -
                                              3600LL * 1000000000LL);
  {
    std::ofstream out(jumped / "timestamps.txt");
    for (const std::string& line : lines) out << line << "\n";
  }
  const auto [status, output] =
      run("--oxts " + jumped.string() + " --output-kitti " + dir_ + "/jumped_poses.txt");
  ASSERT_EQ(status, 0) << output;
  EXPECT_NE(output.find((jumped / "timestamps.txt").string() + ":3: 3599.890 s before"),
            std::string::npos)
      << output;
  EXPECT_EQ(output.find("time jumped back"), std::string::npos) << output;
  EXPECT_NE(output.find("1 frames (first 2) stamped off the frames around them"), std::string::npos)
      << output;
  const std::size_t at = output.find("ATE ");
  ASSERT_NE(at, std::string::npos) << output;
  EXPECT_LT(std::stod(output.substr(at + 4)), 0.5) << output;
}

// A velodyne frame the recorder dropped (its file missing, its line blank, as in
// 2011_09_26_drive_0009_sync): the loop search goes on without it. Before, --loop-closure
// stopped at "no scan for OXTS frame"; an _extract drive's 100 Hz OXTS frames took the scans of
// their own file numbers (KittiSensorStream's framesAt pairs by stamp).
TEST_F(InekfOfflineTest, LoopClosureLeavesOutAFrameWithoutAScan) {
  const fs::path sync = fs::path(oxts_).parent_path();
  const fs::path copy = fs::path(dir_) / "dropped" / sync.parent_path().filename();
  fs::create_directories(copy.parent_path());
  fs::copy(sync.parent_path(), copy, fs::copy_options::recursive);
  const fs::path velodyne = copy / sync.filename() / "velodyne_points";
  std::vector<std::string> lines;
  {
    std::ifstream in(velodyne / "timestamps.txt");
    for (std::string line; std::getline(in, line);) lines.push_back(line);
  }
  ASSERT_GT(lines.size(), 10u);
  lines[3].clear();
  {
    std::ofstream out(velodyne / "timestamps.txt");
    for (const std::string& line : lines) out << line << "\n";
  }
  ASSERT_TRUE(fs::remove(velodyne / "data" / "0000000003.bin"));
  const auto [status, output] =
      run("--oxts " + (copy / sync.filename() / "oxts").string() + " --output-kitti " + dir_ +
          "/dropped_poses.txt --smooth --loop-closure");
  ASSERT_EQ(status, 0) << output;
  EXPECT_NE(output.find("frame 3 left out"), std::string::npos) << output;
  EXPECT_NE(output.find("1 of " + std::to_string(lines.size()) + " OXTS frames have no scan"),
            std::string::npos)
      << output;
  EXPECT_EQ(lineCount(dir_ + "/dropped_poses.txt"), lines.size());
}

TEST_F(InekfOfflineTest, OneFileForTwoOutputsIsRefused) {
  const std::string both = dir_ + "/both.txt";
  const auto [status, output] =
      run("--oxts " + oxts_ + " --output-kitti " + both + " --output-truth " + both);
  EXPECT_NE(status, 0) << output;
  EXPECT_NE(output.find("two outputs"), std::string::npos) << output;
  EXPECT_FALSE(fs::exists(both));
}

}  // namespace
