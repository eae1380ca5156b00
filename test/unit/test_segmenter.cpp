// Segmenter and model cards: the committed U-Net on wide images, card parsing, palette, label
// filtering and the error paths. The ENet of ../shared: test/data/test_segmenter_data.cpp.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/dnn.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "../../src/perception/segmenter_input.h"  // private to src/perception: its steps
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

std::string writeFile(const std::string& dir, const std::string& name, const std::string& text) {
  const std::string path = dir + "/" + name;
  std::ofstream(path) << text;
  return path;
}

TEST(SegmenterUnet, CommittedModelSegmentsWideKittiSizedImagesAtInputResolution) {
  const std::string model = repoPath("models/unet_synthetic.onnx");
  if (!fs::exists(model)) GTEST_SKIP() << "models/unet_synthetic.onnx not committed yet";
  const ModelCard card = defaultModelCardFor(model);
  EXPECT_EQ(card.resize_policy, ResizePolicy::kPadToMultiple);
  Segmenter segmenter(model, card);
  cv::Mat image(375, 1242, CV_8UC3);
  cv::randu(image, cv::Scalar::all(0), cv::Scalar::all(255));
  const Segmentation result = segmenter.segment(image);
  EXPECT_EQ(result.label_ids.size(), image.size());
  // Only ids the card maps to can appear.
  for (int id = 0; id < 256; ++id) {
    const bool in_card = std::find(card.output_label_ids.begin(), card.output_label_ids.end(),
                                   id) != card.output_label_ids.end();
    if (!in_card) {
      EXPECT_EQ(cv::countNonZero(result.label_ids == id), 0) << "labelId " << id;
    }
  }
}

// A load that fails names what is wrong: a class count that does not fit is not blamed on the
// stride (the hint came with every failure of a 0 x 0 card), and a fixed input size the network
// cannot take names the card that set it.
TEST(SegmenterUnet, LoadErrorsBlameTheRightPartOfTheCard) {
  const std::string model = repoPath("models/unet_synthetic.onnx");
  if (!fs::exists(model)) GTEST_SKIP() << "models/unet_synthetic.onnx not committed yet";
  ModelCard card = defaultModelCardFor(model);
  ASSERT_EQ(card.input_width, 0);
  card.output_label_ids = {7, 8, 11};
  card.source = "three_classes.yaml";
  try {
    Segmenter segmenter(model, card);
    ADD_FAILURE() << "a 10-channel network loaded with a 3-class card";
  } catch (const SegmentationError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("outputs 10 channels"), std::string::npos) << what;
    EXPECT_EQ(what.find("stride"), std::string::npos) << what;
  }
  card = defaultModelCardFor(model);
  card.input_width = 17;  // too small for the network's four poolings, not padded
  card.input_height = 9;
  card.pad_multiple = 1;
  card.source = "fixed_size.yaml";
  try {
    Segmenter segmenter(model, card);
    ADD_FAILURE() << "the network took a 17x9 input";
  } catch (const SegmentationError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("the input size 17x9 is its card fixed_size.yaml's"), std::string::npos)
        << what;
  }
}

// A mirrored image's labels with flip_average are the mirror of the image's: both average the
// same two passes. The network alone is not mirror-symmetric, so a card whose flip_average did
// nothing on the single-pass path fails here.
TEST(SegmenterUnet, FlipAverageMakesTheSinglePassMirrorSymmetric) {
  const std::string model = repoPath("models/unet_synthetic.onnx");
  if (!fs::exists(model)) GTEST_SKIP() << "models/unet_synthetic.onnx not committed yet";
  ModelCard card = defaultModelCardFor(model);
  ASSERT_EQ(card.resize_policy, ResizePolicy::kPadToMultiple);
  card.resize_factor = 1.0;  // a 320 x 96 image is the network's input as it is: no padding
  cv::Mat image(96, 320, CV_8UC3);
  cv::randu(image, cv::Scalar::all(0), cv::Scalar::all(255));
  cv::GaussianBlur(image, image, cv::Size(9, 9), 3.0);  // regions the network labels apart
  cv::Mat mirrored_image;
  cv::flip(image, mirrored_image, 1);
  const auto asymmetric_pixels = [&](Segmenter& segmenter) {
    const Segmentation direct = segmenter.segment(image);
    const Segmentation mirrored = segmenter.segment(mirrored_image);
    cv::Mat mirrored_back;
    cv::flip(mirrored.label_ids, mirrored_back, 1);
    return cv::countNonZero(direct.label_ids != mirrored_back);
  };
  Segmenter single(model, card);
  ASSERT_GT(asymmetric_pixels(single), 0) << "the network is mirror-symmetric on this image";
  card.flip_average = true;
  Segmenter averaged(model, card);
  EXPECT_EQ(asymmetric_pixels(averaged), 0);
  const Segmentation result = averaged.segment(image);
  double min_confidence = 0.0, max_confidence = 0.0;
  cv::minMaxLoc(result.confidence, &min_confidence, &max_confidence);
  EXPECT_GT(min_confidence, 0.0);  // the winner's mean probability: in (0, 1]
  EXPECT_LE(max_confidence, 1.0 + 1e-6);
}

TEST(ModelCard, ParsesEveryField) {
  const std::string dir = makeTempDir("card_parse");
  const std::string path = writeFile(dir, "unet.yaml",
                                     "name: test_unet\n"
                                     "input: {width: 624, height: 188}\n"
                                     "resize_policy: pad_to_multiple\n"
                                     "pad_multiple: 16\n"
                                     "resize_factor: 0.5\n"
                                     "mean: [1.5, 2.5, 3.5]\n"
                                     "scale: 0.5\n"
                                     "swap_rb: false\n"
                                     "num_output_channels: 3\n"
                                     "output_label_ids: [7, 26, 23]\n");
  const ModelCard card = loadModelCard(path);
  EXPECT_EQ(card.name, "test_unet");
  EXPECT_EQ(card.input_width, 624);
  EXPECT_EQ(card.input_height, 188);
  EXPECT_EQ(card.resize_policy, ResizePolicy::kPadToMultiple);
  EXPECT_EQ(card.pad_multiple, 16);
  EXPECT_DOUBLE_EQ(card.resize_factor, 0.5);
  EXPECT_DOUBLE_EQ(card.mean[2], 3.5);
  EXPECT_DOUBLE_EQ(card.scale, 0.5);
  EXPECT_FALSE(card.swap_rb);
  EXPECT_EQ(card.output_label_ids, (std::vector<std::uint8_t>{7, 26, 23}));

  // What saveModelCard writes, loadModelCard reads back unchanged.
  const std::string saved = dir + "/saved.yaml";
  saveModelCard(card, saved);
  const ModelCard reloaded = loadModelCard(saved);
  EXPECT_EQ(reloaded.output_label_ids, card.output_label_ids);
  EXPECT_EQ(reloaded.resize_policy, card.resize_policy);
  EXPECT_EQ(reloaded.input_width, card.input_width);
  EXPECT_DOUBLE_EQ(reloaded.resize_factor, card.resize_factor);
  EXPECT_DOUBLE_EQ(reloaded.mean[0], card.mean[0]);
  EXPECT_EQ(reloaded.swap_rb, card.swap_rb);
  fs::remove_all(dir);
}

// The error message of loading `text` as a card (empty when it loads).
std::string cardError(const std::string& text) {
  const std::string dir = makeTempDir("card_error");
  const std::string path = writeFile(dir, "bad.yaml", text);
  try {
    loadModelCard(path);
  } catch (const ModelCardError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(path), std::string::npos) << "error does not name the file: " << what;
    return what;
  }
  return "";
}

TEST(ModelCard, BadCardsAreRejectedNamingTheField) {
  EXPECT_NE(cardError("input: {width: 10, height: 10}\n").find("output_label_ids"),
            std::string::npos);
  EXPECT_NE(cardError("input: {width: 10, height: 10}\nresize_policy: stretchy\n"
                      "output_label_ids: [7]\n")
                .find("stretchy"),
            std::string::npos);
  EXPECT_NE(cardError("input: {width: 10, height: 10}\noutput_label_ids: [7, 40]\n").find("40"),
            std::string::npos);
  EXPECT_NE(cardError("input: {width: 10, height: 10}\nnum_output_channels: 3\n"
                      "output_label_ids: [7, 8]\n")
                .find("num_output_channels"),
            std::string::npos);
  EXPECT_NE(cardError("resize_policy: resize\noutput_label_ids: [7]\n").find("input"),
            std::string::npos);
  // pad_to_multiple with one side only: that side was ignored without a word.
  const std::string one_side =
      "resize_policy: pad_to_multiple\ninput: {width: 640, height: 0}\noutput_label_ids: [7]\n";
  EXPECT_NE(cardError(one_side).find("'input' must have width and height both 0 (any size, "
                                     "padded to pad_multiple) or both > 0 (a fixed input size), "
                                     "not 640x0"),
            std::string::npos)
      << cardError(one_side);
  EXPECT_NE(cardError("input: {width: 10, height: 10}\nscale: abc\noutput_label_ids: [7]\n")
                .find("scale"),
            std::string::npos);
  EXPECT_NE(cardError("output_label_ids: [7\n").find("syntax"), std::string::npos);
  EXPECT_EQ(cardError("input: {width: 10, height: 10}\noutput_label_ids: [7]\n"), "");
  EXPECT_THROW(loadModelCard("/nonexistent/card.yaml"), ModelCardError);
  // Found by fault injection: fields of the wrong shape escaped as bare YAML exceptions, and a
  // 2e9 x 2e9 input was accepted.
  EXPECT_NE(cardError("input: 5\noutput_label_ids: [7]\n").find("card"), std::string::npos);
  EXPECT_NE(cardError("input: {width: 10, height: 10}\nresize_policy: [a]\noutput_label_ids: [7]\n")
                .find("card"),
            std::string::npos);
  EXPECT_NE(cardError("input: {width: 2000000000, height: 2000000000}\noutput_label_ids: [7]\n")
                .find("16384"),
            std::string::npos);
  // A misspelt key would leave its default silently in place: named with its line.
  const std::string typo =
      cardError("input: {width: 10, height: 10}\ntile_scal: 1.2\noutput_label_ids: [7]\n");
  EXPECT_NE(typo.find(":2: key 'tile_scal' is not a known key"), std::string::npos) << typo;
  EXPECT_NE(cardError("input: {width: 10, height: 10, depth: 3}\noutput_label_ids: [7]\n")
                .find("input.depth"),
            std::string::npos);
  EXPECT_NE(cardError("input: {width: 10, height: 10}\nlabel_filter: {min_conf: 0.5}\n"
                      "output_label_ids: [7]\n")
                .find("label_filter.min_conf"),
            std::string::npos);
  EXPECT_NE(cardError("input: {width: 10, height: 10}\nmean: [.nan, 0, 0]\noutput_label_ids: [7]\n")
                .find("mean"),
            std::string::npos);
  // Found by review: a mean beyond float range made every pixel one class at full confidence,
  // and a pad_multiple of 1e9 an allocation of 3e18 bytes that named neither card nor key.
  EXPECT_NE(cardError("input: {width: 10, height: 10}\nmean: [1e39, 0, 0]\noutput_label_ids: [7]\n")
                .find("mean"),
            std::string::npos);
  EXPECT_NE(cardError("resize_policy: pad_to_multiple\npad_multiple: 1000000000\n"
                      "output_label_ids: [7]\n")
                .find("pad_multiple"),
            std::string::npos);
  EXPECT_NE(cardError("input: {width: 10, height: 10}\nscale: 1e300\noutput_label_ids: [7]\n")
                .find("scale"),
            std::string::npos);
  EXPECT_EQ(cardError("input: {width: 10, height: 10}\noutput_label_ids: [7]\n"
                      "validation_miou: 0.9\n"),
            "");
}

TEST(ModelCard, DefaultCardFollowsTheModelFile) {
  const std::string dir = makeTempDir("card_default");
  writeFile(dir, "enet-model.net", "not read for the card");
  const ModelCard enet = defaultModelCardFor(dir + "/enet-model.net");
  ASSERT_EQ(enet.numOutputChannels(), 20);
  EXPECT_EQ(enet.output_label_ids[0], cityscapes::kUnlabeled);
  EXPECT_EQ(enet.output_label_ids[1], cityscapes::kRoad);  // trainId 0
  EXPECT_EQ(enet.output_label_ids[14], cityscapes::kCar);  // trainId 13
  EXPECT_EQ(enet.output_label_ids[19], cityscapes::kBicycle);
  // The KITTI-tuned fitting: undistorted tiles, colours standardized to Cityscapes.
  EXPECT_EQ(enet.resize_policy, ResizePolicy::kTiles);
  EXPECT_EQ(enet.color_normalization, ColorNormalization::kStandardize);
  EXPECT_TRUE(enet.suppress_unlabeled);

  // A model that is not there is named as such, before any card is looked for.
  try {
    defaultModelCardFor(dir + "/net.onnx");
    ADD_FAILURE() << "a card for a model that is not there";
  } catch (const ModelCardError& error) {
    EXPECT_EQ(std::string(error.what()), dir + "/net.onnx: no such model file");
  }
  writeFile(dir, "net.onnx", "not read for the card");
  try {
    defaultModelCardFor(dir + "/net.onnx");
    ADD_FAILURE() << "an .onnx without a card was given one";
  } catch (const ModelCardError& error) {
    EXPECT_NE(std::string(error.what()).find("segmentation_node's ~model_card"), std::string::npos)
        << error.what();
  }
  writeFile(dir, "net.yaml", "input: {width: 32, height: 16}\noutput_label_ids: [7, 11]\n");
  EXPECT_EQ(defaultModelCardFor(dir + "/net.onnx").numOutputChannels(), 2);
  fs::remove_all(dir);
}

TEST(Segmenter, UnknownModelFormatAndMissingFileAreClearErrors) {
  const std::string dir = makeTempDir("seg_format");
  const std::string weights = writeFile(dir, "model.pb2", "not a model");
  try {
    Segmenter segmenter(weights, builtinEnetCityscapesCard());
    FAIL() << "unknown format accepted";
  } catch (const SegmentationError& e) {
    EXPECT_NE(std::string(e.what()).find(".pb2"), std::string::npos) << e.what();
  }
  EXPECT_THROW(Segmenter(dir + "/absent.onnx", builtinEnetCityscapesCard()), SegmentationError);
  const std::string garbage = writeFile(dir, "garbage.onnx", "not a protobuf");
  EXPECT_THROW(Segmenter(garbage, builtinEnetCityscapesCard()), SegmentationError);
  fs::remove_all(dir);
}

// A one-operator ONNX model, written byte by byte (protobuf wire format): AveragePool with a
// k x k kernel and stride k over a 3-channel image of any size, so its output is k times coarser
// than its input; with a 1/255 scale its three "scores" are the pixel's B, G, R.
std::string averagePoolOnnx(int k) {
  const auto varint = [](std::uint64_t n) {
    std::string out;
    do {
      const std::uint8_t low = n & 0x7f;
      n >>= 7;
      out += static_cast<char>(n ? (low | 0x80) : low);
    } while (n);
    return out;
  };
  const auto key = [&](int field, int wire) { return varint((field << 3) | wire); };
  const auto integer = [&](int field, std::uint64_t n) { return key(field, 0) + varint(n); };
  const auto bytes = [&](int field, const std::string& b) {
    return key(field, 2) + varint(b.size()) + b;
  };
  const auto ints = [&](const std::string& name, int a, int b) {  // AttributeProto INTS
    return bytes(1, name) + integer(20, 7) + integer(8, a) + integer(8, b);
  };
  const auto value_info = [&](const std::string& name, const std::string& h, const std::string& w) {
    const std::string shape = bytes(1, integer(1, 1)) + bytes(1, integer(1, 3)) +
                              bytes(1, bytes(2, h)) + bytes(1, bytes(2, w));
    return bytes(1, name) + bytes(2, bytes(1, integer(1, 1) + bytes(2, shape)));
  };
  const std::string node = bytes(1, "x") + bytes(2, "y") + bytes(3, "pool") +
                           bytes(4, "AveragePool") + bytes(5, ints("kernel_shape", k, k)) +
                           bytes(5, ints("strides", k, k));
  const std::string graph = bytes(1, node) + bytes(2, "g") + bytes(11, value_info("x", "h", "w")) +
                            bytes(12, value_info("y", "h2", "w2"));
  return integer(1, 7) + bytes(8, bytes(1, "") + integer(2, 11)) + bytes(7, graph);
}

// A network with an output stride: its labels must land where the image is, in every resize
// policy (the single pass cropped the padding in input pixels from the coarser output: the
// labels came out shifted, or an empty crop threw from OpenCV).
TEST(Segmenter, ACoarserOutputThanInputLabelsTheImageInPlace) {
  const std::string dir = makeTempDir("coarse_output");
  const std::string model = dir + "/pool4.onnx";
  std::ofstream(model, std::ios::binary) << averagePoolOnnx(4);
  cv::Mat image(400, 1200, CV_8UC3, cv::Scalar(255, 0, 0));         // blue: "sky"
  image(cv::Rect(0, 200, 1200, 200)).setTo(cv::Scalar(0, 0, 255));  // red below: "car"
  const std::string common =
      "mean: [0, 0, 0]\nscale: 0.00392156862745098\nswap_rb: false\n"
      "num_output_channels: 3\noutput_label_ids: [23, 21, 26]\n";
  for (const std::string policy :
       {"input: {width: 0, height: 0}\nresize_policy: pad_to_multiple\npad_multiple: 64\n",
        "input: {width: 512, height: 512}\nresize_policy: letterbox\n",
        "input: {width: 512, height: 512}\nresize_policy: letterbox\nflip_average: true\n"}) {
    const ModelCard card = loadModelCard(writeFile(dir, "card.yaml", common + policy));
    Segmenter segmenter(model, card, 1);
    const Segmentation result = segmenter.segment(image);
    ASSERT_EQ(result.label_ids.size(), image.size()) << policy;
    EXPECT_EQ(cv::countNonZero(result.label_ids(cv::Rect(0, 0, 1200, 196)) != 23), 0) << policy;
    EXPECT_EQ(cv::countNonZero(result.label_ids(cv::Rect(0, 204, 1200, 196)) != 26), 0) << policy;
  }
  fs::remove_all(dir);
}

// Labels back at the image's size must sit where the image is: a mirror-symmetric image gives
// mirror-symmetric labels when every resize works on pixel centres. Plain nearest-neighbour
// reads pixel i at i * scale, half an image pixel up and left: at a ratio that is not a whole
// number (here 224x72 network labels to 1024x256) the red block's labels came out shifted, its
// edges a column or row off on one side only. (The ratios 7/32 and 9/32 put no image pixel's
// centre on a network pixel's edge, where no rule could be symmetric.)
TEST(Segmenter, LabelsOfAMirrorSymmetricImageAreMirrorSymmetric) {
  const std::string dir = makeTempDir("symmetric_labels");
  const std::string model = dir + "/pool4.onnx";
  std::ofstream(model, std::ios::binary) << averagePoolOnnx(4);
  cv::Mat image(256, 1024, CV_8UC3, cv::Scalar(255, 0, 0));        // blue: "sky"
  image(cv::Rect(360, 80, 304, 96)).setTo(cv::Scalar(0, 0, 255));  // red: "car"
  image(cv::Rect(0, 0, 1024, 24)).setTo(cv::Scalar(0, 255, 0));    // green bands on top
  image(cv::Rect(0, 232, 1024, 24)).setTo(cv::Scalar(0, 255, 0));  // and at the bottom
  const std::string common =
      "mean: [0, 0, 0]\nscale: 0.00392156862745098\nswap_rb: false\n"
      "num_output_channels: 3\noutput_label_ids: [23, 21, 26]\n"
      "input: {width: 896, height: 288}\nresize_policy: pad_to_multiple\n";
  for (const std::string extra : {"", "flip_average: true\n"}) {
    const ModelCard card = loadModelCard(writeFile(dir, "card.yaml", common + extra));
    Segmenter segmenter(model, card, 1);
    const Segmentation result = segmenter.segment(image);
    ASSERT_EQ(result.label_ids.size(), image.size()) << extra;
    ASSERT_GT(cv::countNonZero(result.label_ids == 26), 290 * 90) << extra;  // the block found
    cv::Mat mirrored, difference;
    for (const int axis : {0, 1}) {  // about the horizontal, the vertical axis
      cv::flip(result.label_ids, mirrored, axis);
      EXPECT_EQ(cv::countNonZero(result.label_ids != mirrored), 0) << extra << " axis " << axis;
      cv::flip(result.confidence, mirrored, axis);  // and the confidence with them
      cv::absdiff(result.confidence, mirrored, difference);
      EXPECT_EQ(cv::countNonZero(difference > 1e-5), 0) << extra << " axis " << axis;
    }
  }
  fs::remove_all(dir);
}

TEST(Palette, ColorsAndTrainIdsFollowCityscapesTable) {
  cv::Mat labels(1, 3, CV_8UC1);
  labels.at<std::uint8_t>(0) = cityscapes::kRoad;
  labels.at<std::uint8_t>(1) = cityscapes::kCar;
  labels.at<std::uint8_t>(2) = cityscapes::kUnlabeled;
  const cv::Mat rgb = colorizeLabelIds(labels);
  EXPECT_EQ(rgb.at<cv::Vec3b>(0), cv::Vec3b(128, 64, 128));
  EXPECT_EQ(rgb.at<cv::Vec3b>(1), cv::Vec3b(0, 0, 142));
  EXPECT_EQ(rgb.at<cv::Vec3b>(2), cv::Vec3b(0, 0, 0));
  const cv::Mat train = labelIdsToTrainIds(labels);
  EXPECT_EQ(train.at<std::uint8_t>(0), 0);
  EXPECT_EQ(train.at<std::uint8_t>(1), 13);
  EXPECT_EQ(train.at<std::uint8_t>(2), 255);

  // Overlay with alpha 1 is the palette, with alpha 0 the image in RGB order.
  const cv::Mat bgr(1, 3, CV_8UC3, cv::Scalar(10, 20, 30));
  EXPECT_EQ(overlayLabelIds(bgr, labels, 1.0).at<cv::Vec3b>(0), cv::Vec3b(128, 64, 128));
  EXPECT_EQ(overlayLabelIds(bgr, labels, 0.0).at<cv::Vec3b>(0), cv::Vec3b(30, 20, 10));
}

TEST(ModelCard, ParsesTileAndColorFields) {
  const std::string dir = makeTempDir("card_tiles");
  const std::string path = writeFile(dir, "enet.yaml",
                                     "input: {width: 1024, height: 512}\n"
                                     "resize_policy: tiles\n"
                                     "tile_scale: 1.5\n"
                                     "network_focal_px: 1131\n"
                                     "tile_overlap: 64\n"
                                     "tile_bottom_margin: 40\n"
                                     "flip_average: true\n"
                                     "gamma: 0.8\n"
                                     "color_normalization: standardize\n"
                                     "color_mean: [73, 83, 72]\n"
                                     "color_std: [48, 48.5, 47.7]\n"
                                     "output_label_ids: [0, 7]\n");
  const ModelCard card = loadModelCard(path);
  EXPECT_EQ(card.resize_policy, ResizePolicy::kTiles);
  EXPECT_DOUBLE_EQ(card.tile_scale, 1.5);
  EXPECT_DOUBLE_EQ(card.network_focal_px, 1131.0);
  EXPECT_EQ(card.tile_overlap, 64);
  EXPECT_EQ(card.tile_bottom_margin, 40);
  EXPECT_TRUE(card.flip_average);
  EXPECT_DOUBLE_EQ(card.gamma, 0.8);
  EXPECT_EQ(card.color_normalization, ColorNormalization::kStandardize);
  EXPECT_DOUBLE_EQ(card.color_mean[1], 83.0);
  EXPECT_DOUBLE_EQ(card.color_std[1], 48.5);

  const std::string saved = dir + "/saved.yaml";
  saveModelCard(card, saved);
  const ModelCard reloaded = loadModelCard(saved);
  EXPECT_EQ(reloaded.resize_policy, ResizePolicy::kTiles);
  EXPECT_DOUBLE_EQ(reloaded.network_focal_px, card.network_focal_px);
  EXPECT_EQ(reloaded.tile_overlap, card.tile_overlap);
  EXPECT_EQ(reloaded.tile_bottom_margin, card.tile_bottom_margin);
  EXPECT_EQ(reloaded.flip_average, card.flip_average);
  EXPECT_DOUBLE_EQ(reloaded.gamma, card.gamma);
  EXPECT_EQ(reloaded.color_normalization, card.color_normalization);
  EXPECT_DOUBLE_EQ(reloaded.color_std[2], card.color_std[2]);

  // The built-in ENet card round-trips too.
  saveModelCard(builtinEnetCityscapesCard(), saved);
  const ModelCard builtin = loadModelCard(saved);
  EXPECT_EQ(builtin.resize_policy, builtinEnetCityscapesCard().resize_policy);
  EXPECT_EQ(builtin.color_normalization, builtinEnetCityscapesCard().color_normalization);
  EXPECT_DOUBLE_EQ(builtin.gamma, builtinEnetCityscapesCard().gamma);
  fs::remove_all(dir);
}

TEST(ModelCard, BadTileAndColorFieldsAreRejectedNamingTheField) {
  const std::string head = "input: {width: 64, height: 32}\nresize_policy: tiles\n";
  const std::string tail = "output_label_ids: [7]\n";
  EXPECT_EQ(cardError(head + tail), "");
  EXPECT_NE(cardError(head + "tile_overlap: 16\n" + tail).find("tile_overlap"), std::string::npos);
  EXPECT_NE(cardError(head + "tile_scale: -1\n" + tail).find("tile_scale"), std::string::npos);
  EXPECT_NE(cardError(head + "tile_bottom_margin: 16\n" + tail).find("tile_bottom_margin"),
            std::string::npos);
  EXPECT_NE(cardError(head + "network_focal_px: -5\n" + tail).find("network_focal_px"),
            std::string::npos);
  EXPECT_NE(cardError(head + "flip_average: maybe\n" + tail).find("flip_average"),
            std::string::npos);
  EXPECT_NE(cardError(head + "gamma: 0\n" + tail).find("gamma"), std::string::npos);
  EXPECT_NE(cardError(head + "color_normalization: auto\n" + tail).find("auto"), std::string::npos);
  EXPECT_NE(cardError(head + "color_normalization: standardize\n" + tail).find("color_mean"),
            std::string::npos);
  EXPECT_NE(cardError(head + "color_mean: [1, 2]\n" + tail).find("color_mean"), std::string::npos);
  EXPECT_NE(cardError(head + "color_std: [1, 0, 2]\n" + tail).find("color_std"), std::string::npos);
  EXPECT_NE(cardError("resize_policy: tiles\n" + tail).find("input"), std::string::npos);
}

// The same checks on a card changed after loading (evaluate_semantics' overrides: --color-std
// 0,0,0 scored 0.0004 without a word): the first value out of range is reported by its key.
TEST(ModelCard, CheckModelCardReportsTheFirstValueOutOfRange) {
  const auto firstFailure = [](const ModelCard& card) {
    std::string key;
    try {
      checkModelCard(card, [](const std::string& k, const std::string& why) {
        throw std::runtime_error(k + ": " + why);
      });
    } catch (const std::runtime_error& error) {
      key = error.what();
    }
    return key.substr(0, key.find(':'));
  };
  const ModelCard good = builtinEnetCityscapesCard();
  EXPECT_EQ(firstFailure(good), "");
  ModelCard bad = good;
  bad.color_std = {0.0, 1.0, 1.0};
  EXPECT_EQ(firstFailure(bad), "color_std");
  bad = good;
  bad.color_mean[1] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(firstFailure(bad), "color_mean");
  bad = good;
  bad.tile_scale = -1.0;
  EXPECT_EQ(firstFailure(bad), "tile_scale");
}

// The ends of the documented ranges: a labelId past 33, a tile overlap of half the input width, a
// confidence threshold of 1 (every pixel dropped) and tiles narrower than the input are refused.
TEST(ModelCard, RangeEndsAreRefusedNamingTheField) {
  const std::string tail = "output_label_ids: [7]\n";
  EXPECT_EQ(cardError("input: {width: 10, height: 10}\noutput_label_ids: [0, 33]\n"), "");
  EXPECT_NE(cardError("input: {width: 10, height: 10}\noutput_label_ids: [7, 34]\n").find("34"),
            std::string::npos);
  const std::string tiles = "input: {width: 32, height: 64}\nresize_policy: tiles\n";
  EXPECT_EQ(cardError(tiles + "tile_overlap: 15\n" + tail), "");
  EXPECT_NE(cardError(tiles + "tile_overlap: 16\n" + tail).find("tile_overlap"), std::string::npos);
  EXPECT_EQ(cardError(tiles + "tile_max_width: 32\n" + tail), "");
  EXPECT_NE(cardError(tiles + "tile_max_width: 31\n" + tail).find("tile_max_width"),
            std::string::npos);
  const std::string plain = "input: {width: 10, height: 10}\n";
  EXPECT_EQ(cardError(plain + "label_filter: {min_confidence: 0.99}\n" + tail), "");
  EXPECT_NE(
      cardError(plain + "label_filter: {min_confidence: 1.0}\n" + tail).find("min_confidence"),
      std::string::npos);
}

// Letterboxing: the image is centred, and its padding is the card's mean colour, so that the
// padding becomes 0 in the blob (blobFromImage swaps R and B, then subtracts the mean).
TEST(SegmenterInput, LetterboxCentresTheImageAndItsPaddingNormalizesToZero) {
  for (bool swap_rb : {true, false}) {
    ModelCard card;
    card.input_width = 64;
    card.input_height = 64;
    card.resize_policy = ResizePolicy::kLetterbox;
    card.mean = {10.0, 60.0, 200.0};
    card.scale = 1.0;
    card.swap_rb = swap_rb;
    const cv::Mat image(32, 16, CV_8UC3, cv::Scalar(90, 120, 150));  // scaled 2x: 32 x 64
    const detail::PreparedInput prepared = detail::prepareInput(image, card);
    ASSERT_EQ(prepared.network_image.size(), cv::Size(64, 64));
    EXPECT_EQ(prepared.valid_region, cv::Rect(16, 0, 32, 64)) << swap_rb;
    cv::Mat blob =
        cv::dnn::blobFromImage(prepared.network_image, card.scale, cv::Size(),
                               cv::Scalar(card.mean[0], card.mean[1], card.mean[2]), swap_rb);
    for (int c = 0; c < 3; ++c) {
      const cv::Mat plane(64, 64, CV_32F, blob.ptr<float>(0, c));
      EXPECT_EQ(plane.at<float>(10, 3), 0.f) << "left padding, channel " << c << " " << swap_rb;
      EXPECT_EQ(plane.at<float>(10, 60), 0.f) << "right padding, channel " << c << " " << swap_rb;
    }
  }
}

// Standardization brings each channel's mean and spread to the card's, given in the network's
// channel order (RGB when swap_rb); a flat channel (no spread to scale) takes the card's mean.
TEST(SegmenterInput, StandardizedColorsTakeTheCardsStatisticsInNetworkOrder) {
  ModelCard card;
  card.swap_rb = true;
  card.color_mean = {90.0, 120.0, 160.0};  // R, G, B
  card.color_std = {20.0, 25.0, 30.0};
  cv::Mat image(64, 64, CV_8UC3);
  cv::RNG rng(7);
  rng.fill(image, cv::RNG::NORMAL, cv::Scalar(60, 128, 200), cv::Scalar(10, 12, 8));
  cv::Scalar mean, stddev;
  cv::meanStdDev(detail::standardizeColors(image, card), mean, stddev);
  for (int c = 0; c < 3; ++c) {  // BGR channel c is RGB channel 2 - c
    EXPECT_NEAR(mean[c], card.color_mean[2 - c], 1.0) << "channel " << c;
    EXPECT_NEAR(stddev[c], card.color_std[2 - c], 1.0) << "channel " << c;
  }
  const cv::Mat flat(8, 8, CV_8UC3, cv::Scalar(40, 40, 40));
  cv::meanStdDev(detail::standardizeColors(flat, card), mean, stddev);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(mean[c], card.color_mean[2 - c], 1.0) << c;
}

// A 20 x 20 label image, road left of column 10 and car right of it, all confident but a 3 x 3
// patch at rows 2..4, columns 2..4.
Segmentation twoRegionSegmentation() {
  Segmentation segmentation;
  segmentation.label_ids = cv::Mat(20, 20, CV_8UC1, cv::Scalar(cityscapes::kRoad));
  segmentation.label_ids.colRange(10, 20).setTo(cityscapes::kCar);
  segmentation.confidence = cv::Mat(20, 20, CV_32FC1, cv::Scalar(0.9f));
  segmentation.confidence(cv::Rect(2, 2, 3, 3)).setTo(0.3f);
  return segmentation;
}

TEST(FilterLabels, RejectsUnconfidentPixelsAndLabelBoundaries) {
  const Segmentation segmentation = twoRegionSegmentation();
  const cv::Mat filtered = filterLabels(segmentation, 0.5, 2);
  ASSERT_EQ(filtered.type(), CV_8UC1);
  ASSERT_EQ(filtered.size(), segmentation.label_ids.size());
  for (int row = 0; row < 20; ++row) {
    for (int col = 0; col < 20; ++col) {
      const bool unconfident = row >= 2 && row <= 4 && col >= 2 && col <= 4;
      const bool boundary = col >= 8 && col <= 11;  // within 2 px of the road | car edge
      const int expected =
          (unconfident || boundary)
              ? static_cast<int>(cityscapes::kUnlabeled)
              : static_cast<int>(segmentation.label_ids.at<std::uint8_t>(row, col));
      EXPECT_EQ(filtered.at<std::uint8_t>(row, col), expected) << "row " << row << " col " << col;
    }
  }
  // Zero thresholds leave the labels alone; the input is not modified.
  EXPECT_EQ(cv::countNonZero(filterLabels(segmentation, 0.0, 0) != segmentation.label_ids), 0);
  EXPECT_EQ(cv::countNonZero(segmentation.label_ids == cityscapes::kUnlabeled), 0);
  // Only the boundary, only the confidence.
  EXPECT_EQ(cv::countNonZero(filterLabels(segmentation, 0.0, 1) == cityscapes::kUnlabeled), 20 * 2);
  EXPECT_EQ(cv::countNonZero(filterLabels(segmentation, 0.5, 0) == cityscapes::kUnlabeled), 9);
  LabelFilterOptions options;
  options.min_confidence = 0.95;
  options.boundary_radius_px = 0;
  EXPECT_EQ(cv::countNonZero(filterLabels(segmentation, options) == cityscapes::kUnlabeled), 400);
}

}  // namespace
}  // namespace perception
}  // namespace inekf_semantic_mapping
