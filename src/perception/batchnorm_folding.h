// Internal to the perception library (and its unit test): how replaced batch normalization
// statistics are folded into an OpenCV dnn network. Includes OpenCV's dnn headers, so it stays
// out of the public headers.
#pragma once

#include <opencv2/dnn.hpp>
#include <string>
#include <vector>

namespace inekf_semantic_mapping {
namespace perception {

// One batch normalization layer whose statistics can be replaced. OpenCV fixes a batch
// normalization layer's scale and shift when it builds the layer (setParam on it changes
// nothing), so the replacement is folded into the layer that feeds it instead: its output
// channel k becomes A_k y_k + C_k, which the trained statistics then standardize exactly as the
// new statistics would standardize y_k.
struct BatchNormSite {
  struct Producer {  // a convolution whose output channels are some of this layer's input
    std::string layer;
    bool deconvolution = false;
    int first_channel = 0;
    int channels = 0;
  };
  std::string layer;
  std::string input;                // the layer whose output the statistics are taken of
  std::vector<double> mean, sigma;  // trained: sigma = sqrt(variance + epsilon)
  double epsilon = 1e-5;
  std::vector<Producer> producers;
  std::vector<char> foldable;  // per channel: a producer can take the affine map
};

// The batch normalization layers of a freshly read network (in the network's order, which is
// an order of dependency) and where their inputs come from.
std::vector<BatchNormSite> findBatchNormSites(cv::dnn::Net& net);

// Folds y -> scale * y + offset (per channel of `site`) into its producers' weights and biases.
// Only before the network's first forward pass: OpenCV reads the weights when it sets up.
void foldChannelMap(cv::dnn::Net& net, const BatchNormSite& site, const std::vector<double>& scale,
                    const std::vector<double>& offset);

// The map that makes the trained statistics standardize y as `mean` / `variance` would.
void channelMapFor(const BatchNormSite& site, std::size_t channel, double mean, double variance,
                   double* scale, double* offset);

}  // namespace perception
}  // namespace inekf_semantic_mapping
