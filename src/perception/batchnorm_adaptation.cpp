#include "inekf_semantic_mapping/perception/batchnorm_adaptation.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <opencv2/dnn/all_layers.hpp>
#include <sstream>

#include "batchnorm_folding.h"
#include "inekf_semantic_mapping/common/atomic_file.h"

namespace inekf_semantic_mapping {
namespace perception {
namespace {

[[noreturn]] void fail(const std::string& path, const YAML::Node& node, const std::string& what) {
  std::ostringstream msg;
  msg << "batch normalization statistics " << path;
  if (node.IsDefined() && node.Mark().line >= 0) msg << ":" << node.Mark().line + 1;
  msg << ": " << what;
  throw BatchNormAdaptationError(msg.str());
}

std::vector<double> readValues(const std::string& path, const YAML::Node& layer,
                               const std::string& field) {
  const YAML::Node node = layer[field];
  if (!node || !node.IsSequence()) fail(path, layer, "each layer needs a list '" + field + "'");
  std::vector<double> values;
  try {
    values = node.as<std::vector<double>>();
  } catch (const YAML::Exception& e) {
    fail(path, node, "'" + field + "' must be a list of numbers (" + e.msg + ")");
  }
  for (double value : values) {
    if (!std::isfinite(value)) fail(path, node, "'" + field + "' holds a value that is not finite");
  }
  return values;
}

}  // namespace

BatchNormAdaptation loadBatchNormAdaptation(const std::string& yaml_path) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(yaml_path);
  } catch (const YAML::BadFile&) {
    throw BatchNormAdaptationError("batch normalization statistics " + yaml_path +
                                   ": cannot open file");
  } catch (const YAML::Exception& e) {
    throw BatchNormAdaptationError("batch normalization statistics " + yaml_path + ":" +
                                   std::to_string(e.mark.line + 1) +
                                   ": YAML syntax error: " + e.msg);
  }
  if (!root.IsMap() || !root["layers"] || !root["layers"].IsSequence())
    fail(yaml_path, root, "expected a map with a list 'layers'");
  BatchNormAdaptation adaptation;
  adaptation.source = yaml_path;
  try {
    adaptation.num_images = root["num_images"] ? root["num_images"].as<int>() : 0;
    adaptation.adapted_layers = root["adapted_layers"] ? root["adapted_layers"].as<int>() : 0;
    adaptation.target_weight = root["target_weight"] ? root["target_weight"].as<double>() : 1.0;
  } catch (const YAML::Exception& e) {
    fail(yaml_path, root,
         "num_images / adapted_layers must be integers, target_weight a number (" + e.msg + ")");
  }
  for (const YAML::Node& layer : root["layers"]) {
    if (!layer.IsMap() || !layer["name"]) fail(yaml_path, layer, "each layer needs a 'name'");
    BatchNormLayerStatistics statistics;
    statistics.layer = layer["name"].as<std::string>();
    statistics.mean = readValues(yaml_path, layer, "mean");
    statistics.variance = readValues(yaml_path, layer, "variance");
    if (statistics.mean.empty() || statistics.mean.size() != statistics.variance.size())
      fail(yaml_path, layer,
           "layer " + statistics.layer + ": mean and variance must have the same, non-zero length");
    for (double variance : statistics.variance) {
      if (variance < 0.0)
        fail(yaml_path, layer, "layer " + statistics.layer + ": negative variance");
    }
    adaptation.layers.push_back(std::move(statistics));
  }
  if (adaptation.layers.empty()) fail(yaml_path, root["layers"], "no layers");
  return adaptation;
}

void saveBatchNormAdaptation(const BatchNormAdaptation& adaptation, const std::string& yaml_path) {
  YAML::Emitter out;
  out.SetDoublePrecision(9);
  out << YAML::Comment(
      "Batch normalization statistics measured on the target camera's images (adapt_segmenter)");
  out << YAML::BeginMap;
  out << YAML::Key << "num_images" << YAML::Value << adaptation.num_images;
  out << YAML::Key << "adapted_layers" << YAML::Value << adaptation.adapted_layers;
  out << YAML::Key << "target_weight" << YAML::Value << adaptation.target_weight;
  out << YAML::Key << "layers" << YAML::Value << YAML::BeginSeq;
  for (const BatchNormLayerStatistics& layer : adaptation.layers) {
    out << YAML::BeginMap << YAML::Key << "name" << YAML::Value << layer.layer;
    out << YAML::Key << "mean" << YAML::Value << YAML::Flow << layer.mean;
    out << YAML::Key << "variance" << YAML::Value << YAML::Flow << layer.variance;
    out << YAML::EndMap;
  }
  out << YAML::EndSeq << YAML::EndMap;
  try {
    common::writeTextAtomically(yaml_path, std::string(out.c_str()) + "\n");
  } catch (const common::AtomicWriteError& error) {
    throw BatchNormAdaptationError("batch normalization statistics " + yaml_path + ": " +
                                   error.reason());
  }
}

namespace {

bool isConvolution(const cv::Ptr<cv::dnn::Layer>& layer) {
  return (layer->type == "Convolution" || layer->type == "Deconvolution") && !layer->blobs.empty();
}

int convolutionOutputChannels(const cv::Ptr<cv::dnn::Layer>& layer) {
  // Convolution weights: out x in x kh x kw; deconvolution: in x out x kh x kw (one group).
  return layer->type == "Deconvolution" ? layer->blobs[0].size[1] : layer->blobs[0].size[0];
}

}  // namespace

std::vector<BatchNormSite> findBatchNormSites(cv::dnn::Net& net) {
  const std::vector<std::string> names = net.getLayerNames();
  std::map<std::string, int> consumers;
  for (int id = 1; id <= static_cast<int>(names.size()); ++id)
    for (const cv::Ptr<cv::dnn::Layer>& input : net.getLayerInputs(id)) ++consumers[input->name];
  std::vector<BatchNormSite> sites;
  for (int id = 1; id <= static_cast<int>(names.size()); ++id) {
    const cv::Ptr<cv::dnn::BatchNormLayer> batch_norm =
        net.getLayer(id).dynamicCast<cv::dnn::BatchNormLayer>();
    if (!batch_norm || batch_norm->blobs.size() < 2) continue;
    const std::vector<cv::Ptr<cv::dnn::Layer>> inputs = net.getLayerInputs(id);
    if (inputs.size() != 1) continue;
    BatchNormSite site;
    site.layer = batch_norm->name;
    site.input = inputs[0]->name;
    site.epsilon = batch_norm->epsilon;
    const cv::Mat mean = batch_norm->blobs[0], variance = batch_norm->blobs[1];
    const int channels = static_cast<int>(mean.total());
    if (mean.type() != CV_32F || variance.type() != CV_32F ||
        static_cast<int>(variance.total()) != channels)
      continue;
    for (int c = 0; c < channels; ++c) {
      site.mean.push_back(mean.ptr<float>()[c]);
      site.sigma.push_back(std::sqrt(std::max(0.0, variance.ptr<float>()[c] + site.epsilon)));
    }
    site.foldable.assign(channels, 0);
    // The producer's output must feed this layer alone: the map changes what it outputs.
    if (consumers[site.input] != 1) {
      sites.push_back(std::move(site));
      continue;
    }
    const auto add_producer = [&](const cv::Ptr<cv::dnn::Layer>& layer, int first_channel) {
      const int produced = convolutionOutputChannels(layer);
      if (first_channel + produced > channels || layer->blobs[0].type() != CV_32F) return;
      site.producers.push_back(
          {layer->name, layer->type == "Deconvolution", first_channel, produced});
      std::fill(site.foldable.begin() + first_channel,
                site.foldable.begin() + first_channel + produced, 1);
    };
    if (isConvolution(inputs[0])) {
      add_producer(inputs[0], 0);
    } else if (inputs[0]->type == "Concat") {
      // ENet's first block concatenates a convolution with a max pooling of the image: the
      // convolution's channels can be adapted, the pooled ones stay. Channel offsets are known
      // when at most one input (the last unknown one) is not a convolution.
      const std::vector<cv::Ptr<cv::dnn::Layer>> parts =
          net.getLayerInputs(net.getLayerId(site.input));
      int known = 0, unknown = 0;
      for (const auto& part : parts) {
        if (isConvolution(part) && consumers[part->name] == 1)
          known += convolutionOutputChannels(part);
        else
          ++unknown;
      }
      if (unknown <= 1) {
        int offset = 0;
        for (const auto& part : parts) {
          if (isConvolution(part) && consumers[part->name] == 1) {
            add_producer(part, offset);
            offset += convolutionOutputChannels(part);
          } else {
            offset += channels - known;
          }
        }
      }
    }
    sites.push_back(std::move(site));
  }
  return sites;
}

void foldChannelMap(cv::dnn::Net& net, const BatchNormSite& site, const std::vector<double>& scale,
                    const std::vector<double>& offset) {
  for (const BatchNormSite::Producer& producer : site.producers) {
    const cv::Ptr<cv::dnn::Layer> layer = net.getLayer(producer.layer);
    cv::Mat weights = layer->blobs[0];
    CV_Assert(weights.isContinuous() && weights.type() == CV_32F);
    float* w = weights.ptr<float>();
    const std::size_t kernel = weights.total() / weights.size[0] / weights.size[1];
    if (layer->blobs.size() < 2)
      layer->blobs.push_back(cv::Mat::zeros(producer.channels, 1, CV_32F));
    float* bias = layer->blobs[1].ptr<float>();
    for (int k = 0; k < producer.channels; ++k) {
      const int c = producer.first_channel + k;
      const float a = static_cast<float>(scale[c]);
      if (producer.deconvolution) {
        for (int i = 0; i < weights.size[0]; ++i) {
          float* slice = w + (static_cast<std::size_t>(i) * weights.size[1] + k) * kernel;
          for (std::size_t j = 0; j < kernel; ++j) slice[j] *= a;
        }
      } else {
        float* slice = w + static_cast<std::size_t>(k) * weights.total() / weights.size[0];
        for (std::size_t j = 0; j < weights.total() / weights.size[0]; ++j) slice[j] *= a;
      }
      bias[k] = static_cast<float>(scale[c] * bias[k] + offset[c]);
    }
  }
}

void channelMapFor(const BatchNormSite& site, std::size_t channel, double mean, double variance,
                   double* scale, double* offset) {
  *scale = site.sigma[channel] / std::sqrt(variance + site.epsilon);
  *offset = site.mean[channel] - *scale * mean;
}

}  // namespace perception
}  // namespace inekf_semantic_mapping
