// forEachRawDriveScan on small raw drives written here: each scan takes the IMU pose at its own
// stamp and the camera image at its stamp, whatever the frame numbers say (an _extract drive's
// 100 Hz OXTS, a drive whose recorder dropped frames: 2011_09_26_drive_0009_sync's velodyne
// frames 177-180).
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <sstream>
#include <vector>

#include "inekf_semantic_mapping/kitti/mercator.h"
#include "inekf_semantic_mapping/kitti/oxts.h"
#include "inekf_semantic_mapping/kitti/timestamps.h"
#include "inekf_semantic_mapping/mapping/offline_mapping.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace mapping {
namespace {

namespace fs = std::filesystem;
using test::makeTempDir;
using test::writeFile;

constexpr double kLat = 49.0, kLon0 = 8.4, kAlt = 110.0;
constexpr double kEastDegPerS = 1e-4;  // about 7.3 m/s east at 49 deg north
const std::int64_t kStart = kitti::parseKittiTimestampNs("2011-09-26 13:02:25.000000000");

std::string stampText(double t_s) {
  return kitti::formatKittiTimestamp(kStart + static_cast<std::int64_t>(t_s * 1e9 + 0.5));
}

// The OXTS line at time t: heading 0.3 rad, moving east at a constant rate.
std::string oxtsLine(double t_s) {
  std::ostringstream line;
  line.precision(15);
  line << kLat << " " << kLon0 + kEastDegPerS * t_s << " " << kAlt << " 0 0 0.3";
  for (int i = 0; i < 17; ++i) line << " 0";
  line << " 0.1 0.1 4 11 6 6 6";
  return line.str();
}

kitti::OxtsRecord recordAt(double t_s) {
  return kitti::parseOxtsLine(oxtsLine(t_s), "oxtsLine", 1);
}

std::string frameName(std::size_t n) {
  char name[32];
  std::snprintf(name, sizeof(name), "%010zu", n);
  return name;
}

// A sensor folder: data/<n><extension> for every frame with content, timestamps.txt with a blank
// line for each frame the recorder dropped (t < 0).
void writeSensor(const std::string& dir, const std::vector<double>& times_s,
                 const std::string& extension, const std::string& content) {
  std::string stamps;
  fs::create_directories(dir + "/data");
  for (std::size_t n = 0; n < times_s.size(); ++n) {
    if (times_s[n] < 0) {
      stamps += "\n";
      continue;
    }
    stamps += stampText(times_s[n]) + "\n";
    writeFile(dir + "/data/" + frameName(n) + extension, content);
  }
  writeFile(dir + "/timestamps.txt", stamps);
}

void writeOxts(const std::string& dir, const std::vector<double>& times_s) {
  std::string stamps;
  fs::create_directories(dir + "/data");
  for (std::size_t n = 0; n < times_s.size(); ++n) {
    writeFile(dir + "/data/" + frameName(n) + ".txt", oxtsLine(times_s[n]) + "\n");
    stamps += stampText(times_s[n]) + "\n";
  }
  writeFile(dir + "/timestamps.txt", stamps);
}

void writeCalibration(const std::string& date_dir) {
  writeFile(date_dir + "/calib_imu_to_velo.txt", "R: 1 0 0 0 1 0 0 0 1\nT: 0 0 0\n");
  writeFile(date_dir + "/calib_velo_to_cam.txt", "R: 0 -1 0 0 0 -1 1 0 0\nT: 0 0 0\n");
  writeFile(date_dir + "/calib_cam_to_cam.txt",
            "S_02: 1392 512\nK_02: 700 0 600 0 700 180 0 0 1\nD_02: 0 0 0 0 0\n"
            "R_02: 1 0 0 0 1 0 0 0 1\nT_02: 0 0 0\nS_rect_02: 1242 375\n"
            "R_rect_02: 1 0 0 0 1 0 0 0 1\nP_rect_02: 700 0 600 0 0 700 180 0 0 0 1 0\n");
}

// A drive folder NAME in a date folder with its calibration, in a temporary folder removed at the
// end of the test.
struct ScratchDrive {
  explicit ScratchDrive(const std::string& name)
      : date_dir(makeTempDir("raw_drive_scans") + "/2011_09_26"), drive_dir(date_dir + "/" + name) {
    writeCalibration(date_dir);
  }
  ~ScratchDrive() { fs::remove_all(fs::path(date_dir).parent_path()); }
  std::string date_dir, drive_dir;
};

std::vector<double> evenTimes(std::size_t count, double step_s, double offset_s = 0.0) {
  std::vector<double> times;
  for (std::size_t i = 0; i < count; ++i) times.push_back(offset_s + step_s * i);
  return times;
}

struct Visited {
  std::string stem, image_stem;
  Eigen::Vector3d position;
  Eigen::Index points = 0;
};

std::vector<Visited> visitAll(const OfflineRawDrive& drive, std::string* warnings) {
  std::vector<Visited> visited;
  std::ostringstream log;
  forEachRawDriveScan(
      drive,
      [&](const RawDriveScan& scan) {
        visited.push_back(
            {scan.stem, scan.image_stem, scan.T_map_velo.translation(), scan.points.cols()});
      },
      &log);
  *warnings = log.str();
  return visited;
}

// What forEachRawDriveScan throws for the drive ("" when it visits it).
std::string visitError(const OfflineRawDrive& drive) {
  std::string warnings;
  try {
    visitAll(drive, &warnings);
  } catch (const std::runtime_error& error) {
    return error.what();
  }
  return "";
}

// Where the IMU is at time t in the map of a drive whose first OXTS frame is at first_s: the
// projection of the record at t (the drive moves at a constant velocity, so the pose between two
// OXTS frames is their interpolation).
Eigen::Vector3d truePosition(double t_s, double first_s = 0.0) {
  return kitti::MercatorProjection::atFirstFix(recordAt(first_s))
      .poseInMap(recordAt(t_s))
      .translation();
}

// An _extract drive: OXTS at 100 Hz, scans as text at 10 Hz, numbered apart from the OXTS. By
// frame number the scan at 0.3 s took the OXTS pose at 0.03 s, 2 m from where it was.
TEST(RawDriveScans, AnExtractDrivesScansTakeThePoseAtTheirOwnStamp) {
  const ScratchDrive scratch("2011_09_26_drive_0001_extract");
  const std::string& drive_dir = scratch.drive_dir;
  writeOxts(drive_dir + "/oxts", evenTimes(61, 0.01));
  const std::vector<double> scan_times = evenTimes(6, 0.1, 0.004);
  writeSensor(drive_dir + "/velodyne_points", scan_times, ".txt", "1 2 3 0.5\n4 5 6 0.25\n");
  writeSensor(drive_dir + "/image_02", evenTimes(6, 0.1, 0.012), ".png", "not read here");

  OfflineRawDrive drive;
  drive.drive_dir = drive_dir;
  std::string warnings;
  const std::vector<Visited> visited = visitAll(drive, &warnings);
  ASSERT_EQ(visited.size(), 6u) << warnings;
  for (std::size_t k = 0; k < visited.size(); ++k) {
    EXPECT_EQ(visited[k].stem, frameName(k));
    EXPECT_EQ(visited[k].image_stem, frameName(k));
    EXPECT_EQ(visited[k].points, 2);
    EXPECT_LT((visited[k].position - truePosition(scan_times[k])).norm(), 0.005)
        << "scan " << k << " at " << visited[k].position.transpose() << ", truth "
        << truePosition(scan_times[k]).transpose();
  }
  EXPECT_GT((truePosition(0.304) - truePosition(0.03)).norm(), 1.9);
  EXPECT_EQ(warnings, "");
}

// The recorder dropped velodyne frames 2-3 (blank lines, no files) and camera frame 4: every
// other scan keeps its own stamp, pose and image, and the gaps are named.
TEST(RawDriveScans, DroppedFramesLeaveTheOthersWithTheirOwnStampsAndImages) {
  const ScratchDrive scratch("2011_09_26_drive_0009_sync");
  const std::string& date_dir = scratch.date_dir;
  const std::string& drive_dir = scratch.drive_dir;
  const std::vector<double> oxts_times = evenTimes(8, 0.1, 0.017);
  writeOxts(drive_dir + "/oxts", oxts_times);
  std::vector<double> scan_times = evenTimes(8, 0.1);
  scan_times[2] = scan_times[3] = -1;
  std::string bin(16, '\0');
  writeSensor(drive_dir + "/velodyne_points", scan_times, ".bin", bin);
  std::vector<double> image_times = evenTimes(8, 0.1, 0.01);
  image_times[4] = -1;
  writeSensor(drive_dir + "/image_02", image_times, ".png", "not read here");

  OfflineRawDrive drive;
  drive.drive_dir = drive_dir;
  std::string warnings;
  const std::vector<Visited> visited = visitAll(drive, &warnings);
  const std::vector<std::string> stems = {frameName(0), frameName(1), frameName(4),
                                          frameName(5), frameName(6), frameName(7)};
  ASSERT_EQ(visited.size(), stems.size()) << warnings;
  for (std::size_t i = 0; i < stems.size(); ++i) {
    const std::size_t k = std::stoul(stems[i]);
    EXPECT_EQ(visited[i].stem, stems[i]);
    EXPECT_EQ(visited[i].image_stem, k == 4 ? "" : stems[i]);
    // The scan at 0.0 s is 17 ms before the first OXTS frame: it takes that frame's pose.
    const double t = std::max(scan_times[k], oxts_times.front());
    EXPECT_LT((visited[i].position - truePosition(t, oxts_times.front())).norm(), 0.005)
        << stems[i];
  }
  EXPECT_NE(warnings.find("velodyne_points: frames 2-3 left out: blank in timestamps.txt and no "
                          "data file (dropped by the recorder)"),
            std::string::npos)
      << warnings;
  EXPECT_NE(warnings.find("image_02: frame 4 left out"), std::string::npos) << warnings;

  // A pose file has one pose per OXTS frame: the scans take them at the OXTS stamps too.
  std::string poses;
  const kitti::MercatorProjection projection =
      kitti::MercatorProjection::atFirstFix(recordAt(oxts_times.front()));
  for (double t : oxts_times) {
    const Eigen::Isometry3d T = projection.poseInMap(recordAt(t));
    std::ostringstream line;
    line.precision(12);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) line << T.matrix()(r, c) << (r == 2 && c == 3 ? "\n" : " ");
    poses += line.str();
  }
  writeFile(date_dir + "/poses.txt", poses);
  drive.poses_path = date_dir + "/poses.txt";
  const std::vector<Visited> from_file = visitAll(drive, &warnings);
  ASSERT_EQ(from_file.size(), visited.size());
  for (std::size_t i = 0; i < visited.size(); ++i) {
    EXPECT_LT((from_file[i].position - visited[i].position).norm(), 1e-6) << stems[i];
  }
  writeFile(date_dir + "/poses.txt", poses + poses);
  const std::string error = visitError(drive);
  EXPECT_NE(error.find("16 poses for the 8 frames of"), std::string::npos) << error;
}

// A scan outside the OXTS frames' span, or inside a long OXTS gap, has no pose: it is left out
// with a warning rather than put at the nearest frame's pose seconds away.
TEST(RawDriveScans, AScanWithoutAPoseNearItsStampIsLeftOutAndNamed) {
  const ScratchDrive scratch("2011_09_26_drive_0002_sync");
  const std::string& drive_dir = scratch.drive_dir;
  writeOxts(drive_dir + "/oxts", {0.0, 0.1, 0.2, 1.5, 1.6});
  writeSensor(drive_dir + "/velodyne_points", {0.05, 0.8, 1.55, 1.7}, ".bin", std::string(16, 0));
  OfflineRawDrive drive;
  drive.drive_dir = drive_dir;
  std::string warnings;
  const std::vector<Visited> visited = visitAll(drive, &warnings);
  ASSERT_EQ(visited.size(), 2u) << warnings;
  EXPECT_EQ(visited[0].stem, frameName(0));
  EXPECT_EQ(visited[1].stem, frameName(2));
  EXPECT_LT((visited[1].position - truePosition(1.55)).norm(), 0.005);
  for (const std::size_t k : {1u, 3u}) {
    EXPECT_NE(warnings.find(frameName(k) + ".bin: no pose in " + drive_dir + "/oxts at its stamp"),
              std::string::npos)
        << warnings;
  }
}

// Nothing mapped is an error, not an empty map written with exit status 0.
TEST(RawDriveScans, NoScanWithAPoseIsAnError) {
  const ScratchDrive scratch("2011_09_26_drive_0003_sync");
  const std::string& drive_dir = scratch.drive_dir;
  writeOxts(drive_dir + "/oxts", evenTimes(5, 0.1));
  writeSensor(drive_dir + "/velodyne_points", evenTimes(3, 0.1, 600.0), ".bin", std::string(16, 0));
  OfflineRawDrive drive;
  drive.drive_dir = drive_dir;
  const std::string error = visitError(drive);
  EXPECT_NE(error.find("none of the 3 scans has a pose in"), std::string::npos) << error;
}

// A poses file of the drive's first OXTS frames places the scans it covers; a drive without
// oxts/ takes one pose per velodyne frame number.
TEST(RawDriveScans, APosesFileCoversWhatItHas) {
  const ScratchDrive scratch("2011_09_26_drive_0004_sync");
  const std::string& date_dir = scratch.date_dir;
  const std::string& drive_dir = scratch.drive_dir;
  const std::vector<double> times = evenTimes(6, 0.1);
  writeOxts(drive_dir + "/oxts", times);
  std::vector<double> scan_times = times;
  scan_times[1] = -1;  // dropped
  writeSensor(drive_dir + "/velodyne_points", scan_times, ".bin", std::string(16, 0));
  std::string poses;
  for (int k = 0; k < 4; ++k) poses += "1 0 0 " + std::to_string(k) + " 0 1 0 0 0 0 1 0\n";
  writeFile(date_dir + "/poses.txt", poses);
  OfflineRawDrive drive;
  drive.drive_dir = drive_dir;
  drive.poses_path = date_dir + "/poses.txt";
  std::string warnings;
  std::vector<Visited> visited = visitAll(drive, &warnings);
  ASSERT_EQ(visited.size(), 3u) << warnings;  // frames 0, 2, 3; 4 and 5 beyond the file
  for (const Visited& scan : visited) {
    EXPECT_NEAR(scan.position.x(), std::stod(scan.stem), 1e-9) << scan.stem;
  }
  EXPECT_NE(warnings.find(frameName(4) + ".bin: no pose in"), std::string::npos) << warnings;
  fs::remove_all(drive_dir + "/oxts");
  visited = visitAll(drive, &warnings);
  ASSERT_EQ(visited.size(), 3u) << warnings;
  for (const Visited& scan : visited) {
    EXPECT_NEAR(scan.position.x(), std::stod(scan.stem), 1e-9) << scan.stem;
  }
}

// A map made offline keeps its frame's geodetic origin (the first OXTS frame, where the OXTS
// solution and inekf_offline's poses put the map frame), so that a node resuming it can check
// its own frame against it; a drive whose poses file is the only pose source has none.
TEST(RawDriveScans, TheMapKeepsTheDrivesFirstOxtsFrameAsItsOrigin) {
  const ScratchDrive scratch("2011_09_26_drive_0005_sync");
  const std::vector<double> times = evenTimes(4, 0.1, 2.0);
  writeOxts(scratch.drive_dir + "/oxts", times);
  writeSensor(scratch.drive_dir + "/velodyne_points", times, ".bin", std::string(16, 0));
  OfflineRawDrive drive;
  drive.drive_dir = scratch.drive_dir;
  SemanticMappingSession session{SemanticMappingConfig()};
  std::ostringstream log;
  mapRawDrive(drive, &session, nullptr, &log);
  ASSERT_TRUE(session.geodeticOrigin().has_value()) << log.str();
  const kitti::OxtsRecord first = recordAt(2.0);
  EXPECT_DOUBLE_EQ(session.geodeticOrigin()->lat_deg, first.lat);
  EXPECT_DOUBLE_EQ(session.geodeticOrigin()->lon_deg, first.lon);
  EXPECT_DOUBLE_EQ(session.geodeticOrigin()->alt_m, first.alt);
  EXPECT_NE(log.str().find("map frame: east-north-up at the drive's first OXTS frame (lat 49, lon "
                           "8.4002"),
            std::string::npos)
      << log.str();

  fs::remove_all(scratch.drive_dir + "/oxts");
  std::string poses;
  for (int k = 0; k < 4; ++k) poses += "1 0 0 " + std::to_string(k) + " 0 1 0 0 0 0 1 0\n";
  writeFile(scratch.date_dir + "/poses.txt", poses);
  drive.poses_path = scratch.date_dir + "/poses.txt";
  SemanticMappingSession without_oxts{SemanticMappingConfig()};
  mapRawDrive(drive, &without_oxts, nullptr, nullptr);
  EXPECT_EQ(without_oxts.statistics().scans_inserted, 4u);
  EXPECT_FALSE(without_oxts.geodeticOrigin().has_value());
}

}  // namespace
}  // namespace mapping
}  // namespace inekf_semantic_mapping
