// The strict config reader that every config file and every node's private parameters go through.
#include <gtest/gtest.h>

#include <string>

#include "inekf_semantic_mapping/common/yaml_reader.h"

namespace {

using inekf_semantic_mapping::common::ConfigError;
using inekf_semantic_mapping::common::YamlReader;

std::string errorOf(const std::string& yaml, void (*reads)(YamlReader*)) {
  try {
    YamlReader reader("ROS parameters of /node", YAML::Load(yaml));
    reads(&reader);
    reader.rejectUnknown();
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "no error";
}

void readWait(YamlReader* reader) {
  double wait_s = 0.0;
  reader->read("label_wait_s", &wait_s);
  reader->renamed("label_wait", "label_wait_s");
}

TEST(YamlReader, RenamedKeyNamesTheNewKeyAndTheSource) {
  EXPECT_EQ(errorOf("label_wait_s: 1.0", readWait), "no error");
  EXPECT_EQ(errorOf("label_wait: 1.0", readWait),
            "ROS parameters of /node: key 'label_wait' was renamed to 'label_wait_s'");
}

TEST(YamlReader, UnknownAndMistypedKeysNameTheKey) {
  EXPECT_EQ(errorOf("label_wiat_s: 1.0", readWait),
            "ROS parameters of /node: key 'label_wiat_s' is not a known key");
  EXPECT_NE(errorOf("label_wait_s: soon", readWait).find("'label_wait_s' is not a number"),
            std::string::npos);
}

TEST(YamlReader, AMissingSectionIsAnEmptyMap) {
  const YAML::Node root = YAML::Load("resolution: 0.2");
  const YAML::Node& const_root = root;  // operator[] of a const map: an invalid node
  YamlReader reader("test, diagnostics", const_root["diagnostics"]);
  double window_s = 10.0;
  reader.read("window_s", &window_s);
  EXPECT_EQ(window_s, 10.0);
  EXPECT_NO_THROW(reader.rejectUnknown());
}

TEST(YamlReader, HasMarksTheKeyRead) {
  YamlReader reader("test", YAML::Load("origin_lat: 49.0"));
  EXPECT_TRUE(reader.has("origin_lat"));
  EXPECT_FALSE(reader.has("origin_lon"));
  EXPECT_NO_THROW(reader.rejectUnknown());
}

}  // namespace
