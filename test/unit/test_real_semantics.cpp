// The default camera labelling path on real KITTI data (issue 12): the Cityscapes ENet from
// ../shared with its built-in card, filterLabels at its defaults and the occlusion test, on the
// 20 SemanticKITTI frames of ../shared (sequences 05 and 08), scored at the lidar points against
// the human labels mapped to Cityscapes. The thresholds are the figures measured with
// evaluate_semantics (README) less a margin for numeric differences between OpenCV builds.
#include <gtest/gtest.h>

#include <chrono>
#include <iostream>
#include <string>

#include "inekf_semantic_mapping/perception/model_card.h"
#include "inekf_semantic_mapping/perception/segmenter.h"
#include "inekf_semantic_mapping/perception/semantic_evaluation.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace perception {
namespace {

constexpr char kEnetModel[] = "models/enet-cityscapes/enet-model.net";
constexpr char kSequences[] = "data/semantickitti/sequences";

PointLabelScore scoreSequence(Segmenter* segmenter, const std::string& dir,
                              const PointLabellingOptions& options) {
  PointLabelScore score;
  for (const std::string& name : listSemanticKittiFrames(dir)) {
    const SemanticKittiFrame frame = readSemanticKittiFrame(dir, name);
    const kitti::CameraProjection camera =
        readSemanticKittiCamera(dir, frame.image.cols, frame.image.rows);
    const Segmentation segmentation = segmenter->segment(frame.image, camera.P_rect(0, 0));
    const PointProjector projector(camera.P_rect, camera.R_rect, camera.T_cam0_velo,
                                   frame.image.cols, frame.image.rows);
    ProjectedPoints projected;
    const std::vector<std::uint32_t> labels =
        labelScanPoints(segmentation, projector, frame.scan, options, &projected);
    for (std::size_t i = 0; i < labels.size(); ++i) {
      if (projected.valid[i]) score.add(frame.truth[i], labels[i]);
    }
  }
  return score;
}

struct Expectation {
  const char* sequence;
  double min_accuracy;  // over the points that got a camera label
  double min_coverage;  // points with a camera label / scored points in the image
};

TEST(RealSemantics, DefaultEnetLabellingPathMeetsAccuracyOnSemanticKitti) {
  ISM_REQUIRE_SHARED(kEnetModel);
  ISM_REQUIRE_SHARED(kSequences);
  const std::string model = test::sharedPath(kEnetModel);
  Segmenter segmenter(model, defaultModelCardFor(model));
  const PointLabellingOptions options;  // the defaults the mapping uses

  // Measured: 05 accuracy 0.903 coverage 0.773; 08 accuracy 0.814 coverage 0.742. Margins: 0.03
  // on accuracy, 0.05 on coverage.
  const Expectation expectations[] = {{"05", 0.87, 0.72}, {"08", 0.78, 0.69}};
  PointLabelScore total;
  for (const Expectation& expected : expectations) {
    const auto start = std::chrono::steady_clock::now();
    const PointLabelScore score =
        scoreSequence(&segmenter, test::sharedPath(kSequences) + "/" + expected.sequence, options);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::cout << "sequence " << expected.sequence << ": accuracy " << score.accuracy()
              << ", coverage " << score.coverage() << ", mIoU " << score.meanIoU() << " ("
              << score.labelled() << " of " << score.scored() << " points labelled, " << seconds
              << " s)\n";
    EXPECT_GT(score.scored(), 100000u) << expected.sequence;
    EXPECT_GE(score.accuracy(), expected.min_accuracy) << expected.sequence;
    EXPECT_GE(score.coverage(), expected.min_coverage) << expected.sequence;
    total.merge(score);
  }
  EXPECT_GE(total.accuracy(), 0.80);
}

}  // namespace
}  // namespace perception
}  // namespace inekf_semantic_mapping
