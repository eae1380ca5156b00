// YAML configs: the semantic-mapping config, the localizer's inekf.yaml and model cards.
#include <yaml-cpp/yaml.h>

#include "fuzz_support.h"
#include "inekf_semantic_mapping/common/yaml_reader.h"
#include "inekf_semantic_mapping/estimation/localizer.h"
#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"
#include "inekf_semantic_mapping/perception/model_card.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  namespace ism = inekf_semantic_mapping;
  // A deprecated key name warns on stderr, which would flood the fuzzer's output (the warning
  // itself is tested in test_yaml_reader).
  static const bool quiet = [] {
    ism::common::setConfigWarningHandler(nullptr);
    return true;
  }();
  (void)quiet;
  const std::string path = ism_fuzz::writeInput(data, size, "config.yaml");
  try {
    ism::mapping::loadSemanticMappingConfig(path);
  } catch (const std::exception&) {
  }
  try {
    ism::estimation::LocalizerConfig::fromYamlFile(path);
  } catch (const std::exception&) {
  }
  try {
    ism::perception::loadModelCard(path);
  } catch (const std::exception&) {
  }
  return 0;
}
