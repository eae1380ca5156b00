// make_camera_labels on a small SemanticKITTI-layout sequence written here: which lidar point's
// class lands on which pixel of each camera (nearest wins, hidden points and points behind the
// camera label nothing, the instance bits are dropped, the right camera sees with its own
// parallax), which frames and files it writes, and its errors on bad input.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "test_data.h"

namespace fs = std::filesystem;

namespace {

template <typename T>
void writeBinary(const fs::path& path, const std::vector<T>& values) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(values.data()),
            static_cast<std::streamsize>(values.size() * sizeof(T)));
}

std::string readBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// Camera 2: f = 100 px, principal point (100, 50), a 200 x 100 image; camera 3 the same 0.54 m
// to its right. Tr: x_cam = -y_velo, y_cam = -z_velo, z_cam = x_velo.
constexpr char kCalib[] =
    "P0: 100 0 100 0 0 100 50 0 0 0 1 0\n"
    "P1: 100 0 100 -54 0 100 50 0 0 0 1 0\n"
    "P2: 100 0 100 0 0 100 50 0 0 0 1 0\n"
    "P3: 100 0 100 -54 0 100 50 0 0 0 1 0\n"
    "Tr: 0 -1 0 0 0 0 -1 0 1 0 0 0\n";

// Velodyne points (x forward, y left, z up) and their SemanticKITTI labels; camera 2's pixel of
// each is in the comment.
const std::vector<float> kScan = {
    10,  0,      0,     0,  // A road, (100, 50)
    20,  0,      0,     0,  // B sidewalk, (100, 50) behind A
    10,  2,      1,     0,  // C building, (80, 40)
    5,   0.5f,   -0.5f, 0,  // D fence, (90, 60)
    20,  1.6f,   -2,    0,  // E vegetation, (92, 60): hidden by D's depth beside it
    8,   -2,     0,     0,  // F unlabelled, (125, 50)
    9,   -2.25f, 0,     0,  // G terrain, (125, 50) behind F
    -10, 0,      0,     0,  // H car, behind the camera
};
const std::vector<std::uint32_t> kLabels = {40u | (3u << 16), 48, 50, 51, 70, 0, 72, 10};

class MakeCameraLabelsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = inekf_semantic_mapping::test::makeTempDir("make_camera_labels");
    seq_ = fs::path(dir_) / "seq";
    out_ = fs::path(dir_) / "out" / "sequences" / "01";
    for (const char* sub : {"velodyne", "labels", "image_2", "image_3"})
      fs::create_directories(seq_ / sub);
    std::ofstream(seq_ / "calib.txt") << kCalib;
    std::ofstream(seq_ / "poses.txt") << "1 0 0 0 0 1 0 0 0 0 1 0\n";
    std::ofstream(seq_ / "times.txt") << "0.0\n0.1\n0.2\n";
    const cv::Mat image(100, 200, CV_8UC3, cv::Scalar(40, 90, 160));
    for (const char* frame : {"000000", "000001", "000002"}) {
      writeBinary(seq_ / "velodyne" / (std::string(frame) + ".bin"), kScan);
      writeBinary(seq_ / "labels" / (std::string(frame) + ".label"), kLabels);
      cv::imwrite((seq_ / "image_2" / (std::string(frame) + ".png")).string(), image);
    }
    cv::imwrite((seq_ / "image_3" / "000000.png").string(), image);  // frame 0 only
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::pair<int, std::string> makeLabels(const std::string& args) const {
    return inekf_semantic_mapping::test::runCommand(std::string(MAKE_CAMERA_LABELS_PATH) +
                                                    " --sequence " + seq_.string() + " --output " +
                                                    out_.string() + " " + args);
  }
  fs::path labelPath(int camera, const std::string& frame) const {
    return out_ / ("labels_" + std::to_string(camera)) / (frame + ".png");
  }
  cv::Mat labels(int camera, const std::string& frame) const {
    return cv::imread(labelPath(camera, frame).string(), cv::IMREAD_UNCHANGED);
  }

  std::string dir_;
  fs::path seq_, out_;
};

TEST_F(MakeCameraLabelsTest, TheNearestVisiblePointLabelsItsPixelInEachCamera) {
  const auto [status, output] = makeLabels("");
  ASSERT_EQ(status, 0) << output;
  const cv::Mat left = labels(2, "000000");
  ASSERT_EQ(left.type(), CV_16UC1);
  ASSERT_EQ(left.size(), cv::Size(200, 100));
  EXPECT_EQ(left.at<std::uint16_t>(50, 100), 40);  // A: its class without the instance bits
  EXPECT_EQ(left.at<std::uint16_t>(40, 80), 50);   // C
  EXPECT_EQ(left.at<std::uint16_t>(60, 90), 51);   // D
  EXPECT_EQ(left.at<std::uint16_t>(60, 92), 0);    // E: the camera cannot see it
  EXPECT_EQ(left.at<std::uint16_t>(50, 125), 0);   // F, unlabelled, hides G
  EXPECT_EQ(cv::countNonZero(left), 3);            // B behind A, H behind the camera

  // The right camera sees A 5.4 px to the left and B, no longer behind A, beside it: too deep
  // beside A's depth to be seen.
  const cv::Mat right = labels(3, "000000");
  ASSERT_EQ(right.type(), CV_16UC1);
  EXPECT_EQ(right.at<std::uint16_t>(50, 95), 40);
  EXPECT_EQ(right.at<std::uint16_t>(50, 97), 0);
  EXPECT_EQ(right.at<std::uint16_t>(50, 100), 0);

  EXPECT_EQ(readBytes(out_ / "image_2" / "000000.png"), readBytes(seq_ / "image_2" / "000000.png"));
  EXPECT_EQ(readBytes(out_ / "calib.txt"), kCalib);
  EXPECT_TRUE(fs::exists(out_ / "poses.txt"));
  EXPECT_TRUE(fs::exists(out_ / "times.txt"));
}

TEST_F(MakeCameraLabelsTest, EveryAndMaxFramesPickFramesAndAMissingRightImageIsSaid) {
  const auto [status, output] = makeLabels("--every 2");
  ASSERT_EQ(status, 0) << output;
  EXPECT_FALSE(labels(2, "000000").empty());
  EXPECT_FALSE(fs::exists(labelPath(2, "000001")));
  EXPECT_FALSE(labels(2, "000002").empty());
  EXPECT_FALSE(fs::exists(labelPath(3, "000002")));
  EXPECT_NE(output.find("1 frames have no image_3/<frame>.png"), std::string::npos) << output;
  EXPECT_NE(output.find("3 label images"), std::string::npos) << output;

  fs::remove_all(out_);
  const auto [status_one, output_one] = makeLabels("--max-frames 1 --cameras 3");
  ASSERT_EQ(status_one, 0) << output_one;
  EXPECT_FALSE(labels(3, "000000").empty());
  EXPECT_FALSE(fs::exists(out_ / "labels_2"));
  EXPECT_FALSE(fs::exists(labelPath(3, "000001")));
}

TEST_F(MakeCameraLabelsTest, BadInputIsNamed) {
  writeBinary(seq_ / "labels" / "000001.label", std::vector<std::uint32_t>{40, 40});
  const auto [status, output] = makeLabels("");
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find("000001.label has 2 labels for the 8 points"), std::string::npos) << output;

  const auto [usage_status, usage] = makeLabels("--cameras 4");
  EXPECT_EQ(usage_status, 2) << usage;
  EXPECT_NE(usage.find("--cameras"), std::string::npos) << usage;
  for (const char* list : {"2,", ",2", "2,,3"}) {  // "2," was taken as 2
    const auto [comma_status, comma] = makeLabels(std::string("--cameras ") + list);
    EXPECT_EQ(comma_status, 2) << list << ": " << comma;
  }

  // A failed run leaves no output folder (it left the frames before the bad one, and poses for
  // frames it had no images of, for a training run to read).
  EXPECT_FALSE(fs::exists(out_));
  EXPECT_FALSE(fs::exists(out_.string() + ".partial"));

  fs::remove(seq_ / "calib.txt");
  const auto [calib_status, calib] = makeLabels("");
  EXPECT_EQ(calib_status, 1) << calib;
  EXPECT_NE(calib.find("calib.txt"), std::string::npos) << calib;
}

// Images the calibration is not of: labelled through it anyway, the labels landed in the wrong
// pixels (a resized image), or a 16-bit image went into the training set, with exit status 0.
TEST_F(MakeCameraLabelsTest, ImagesNotOfTheCalibratedCameraAreRefused) {
  const cv::Mat small(50, 100, CV_8UC3, cv::Scalar(40, 90, 160));
  cv::imwrite((seq_ / "image_2" / "000001.png").string(), small);
  const auto [status, output] = makeLabels("--cameras 2");
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find("000001.png: 100x50, but the calibration's principal point (100, 50)"),
            std::string::npos)
      << output;
  EXPECT_FALSE(fs::exists(out_));

  const cv::Mat deep(100, 200, CV_16UC3, cv::Scalar(4000, 9000, 16000));
  cv::imwrite((seq_ / "image_2" / "000001.png").string(), deep);
  const auto [deep_status, deep_output] = makeLabels("--cameras 2");
  EXPECT_EQ(deep_status, 1) << deep_output;
  EXPECT_NE(deep_output.find("000001.png: 16-bit image"), std::string::npos) << deep_output;

  // The output folder must not be the sequence itself (its calib.txt and poses were copied onto
  // themselves).
  const auto [same_status, same] = inekf_semantic_mapping::test::runCommand(
      std::string(MAKE_CAMERA_LABELS_PATH) + " --sequence " + seq_.string() + " --output " +
      seq_.string());
  EXPECT_NE(same_status, 0) << same;
  EXPECT_NE(same.find("is an input"), std::string::npos) << same;
}

// A second run into the folder of a first replaces it whole; a folder it did not write is never
// replaced (a user's folder, with the sequence in it, was deleted), and "OUT/" is OUT.
TEST_F(MakeCameraLabelsTest, ASecondRunReplacesTheFirstsFolderAndNoOther) {
  ASSERT_EQ(makeLabels("").first, 0);
  ASSERT_TRUE(fs::exists(labelPath(3, "000000")));
  const auto [status, output] = makeLabels("--cameras 2 --max-frames 1");
  ASSERT_EQ(status, 0) << output;
  EXPECT_TRUE(fs::exists(labelPath(2, "000000")));
  EXPECT_FALSE(fs::exists(labelPath(2, "000001")));  // of the first run
  EXPECT_FALSE(fs::exists(labelPath(3, "000000")));
  EXPECT_FALSE(fs::exists(out_.string() + ".partial"));

  const auto runInto = [&](const std::string& folder) {
    return inekf_semantic_mapping::test::runCommand(std::string(MAKE_CAMERA_LABELS_PATH) +
                                                    " --sequence " + seq_.string() +
                                                    " --cameras 2 --output " + folder);
  };
  std::ofstream(fs::path(dir_) / "notes.txt") << "mine";
  const auto [parent_status, parent] = runInto(dir_);  // holds the sequence and notes.txt
  EXPECT_NE(parent_status, 0) << parent;
  EXPECT_NE(parent.find("holds the input sequence"), std::string::npos) << parent;
  EXPECT_TRUE(fs::exists(seq_ / "calib.txt"));
  EXPECT_TRUE(fs::exists(fs::path(dir_) / "notes.txt"));
  const fs::path users = fs::path(dir_) / "users_folder";
  fs::create_directories(users);
  std::ofstream(users / "keep.txt") << "mine";
  const auto [users_status, users_output] = runInto(users.string());
  EXPECT_NE(users_status, 0) << users_output;
  EXPECT_NE(users_output.find("is not a make_camera_labels output"), std::string::npos)
      << users_output;
  EXPECT_TRUE(fs::exists(users / "keep.txt"));
  const auto [slash_status, slash] = runInto((fs::path(dir_) / "fresh").string() + "/");
  EXPECT_EQ(slash_status, 0) << slash;
  EXPECT_TRUE(fs::exists(fs::path(dir_) / "fresh" / "labels_2" / "000000.png"));
  EXPECT_FALSE(fs::exists(fs::path(dir_) / "fresh" / ".partial"));

  // An earlier version's folder (no marker file, only this tool's files) is still replaced.
  fs::remove(out_ / ".make_camera_labels");
  EXPECT_EQ(runInto(out_.string()).first, 0);
  // Through a link, the folder linked to is replaced (the link moved, the old labels stayed).
  fs::create_symlink(out_, fs::path(dir_) / "link");
  fs::remove(labelPath(2, "000002"));
  EXPECT_EQ(runInto((fs::path(dir_) / "link").string()).first, 0);
  EXPECT_TRUE(fs::is_symlink(fs::path(dir_) / "link"));
  EXPECT_TRUE(fs::exists(labelPath(2, "000002")));
  // A folder inside the sequence: refused on every run, new or not.
  const auto [inside_status, inside] = runInto((seq_ / "my_labels").string());
  EXPECT_NE(inside_status, 0) << inside;
  EXPECT_NE(inside.find("is in the input folder"), std::string::npos) << inside;
}

}  // namespace
