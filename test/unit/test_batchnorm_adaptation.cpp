// Batch normalization adaptation (perception/batchnorm_adaptation.h): the statistics file, and
// the folding of replaced statistics into the convolutions that feed each batch normalization
// layer, checked on a small network built here (a convolution and a max pooling concatenated as
// in ENet's first block, a convolution without bias, a deconvolution) against batch
// normalization computed by hand with the new statistics.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/dnn.hpp>
#include <random>
#include <string>
#include <vector>

#include "batchnorm_folding.h"
#include "inekf_semantic_mapping/perception/batchnorm_adaptation.h"

namespace inekf_semantic_mapping {
namespace perception {
namespace {

namespace fs = std::filesystem;

cv::Mat randomBlob(const std::vector<int>& shape, std::mt19937* rng, float low, float high) {
  cv::Mat blob(static_cast<int>(shape.size()), shape.data(), CV_32F);
  std::uniform_real_distribution<float> uniform(low, high);
  for (std::size_t i = 0; i < blob.total(); ++i) blob.ptr<float>()[i] = uniform(*rng);
  return blob;
}

cv::dnn::LayerParams batchNorm(int channels, std::mt19937* rng) {
  cv::dnn::LayerParams params;
  params.set("has_weight", true);
  params.set("has_bias", true);
  params.set("eps", 1e-5);
  params.blobs = {randomBlob({channels, 1}, rng, -0.5f, 0.5f),   // mean
                  randomBlob({channels, 1}, rng, 0.05f, 2.0f),   // variance
                  randomBlob({channels, 1}, rng, 0.5f, 1.5f),    // weight
                  randomBlob({channels, 1}, rng, -0.3f, 0.3f)};  // bias
  return params;
}

cv::dnn::LayerParams convolution(int out, int in, int kernel, int stride, int pad, bool bias,
                                 std::mt19937* rng) {
  cv::dnn::LayerParams params;
  params.set("kernel_size", kernel);
  params.set("stride", stride);
  params.set("pad", pad);
  params.set("num_output", out);
  params.set("bias_term", bias);
  params.blobs = {randomBlob({out, in, kernel, kernel}, rng, -0.5f, 0.5f)};
  if (bias) params.blobs.push_back(randomBlob({out, 1}, rng, -0.2f, 0.2f));
  return params;
}

// data (3 x 8 x 8) -> [conv_a 3->2 | max pool] -> concat (5) -> bn1 -> conv_b 5->4 (no bias)
// -> bn2 -> deconv 4->3 (x2) -> bn3. The same weights for the same seed.
cv::dnn::Net smallNetwork() {
  std::mt19937 rng(7);
  cv::dnn::Net net;
  net.setInputsNames({"data"});
  cv::dnn::LayerParams conv_a_params = convolution(2, 3, 3, 2, 1, true, &rng);
  const int conv_a = net.addLayer("conv_a", "Convolution", conv_a_params);
  net.connect(0, 0, conv_a, 0);
  cv::dnn::LayerParams pool_params;
  pool_params.set("pool", "max");
  pool_params.set("kernel_size", 2);
  pool_params.set("stride", 2);
  const int pool = net.addLayer("pool", "Pooling", pool_params);
  net.connect(0, 0, pool, 0);
  cv::dnn::LayerParams concat_params;
  concat_params.set("axis", 1);
  const int concat = net.addLayer("concat", "Concat", concat_params);
  net.connect(conv_a, 0, concat, 0);
  net.connect(pool, 0, concat, 1);
  cv::dnn::LayerParams bn1_params = batchNorm(5, &rng);
  const int bn1 = net.addLayer("bn1", "BatchNorm", bn1_params);
  net.connect(concat, 0, bn1, 0);
  cv::dnn::LayerParams conv_b_params = convolution(4, 5, 1, 1, 0, false, &rng);
  const int conv_b = net.addLayer("conv_b", "Convolution", conv_b_params);
  net.connect(bn1, 0, conv_b, 0);
  cv::dnn::LayerParams bn2_params = batchNorm(4, &rng);
  const int bn2 = net.addLayer("bn2", "BatchNorm", bn2_params);
  net.connect(conv_b, 0, bn2, 0);
  cv::dnn::LayerParams deconv_params;
  deconv_params.set("kernel_size", 2);
  deconv_params.set("stride", 2);
  deconv_params.set("num_output", 3);
  deconv_params.set("bias_term", true);
  deconv_params.blobs = {randomBlob({4, 3, 2, 2}, &rng, -0.5f, 0.5f),
                         randomBlob({3, 1}, &rng, -0.2f, 0.2f)};
  const int deconv = net.addLayer("deconv", "Deconvolution", deconv_params);
  net.connect(bn2, 0, deconv, 0);
  cv::dnn::LayerParams bn3_params = batchNorm(3, &rng);
  const int bn3 = net.addLayer("bn3", "BatchNorm", bn3_params);
  net.connect(deconv, 0, bn3, 0);
  net.setPreferableBackend(cv::dnn::DNN_BACKEND_OPENCV);
  net.setPreferableTarget(cv::dnn::DNN_TARGET_CPU);
  return net;
}

cv::Mat networkInput() {
  std::mt19937 rng(11);
  return randomBlob({1, 3, 8, 8}, &rng, 0.0f, 1.0f);
}

TEST(BatchNormFolding, FindsEachLayerAndTheConvolutionsThatFeedIt) {
  cv::dnn::Net net = smallNetwork();
  const std::vector<BatchNormSite> sites = findBatchNormSites(net);
  ASSERT_EQ(sites.size(), 3u);
  EXPECT_EQ(sites[0].layer, "bn1");
  EXPECT_EQ(sites[0].input, "concat");
  ASSERT_EQ(sites[0].producers.size(), 1u);
  EXPECT_EQ(sites[0].producers[0].layer, "conv_a");
  EXPECT_EQ(sites[0].producers[0].first_channel, 0);
  EXPECT_EQ(sites[0].producers[0].channels, 2);
  // The pooled image's channels have no convolution to take the map.
  EXPECT_EQ(sites[0].foldable, (std::vector<char>{1, 1, 0, 0, 0}));
  ASSERT_EQ(sites[1].producers.size(), 1u);
  EXPECT_EQ(sites[1].producers[0].layer, "conv_b");
  EXPECT_FALSE(sites[1].producers[0].deconvolution);
  ASSERT_EQ(sites[2].producers.size(), 1u);
  EXPECT_EQ(sites[2].producers[0].layer, "deconv");
  EXPECT_TRUE(sites[2].producers[0].deconvolution);
  EXPECT_EQ(sites[2].producers[0].channels, 3);
  EXPECT_NEAR(sites[1].epsilon, 1e-5, 1e-9);
}

// For each layer alone: new statistics folded into its producer give the layer's output that
// batch normalization with those statistics gives, computed here from the unfolded input;
// channels that cannot be folded keep their output. With OpenCV's layer fusion on and off.
TEST(BatchNormFolding, TheFoldedNetworkNormalizesWithTheNewStatistics) {
  for (const bool fusion : {false, true}) {
    cv::dnn::Net reference = smallNetwork();
    const std::vector<BatchNormSite> sites = findBatchNormSites(reference);
    for (std::size_t s = 0; s < sites.size(); ++s) {
      const BatchNormSite& site = sites[s];
      SCOPED_TRACE(site.layer + (fusion ? " (fusion)" : " (no fusion)"));
      cv::dnn::Net plain = smallNetwork();
      plain.enableFusion(false);
      plain.setInput(networkInput());
      std::vector<cv::Mat> outputs;
      plain.forward(outputs, std::vector<cv::String>{site.input, site.layer});
      const cv::Mat input = outputs[0].clone(), trained_output = outputs[1].clone();
      const cv::Ptr<cv::dnn::Layer> layer = plain.getLayer(site.layer);
      const cv::Mat weight = layer->blobs[2], bias = layer->blobs[3];

      const std::size_t channels = site.mean.size();
      std::vector<double> new_mean(channels), new_variance(channels), scale(channels, 1.0),
          offset(channels, 0.0);
      for (std::size_t c = 0; c < channels; ++c) {
        new_mean[c] = site.mean[c] + (0.7 - 0.3 * c) * site.sigma[c];
        new_variance[c] = site.sigma[c] * site.sigma[c] * (0.4 + 0.5 * c);
        if (site.foldable[c])
          channelMapFor(site, c, new_mean[c], new_variance[c], &scale[c], &offset[c]);
      }
      cv::dnn::Net folded = smallNetwork();
      folded.enableFusion(fusion);
      foldChannelMap(folded, site, scale, offset);
      folded.setInput(networkInput());
      const cv::Mat output = folded.forward(site.layer);
      ASSERT_EQ(output.total(), trained_output.total());

      const int plane = input.size[2] * input.size[3];
      for (std::size_t c = 0; c < channels; ++c) {
        const float* y = input.ptr<float>(0, static_cast<int>(c));
        const float* got = output.ptr<float>(0, static_cast<int>(c));
        const float* trained = trained_output.ptr<float>(0, static_cast<int>(c));
        double worst = 0.0;
        for (int i = 0; i < plane; ++i) {
          const double expected = site.foldable[c]
                                      ? weight.ptr<float>()[c] * (y[i] - new_mean[c]) /
                                                std::sqrt(new_variance[c] + site.epsilon) +
                                            bias.ptr<float>()[c]
                                      : trained[i];
          worst = std::max(worst, std::abs(got[i] - expected));
        }
        EXPECT_LT(worst, 1e-4) << "channel " << c;
      }
    }
  }
}

TEST(BatchNormAdaptationFile, RoundTripsAndNamesTheFileOnErrors) {
  const fs::path dir = fs::temp_directory_path() / ("ism_bn_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  BatchNormAdaptation adaptation;
  adaptation.num_images = 12;
  adaptation.adapted_layers = 2;
  adaptation.target_weight = 0.5;
  adaptation.layers = {{"l5_BatchNorm", {0.25, -1.5e-3}, {0.01, 2.0}},
                       {"l9_BatchNorm", {3.0}, {0.0}}};
  const std::string path = (dir / "stats.yaml").string();
  saveBatchNormAdaptation(adaptation, path);
  const BatchNormAdaptation loaded = loadBatchNormAdaptation(path);
  EXPECT_EQ(loaded.num_images, 12);
  EXPECT_EQ(loaded.adapted_layers, 2);
  EXPECT_DOUBLE_EQ(loaded.target_weight, 0.5);
  ASSERT_EQ(loaded.layers.size(), 2u);
  EXPECT_EQ(loaded.layers[0].layer, "l5_BatchNorm");
  EXPECT_EQ(loaded.layers[0].mean, adaptation.layers[0].mean);
  EXPECT_EQ(loaded.layers[0].variance, adaptation.layers[0].variance);
  EXPECT_EQ(loaded.layers[1].variance, std::vector<double>{0.0});

  const auto expect_error = [&](const std::string& text, const std::string& what) {
    const std::string bad = (dir / "bad.yaml").string();
    std::ofstream(bad) << text;
    try {
      loadBatchNormAdaptation(bad);
      ADD_FAILURE() << "no error for: " << text;
    } catch (const BatchNormAdaptationError& error) {
      const std::string message = error.what();
      EXPECT_NE(message.find(bad), std::string::npos) << message;
      EXPECT_NE(message.find(what), std::string::npos) << message;
    }
  };
  expect_error("layers:\n  - name: a\n    mean: [1, 2]\n    variance: [1]\n", "same");
  expect_error("layers:\n  - name: a\n    mean: [1]\n    variance: [-1]\n", "negative variance");
  expect_error("layers:\n  - name: a\n    mean: [1, .nan]\n    variance: [1, 1]\n", "not finite");
  expect_error("layers: []\n", "no layers");
  expect_error("num_images: 3\n", "list 'layers'");
  EXPECT_THROW(loadBatchNormAdaptation((dir / "missing.yaml").string()), BatchNormAdaptationError);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace perception
}  // namespace inekf_semantic_mapping
