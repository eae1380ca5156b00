// segment_image with the repository's U-Net: a label PNG of the image's size; label and
// confidence images only as PNG (a .jpg changed the ids of one pixel in ten), an overlay only in
// a format OpenCV writes, both refused before the network runs, with nothing written.
#include <gtest/gtest.h>

#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>

#include "test_data.h"

namespace fs = std::filesystem;
namespace ism = inekf_semantic_mapping;

namespace {

class SegmentImageTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = ism::test::makeTempDir("segment_image_cli");
    input_ = dir_ + "/input.png";
    cv::Mat image(96, 160, CV_8UC3);
    cv::randu(image, cv::Scalar::all(0), cv::Scalar::all(255));
    cv::imwrite(input_, image);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::pair<int, std::string> run(const std::string& outputs) const {
    return ism::test::runCommand(std::string(SEGMENT_IMAGE_PATH) + " --model " +
                                 ism::test::repoPath("models/unet_synthetic.onnx") + " --input " +
                                 input_ + " " + outputs);
  }

  std::string dir_, input_;
};

TEST_F(SegmentImageTest, WritesALabelImageOfTheInputsSize) {
  const auto [status, output] = run("--output " + dir_ + "/labels.png --confidence " + dir_ +
                                    "/confidence.png --overlay " + dir_ + "/overlay.jpg");
  ASSERT_EQ(status, 0) << output;
  const cv::Mat labels = cv::imread(dir_ + "/labels.png", cv::IMREAD_UNCHANGED);
  EXPECT_EQ(labels.type(), CV_8UC1);
  EXPECT_EQ(labels.size(), cv::Size(160, 96));
  EXPECT_TRUE(fs::exists(dir_ + "/confidence.png"));
  EXPECT_TRUE(fs::exists(dir_ + "/overlay.jpg"));  // a picture: any format
}

TEST_F(SegmentImageTest, LabelsOnlyAsPngAndOverlaysOnlyInAWritableFormat) {
  for (const std::string& outputs :
       {"--output " + dir_ + "/labels.jpg",
        "--output " + dir_ + "/labels.png --confidence " + dir_ + "/confidence.jpg",
        "--output " + dir_ + "/labels.png --overlay " + dir_ + "/overlay.xyz"}) {
    const auto [status, output] = run(outputs);
    EXPECT_EQ(status, 2) << outputs << "\n" << output;
    EXPECT_EQ(output.find("segmentation/"), std::string::npos) << "the network ran:\n" << output;
  }
  EXPECT_FALSE(fs::exists(dir_ + "/labels.jpg"));
  EXPECT_FALSE(fs::exists(dir_ + "/labels.png"));
}

}  // namespace
