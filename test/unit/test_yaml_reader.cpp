// The strict config reader that every config file and every node's private parameters go through.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/common/yaml_reader.h"
#include "test_data.h"

namespace {

using inekf_semantic_mapping::common::ConfigError;
using inekf_semantic_mapping::common::loadYamlFile;
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
  reader->renamed("label_wait", "label_wait_s");
  reader->read("label_wait_s", &wait_s);
}

// Collects the readers' warnings while it lives, then restores the default handler.
class WarningCapture {
 public:
  WarningCapture() {
    inekf_semantic_mapping::common::setConfigWarningHandler(
        [this](const std::string& message) { warnings.push_back(message); });
  }
  ~WarningCapture() {
    inekf_semantic_mapping::common::setConfigWarningHandler(
        [](const std::string& message) { std::cerr << "warning: " << message << std::endl; });
  }
  std::vector<std::string> warnings;
};

TEST(YamlReader, AnOldKeyNameIsReadAsTheNewOneWithOneWarningNamingBoth) {
  WarningCapture capture;
  YamlReader reader("config/x.yaml", YAML::Load("a: 1\nlabel_wait: 0.5\n"), /*cite_lines=*/true);
  reader.renamed("label_wait", "label_wait_s");
  double wait_s = 3.0;
  reader.read("label_wait_s", &wait_s);
  int a = 0;
  reader.read("a", &a);
  EXPECT_NO_THROW(reader.rejectUnknown());  // the old name counts as read
  EXPECT_DOUBLE_EQ(wait_s, 0.5);
  ASSERT_EQ(capture.warnings.size(), 1u);
  EXPECT_EQ(capture.warnings[0],
            "config/x.yaml:2: key 'label_wait' is deprecated, renamed to 'label_wait_s' (the old "
            "name is still accepted in this release)");
  // A bad value under the old name is cited by the name the file has.
  YamlReader bad("p", YAML::Load("label_wait: soon"));
  bad.renamed("label_wait", "label_wait_s");
  try {
    bad.read("label_wait_s", &wait_s);
    FAIL() << "a non-number was read";
  } catch (const ConfigError& e) {
    EXPECT_EQ(std::string(e.what()),
              "p: key 'label_wait' (now 'label_wait_s') is not a number: 'soon'");
  }
}

TEST(YamlReader, TheNewNameAloneWarnsOfNothingAndBothNamesAreAnError) {
  WarningCapture capture;
  EXPECT_EQ(errorOf("label_wait_s: 1.0", readWait), "no error");
  EXPECT_TRUE(capture.warnings.empty());
  EXPECT_EQ(errorOf("label_wait: 1.0\nlabel_wait_s: 2.0", readWait),
            "ROS parameters of /node: key 'label_wait' was renamed to 'label_wait_s', which is set "
            "too: remove 'label_wait'");
}

TEST(YamlReader, UnknownAndMistypedKeysNameTheKey) {
  EXPECT_EQ(errorOf("label_wiat_s: 1.0", readWait),
            "ROS parameters of /node: key 'label_wiat_s' is not a known key");
  EXPECT_NE(errorOf("label_wait_s: soon", readWait).find("'label_wait_s' is not a number"),
            std::string::npos);
}

TEST(YamlReader, ListsOfNumbersAreCheckedItemByItem) {
  YamlReader reader("test", YAML::Load("mean: [1, 2.5, 3]\nids: [7, 8]\nbad: [1, x]\nhalf: [1.5]"));
  std::vector<double> mean;
  reader.read("mean", &mean);
  EXPECT_EQ(mean, (std::vector<double>{1.0, 2.5, 3.0}));
  std::vector<int> ids;
  reader.read("ids", &ids);
  EXPECT_EQ(ids, (std::vector<int>{7, 8}));
  std::vector<int> unset{4};
  reader.read("absent", &unset);  // left as it was
  EXPECT_EQ(unset, std::vector<int>{4});
  EXPECT_THROW(reader.read("bad", &mean), ConfigError);
  EXPECT_THROW(reader.read("half", &ids), ConfigError);
}

TEST(YamlReader, AParsedFileNamesTheLineOfTheKey) {
  const std::string text = "a: 1\nsection:\n  b: 2\n  typo: 3\n";
  YamlReader cited("card.yaml", YAML::Load(text), /*cite_lines=*/true);
  int a = 0, b = 0;
  cited.read("a", &a);
  cited.read("section.b", &b);
  try {
    cited.rejectUnknown();
    ADD_FAILURE() << "the unknown key was accepted";
  } catch (const ConfigError& e) {
    EXPECT_EQ(std::string(e.what()), "card.yaml:4: key 'section.typo' is not a known key");
  }
  YamlReader plain("ROS parameters of /node", YAML::Load(text));  // no lines: not a file's
  plain.read("a", &a);
  plain.read("section.b", &b);
  EXPECT_THROW(plain.rejectUnknown(), ConfigError);
  try {
    plain.rejectUnknown();
  } catch (const ConfigError& e) {
    EXPECT_EQ(std::string(e.what()),
              "ROS parameters of /node: key 'section.typo' is not a known key");
  }
}

// A folder given for a file (--config, --model-card) failed with "basic_filebuf::underflow error
// reading the file: Is a directory", naming neither; a syntax error names the file and its line.
TEST(YamlReader, AFileThatIsAFolderMissingOrNotYamlIsNamed) {
  const std::string dir = inekf_semantic_mapping::test::makeTempDir("yaml_files");
  const auto error = [](const std::string& path) {
    try {
      loadYamlFile(path);
    } catch (const ConfigError& e) {
      return std::string(e.what());
    }
    return std::string("loaded");
  };
  EXPECT_EQ(error(dir), dir + ": is a folder, not a file");
  EXPECT_EQ(error(dir + "/missing.yaml"),
            dir + "/missing.yaml: file not found (or not a regular file)");
  std::ofstream(dir + "/bad.yaml") << "a: 1\nb: [2, 3\n";
  EXPECT_EQ(error(dir + "/bad.yaml")
                .rfind(dir + "/bad.yaml: YAML syntax error: yaml-cpp: error at line 3", 0),
            0u)
      << error(dir + "/bad.yaml");
  std::ofstream(dir + "/good.yaml") << "a: 1\n";
  EXPECT_EQ(loadYamlFile(dir + "/good.yaml")["a"].as<int>(), 1);
  std::filesystem::remove_all(dir);
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
