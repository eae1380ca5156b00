// Bad values in KITTI files and pose files (found by fault injection): each is refused with an
// error that names the file (and line) and the field, never read as a silently wrong value.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/kitti/drive_timeline.h"
#include "inekf_semantic_mapping/kitti/errors.h"
#include "inekf_semantic_mapping/kitti/oxts.h"
#include "inekf_semantic_mapping/kitti/poses.h"
#include "inekf_semantic_mapping/kitti/timestamps.h"
#include "inekf_semantic_mapping/mapping/offline_mapping.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace {

// The message of what `call` throws, or "no error".
template <typename Call>
std::string errorOf(Call call) {
  try {
    call();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "no error";
}

void expectMentions(const std::string& message, std::initializer_list<const char*> parts) {
  for (const char* part : parts) {
    EXPECT_NE(message.find(part), std::string::npos) << "'" << part << "' not in: " << message;
  }
}

std::string oxtsLine(const std::string& lat) {
  return lat +
         " 8.4 116.4 0.03 0.01 0.9 1.0 2.0 3.0 0.1 0.0 0.1 0.2 9.8 0.1 0.2 9.8 0.01 0.02 "
         "0.03 0.01 0.02 0.03 0.5 0.1 4 9 4 4 4";
}

TEST(InputValidation, OxtsLatitudeBeyondThePoles) {
  EXPECT_NO_THROW(kitti::parseOxtsLine(oxtsLine("49.0"), "f.txt", 1));
  expectMentions(errorOf([] { kitti::parseOxtsLine(oxtsLine("270"), "f.txt", 3); }),
                 {"f.txt:3", "lat"});
  // At a pole the Mercator y is infinite (-90: log(tan(0))): refused as well.
  expectMentions(errorOf([] { kitti::parseOxtsLine(oxtsLine("-90"), "f.txt", 4); }),
                 {"f.txt:4", "lat"});
  expectMentions(errorOf([] { kitti::parseOxtsLine(oxtsLine("90.0"), "f.txt", 5); }),
                 {"f.txt:5", "lat"});
}

// The longitude and altitude have their ranges too (|lon| <= 180, |alt| <= 1e5 m).
TEST(InputValidation, OxtsLongitudeAndAltitudeOutOfRange) {
  const std::string rest =
      " 0.03 0.01 0.9 1.0 2.0 3.0 0.1 0.0 0.1 0.2 9.8 0.1 0.2 9.8 0.01 0.02 0.03 0.01 0.02 0.03 "
      "0.5 "
      "0.1 4 9 4 4 4";
  EXPECT_NO_THROW(kitti::parseOxtsLine("49.0 -180.0 99999.0" + rest, "f.txt", 1));
  expectMentions(errorOf([&] { kitti::parseOxtsLine("49.0 181.0 116.4" + rest, "f.txt", 2); }),
                 {"f.txt:2", "lat/lon/alt out of range"});
  expectMentions(errorOf([&] { kitti::parseOxtsLine("49.0 8.4 -200000" + rest, "f.txt", 3); }),
                 {"f.txt:3", "lat/lon/alt out of range"});
}

TEST(InputValidation, TimestampsMustBeRealCalendarDates) {
  EXPECT_NO_THROW(kitti::parseKittiTimestampNs("2012-02-29 10:00:00.5"));  // leap year
  expectMentions(errorOf([] { kitti::parseKittiTimestampNs("2011-02-31 10:00:00"); }),
                 {"2011-02-31", "does not exist"});
  expectMentions(errorOf([] { kitti::parseKittiTimestampNs("2011-02-29 10:00:00"); }),
                 {"does not exist"});
  expectMentions(errorOf([] { kitti::parseKittiTimestampNs("1500-01-01 00:00:00"); }), {"year"});
  expectMentions(errorOf([] { kitti::parseKittiTimestampNs("2300-01-01 00:00:00"); }), {"year"});
}

class CalibrationFiles : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = test::makeTempDir("calib_validation"); }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& text) {
    std::ofstream(dir_ + "/" + name) << text;
    return dir_ + "/" + name;
  }
  std::string dir_;
};

constexpr char kOdometryCalib[] =
    "P0: 700 0 600 0 0 700 180 0 0 0 1 0\n"
    "P1: 700 0 600 -380 0 700 180 0 0 0 1 0\n"
    "P2: 700 0 600 45 0 700 180 0 0 0 1 0\n"
    "P3: 700 0 600 -330 0 700 180 0 0 0 1 0\n";

TEST_F(CalibrationFiles, NonFiniteValuesAndNonRotationsAreRefused) {
  EXPECT_NO_THROW(kitti::readObjectCalibration(
      write("good.txt", std::string(kOdometryCalib) + "Tr: 0 -1 0 0.1 0 0 -1 -0.2 1 0 0 -0.3\n")));
  expectMentions(
      errorOf([&] {
        kitti::readObjectCalibration(
            write("nan.txt", std::string(kOdometryCalib) + "Tr: 0 -1 0 nan 0 0 -1 0 1 0 0 0\n"));
      }),
      {"nan.txt:5", "Tr", "not finite"});
  expectMentions(errorOf([&] {
                   kitti::readObjectCalibration(write(
                       "zero.txt", std::string(kOdometryCalib) + "Tr: 0 0 0 0 0 0 0 0 0 0 0 0\n"));
                 }),
                 {"zero.txt", "'Tr' is not a rotation"});
  // Orthonormal but a reflection (det -1): no rotation either, never turned into one.
  expectMentions(
      errorOf([&] {
        kitti::readObjectCalibration(
            write("mirror.txt", std::string(kOdometryCalib) + "Tr: 0 -1 0 0 0 0 -1 0 -1 0 0 0\n"));
      }),
      {"mirror.txt", "'Tr' is not a rotation"});
  std::filesystem::create_directories(dir_ + "/a_directory");
  expectMentions(errorOf([&] { kitti::readObjectCalibration(dir_ + "/a_directory"); }),
                 {"a_directory", "is a directory"});
}

TEST_F(CalibrationFiles, RectifiedImageSizeMustBeAnImageSize) {
  write("calib_imu_to_velo.txt", "R: 1 0 0 0 1 0 0 0 1\nT: 0 0 0\n");
  write("calib_velo_to_cam.txt", "R: 0 -1 0 0 0 -1 1 0 0\nT: 0 0 0\n");
  const std::string camera =
      "S_00: 1392 512\nK_00: 700 0 600 0 700 180 0 0 1\nD_00: 0 0 0 0 0\n"
      "R_00: 1 0 0 0 1 0 0 0 1\nT_00: 0 0 0\nR_rect_00: 1 0 0 0 1 0 0 0 1\n"
      "P_rect_00: 700 0 600 0 0 700 180 0 0 0 1 0\n";
  write("calib_cam_to_cam.txt", camera + "S_rect_00: 1242 375\n");
  EXPECT_NO_THROW(kitti::readRawCalibration(dir_));
  // A camera the file lacks is named with the file's path (it said "calib_cam_to_cam.txt").
  const std::string missing = errorOf([&] { kitti::readRawCalibration(dir_).projection(2); });
  EXPECT_NE(missing.find(dir_ + "/calib_cam_to_cam.txt: camera 2 is not there (no P_rect_02 line)"),
            std::string::npos)
      << missing;
  write("calib_cam_to_cam.txt", camera + "S_rect_00: 1e30 375\n");
  expectMentions(errorOf([&] { kitti::readRawCalibration(dir_); }),
                 {"calib_cam_to_cam.txt", "S_rect_00"});
  write("calib_cam_to_cam.txt", camera + "S_rect_00: 0 375\n");
  expectMentions(errorOf([&] { kitti::readRawCalibration(dir_); }),
                 {"calib_cam_to_cam.txt", "S_rect_00"});
}

// Found by review: a zero focal length made the camera's tf NaN in the bag and put every point
// at the principal point; an R_rect that is no rotation turned every camera without a word.
TEST_F(CalibrationFiles, CameraProjectionsAndRectifyingRotationsMustBeThat) {
  write("calib_imu_to_velo.txt", "R: 1 0 0 0 1 0 0 0 1\nT: 0 0 0\n");
  write("calib_velo_to_cam.txt", "R: 0 -1 0 0 0 -1 1 0 0\nT: 0 0 0\n");
  const std::string head =
      "S_00: 1392 512\nK_00: 700 0 600 0 700 180 0 0 1\nD_00: 0 0 0 0 0\n"
      "R_00: 1 0 0 0 1 0 0 0 1\nT_00: 0 0 0\nS_rect_00: 1242 375\n";
  // calib_cam_to_cam.txt with this R_rect_00 (line 7) and P_rect_00 (line 8): the error read.
  const auto rectifiedError = [&](const std::string& rect, const std::string& projection) {
    write("calib_cam_to_cam.txt",
          head + "R_rect_00: " + rect + "\n" + "P_rect_00: " + projection + "\n");
    return errorOf([&] { kitti::readRawCalibration(dir_); });
  };
  const std::string identity = "1 0 0 0 1 0 0 0 1", camera = "700 0 600 0 0 700 180 0 0 0 1 0";
  expectMentions(rectifiedError(identity, "0 0 600 0 0 0 180 0 0 0 1 0"),
                 {"calib_cam_to_cam.txt:8", "P_rect_00", "not a camera projection"});
  expectMentions(rectifiedError("5 0 0 0 1 0 0 0 1", camera),
                 {"calib_cam_to_cam.txt:7", "R_rect_00", "not a rotation"});
  expectMentions(errorOf([&] {
                   kitti::readObjectCalibration(write(
                       "r0.txt", std::string(kOdometryCalib) + "R0_rect: 3 0 0 0 1 0 0 0 1\n" +
                                     "Tr_velo_to_cam: 0 -1 0 0 0 0 -1 0 1 0 0 0\n"));
                 }),
                 {"r0.txt:5", "R0_rect", "not a rotation"});
  // A reflection as R_rect, and a projection whose third row does not give the depth.
  expectMentions(rectifiedError("-1 0 0 0 1 0 0 0 1", camera),
                 {"calib_cam_to_cam.txt:7", "R_rect_00", "not a rotation"});
  expectMentions(rectifiedError(identity, "700 0 600 0 0 700 180 0 0 0 0 1"),
                 {"calib_cam_to_cam.txt:8", "P_rect_00", "not a camera projection"});
  expectMentions(errorOf([&] {
                   kitti::readObjectCalibration(write("p2.txt",
                                                      "P0: 700 0 600 0 0 700 180 0 0 0 1 0\n"
                                                      "P1: 700 0 600 0 0 700 180 0 0 0 1 0\n"
                                                      "P2: 0 0 600 45 0 0 180 0 0 0 1 0\n"
                                                      "P3: 700 0 600 0 0 700 180 0 0 0 1 0\n"
                                                      "Tr: 0 -1 0 0 0 0 -1 0 1 0 0 0\n"));
                 }),
                 {"p2.txt:3", "'P2' is not a camera projection"});
}

TEST_F(CalibrationFiles, PosesWithExtraNumbersOrNoRotationAreRefused) {
  EXPECT_EQ(kitti::readKittiPoses(write("ok.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n")).size(), 1u);
  expectMentions(
      errorOf([&] { kitti::readKittiPoses(write("extra.txt", "1 0 0 0 0 1 0 0 0 0 1 0 7\n")); }),
      {"extra.txt:1", "more than 12"});
  expectMentions(errorOf([&] {
                   kitti::readKittiPoses(
                       write("zero.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n0 0 0 0 0 0 0 0 0 0 0 0\n"));
                 }),
                 {"zero.txt:2", "not a rotation"});
  // A reflection, and a matrix 1 % off a rotation (beyond the files' printing precision).
  expectMentions(
      errorOf([&] { kitti::readKittiPoses(write("mirror.txt", "-1 0 0 0 0 1 0 0 0 0 1 0\n")); }),
      {"mirror.txt:1", "not a rotation"});
  expectMentions(
      errorOf([&] { kitti::readKittiPoses(write("scaled.txt", "1.01 0 0 0 0 1 0 0 0 0 1 0\n")); }),
      {"scaled.txt:1", "not a rotation"});
  // Lines of blanks only (a CRLF file's last line) are no poses, not errors.
  EXPECT_EQ(kitti::readKittiPoses(write("blank.txt",
                                        "1 0 0 0 0 1 0 0 0 0 1 0\r\n \t\r\n"
                                        "1 0 0 1 0 1 0 0 0 0 1 0\r\n\r\n"))
                .size(),
            2u);
  // Found by review: "1.0abc" was read as 1.0 (and the rest as the next values), "nan" as
  // "got 0 numbers", and a folder as an empty file of 0 poses.
  expectMentions(
      errorOf([&] { kitti::readKittiPoses(write("junk.txt", "1 0 0 0 0 1.0abc 0 0 0 0 1 0\n")); }),
      {"junk.txt:1", "value 6 '1.0abc' is not a number"});
  expectMentions(
      errorOf([&] { kitti::readKittiPoses(write("nan.txt", "1 0 0 nan 0 1 0 0 0 0 1 0\n")); }),
      {"nan.txt:1", "non-finite"});
  expectMentions(errorOf([&] { kitti::readKittiPoses(dir_); }), {dir_.c_str(), "is a directory"});
}

// A sequence of one 300-point scan: the errors of the map insertion name the file to blame.
TEST_F(CalibrationFiles, MappingErrorsNameThePosesOrTheLabelFile) {
  std::filesystem::create_directories(dir_ + "/velodyne");
  std::filesystem::create_directories(dir_ + "/labels");
  std::vector<float> xyzi;
  std::vector<std::uint32_t> labels;
  for (int i = 0; i < 300; ++i) {
    xyzi.insert(xyzi.end(), {5.0f + 0.1f * i, 1.0f, -1.0f, 0.5f});
    labels.push_back(1000u + static_cast<std::uint32_t>(i));  // 300 distinct classes
  }
  std::ofstream(dir_ + "/velodyne/000000.bin", std::ios::binary)
      .write(reinterpret_cast<const char*>(xyzi.data()), xyzi.size() * sizeof(float));
  std::ofstream(dir_ + "/labels/000000.label", std::ios::binary)
      .write(reinterpret_cast<const char*>(labels.data()), labels.size() * sizeof(std::uint32_t));
  mapping::OfflineSequence sequence;
  sequence.scans_dir = dir_ + "/velodyne";
  sequence.calib_path =
      write("calib.txt", std::string(kOdometryCalib) + "Tr: 0 -1 0 0 0 0 -1 0 1 0 0 0\n");
  mapping::SemanticMappingConfig config;
  config.class_set = mapping::MapClassSet::kSemanticKitti;
  // A pose 10,000 km away (a wrong poses file): outside the octree's +-6.5 km at 0.2 m.
  sequence.poses_path = write("far.txt", "1 0 0 1e7 0 1 0 0 0 0 1 0\n");
  {
    mapping::SemanticMappingSession session(config);
    expectMentions(errorOf([&] { mapping::mapSequence(sequence, &session, nullptr, nullptr); }),
                   {"far.txt", "frame 000000", "outside the map's range"});
  }
  // More distinct label ids than a map holds classes: not a SemanticKITTI .label file.
  sequence.poses_path = write("ok.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n");
  sequence.labels_dir = dir_ + "/labels";
  mapping::SemanticMappingSession session(config);
  expectMentions(errorOf([&] { mapping::mapSequence(sequence, &session, nullptr, nullptr); }),
                 {"000000.label", "at most 255 classes"});
}

}  // namespace
}  // namespace inekf_semantic_mapping
