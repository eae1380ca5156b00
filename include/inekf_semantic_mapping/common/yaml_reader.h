// A strict reader of YAML configuration maps: every value is checked for its type, and keys that
// nobody reads are errors. Messages name the source (a file, or "ROS parameters of /node") and
// the key, e.g. "config/x.yaml: key 'sensor_model.hit' is not a number"; a reader of a parsed
// file (fromFile, or cite_lines) also names the key's line: "config/x.yaml:12: key ...".
// The configs, the nodes' private parameters and the model cards all go through it.
#pragma once

#include <yaml-cpp/yaml.h>

#include <functional>
#include <map>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

namespace inekf_semantic_mapping {
namespace common {

class ConfigError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

// The YAML document in `path`. Throws ConfigError naming the path when it is missing, is not a
// regular file (a folder given for a file failed with "basic_filebuf::underflow") or is not
// valid YAML (with the line).
YAML::Node loadYamlFile(const std::string& path);

// Where the readers' warnings (a deprecated key name) go: by default "warning: ..." on stderr;
// the ROS nodes route them to rosconsole; an empty handler drops them. Set it before any reader
// runs (not thread-safe).
using ConfigWarningHandler = std::function<void(const std::string& message)>;
void setConfigWarningHandler(ConfigWarningHandler handler);
void configWarning(const std::string& message);

class YamlReader {
 public:
  // `root` must be a map (or null: an empty file; or missing: a section that is not there).
  // cite_lines: messages name the line of the key (for a root parsed from text).
  YamlReader(std::string source, YAML::Node root, bool cite_lines = false);
  // Parses a file; throws ConfigError naming it when it cannot be read or is not a YAML map.
  static YamlReader fromFile(const std::string& path);

  // Read `key` ("section.key" for nested maps) into *out if present; leave *out otherwise.
  void read(const std::string& key, double* out);  // finite numbers only
  void read(const std::string& key, int* out);     // integers that fit an int
  void read(const std::string& key, bool* out);
  void read(const std::string& key, std::string* out);
  void read(const std::string& key, std::vector<std::string>* out);  // a list of strings
  void read(const std::string& key, std::vector<double>* out);       // finite numbers
  void read(const std::string& key, std::vector<int>* out);          // integers that fit an int
  // read(), then the value (read or kept) must lie in [min, max], or in (min, max] where
  // min_exclusive; otherwise fails naming the key and the range.
  void readInRange(const std::string& key, double* out, double min, double max,
                   bool min_exclusive = false);
  // The same for an integer in [min, max].
  void readInRange(const std::string& key, int* out, int min, int max);
  // A name from a set of choices, converted once by `parse` (which throws std::invalid_argument
  // for a name it does not know, saying which it knows): the error names the key. Leaves *out
  // where the key is absent or empty.
  template <typename T, typename Parse>
  void readChoice(const std::string& key, Parse parse, T* out) {
    std::string name;
    read(key, &name);
    if (name.empty()) return;
    try {
      *out = parse(name);
    } catch (const std::invalid_argument& error) {
      fail(key, error.what());
    }
  }
  // Keys (or whole sections: "name.*") that are valid but read elsewhere.
  void allow(const std::string& key);
  // A key that gained its unit (resolution -> resolution_m), accepted under its old name for one
  // release: call it before reading `new_key`. Where only `old_key` is set, reads of `new_key`
  // take its value and one warning names both; where both are set, throws ConfigError.
  void renamed(const std::string& old_key, const std::string& new_key);
  // Whether `key` is set (marks it read).
  bool has(const std::string& key);
  // Throws ConfigError for the first key that was neither read nor allowed.
  void rejectUnknown() const;

  [[noreturn]] void fail(const std::string& key, const std::string& what) const;
  const std::string& source() const { return source_; }

 private:
  YAML::Node lookup(const std::string& key);      // marks the key read
  YAML::Node find(const std::string& key) const;  // through a renamed key's old name
  YAML::Node findPath(const std::string& path) const;
  // "source" or, for a parsed file, "source:LINE" of `node`.
  std::string citation(const YAML::Node& node) const;
  void collectKeys(const YAML::Node& node, const std::string& prefix,
                   std::vector<std::string>* keys) const;

  std::string source_;
  YAML::Node root_;
  std::set<std::string> used_;
  std::map<std::string, std::string> old_names_;  // new key -> the old name set in the file
  bool cite_lines_ = false;
};

}  // namespace common
}  // namespace inekf_semantic_mapping
