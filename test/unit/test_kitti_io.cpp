// KITTI raw I/O on small files the tests write themselves (formats, bad input, round trips).
// The real data of ../shared: test/data/test_kitti_io_data.cpp.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>

#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/kitti/drive_timeline.h"
#include "inekf_semantic_mapping/kitti/errors.h"
#include "inekf_semantic_mapping/kitti/mercator.h"
#include "inekf_semantic_mapping/kitti/oxts.h"
#include "inekf_semantic_mapping/kitti/poses.h"
#include "inekf_semantic_mapping/kitti/raw_drive.h"
#include "inekf_semantic_mapping/kitti/sensor_stream.h"
#include "inekf_semantic_mapping/kitti/timestamps.h"
#include "inekf_semantic_mapping/kitti/velodyne.h"
#include "kitti_format_error.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace kitti {
namespace {

namespace fs = std::filesystem;
using test::expectFormatError;
using test::makeTempDir;
using test::sharedPath;
using test::writeFile;

const char kLine0001Frame0[] =
    "49.015003823272 8.4342971002335 116.43032836914 0.035752 0.00903 -2.6087069803847 "
    "-6.811441479104 -11.275641809511 13.172716663769 -0.12475264293164 -0.032919903047354 "
    "-0.44519814607457 0.042957369847256 10.209865300506 -0.34030092211055 -0.31686915378551 "
    "10.209117821189 0.0090951755733632 -0.023140741253985 -0.017909034508194 "
    "0.0089018002187228 -0.022495299354602 -0.018809330937153 0.027658633371879 "
    "0.012727922061358 4 11 6 6 6";

// ---------------------------------------------------------------------------- timestamps
TEST(KittiTimestamps, ParsesAsUtcNanoseconds) {
  // 2011-09-26 is day 15243 after 1970-01-01: 15243*86400 + 13*3600 + 2*60 + 25 = 1317042145 s.
  EXPECT_EQ(parseKittiTimestampNs("2011-09-26 13:02:25.964389445"), 1317042145964389445LL);
  EXPECT_EQ(parseKittiTimestampNs("1970-01-01 00:00:00.000000001"), 1);
  EXPECT_EQ(parseKittiTimestampNs("1970-01-02 00:00:00"), 86400LL * 1000000000LL);
  // Leap day, short fraction (".5" is half a second, not 5 ns).
  EXPECT_EQ(
      parseKittiTimestampNs("2012-03-01 00:00:00.5") - parseKittiTimestampNs("2012-02-28 00:00:00"),
      2 * 86400LL * 1000000000LL + 500000000LL);
}

TEST(KittiTimestamps, RejectsMalformedText) {
  EXPECT_THROW(parseKittiTimestampNs("2011-09-26T13:02:25"), KittiFormatError);
  EXPECT_THROW(parseKittiTimestampNs("2011-13-26 13:02:25"), KittiFormatError);
  EXPECT_THROW(parseKittiTimestampNs("2011-09-26 13:02:25.1234567890"), KittiFormatError);
  EXPECT_THROW(parseKittiTimestampNs("2011-09-26 13:02:25.12x"), KittiFormatError);
  EXPECT_THROW(parseKittiTimestampNs(""), KittiFormatError);
}

// A day the month does not have (the Gregorian leap rule: 2100 is no leap year, 2000 is).
TEST(KittiTimestamps, RejectsDaysTheMonthDoesNotHave) {
  EXPECT_THROW(parseKittiTimestampNs("2011-04-31 00:00:00"), KittiFormatError);
  EXPECT_THROW(parseKittiTimestampNs("2011-02-29 00:00:00"), KittiFormatError);
  EXPECT_THROW(parseKittiTimestampNs("2100-02-29 00:00:00"), KittiFormatError);
  EXPECT_EQ(
      parseKittiTimestampNs("2000-03-01 00:00:00") - parseKittiTimestampNs("2000-02-29 00:00:00"),
      86400LL * 1000000000LL);
}

// ---------------------------------------------------------------------------- OXTS
// A stamp that goes back, or a jump of an hour: named by file and line (inekf_offline scored
// such a drive at an ATE of 36,000 km; kitti2bag dropped the frame without a word).
TEST(KittiTimestamps, WarningsNameTheLinesThatGoBackOrJump) {
  const std::int64_t s = 1000000000LL;
  EXPECT_TRUE(timestampWarnings({0, s / 10, 2 * s / 10, 3 * s / 10}, "t.txt").empty());
  const std::vector<std::string> warnings = timestampWarnings(
      {0, s / 10, -4 * s, s / 10 + 3600 * s, s / 10 + 3600 * s + s / 10}, "t.txt");
  ASSERT_EQ(warnings.size(), 2u);
  EXPECT_EQ(warnings[0], "t.txt:3: 4.100 s before the line above");
  EXPECT_EQ(warnings[1], "t.txt:4: 3604.100 s after the line above");
  EXPECT_EQ(timestampWarnings({0, s / 10, s / 10, 3 * s / 10}, "d.txt"),
            std::vector<std::string>{"d.txt:3: the same stamp as the line above"});
  std::vector<std::int64_t> zigzag;
  for (int i = 0; i < 20; ++i) zigzag.push_back(i % 2 == 0 ? 0 : 5 * s);
  const std::vector<std::string> capped = timestampWarnings(zigzag, "z.txt", 1.0, 5);
  ASSERT_EQ(capped.size(), 6u);
  EXPECT_EQ(capped.back(), "z.txt: 14 more such steps");
  // Stamps read from lines apart (blank lines between): the lines named are the file's.
  EXPECT_EQ(timestampWarnings({0, s / 10, 5 * s}, "v.txt", 1.0, 5, {0, 1, 6}),
            std::vector<std::string>{"v.txt:7: 4.900 s after line 2"});
}

TEST(KittiOxts, ParsesAllThirtyFields) {
  const OxtsRecord r = parseOxtsLine(kLine0001Frame0, "f.txt", 1);
  EXPECT_DOUBLE_EQ(r.lat, 49.015003823272);
  EXPECT_DOUBLE_EQ(r.lon, 8.4342971002335);
  EXPECT_DOUBLE_EQ(r.alt, 116.43032836914);
  EXPECT_DOUBLE_EQ(r.yaw, -2.6087069803847);
  EXPECT_DOUBLE_EQ(r.vn, -6.811441479104);
  EXPECT_DOUBLE_EQ(r.vf, 13.172716663769);
  EXPECT_DOUBLE_EQ(r.ax, -0.44519814607457);
  EXPECT_DOUBLE_EQ(r.az, 10.209865300506);
  EXPECT_DOUBLE_EQ(r.af, -0.34030092211055);
  EXPECT_DOUBLE_EQ(r.wx, 0.0090951755733632);
  EXPECT_DOUBLE_EQ(r.wz, -0.017909034508194);
  EXPECT_DOUBLE_EQ(r.wu, -0.018809330937153);
  EXPECT_DOUBLE_EQ(r.pos_accuracy, 0.027658633371879);
  EXPECT_DOUBLE_EQ(r.vel_accuracy, 0.012727922061358);
  EXPECT_EQ(r.navstat, 4);
  EXPECT_EQ(r.numsats, 11);
  EXPECT_EQ(r.posmode, 6);
  EXPECT_EQ(r.velmode, 6);
  EXPECT_EQ(r.orimode, 6);
}

TEST(KittiOxts, ParsesFourteenDecimalIntegersOfTheLaterDates) {
  // 2011_10_03 style: the flags printed as "4.00000000000000", here with posmode -1.
  const std::string dir = makeTempDir("kitti_oxts14");
  std::string line = kLine0001Frame0;
  line = line.substr(0, line.rfind(" 4 11 6 6 6")) +
         " 4.00000000000000 9.00000000000000 -1.00000000000000 2.00000000000000 0.00000000000000";
  writeFile(dir + "/0000000000.txt", line + "\n");
  const OxtsRecord r = readOxtsFile(dir + "/0000000000.txt");
  EXPECT_EQ(r.navstat, 4);
  EXPECT_EQ(r.numsats, 9);
  EXPECT_EQ(r.posmode, -1);
  EXPECT_EQ(r.velmode, 2);
  EXPECT_EQ(r.orimode, 0);
  fs::remove_all(dir);
}

TEST(KittiOxts, BadLinesNameFileLineAndField) {
  std::string line = kLine0001Frame0;
  expectFormatError([&] { parseOxtsLine(line.substr(0, line.rfind(' ')), "a.txt", 3); },
                    {"a.txt:3", "found 29"});
  std::string non_numeric = line;
  non_numeric.replace(non_numeric.find("0.035752"), 8, "0.03x752");
  expectFormatError([&] { parseOxtsLine(non_numeric, "b.txt", 1); }, {"b.txt:1", "roll"});
  std::string fractional_flag = line.substr(0, line.rfind(" 6")) + " 6.5";
  expectFormatError([&] { parseOxtsLine(fractional_flag, "c.txt", 1); }, {"c.txt", "orimode"});
  std::string nan_lat = line;
  nan_lat.replace(0, 15, "nan");
  expectFormatError([&] { parseOxtsLine(nan_lat, "d.txt", 1); }, {"d.txt", "lat"});
  std::string inf_wz = line;
  inf_wz.replace(inf_wz.find("-0.017909034508194"), 18, "inf");
  expectFormatError([&] { parseOxtsLine(inf_wz, "e.txt", 2); }, {"e.txt:2", "wz", "not finite"});
  expectFormatError([&] { readOxtsFile("/nonexistent/0000000000.txt"); },
                    {"/nonexistent/0000000000.txt"});
}

// A stamp whose file is missing: the frame is left out and named, not an error that stops the
// whole drive.
TEST(KittiOxts, AFrameWithoutItsFileIsLeftOutAndNamed) {
  const std::string dir = makeTempDir("kitti_oxts_count");
  writeFile(dir + "/oxts/data/0000000000.txt", std::string(kLine0001Frame0) + "\n");
  writeFile(dir + "/oxts/data/0000000002.txt", std::string(kLine0001Frame0) + "\n");
  writeFile(dir + "/oxts/timestamps.txt",
            "2011-09-26 13:02:25.964389445\n2011-09-26 13:02:26.074347616\n"
            "2011-09-26 13:02:26.184347616\n");
  std::vector<std::string> warnings;
  const std::vector<OxtsFrame> frames = readOxtsFolder(dir + "/oxts", &warnings);
  ASSERT_EQ(frames.size(), 2u);
  // The frame after the missing one keeps its own number: its scan is the file of that number
  // (inekf_offline --loop-closure paired OXTS frame k with scan k).
  EXPECT_EQ(frames[1].file_number, 2u);
  EXPECT_EQ(frames[1].stamp_ns, parseKittiTimestampNs("2011-09-26 13:02:26.184347616"));
  const std::string expected = dir + "/oxts: frame 1 left out: in timestamps.txt but no data/ file";
  EXPECT_EQ(warnings, std::vector<std::string>{expected});
  EXPECT_EQ(RawDrive(dir).frameWarnings(), std::vector<std::string>{expected});
  // No frames at all: named here, not as "runLocalizerOnOxts: no OXTS frames" later.
  fs::remove(dir + "/oxts/data/0000000000.txt");
  fs::remove(dir + "/oxts/data/0000000002.txt");
  writeFile(dir + "/oxts/timestamps.txt", "");
  expectFormatError([&] { readOxtsFolder(dir + "/oxts"); }, {dir + "/oxts", "no frames"});
  fs::remove_all(dir);
}

// ---------------------------------------------------------------------------- sensor streams
// 2011_09_26_drive_0009_sync: the recorder dropped velodyne frames 177-180, leaving their lines
// blank and no files. Read by line, frame 181's file keeps frame 181's stamp (dropping the blank
// lines paired every later file with a stamp 0.4 s early, and the reader then opened the missing
// file 177 and stopped).
TEST(KittiSensorStream, AFrameTheRecorderDroppedKeepsTheOthersOnTheirOwnLines) {
  const std::string dir = makeTempDir("kitti_stream") + "/velodyne_points";
  const std::string stamps[] = {"2011-09-26 13:02:25.0", "2011-09-26 13:02:25.1", "", "",
                                "2011-09-26 13:02:25.4", "2011-09-26 13:02:25.5"};
  std::string lines, start_lines;
  for (int n = 0; n < 6; ++n) {
    lines += stamps[n] + "\n";
    start_lines += (stamps[n].empty() ? "" : stamps[n] + "5") + "\n";
    if (!stamps[n].empty()) {
      writeFile(dir + "/data/" + std::string("000000000") + std::to_string(n) + ".bin", "");
    }
  }
  writeFile(dir + "/timestamps.txt", lines + "\n\n");  // blank lines at the end are no frames
  writeFile(dir + "/timestamps_start.txt", start_lines);
  writeFile(dir + "/data/notes.txt", "not a frame");
  const SensorStream stream = readSensorStream(dir, "velodyne_points");
  ASSERT_TRUE(stream.present);
  EXPECT_EQ(stream.extension, ".bin");
  ASSERT_EQ(stream.size(), 4u);
  EXPECT_EQ(stream.file_numbers, (std::vector<std::size_t>{0, 1, 4, 5}));
  EXPECT_EQ(stream.stamps_ns[2], parseKittiTimestampNs("2011-09-26 13:02:25.4"));
  EXPECT_EQ(stream.framePath(2), dir + "/data/0000000004.bin");
  EXPECT_EQ(stream.fileStem(3), "0000000005");
  ASSERT_EQ(stream.start_stamps_ns.size(), 4u);
  EXPECT_EQ(stream.start_stamps_ns[2], parseKittiTimestampNs("2011-09-26 13:02:25.45"));
  EXPECT_EQ(stream.warnings,
            std::vector<std::string>{dir + ": frames 2-3 left out: blank in timestamps.txt and no "
                                           "data file (dropped by the recorder)"});
  // The nearest frame in time, if near enough.
  const std::int64_t t4 = stream.stamps_ns[2];
  EXPECT_EQ(stream.nearestFrame(t4 - 40'000'000, 50'000'000), 2);
  EXPECT_EQ(stream.nearestFrame(t4 - 160'000'000, 50'000'000), -1);
  // Another stream's frames at 100 Hz (an _extract drive's OXTS): each scan goes with the one
  // nearest it, the frames between scans and those of the dropped scans with none.
  std::vector<std::int64_t> oxts_ns;
  const std::int64_t t0 = stream.stamps_ns[0];
  for (int k = 0; k < 60; ++k) oxts_ns.push_back(t0 - 3'000'000 + 10'000'000 * k);
  const std::vector<std::ptrdiff_t> scan_of = stream.framesAt(oxts_ns, 50'000'000);
  ASSERT_EQ(scan_of.size(), oxts_ns.size());
  for (int k = 0; k < 60; ++k) {
    const std::ptrdiff_t expected = k == 0 ? 0 : k == 10 ? 1 : k == 40 ? 2 : k == 50 ? 3 : -1;
    EXPECT_EQ(scan_of[k], expected) << "OXTS frame " << k;
  }
  // Far from every frame: none.
  EXPECT_EQ(stream.framesAt({t0 + 10'000'000'000}, 50'000'000), (std::vector<std::ptrdiff_t>{-1}));
  // The start stamps of a frame the main file has but this one lacks: not used, and named.
  writeFile(dir + "/timestamps_start.txt", "2011-09-26 13:02:25.05\n");
  const SensorStream short_start = readSensorStream(dir, "velodyne_points");
  EXPECT_TRUE(short_start.start_stamps_ns.empty());
  ASSERT_EQ(short_start.warnings.size(), 2u);
  EXPECT_EQ(short_start.warnings[1], dir +
                                         "/timestamps_start.txt:2: no stamp for frame 1, which "
                                         "timestamps.txt stamps: the file is not used");
  fs::remove_all(fs::path(dir).parent_path());
}

// An _extract drive's camera images are the raw 1392x512 ones: projected with P_rect they label
// every point from the wrong pixel. semantic_map_offline labelled such a drive without a word.
TEST(KittiCalibration, AnImageNotOfTheRectifiedSizeIsRefusedNamingIt) {
  CameraProjection camera;
  camera.width = 1242;
  camera.height = 375;
  const std::string path = "drive/image_02/data/0000000000.png";
  EXPECT_NO_THROW(camera.checkRectifiedImageSize(path, 1242, 375));
  try {
    camera.checkRectifiedImageSize(path, 1392, 512);
    ADD_FAILURE() << "an unrectified image was taken";
  } catch (const KittiFormatError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(path), std::string::npos) << what;
    EXPECT_NE(what.find("1392x512, the calibration's rectified size (S_rect) says 1242x375"),
              std::string::npos)
        << what;
    EXPECT_NE(what.find("_sync drive"), std::string::npos) << what;
  }
  camera.width = camera.height = 0;  // a calibration that states no size
  EXPECT_NO_THROW(camera.checkRectifiedImageSize(path, 1392, 512));
}

TEST(KittiSensorStream, FilesNumberedOtherwiseAreAnErrorNamingTheFolder) {
  const std::string dir = makeTempDir("kitti_stream") + "/image_02";
  writeFile(dir + "/timestamps.txt", "2011-09-26 13:02:25.0\n2011-09-26 13:02:25.1\n");
  writeFile(dir + "/data/0000000010.png", "");
  writeFile(dir + "/data/0000000011.png", "");
  expectFormatError([&] { readSensorStream(dir, "image_02"); },
                    {dir, "2 files in data/ (.png, e.g. 00000000", "none named as a line"});
  // Named with 6 digits (the odometry benchmark's way): no frame of a raw drive.
  fs::remove_all(dir + "/data");
  writeFile(dir + "/data/000000.png", "");
  writeFile(dir + "/data/000001.png", "");
  expectFormatError([&] { readSensorStream(dir, "image_02"); }, {dir, "e.g. 00000"});
  // Files but no stamp at all: timestamps.txt is named, not the files.
  writeFile(dir + "/timestamps.txt", "\n\n");
  expectFormatError([&] { readSensorStream(dir, "image_02"); },
                    {dir + "/timestamps.txt", "no stamp for the 2 files in data/"});
  // A folder without data/ is no sensor at all.
  EXPECT_FALSE(readSensorStream(dir + "/none", "image_03").present);
  fs::remove_all(fs::path(dir).parent_path());
}

// ---------------------------------------------------------------------------- Mercator
TEST(KittiMercator, FirstTwoFramesOfDrive0001) {
  const OxtsRecord r0 = parseOxtsLine(kLine0001Frame0, "f", 1);
  const MercatorProjection projection = MercatorProjection::atFirstFix(r0);
  EXPECT_NEAR(projection.scale(), std::cos(49.015003823272 * M_PI / 180.0), 1e-15);
  EXPECT_LT(projection.toMap(r0.lat, r0.lon, r0.alt).norm(), 1e-9);
  // Devkit by hand: s = cos(lat0), mx = s*er*lon*pi/180, my = s*er*log(tan((90+lat)*pi/360)).
  const Eigen::Vector3d p1 = projection.toMap(49.014997147797, 8.4342801643975, 116.43227386475);
  EXPECT_NEAR(p1.x(), -1.2364879969973117, 1e-6);  // moving west-south-west (yaw -2.61)
  EXPECT_NEAR(p1.y(), -0.7431104257702827, 1e-6);
  EXPECT_NEAR(p1.z(), 0.0019454956100020127, 1e-9);
  // 0.11 s at ~13.2 m/s forward: the step length must agree with the speed.
  EXPECT_NEAR(p1.head<2>().norm(), 13.17 * 0.10996, 0.05);
}

TEST(KittiMercator, PoseRotationIsRzRyRx) {
  OxtsRecord r;
  r.lat = 49.0;
  r.lon = 8.4;
  r.alt = 100.0;
  r.roll = 0.1;
  r.pitch = -0.2;
  r.yaw = 1.3;
  const Eigen::Isometry3d pose = MercatorProjection::atFirstFix(r).poseInMap(r);
  const double cr = std::cos(0.1), sr = std::sin(0.1), cp = std::cos(-0.2), sp = std::sin(-0.2),
               cy = std::cos(1.3), sy = std::sin(1.3);
  Eigen::Matrix3d rx, ry, rz;
  rx << 1, 0, 0, 0, cr, -sr, 0, sr, cr;
  ry << cp, 0, sp, 0, 1, 0, -sp, 0, cp;
  rz << cy, -sy, 0, sy, cy, 0, 0, 0, 1;
  EXPECT_TRUE(pose.linear().isApprox(rz * ry * rx, 1e-12));
  EXPECT_LT(pose.translation().norm(), 1e-9);
  // Body x axis points along yaw in the east-north plane (yaw 0 = east).
  const Eigen::Vector3d forward =
      rotationFromRollPitchYaw(0, 0, M_PI / 2) * Eigen::Vector3d::UnitX();
  EXPECT_TRUE(forward.isApprox(Eigen::Vector3d::UnitY(), 1e-12));
}

TEST(KittiMercator, TheProjectionsDomainExcludesThePolesAndNonFiniteValues) {
  EXPECT_TRUE(isGeodeticInRange(49.0, 8.4, 112.0));
  EXPECT_TRUE(isGeodeticInRange(-89.9, -180.0, -30.0));
  EXPECT_FALSE(isGeodeticInRange(90.0, 8.4, 112.0));
  EXPECT_FALSE(isGeodeticInRange(-90.0, 8.4, 112.0));
  EXPECT_FALSE(isGeodeticInRange(49.0, 180.5, 112.0));
  EXPECT_FALSE(isGeodeticInRange(std::nan(""), 8.4, 112.0));
  EXPECT_FALSE(isGeodeticInRange(49.0, 8.4, std::numeric_limits<double>::infinity()));
}

// One bad line (6.4 s back, or an hour ahead) is listed; a real jump moves every stamp after it
// and is not; the ends cannot be judged.
TEST(KittiTimestamps, OnlyAStampOffBothItsNeighboursIsMisstamped) {
  const std::int64_t s = 1000000000LL;
  const std::vector<std::int64_t> stamps{
      0,          s / 10, 2 * s / 10 - 64 * s / 10, 3 * s / 10, 4 * s / 10 + 3600 * s,
      5 * s / 10, 60 * s, 60 * s + s / 10,          -5 * s};
  const std::vector<bool> misstamped = isolatedMisstampedFrames(stamps);
  EXPECT_EQ(misstamped,
            (std::vector<bool>{false, false, true, false, true, false, false, false, false}));
  EXPECT_TRUE(isolatedMisstampedFrames({}).empty());
}

// Two and three bad lines in a row (the same or different offsets) are listed as well; a run
// longer than max_run, or one that never comes back, is a jump.
TEST(KittiTimestamps, AShortRunOfMisstampedLinesIsListedAsWhole) {
  const std::int64_t s = 1000000000LL;
  const auto tenths = [s](std::int64_t k) { return k * s / 10; };
  std::vector<std::int64_t> stamps;
  for (int k = 0; k < 20; ++k) stamps.push_back(tenths(k));
  stamps[3] -= 64 * s / 10;  // two lines 6.4 s back
  stamps[4] -= 64 * s / 10;
  stamps[8] += 3600 * s;  // three lines: an hour ahead, 5 s back, half an hour ahead
  stamps[9] -= 5 * s;
  stamps[10] += 1800 * s;
  std::vector<bool> expected(20, false);
  for (int k : {3, 4, 8, 9, 10}) expected[k] = true;
  EXPECT_EQ(isolatedMisstampedFrames(stamps), expected);
  // With runs of at most two, the three are not listed.
  for (int k : {8, 9, 10}) expected[k] = false;
  EXPECT_EQ(isolatedMisstampedFrames(stamps, 1.0, 2), expected);
  // A jump that lasts (every later stamp 6.4 s back) is the recording's own.
  std::vector<std::int64_t> jump;
  for (int k = 0; k < 20; ++k) jump.push_back(tenths(k) - (k >= 12 ? 64 * s / 10 : 0));
  EXPECT_EQ(isolatedMisstampedFrames(jump), std::vector<bool>(20, false));
  // A gap of 2 s is real too: the frames after it are in order among themselves.
  std::vector<std::int64_t> gap;
  for (int k = 0; k < 20; ++k) gap.push_back(tenths(k) + (k >= 5 ? 2 * s : 0));
  EXPECT_EQ(isolatedMisstampedFrames(gap), std::vector<bool>(20, false));
}

TEST(KittiMercator, ToGeodeticInvertsToMap) {
  const MercatorProjection projection(49.015, 8.434, 116.4);
  for (const Eigen::Vector3d& p : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(-1234.5, 876.25, -3.5),
                                   Eigen::Vector3d(5000, -4000, 20)}) {
    double lat, lon, alt;
    projection.toGeodetic(p, &lat, &lon, &alt);
    EXPECT_LT((projection.toMap(lat, lon, alt) - p).norm(), 1e-6) << p.transpose();
  }
}

TEST(KittiCalibration, OdometryCalibTxtAndErrors) {
  const std::string dir = makeTempDir("kitti_calib");
  const std::string p = "7 0 6 0 0 7 1 0 0 0 1 0";
  writeFile(dir + "/calib.txt", "P0: " + p + "\nP1: " + p + "\nP2: " + p + "\nP3: " + p +
                                    "\nTr: 0 -1 0 0.1 0 0 -1 0.2 1 0 0 0.3\n");
  const ObjectCalibration calib = readObjectCalibration(dir + "/calib.txt");
  EXPECT_TRUE(calib.R0_rect.isIdentity());
  EXPECT_FALSE(calib.has_imu_to_velo);
  EXPECT_EQ(calib.Tr_velo_to_cam.translation(), Eigen::Vector3d(0.1, 0.2, 0.3));

  writeFile(dir + "/short.txt", "P0: " + p + "\nP1: 1 2 3\n");
  expectFormatError([&] { readObjectCalibration(dir + "/short.txt"); },
                    {dir + "/short.txt:2", "P1", "3 values"});
  writeFile(dir + "/nan.txt", "P0: 1 2 x\n");
  expectFormatError([&] { readObjectCalibration(dir + "/nan.txt"); }, {"nan.txt:1", "'x'"});
  expectFormatError([&] { readRawCalibration(dir); }, {"calib_imu_to_velo.txt"});
  // The object format without its R0_rect (a file cut short) was read with the identity.
  writeFile(dir + "/no_r0.txt", "P0: " + p + "\nP1: " + p + "\nP2: " + p + "\nP3: " + p +
                                    "\nTr_velo_to_cam: 0 -1 0 0 0 0 -1 0 1 0 0 0\n");
  expectFormatError([&] { readObjectCalibration(dir + "/no_r0.txt"); },
                    {"no_r0.txt", "missing key 'R0_rect'"});
  fs::remove_all(dir);
}

// ---------------------------------------------------------------------------- velodyne
TEST(KittiPoses, WrittenPosesReadBackExactlyAndBadLinesNameTheLine) {
  const std::string path =
      (std::filesystem::temp_directory_path() / ("ism_poses_" + std::to_string(::getpid())))
          .string();
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  pose.translation() << 4123.456789012345, -0.000123456789, 98.7654321;
  {
    std::ofstream(path) << kittiPoseLine(Eigen::Isometry3d::Identity()) << "\n"
                        << kittiPoseLine(pose);
  }
  const std::vector<Eigen::Isometry3d> poses = readKittiPoses(path);
  ASSERT_EQ(poses.size(), 2u);  // the blank line is skipped
  EXPECT_TRUE(poses[0].isApprox(Eigen::Isometry3d::Identity(), 1e-15));
  EXPECT_LT((poses[1].matrix() - pose.matrix()).cwiseAbs().maxCoeff(), 1e-8);
  std::ofstream(path, std::ios::app) << "1 0 0 0 0 1 0 0 0 0 1\n";
  try {
    readKittiPoses(path);
    FAIL() << "a line of 11 numbers was accepted";
  } catch (const KittiFormatError& e) {
    EXPECT_EQ(e.lineNumber(), 4);
    EXPECT_NE(std::string(e.what()).find(path + ":4"), std::string::npos) << e.what();
  }
  std::filesystem::remove(path);
}

TEST(KittiVelodyne, BadSizeAndMissingFileNameTheFile) {
  const std::string dir = makeTempDir("kitti_velo");
  writeFile(dir + "/bad.bin", std::string(20, '\0'));
  expectFormatError([&] { readVelodyneBin(dir + "/bad.bin"); }, {dir + "/bad.bin", "20 bytes"});
  expectFormatError([&] { readVelodyneBin(dir + "/none.bin"); }, {dir + "/none.bin"});
  const float points[8] = {1, 2, 3, 0.5f, -4, 5, -6, 0.25f};
  writeFile(dir + "/ok.bin", std::string(reinterpret_cast<const char*>(points), sizeof(points)));
  const VelodyneScan scan = readVelodyneScan(dir + "/ok.bin");
  ASSERT_EQ(scan.size(), 2u);
  EXPECT_EQ(scan.point(1)[2], -6.0f);
  EXPECT_EQ(scan.point(1)[3], 0.25f);
  writeFile(dir + "/scan.txt", "1 2 3 0.5\n4 5 6\n");
  expectFormatError([&] { readVelodyneScan(dir + "/scan.txt"); }, {"scan.txt:2"});
  fs::remove_all(dir);
}

// One point 10 m away at `azimuth` (rad, atan2(y, x)) and height z.
void appendPoint(VelodyneScan* scan, double azimuth, float z) {
  scan->xyzi.insert(scan->xyzi.end(), {static_cast<float>(10.0 * std::cos(azimuth)),
                                       static_cast<float>(10.0 * std::sin(azimuth)), z, 0.5f});
}

// One laser's sweep as the scans store it: from straight ahead, azimuth rising in 10 degree steps
// round to just before straight ahead again (atan2 wraps from +180 to -180 degrees at the rear).
void appendSweep(VelodyneScan* scan, float z) {
  for (int step = 0; step < 36; ++step) appendPoint(scan, step * M_PI / 18.0, z);
}

// More wraps than lasers (a merged or repeated cloud) keep the extra points on the last ring.
TEST(KittiVelodyne, RingsBeyondTheLaserCountStayOnTheLastRing) {
  VelodyneScan scan;
  for (int laser = 0; laser < 4; ++laser) appendSweep(&scan, -1.0f - 0.1f * laser);
  const std::vector<std::uint16_t> all = computeRings(scan, 64);
  ASSERT_EQ(all.size(), 4u * 36u);
  EXPECT_EQ(all[35], 0);
  EXPECT_EQ(all[36], 1);
  EXPECT_EQ(all.back(), 3);
  const std::vector<std::uint16_t> clamped = computeRings(scan, 2);
  ASSERT_EQ(clamped.size(), scan.size());
  EXPECT_EQ(clamped[35], 0);
  for (std::size_t i = 36; i < clamped.size(); ++i) ASSERT_EQ(clamped[i], 1) << "point " << i;
}

// A laser's azimuth dithering about straight ahead as its sweep begins starts no new ring: the
// ring ends only after the sweep went round by the rear.
TEST(KittiVelodyne, AzimuthJitterAroundStraightAheadStartsNoRing) {
  VelodyneScan scan;
  for (int laser = 0; laser < 3; ++laser) {
    for (const double jitter : {0.0, -0.002, 0.001, -0.001, 0.003}) {
      appendPoint(&scan, jitter, -1.0f - 0.1f * laser);
    }
    for (int step = 1; step < 36; ++step) appendPoint(&scan, step * M_PI / 18.0, -1.0f);
  }
  const std::vector<std::uint16_t> rings = computeRings(scan, 64);
  ASSERT_EQ(rings.size(), 3u * 40u);
  for (std::size_t i = 0; i < rings.size(); ++i) {
    ASSERT_EQ(rings[i], i / 40) << "point " << i;
  }
}

TEST(KittiRawDrive, AFileWithoutAStampIsLeftOutAndNamed) {
  const std::string dir = makeTempDir("kitti_drive") + "/2011_09_26_drive_0001_extract";
  writeFile(dir + "/velodyne_points/data/0000000000.bin", std::string(16, '\0'));
  writeFile(dir + "/velodyne_points/timestamps.txt", "2011-09-26 13:02:25.9\n");
  writeFile(dir + "/velodyne_points/timestamps_start.txt", "2011-09-26 13:02:25.85\n");
  {
    const RawDrive drive(dir);
    EXPECT_TRUE(drive.isExtract());
    EXPECT_TRUE(drive.hasVelodyne());
    EXPECT_EQ(drive.velodyne().start_stamps_ns.size(), 1u);
    EXPECT_TRUE(drive.velodyne().end_stamps_ns.empty());
    EXPECT_EQ(drive.velodyne().extension, ".bin");
    // An oxts/ with its folders but no frame is named as missing (a bag without IMU was written
    // without a word).
    fs::create_directories(dir + "/oxts/data");
    writeFile(dir + "/oxts/timestamps.txt", "");
    const std::vector<std::string> missing = RawDrive(dir).missingParts();
    EXPECT_NE(std::find(missing.begin(), missing.end(), "oxts (no frames in " + dir + "/oxts)"),
              missing.end());
    fs::remove_all(dir + "/oxts");
  }
  // A file with no line in timestamps.txt: left out, named.
  writeFile(dir + "/velodyne_points/data/0000000001.bin", std::string(16, '\0'));
  const RawDrive drive(dir);
  EXPECT_EQ(drive.velodyne().size(), 1u);
  EXPECT_EQ(drive.frameWarnings(),
            std::vector<std::string>{dir + "/velodyne_points: frame 1 left out: a data/ file but "
                                           "no line in timestamps.txt"});
  fs::remove_all(fs::path(dir).parent_path());
}

// ---------------------------------------------------------------------------- timeline
TEST(KittiDriveTimeline, MergesSensorsInTimeOrderWithinTheWindow) {
  const std::string dir = makeTempDir("kitti_timeline") + "/2011_09_26_drive_0002_sync";
  // OXTS at 0.0, 0.1, 0.2, 0.3 s; velodyne at 0.05, 0.1 (tie with OXTS), 0.25 s.
  std::string oxts_stamps;
  for (int i = 0; i < 4; ++i) {
    char name[64];
    std::snprintf(name, sizeof(name), "/oxts/data/%010d.txt", i);
    writeFile(dir + name, std::string(kLine0001Frame0) + "\n");
    oxts_stamps += "2011-09-26 13:02:25." + std::to_string(i) + "00000000\n";
  }
  writeFile(dir + "/oxts/timestamps.txt", oxts_stamps);
  for (int i = 0; i < 3; ++i) {
    char name[64];
    std::snprintf(name, sizeof(name), "/velodyne_points/data/%010d.bin", i);
    writeFile(dir + name, std::string(16, '\0'));
  }
  writeFile(dir + "/velodyne_points/timestamps.txt",
            "2011-09-26 13:02:25.05\n2011-09-26 13:02:25.1\n2011-09-26 13:02:25.25\n");
  const RawDrive drive(dir);
  EXPECT_FALSE(drive.hasCalibration());
  auto events = buildDriveTimeline(drive, TimelineOptions());
  ASSERT_EQ(events.size(), 7u);
  const std::vector<std::pair<DriveSensor, std::size_t>> expected = {
      {DriveSensor::kOxts, 0},     {DriveSensor::kVelodyne, 0}, {DriveSensor::kOxts, 1},
      {DriveSensor::kVelodyne, 1}, {DriveSensor::kOxts, 2},     {DriveSensor::kVelodyne, 2},
      {DriveSensor::kOxts, 3}};
  for (std::size_t i = 0; i < events.size(); ++i) {
    EXPECT_EQ(events[i].sensor, expected[i].first) << i;
    EXPECT_EQ(events[i].frame, expected[i].second) << i;
  }
  // Window [0.1, 0.25): OXTS 1, 2 and velodyne 1.
  TimelineOptions window;
  window.start_offset_s = 0.1;
  window.duration_s = 0.15;
  events = buildDriveTimeline(drive, window);
  ASSERT_EQ(events.size(), 3u);
  EXPECT_EQ(events[0].frame, 1u);
  EXPECT_EQ(events[1].sensor, DriveSensor::kVelodyne);
  EXPECT_EQ(events[2].frame, 2u);
  window.velodyne = false;
  EXPECT_EQ(buildDriveTimeline(drive, window).size(), 2u);
  window.start_offset_s = -1;
  EXPECT_THROW(buildDriveTimeline(drive, window), std::invalid_argument);
  fs::remove_all(fs::path(dir).parent_path());
}

TEST(KittiTimestamps, FormatIsTheInverseOfParse) {
  const std::int64_t stamp = parseKittiTimestampNs("2011-09-26 13:02:25.964389445");
  EXPECT_EQ(formatKittiTimestamp(stamp), "2011-09-26 13:02:25.964389445");
  const std::int64_t leap = parseKittiTimestampNs("2012-02-29 23:59:59.999999999");
  EXPECT_EQ(formatKittiTimestamp(leap), "2012-02-29 23:59:59.999999999");
  EXPECT_EQ(formatKittiTimestamp(leap + 1), "2012-03-01 00:00:00.000000000");
  EXPECT_EQ(formatKittiTimestamp(-1), "1969-12-31 23:59:59.999999999");
}
}  // namespace
}  // namespace kitti
}  // namespace inekf_semantic_mapping
