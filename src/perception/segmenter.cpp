// Segmenter's network: reading it, the forward pass, the tiled and the single-pass segmentation
// (softmax, argmax, back to the image). The input preparation is in segmenter_input.cpp, the
// label-image functions in segmenter_labels.cpp.
#include "inekf_semantic_mapping/perception/segmenter.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/dnn.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <vector>

#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/perception/cityscapes.h"
#include "inekf_semantic_mapping/perception/dnn_bilinear_resize.h"
#include "segmenter_input.h"

namespace inekf_semantic_mapping {
namespace perception {
namespace {

// The network itself failed on its input (a shape it cannot take), as opposed to an output that
// does not fit the card: only this one is a question of the input size.
class ForwardPassError : public SegmentationError {
 public:
  using SegmentationError::SegmentationError;
};

using detail::applyGamma;
using detail::PreparedInput;
using detail::prepareInput;
using detail::standardizeColors;
using detail::toBgr;

namespace fs = std::filesystem;

cv::dnn::Net readNetwork(const std::string& model_path) {
  if (!fs::exists(model_path)) throw SegmentationError("model file not found: " + model_path);
  const std::string extension = fs::path(model_path).extension().string();
  useFastBilinearResize();  // before reading: OpenCV creates the layers as it reads
  try {
    if (extension == ".onnx") return cv::dnn::readNetFromONNX(model_path);
    if (extension == ".net" || extension == ".t7") return cv::dnn::readNetFromTorch(model_path);
  } catch (const cv::Exception& e) {
    throw SegmentationError("cannot load model " + model_path + ": " + e.what());
  }
  throw SegmentationError("unknown model format '" + extension + "' of " + model_path +
                          " (expected .onnx, or Torch7 .net / .t7)");
}

// Starts of the fewest windows of `window` pixels that cover [0, extent) with neighbours
// overlapping by at least `overlap` pixels, spread evenly (first at 0, last at extent - window).
std::vector<int> tileStarts(int extent, int window, int overlap) {
  if (extent <= window) return {0};
  const int stride = window - overlap;
  const int count = std::max(2, (extent - overlap + stride - 1) / stride);
  std::vector<int> starts(count);
  for (int i = 0; i < count; ++i)
    starts[i] =
        static_cast<int>(std::lround(static_cast<double>(i) * (extent - window) / (count - 1)));
  return starts;
}

// Weights along one side of a tile: ramping up over `ramp` pixels from an edge that lies inside
// the canvas (a network sees least context at its input's edges, and the neighbouring tile
// covers those pixels), 1 at edges on the canvas border (nothing else covers them).
std::vector<float> featherWeights(int start, int length, int extent, int ramp) {
  std::vector<float> weights(length, 1.f);
  if (ramp <= 1) return weights;
  for (int i = 0; i < length; ++i) {
    float w = 1.f;
    if (start > 0) w = std::min(w, (i + 1.f) / ramp);
    if (start + length < extent) w = std::min(w, (length - i) / static_cast<float>(ramp));
    weights[i] = w;
  }
  return weights;
}

// The network input's valid region (the image without its padding) in the pixels of an output
// of width x height, rounded to the nearest output pixel edges and at least one pixel.
cv::Rect validRegionInOutput(const cv::Rect& valid, const cv::Size& input, int width, int height) {
  const auto scale = [](int at, int output, int input_size) {
    return static_cast<int>((static_cast<long long>(at) * output + input_size / 2) / input_size);
  };
  const int x0 = std::clamp(scale(valid.x, width, input.width), 0, width - 1);
  const int y0 = std::clamp(scale(valid.y, height, input.height), 0, height - 1);
  const int x1 = std::clamp(scale(valid.x + valid.width, width, input.width), x0 + 1, width);
  const int y1 = std::clamp(scale(valid.y + valid.height, height, input.height), y0 + 1, height);
  return cv::Rect(x0, y0, x1 - x0, y1 - y0);
}

// Softmax over the channels of a 1 x C x h x w score blob, added into the C planes of `sum`
// over `tile`; flipped: the scores are of the mirrored tile. Row by row, so that the row's
// channels stay in cache (a tile's full planes are 40 MB of temporaries otherwise).
void addSoftmax(const cv::Mat& scores, bool flipped, const cv::Rect& tile,
                const std::vector<float>& column_weight, const std::vector<float>& row_weight,
                std::vector<cv::Mat>* sum) {
  const int channels = scores.size[1];
  const int height = scores.size[2];
  const int width = scores.size[3];
  if (height != tile.height || width != tile.width) {
    // A network with a coarser output than its input: the probabilities at its resolution,
    // then resized to the tile's pixels.
    cv::Mat probabilities(channels, height * width, CV_32F);
    cv::Mat flat(channels, height * width, CV_32F, const_cast<float*>(scores.ptr<float>()));
    cv::Mat column_max;
    cv::reduce(flat, column_max, 0, cv::REDUCE_MAX);
    for (int c = 0; c < channels; ++c) cv::subtract(flat.row(c), column_max, probabilities.row(c));
    cv::exp(probabilities, probabilities);
    cv::Mat column_sum;
    cv::reduce(probabilities, column_sum, 0, cv::REDUCE_SUM);
    const cv::Mat weight = cv::Mat(row_weight).reshape(1, tile.height) *
                           cv::Mat(column_weight).reshape(1, 1);  // outer product
    for (int c = 0; c < channels; ++c) {
      cv::Mat plane = probabilities.row(c) / column_sum;
      plane = plane.reshape(1, height);
      if (flipped) cv::flip(plane, plane, 1);
      cv::resize(plane, plane, tile.size(), 0, 0, cv::INTER_LINEAR);
      cv::Mat target = (*sum)[c](tile);
      target += plane.mul(weight);
    }
    return;
  }
  // Rows are independent (each adds into its own row of `sum`): spread over OpenCV's threads.
  cv::parallel_for_(
      cv::Range(0, height),
      [&](const cv::Range& rows) {
        cv::Mat exps(channels, width, CV_32F);
        cv::Mat row_max(1, width, CV_32F);
        cv::Mat row_sum(1, width, CV_32F);
        for (int y = rows.start; y < rows.end; ++y) {
          const auto score_row = [&](int c) {
            return cv::Mat(1, width, CV_32F, const_cast<float*>(scores.ptr<float>(0, c, y)));
          };
          score_row(0).copyTo(row_max);
          for (int c = 1; c < channels; ++c) cv::max(row_max, score_row(c), row_max);
          for (int c = 0; c < channels; ++c) {
            cv::Mat exp_row = exps.row(c);
            cv::subtract(score_row(c), row_max, exp_row);
          }
          cv::exp(exps, exps);
          cv::reduce(exps, row_sum, 0, cv::REDUCE_SUM);
          // inverse[x]: the weight of output pixel x over its exp sum (in output order).
          cv::divide(row_weight[y], row_sum, row_sum);
          float* inverse = row_sum.ptr<float>();
          for (int x = 0; x < width; ++x) inverse[x] *= column_weight[flipped ? width - 1 - x : x];
          for (int c = 0; c < channels; ++c) {
            const float* e = exps.ptr<float>(c);
            float* target = (*sum)[c].ptr<float>(tile.y + y) + tile.x;
            if (flipped) {
              for (int x = 0; x < width; ++x)
                target[x] += e[width - 1 - x] * inverse[width - 1 - x];
            } else {
              for (int x = 0; x < width; ++x) target[x] += e[x] * inverse[x];
            }
          }
        }
      },
      std::max(1.0, height / 8.0));
}

// One row's argmax over the channels: index[x] = the channel c (not skipped) whose row_of(c)[x]
// is highest, best[x] its value; best holds the starting value (lower than any score) on entry.
template <typename RowOf, typename Skip>
void argmaxOverChannels(int channels, int width, RowOf row_of, Skip skip, float* best,
                        std::uint8_t* index) {
  for (int c = 0; c < channels; ++c) {
    if (skip(c)) continue;
    const float* value = row_of(c);
    for (int x = 0; x < width; ++x) {
      if (value[x] > best[x]) {
        best[x] = value[x];
        index[x] = static_cast<std::uint8_t>(c);
      }
    }
  }
}

}  // namespace

struct Segmenter::Network {
  cv::dnn::Net net;
  cv::Mat label_lut;            // 1x256 CV_8U: channel index -> labelId
  cv::Size input_size;          // of the last forward pass
  bool output_checked = false;  // checkOutputIsScores has seen one output
};

namespace {

// OpenCV 4.6 keeps some layer shapes from a network's first forward pass: ENet (Torch
// importer, MaxUnpool) run at 1024x512 and then at 1392x512 labels 1 % of KITTI's lidar points
// right, the same network read afresh for 1392x512 80 %. A network is therefore read again
// whenever the input size changes (once per camera in practice; tiles keep one size).
cv::dnn::Net readNetworkForCpu(const std::string& model_path) {
  cv::dnn::Net net = readNetwork(model_path);
  net.setPreferableBackend(cv::dnn::DNN_BACKEND_OPENCV);
  net.setPreferableTarget(cv::dnn::DNN_TARGET_CPU);
  return net;
}

}  // namespace

Segmenter::Segmenter(const std::string& model_path, const ModelCard& card, int num_threads)
    : model_path_(model_path), card_(card), network_(std::make_unique<Network>()) {
  if (card_.output_label_ids.empty())
    throw SegmentationError("model card " + card_.source + " has no output_label_ids");
  if (card_.numOutputChannels() > 256)
    throw SegmentationError("model card " + card_.source + ": more than 256 output channels");
  cv::setNumThreads(num_threads);
  network_->net = readNetworkForCpu(model_path);
  checkOutputName();
  network_->label_lut = cv::Mat::zeros(1, 256, CV_8U);
  for (int i = 0; i < card_.numOutputChannels(); ++i)
    network_->label_lut.at<std::uint8_t>(i) = card_.output_label_ids[i];

  // One forward pass on a neutral image: catches a card that does not fit the model now,
  // not on the first camera frame (and warms up the network). Odd multiples of pad_multiple: a
  // 64x64 probe passed a network that needs multiples of 32 under a card saying 8, and every
  // camera frame then failed.
  int odd_multiple = std::max(3, (64 + card_.pad_multiple - 1) / card_.pad_multiple);
  if (odd_multiple % 2 == 0) ++odd_multiple;  // 64 px or more, an odd multiple of pad_multiple
  const int probe_width =
      card_.input_width > 0 ? card_.input_width : odd_multiple * card_.pad_multiple;
  const int probe_height =
      card_.input_height > 0 ? card_.input_height : odd_multiple * card_.pad_multiple;
  try {
    segment(cv::Mat(probe_height, probe_width, CV_8UC3, cv::Scalar(127, 127, 127)));
  } catch (const ForwardPassError& e) {
    if (card_.input_width > 0 && card_.input_height > 0) {
      throw SegmentationError(std::string(e.what()) + " (the input size " +
                              std::to_string(card_.input_width) + "x" +
                              std::to_string(card_.input_height) + " is its card " + card_.source +
                              "'s: is it the size the model was exported at?)");
    }
    throw SegmentationError(std::string(e.what()) + " (a probe of the input sizes its card " +
                            card_.source + " allows: is pad_multiple " +
                            std::to_string(card_.pad_multiple) +
                            " the network's own stride, e.g. 32?)");
  }
}

void Segmenter::checkOutputName() {
  const std::vector<std::string> outputs = network_->net.getUnconnectedOutLayersNames();
  std::string listed;
  for (const std::string& name : outputs) listed += (listed.empty() ? "" : ", ") + name;
  if (card_.output_name.empty()) {
    if (outputs.size() <= 1) return;
    throw SegmentationError("model " + model_path_ + " has " + std::to_string(outputs.size()) +
                            " outputs (" + listed + "): name the one with the class scores in " +
                            "its card " + card_.source + " (output_name: ...)");
  }
  if (std::find(outputs.begin(), outputs.end(), card_.output_name) == outputs.end()) {
    throw SegmentationError("model card " + card_.source + ": output_name '" + card_.output_name +
                            "' is not an output of " + model_path_ + " (" + listed + ")");
  }
}

Segmenter::~Segmenter() = default;
Segmenter::Segmenter(Segmenter&&) noexcept = default;
Segmenter& Segmenter::operator=(Segmenter&&) noexcept = default;

cv::Mat Segmenter::forward(const cv::Mat& network_image) {
  cv::Mat output;
  const cv::Scalar mean(card_.mean[0], card_.mean[1], card_.mean[2]);
  const cv::Mat blob = cv::dnn::blobFromImage(network_image, card_.scale, cv::Size(), mean,
                                              card_.swap_rb, false, CV_32F);
  try {
    const cv::Size input_size(blob.size[3], blob.size[2]);
    if (!network_->input_size.empty() && input_size != network_->input_size) {
      ScopedTimer timer("segmentation/reload");
      network_->net = readNetworkForCpu(model_path_);
    }
    network_->input_size = input_size;
    network_->net.setInput(blob);
    output = card_.output_name.empty() ? network_->net.forward()
                                       : network_->net.forward(card_.output_name);
  } catch (const cv::Exception& e) {
    throw ForwardPassError("forward pass of " + model_path_ + " on a " +
                           std::to_string(blob.size[3]) + "x" + std::to_string(blob.size[2]) +
                           " input failed: " + e.what());
  }
  const int channels = output.dims == 4 ? output.size[1] : -1;
  if (output.dims != 4 || output.size[0] != 1 || channels != card_.numOutputChannels()) {
    std::ostringstream msg;
    msg << "model " << model_path_ << " outputs " << (output.dims == 4 ? channels : -1)
        << " channels (output dims " << output.dims << ") but its card " << card_.source << " maps "
        << card_.numOutputChannels() << " channels to labelIds";
    throw SegmentationError(msg.str());
  }
  // On the load probe's neutral grey only: class scores of a real image can pass for
  // probabilities here and there (a pooled pure colour is in [0, 1] and sums to 1).
  if (!network_->output_checked) {
    checkOutputIsScores(output);
    network_->output_checked = true;
  }
  return output;
}

void Segmenter::checkOutputIsScores(const cv::Mat& output) const {
  // Probabilities (a softmax in the graph) take a second softmax here: 3 classes never pass
  // 0.58, and the card's label filter blanked every label, with no error.
  const int channels = output.size[1];
  const int pixels = output.size[2] * output.size[3];
  const float* data = output.ptr<float>();
  const int step = std::max(1, pixels / 64);
  for (int p = 0; p < pixels; p += step) {
    double sum = 0.0;
    for (int c = 0; c < channels; ++c) {
      const float v = data[static_cast<std::size_t>(c) * pixels + p];
      if (!(v >= 0.0f && v <= 1.0f)) return;  // scores outside [0, 1]: not probabilities
      sum += v;
    }
    if (std::abs(sum - 1.0) > 1e-3) return;
  }
  throw SegmentationError("model " + model_path_ + " outputs probabilities (every pixel's " +
                          std::to_string(channels) +
                          " channels are in [0, 1] and sum to 1: a softmax in the graph); the "
                          "Segmenter takes the softmax of the class scores itself: export the "
                          "model without its final softmax");
}

double Segmenter::tileScaleFor(const cv::Size& image_size, double camera_focal_px) const {
  if (card_.resize_policy != ResizePolicy::kTiles) return 1.0;
  if (card_.network_focal_px > 0.0 && camera_focal_px > 0.0)
    return card_.network_focal_px / camera_focal_px;
  if (card_.tile_scale > 0.0) return card_.tile_scale;
  return std::max(
      static_cast<double>(card_.input_width) / image_size.width,
      static_cast<double>(card_.input_height - card_.tile_bottom_margin) / image_size.height);
}

bool Segmenter::skipsInArgmax(int channel) const {
  return card_.suppress_unlabeled && card_.output_label_ids[channel] == cityscapes::kUnlabeled &&
         card_.numOutputChannels() > 1;
}

Segmentation Segmenter::segmentTiles(const cv::Mat& bgr, double camera_focal_px) {
  const double scale = tileScaleFor(bgr.size(), camera_focal_px);
  cv::Size tile_size(card_.input_width, card_.input_height);
  cv::Mat canvas;
  std::vector<cv::Rect> tiles;
  cv::Rect valid;
  {
    ScopedTimer timer("segmentation/preprocess");
    const cv::Size scaled(std::max(1, static_cast<int>(std::lround(bgr.cols * scale))),
                          std::max(1, static_cast<int>(std::lround(bgr.rows * scale))));
    cv::resize(bgr, canvas, scaled, 0, 0, scale < 1.0 ? cv::INTER_AREA : cv::INTER_LINEAR);
    valid = cv::Rect(cv::Point(0, 0), scaled);
    if (card_.tile_max_width > 0 && scaled.width > tile_size.width) {
      const int multiple = card_.pad_multiple > 1 ? card_.pad_multiple : 16;
      const int wide = (scaled.width + multiple - 1) / multiple * multiple;
      tile_size.width = std::min(card_.tile_max_width, wide);
    }
    // Smaller than a tile: reflect-pad (the scale stays), the padding is cropped afterwards.
    // The bottom margin is padding too: the image's bottom stays out of the rows where the
    // training images showed the ego vehicle.
    const int pad_right = std::max(0, tile_size.width - scaled.width);
    const int pad_bottom = std::max(card_.tile_bottom_margin, tile_size.height - scaled.height);
    if (pad_right > 0 || pad_bottom > 0) {
      const bool reflect = pad_right < scaled.width && pad_bottom < scaled.height;
      cv::copyMakeBorder(canvas, canvas, 0, pad_bottom, 0, pad_right,
                         reflect ? cv::BORDER_REFLECT_101 : cv::BORDER_REPLICATE);
    }
    for (int y : tileStarts(canvas.rows, tile_size.height, card_.tile_overlap))
      for (int x : tileStarts(canvas.cols, tile_size.width, card_.tile_overlap))
        tiles.emplace_back(cv::Point(x, y), tile_size);
  }

  std::vector<cv::Mat> sum(card_.numOutputChannels());
  for (cv::Mat& plane : sum) plane = cv::Mat::zeros(canvas.size(), CV_32F);
  cv::Mat weight = cv::Mat::zeros(canvas.size(), CV_32F);
  const int ramp = std::max(1, card_.tile_overlap / 2);
  for (const cv::Rect& tile : tiles) {
    accumulateProbabilities(canvas, tile, featherWeights(tile.x, tile.width, canvas.cols, ramp),
                            featherWeights(tile.y, tile.height, canvas.rows, ramp), &sum, &weight);
  }

  return labelsFromProbabilitySums(sum, weight, valid, bgr.size());
}

void Segmenter::accumulateProbabilities(const cv::Mat& canvas, const cv::Rect& tile,
                                        const std::vector<float>& column_weight,
                                        const std::vector<float>& row_weight,
                                        std::vector<cv::Mat>* sum, cv::Mat* weight) {
  const cv::Mat input = canvas(tile);
  const cv::Mat tile_weights =
      cv::Mat(row_weight).reshape(1, tile.height) * cv::Mat(column_weight).reshape(1, 1);
  cv::Mat mirrored;
  if (card_.flip_average) cv::flip(input, mirrored, 1);
  const int passes = card_.flip_average ? 2 : 1;
  for (int pass = 0; pass < passes; ++pass) {
    const bool is_mirrored = pass == 1;
    cv::Mat scores;
    {
      ScopedTimer timer("segmentation/forward");
      scores = forward(is_mirrored ? mirrored : input);
    }
    ScopedTimer timer("segmentation/softmax");
    addSoftmax(scores, is_mirrored, tile, column_weight, row_weight, sum);
    cv::Mat tile_weight = (*weight)(tile);
    tile_weight += tile_weights;
  }
}

Segmentation Segmenter::segmentMirrorAveraged(const cv::Mat& network_image, const cv::Rect& valid,
                                              const cv::Size& image_size) {
  std::vector<cv::Mat> sum(card_.numOutputChannels());
  for (cv::Mat& plane : sum) plane = cv::Mat::zeros(network_image.size(), CV_32F);
  cv::Mat weight = cv::Mat::zeros(network_image.size(), CV_32F);
  accumulateProbabilities(network_image, cv::Rect(cv::Point(0, 0), network_image.size()),
                          std::vector<float>(network_image.cols, 1.f),
                          std::vector<float>(network_image.rows, 1.f), &sum, &weight);
  return labelsFromProbabilitySums(sum, weight, valid, image_size);
}

Segmentation Segmenter::labelsFromProbabilitySums(const std::vector<cv::Mat>& sum,
                                                  const cv::Mat& weight, const cv::Rect& valid,
                                                  const cv::Size& image_size) const {
  Segmentation result;
  ScopedTimer timer("segmentation/argmax");
  // Argmax of the summed probabilities (the same as of their mean: every channel of a pixel has
  // the same weight) at the network's resolution, then labels and confidence back to the
  // image's size: two resizes instead of one per channel.
  const cv::Size scaled = valid.size();
  cv::Mat best_sum(scaled, CV_32F, cv::Scalar(-1.0));
  cv::Mat best_index(scaled, CV_8U, cv::Scalar(0));
  cv::parallel_for_(
      cv::Range(0, scaled.height),
      [&](const cv::Range& rows) {
        for (int row = rows.start; row < rows.end; ++row) {
          argmaxOverChannels(
              static_cast<int>(sum.size()), scaled.width,
              [&](int c) { return sum[c].ptr<float>(valid.y + row) + valid.x; },
              [this](int c) { return skipsInArgmax(c); }, best_sum.ptr<float>(row),
              best_index.ptr<std::uint8_t>(row));
        }
      },
      std::max(1.0, scaled.height / 8.0));
  cv::Mat confidence;
  cv::divide(best_sum, weight(valid), confidence);
  cv::Mat label_ids;
  cv::LUT(best_index, network_->label_lut, label_ids);
  if (scaled != image_size) {  // at pixel centres, as below
    cv::resize(label_ids, result.label_ids, image_size, 0, 0, cv::INTER_NEAREST_EXACT);
    cv::resize(confidence, result.confidence, image_size, 0, 0, cv::INTER_LINEAR);
  } else {
    result.label_ids = label_ids;
    result.confidence = confidence;
  }
  return result;
}

Segmentation Segmenter::segment(const cv::Mat& image, double camera_focal_px) {
  cv::Mat bgr = toBgr(image);
  if (card_.gamma != 1.0 || card_.color_normalization == ColorNormalization::kStandardize) {
    ScopedTimer timer("segmentation/preprocess");
    if (card_.gamma != 1.0) bgr = applyGamma(bgr, card_.gamma);
    if (card_.color_normalization == ColorNormalization::kStandardize) {
      bgr = standardizeColors(bgr, card_);
    }
  }
  if (card_.resize_policy == ResizePolicy::kTiles) return segmentTiles(bgr, camera_focal_px);
  PreparedInput prepared;
  cv::Mat output;
  {
    ScopedTimer timer("segmentation/preprocess");
    prepared = prepareInput(bgr, card_);
  }
  if (card_.flip_average) {
    return segmentMirrorAveraged(prepared.network_image, prepared.valid_region, bgr.size());
  }
  {
    ScopedTimer timer("segmentation/forward");
    output = forward(prepared.network_image);
  }
  const int channels = output.size[1];
  const int height = output.size[2];
  const int width = output.size[3];

  Segmentation result;
  {
    ScopedTimer timer("segmentation/argmax");
    // Argmax and the winner's softmax probability, 1 / sum_c exp(score_c - best), row by row
    // over OpenCV's threads: one row's channels stay in cache (whole planes are 17 MB at
    // 832x256), and the per-pixel sums run in channel order.
    cv::Mat best_index(height, width, CV_8U);
    cv::Mat confidence(height, width, CV_32F);
    const std::size_t plane_size = static_cast<std::size_t>(height) * width;
    const float* scores = output.ptr<float>();
    cv::parallel_for_(
        cv::Range(0, height),
        [&](const cv::Range& rows) {
          std::vector<float> best(width);
          cv::Mat shifted(channels, width, CV_32F);
          for (int y = rows.start; y < rows.end; ++y) {
            const std::size_t offset = static_cast<std::size_t>(y) * width;
            std::uint8_t* index = best_index.ptr<std::uint8_t>(y);
            std::fill(best.begin(), best.end(), -std::numeric_limits<float>::infinity());
            std::fill(index, index + width, std::uint8_t{0});
            argmaxOverChannels(
                channels, width, [&](int c) { return scores + c * plane_size + offset; },
                [this](int c) { return skipsInArgmax(c); }, best.data(), index);
            for (int c = 0; c < channels; ++c) {
              const float* score = scores + c * plane_size + offset;
              float* row = shifted.ptr<float>(c);
              for (int x = 0; x < width; ++x) row[x] = score[x] - best[x];
            }
            cv::exp(shifted, shifted);
            float* sum = confidence.ptr<float>(y);
            std::fill(sum, sum + width, 0.f);
            for (int c = 0; c < channels; ++c) {
              const float* e = shifted.ptr<float>(c);
              for (int x = 0; x < width; ++x) sum[x] += e[x];
            }
            for (int x = 0; x < width; ++x) sum[x] = 1.f / sum[x];
          }
        },
        std::max(1.0, height / 8.0));
    cv::Mat label_ids;
    cv::LUT(best_index, network_->label_lut, label_ids);

    // Back to the input image: crop the padding (in the output's pixels: a network with an
    // output stride labels a coarser grid than its input), nearest-neighbour to the input size
    // at pixel centres (plain INTER_NEAREST reads pixel i at i * scale: labels half an image
    // pixel up and left of what they label).
    const cv::Rect valid =
        validRegionInOutput(prepared.valid_region, prepared.network_image.size(), width, height);
    label_ids = label_ids(valid);
    confidence = confidence(valid);
    if (label_ids.size() != bgr.size()) {
      cv::resize(label_ids, result.label_ids, bgr.size(), 0, 0, cv::INTER_NEAREST_EXACT);
      cv::resize(confidence, result.confidence, bgr.size(), 0, 0, cv::INTER_NEAREST_EXACT);
    } else {
      result.label_ids = label_ids.clone();
      result.confidence = confidence.clone();
    }
  }
  return result;
}

}  // namespace perception
}  // namespace inekf_semantic_mapping
