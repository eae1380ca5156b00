// The ENet of ../shared in the Segmenter: pixel accuracy on the real Cityscapes sample, a card
// with the wrong channel count, bad images, the tiles on wide images.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "inekf_semantic_mapping/perception/cityscapes.h"
#include "inekf_semantic_mapping/perception/model_card.h"
#include "inekf_semantic_mapping/perception/segmenter.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace perception {
namespace {

namespace fs = std::filesystem;
using test::makeTempDir;
using test::repoPath;
using test::sharedPath;

constexpr char kEnetModel[] = "models/enet-cityscapes/enet-model.net";
constexpr char kCityscapesImage[] =
    "data/cityscapes/leftImg8bit/val/frankfurt/frankfurt_000000_000294_leftImg8bit.png";
constexpr char kCityscapesTrainIds[] =
    "data/cityscapes/gtFine/val/frankfurt/frankfurt_000000_000294_gtFine_labelTrainIds.png";

// Fraction of pixels with a valid trainId (not 255) where prediction and truth agree.
double pixelAccuracy(const cv::Mat& predicted_train_ids, const cv::Mat& truth_train_ids) {
  const cv::Mat valid = truth_train_ids != cityscapes::kIgnoreTrainId;
  const cv::Mat correct = (predicted_train_ids == truth_train_ids) & valid;
  return static_cast<double>(cv::countNonZero(correct)) / cv::countNonZero(valid);
}

TEST(SegmenterEnet, ReachesPixelAccuracyOnCityscapesSample) {
  ISM_REQUIRE_SHARED(kEnetModel);
  ISM_REQUIRE_SHARED(kCityscapesImage);
  const cv::Mat image = cv::imread(sharedPath(kCityscapesImage), cv::IMREAD_COLOR);
  const cv::Mat truth = cv::imread(sharedPath(kCityscapesTrainIds), cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(image.empty());
  ASSERT_EQ(truth.type(), CV_8UC1);

  Segmenter segmenter(sharedPath(kEnetModel), defaultModelCardFor(sharedPath(kEnetModel)));
  const Segmentation result = segmenter.segment(image);
  ASSERT_EQ(result.label_ids.size(), image.size());
  ASSERT_EQ(result.confidence.size(), image.size());
  ASSERT_EQ(result.confidence.type(), CV_32FC1);

  const double accuracy = pixelAccuracy(labelIdsToTrainIds(result.label_ids), truth);
  std::cout << "ENet pixel accuracy on the Cityscapes sample: " << accuracy << "\n";
  EXPECT_GE(accuracy, 0.78);

  double min_confidence = 0, max_confidence = 0;
  cv::minMaxLoc(result.confidence, &min_confidence, &max_confidence);
  // The winner of 20 classes has >= 1/20, unless "unlabeled" may not win (then only > 0).
  EXPECT_GE(min_confidence, segmenter.card().suppress_unlabeled ? 1e-9 : 1.0 / 20.0 - 1e-6);
  EXPECT_LE(max_confidence, 1.0 + 1e-6);
  // Every produced id is a real labelId.
  double max_label = 0;
  cv::minMaxLoc(result.label_ids, nullptr, &max_label);
  EXPECT_LT(max_label, cityscapes::kNumLabelIds);
}

TEST(SegmenterEnet, WrongChannelCountInCardIsRejectedNamingModelAndCard) {
  ISM_REQUIRE_SHARED(kEnetModel);
  ModelCard card = builtinEnetCityscapesCard();
  card.output_label_ids.pop_back();  // 19 instead of 20
  card.source = "my_card.yaml";
  try {
    Segmenter segmenter(sharedPath(kEnetModel), card);
    FAIL() << "a 19-channel card was accepted for a 20-channel model";
  } catch (const SegmentationError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("enet-model.net"), std::string::npos) << what;
    EXPECT_NE(what.find("my_card.yaml"), std::string::npos) << what;
    EXPECT_NE(what.find("20"), std::string::npos) << what;
  }
}

TEST(SegmenterEnet, RejectsEmptyAndNon8BitImages) {
  ISM_REQUIRE_SHARED(kEnetModel);
  Segmenter segmenter(sharedPath(kEnetModel), builtinEnetCityscapesCard());
  EXPECT_THROW(segmenter.segment(cv::Mat()), SegmentationError);
  EXPECT_THROW(segmenter.segment(cv::Mat(100, 200, CV_16UC1, cv::Scalar(0))), SegmentationError);
  EXPECT_THROW(segmenter.segment(cv::Mat(100, 200, CV_8UC2, cv::Scalar(0))), SegmentationError);
  // Gray images are accepted and come back at their own size.
  const Segmentation gray = segmenter.segment(cv::Mat(37, 124, CV_8UC1, cv::Scalar(90)));
  EXPECT_EQ(gray.label_ids.size(), cv::Size(124, 37));
}

TEST(SegmenterEnet, TilesScaleByFocalLengthAndCoverWideImages) {
  ISM_REQUIRE_SHARED(kEnetModel);
  ModelCard card = builtinEnetCityscapesCard();
  card.resize_policy = ResizePolicy::kTiles;
  card.network_focal_px = 1131.0;
  card.tile_scale = 0.0;
  card.tile_overlap = 128;
  card.tile_bottom_margin = 0;
  Segmenter segmenter(sharedPath(kEnetModel), card);
  // The focal-length ratio when the camera's is known; otherwise the least scale that fills
  // one tile.
  EXPECT_NEAR(segmenter.tileScaleFor(cv::Size(1226, 370), 707.0), 1131.0 / 707.0, 1e-12);
  EXPECT_NEAR(segmenter.tileScaleFor(cv::Size(1226, 370)), 512.0 / 370.0, 1e-12);
  EXPECT_NEAR(segmenter.tileScaleFor(cv::Size(256, 128)), 4.0, 1e-12);
  // A bottom margin leaves input rows free below the image.
  card.tile_bottom_margin = 112;
  EXPECT_NEAR(Segmenter(sharedPath(kEnetModel), card).tileScaleFor(cv::Size(1226, 370)),
              400.0 / 370.0, 1e-12);

  cv::Mat image(150, 500, CV_8UC3);
  cv::randu(image, cv::Scalar::all(0), cv::Scalar::all(255));
  const Segmentation result = segmenter.segment(image, 1131.0 / 2.5);  // 1250 x 375: 2 tiles
  ASSERT_EQ(result.label_ids.size(), image.size());
  ASSERT_EQ(result.confidence.size(), image.size());
  double min_confidence = 0, max_confidence = 0;
  cv::minMaxLoc(result.confidence, &min_confidence, &max_confidence);
  EXPECT_GT(min_confidence, 0.0);
  EXPECT_LE(max_confidence, 1.0 + 1e-6);
  // "unlabeled" never wins with suppress_unlabeled (the built-in card's choice).
  EXPECT_EQ(cv::countNonZero(result.label_ids == cityscapes::kUnlabeled), 0);
}

}  // namespace
}  // namespace perception
}  // namespace inekf_semantic_mapping
