// The default U-Net's accuracy target (mIoU >= 0.85 on held-out synthetic frames),
// measured the way the pipeline uses it: the C++ Segmenter on full-size rendered images, its
// label image (at the input resolution) against the renderer's ground truth. The drives are
// generated here with seeds the model never trained on (8 was its validation seed, 13 was never
// used), so the test needs nothing from ../shared.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <vector>

#include "inekf_semantic_mapping/perception/model_card.h"
#include "inekf_semantic_mapping/perception/segmenter.h"
#include "inekf_semantic_mapping/synthetic/drive_generator.h"
#include "inekf_semantic_mapping/synthetic/label_iou.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace perception {
namespace {

namespace fs = std::filesystem;

// The target. The committed model measures 0.873 here (README; the generator and the
// dnn forward pass are deterministic), so a worse model or a broken pre/post-processing fails.
constexpr double kMinMiou = 0.85;
constexpr double kMinPixelAccuracy = 0.95;

struct HeldOutDrive {
  std::uint64_t seed;
  double duration_s;
};

TEST(UnetSyntheticAccuracy, DefaultModelReachesTargetMiouOnHeldOutDrives) {
  const std::string model = test::repoPath("models/unet_synthetic.onnx");
  if (!fs::exists(model)) GTEST_SKIP() << "models/unet_synthetic.onnx is not in the repository";
  const ModelCard card = defaultModelCardFor(model);
  Segmenter segmenter(model, card, 2);

  std::vector<bool> in_card(256, false);
  for (std::uint8_t id : card.output_label_ids) in_card[id] = true;
  synthetic::LabelIouCounter counter;
  long long ignored_truth = 0;  // pixels of classes the network does not have

  const std::string root = test::makeTempDir("unet_accuracy");
  int frames = 0;
  for (const HeldOutDrive& drive : {HeldOutDrive{8, 8.0}, HeldOutDrive{13, 10.0}}) {
    synthetic::DriveOptions options;
    options.output_dir = root + "/seed" + std::to_string(drive.seed);
    options.seed = drive.seed;
    options.duration_s = drive.duration_s;
    options.camera_rate_hz = 2.0;
    options.write_lidar = false;
    const synthetic::DriveSummary summary = synthetic::generateSyntheticDrive(options);
    ASSERT_GT(summary.images, 10) << "seed " << drive.seed;

    for (const auto& entry : fs::directory_iterator(summary.sync_dir + "/image_02/data")) {
      const cv::Mat image = cv::imread(entry.path().string(), cv::IMREAD_COLOR);
      const cv::Mat truth = cv::imread(
          summary.sync_dir + "/ground_truth/image_02_labels/" + entry.path().filename().string(),
          cv::IMREAD_UNCHANGED);
      ASSERT_FALSE(image.empty());
      ASSERT_EQ(truth.size(), image.size());
      const Segmentation result = segmenter.segment(image);
      ASSERT_EQ(result.label_ids.size(), image.size());
      for (int r = 0; r < truth.rows; ++r) {
        const auto* t = truth.ptr<std::uint8_t>(r);
        const auto* p = result.label_ids.ptr<std::uint8_t>(r);
        for (int c = 0; c < truth.cols; ++c) {
          ASSERT_TRUE(in_card[p[c]]) << "labelId " << int(p[c]) << " is not in the card";
          if (in_card[t[c]]) {
            counter.add(t[c], p[c]);
          } else {
            ++ignored_truth;
          }
        }
      }
      ++frames;
    }
  }

  const std::vector<synthetic::ClassIou> classes = counter.classes();
  for (const synthetic::ClassIou& c : classes) {
    std::printf("  labelId %2d  IoU %.3f  (%zu truth pixels)\n", c.label_id, c.iou(),
                c.true_positive + c.false_negative);
  }
  ASSERT_GE(classes.size(), 8u) << "the held-out drives should show most of the classes";
  const double miou = counter.meanIou();
  const double pixel_accuracy = static_cast<double>(counter.correct()) / counter.pairs();
  std::printf(
      "%d held-out frames, full resolution: mIoU %.4f over %zu classes, pixel accuracy "
      "%.4f (%lld pixels of classes outside the card ignored)\n",
      frames, miou, classes.size(), pixel_accuracy, ignored_truth);
  EXPECT_GE(miou, kMinMiou);
  EXPECT_GE(pixel_accuracy, kMinPixelAccuracy);
}

}  // namespace
}  // namespace perception
}  // namespace inekf_semantic_mapping
