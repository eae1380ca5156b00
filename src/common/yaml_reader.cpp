#include "inekf_semantic_mapping/common/yaml_reader.h"

#include <cmath>
#include <filesystem>
#include <iostream>
#include <limits>
#include <utility>

namespace inekf_semantic_mapping {
namespace common {
namespace {

ConfigWarningHandler& warningHandler() {
  static ConfigWarningHandler handler = [](const std::string& message) {
    std::cerr << "warning: " << message << std::endl;
  };
  return handler;
}

}  // namespace

void setConfigWarningHandler(ConfigWarningHandler handler) {
  warningHandler() = std::move(handler);
}

void configWarning(const std::string& message) {
  if (warningHandler()) warningHandler()(message);
}

YamlReader::YamlReader(std::string source, YAML::Node root, bool cite_lines)
    : source_(std::move(source)), cite_lines_(cite_lines) {
  // IsDefined first and reset(), not operator=: a missing section of a const map is an invalid
  // node, which throws on IsNull and on assignment (and assigning would write into `root`).
  if (!root.IsDefined() || root.IsNull()) {
    root_.reset(YAML::Node(YAML::NodeType::Map));
  } else if (!root.IsMap()) {
    throw ConfigError(source_ + ": expected a map of keys to values at the top level");
  } else {
    root_.reset(root);
  }
}

YAML::Node loadYamlFile(const std::string& path) {
  if (std::filesystem::is_directory(path)) throw ConfigError(path + ": is a folder, not a file");
  if (!std::filesystem::is_regular_file(path)) {
    throw ConfigError(path + ": file not found (or not a regular file)");
  }
  try {
    return YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    throw ConfigError(path + ": cannot read the file (permissions?)");
  } catch (const YAML::Exception& e) {
    throw ConfigError(path + ": YAML syntax error: " + e.what());
  }
}

YamlReader YamlReader::fromFile(const std::string& path) {
  return YamlReader(path, loadYamlFile(path), /*cite_lines=*/true);
}

std::string YamlReader::citation(const YAML::Node& node) const {
  if (!cite_lines_ || !node.IsDefined() || node.Mark().line < 0) return source_;
  return source_ + ":" + std::to_string(node.Mark().line + 1);
}

void YamlReader::fail(const std::string& key, const std::string& what) const {
  const std::string where = citation(find(key));
  // A value read through a renamed key is cited by the name the file has.
  const auto old_name = old_names_.find(key);
  const std::string name = old_name == old_names_.end()
                               ? "'" + key + "'"
                               : "'" + old_name->second + "' (now '" + key + "')";
  throw ConfigError(where + ": key " + name + " " + what);
}

YAML::Node YamlReader::lookup(const std::string& key) {
  used_.insert(key);
  return find(key);
}

YAML::Node YamlReader::find(const std::string& key) const {
  const auto old_name = old_names_.find(key);
  return findPath(old_name == old_names_.end() ? key : old_name->second);
}

YAML::Node YamlReader::findPath(const std::string& key) const {
  // Walk through const nodes: operator[] on a non-const node would insert the key.
  YAML::Node node;
  node.reset(root_);
  std::size_t begin = 0;
  while (true) {
    const std::size_t dot = key.find('.', begin);
    const std::string part = key.substr(begin, dot == std::string::npos ? dot : dot - begin);
    if (!node.IsMap()) return YAML::Node(YAML::NodeType::Undefined);
    const YAML::Node& const_node = node;
    const YAML::Node child = const_node[part];
    if (!child.IsDefined()) return YAML::Node(YAML::NodeType::Undefined);
    if (dot == std::string::npos) return child;
    node.reset(child);  // operator= would overwrite the referenced node's content
    begin = dot + 1;
  }
}

void YamlReader::read(const std::string& key, double* out) {
  const YAML::Node node = lookup(key);
  if (!node.IsDefined()) return;
  double value = 0.0;
  try {
    if (!node.IsScalar())
      fail(key, "is not a number (got a " + std::string(node.IsMap() ? "map" : "list") + ")");
    value = node.as<double>();
  } catch (const YAML::Exception&) {
    fail(key, "is not a number: '" + node.Scalar() + "'");
  }
  if (!std::isfinite(value)) fail(key, "must be a finite number");
  *out = value;
}

void YamlReader::readInRange(const std::string& key, double* out, double min, double max,
                             bool min_exclusive) {
  read(key, out);
  if ((min_exclusive ? *out > min : *out >= min) && *out <= max) return;
  std::ostringstream range;
  range << "must be in " << (min_exclusive ? "(" : "[") << min << ", " << max << "], got " << *out;
  fail(key, range.str());
}

void YamlReader::readInRange(const std::string& key, int* out, int min, int max) {
  read(key, out);
  if (*out >= min && *out <= max) return;
  fail(key, "must be an integer in [" + std::to_string(min) + ", " + std::to_string(max) +
                "], got " + std::to_string(*out));
}

void YamlReader::read(const std::string& key, int* out) {
  double value = 0.0;
  const YAML::Node node = lookup(key);
  if (!node.IsDefined()) return;
  read(key, &value);
  if (value != std::floor(value) || value < std::numeric_limits<int>::min() ||
      value > std::numeric_limits<int>::max()) {
    fail(key, "must be an integer in the range of int");
  }
  *out = static_cast<int>(value);
}

void YamlReader::read(const std::string& key, bool* out) {
  const YAML::Node node = lookup(key);
  if (!node.IsDefined()) return;
  try {
    if (!node.IsScalar()) fail(key, "is not true/false");
    *out = node.as<bool>();
  } catch (const YAML::Exception&) {
    fail(key, "is not true/false: '" + node.Scalar() + "'");
  }
}

void YamlReader::read(const std::string& key, std::string* out) {
  const YAML::Node node = lookup(key);
  if (!node.IsDefined()) return;
  if (!node.IsScalar()) fail(key, "is not a string");
  *out = node.Scalar();
}

void YamlReader::read(const std::string& key, std::vector<std::string>* out) {
  const YAML::Node node = lookup(key);
  if (!node.IsDefined()) return;
  if (!node.IsSequence()) fail(key, "is not a list of strings");
  std::vector<std::string> values;
  for (const YAML::Node& item : node) {
    if (!item.IsScalar()) fail(key, "is not a list of strings");
    values.push_back(item.Scalar());
  }
  *out = std::move(values);
}

void YamlReader::read(const std::string& key, std::vector<double>* out) {
  const YAML::Node node = lookup(key);
  if (!node.IsDefined()) return;
  if (!node.IsSequence()) fail(key, "is not a list of numbers");
  std::vector<double> values;
  for (const YAML::Node& item : node) {
    double value = 0.0;
    try {
      if (!item.IsScalar()) fail(key, "is not a list of numbers");
      value = item.as<double>();
    } catch (const YAML::Exception&) {
      fail(key, "is not a list of numbers: '" + item.Scalar() + "'");
    }
    if (!std::isfinite(value)) fail(key, "must hold finite numbers");
    values.push_back(value);
  }
  *out = std::move(values);
}

void YamlReader::read(const std::string& key, std::vector<int>* out) {
  std::vector<double> values;
  read(key, &values);
  if (!find(key).IsDefined()) return;
  std::vector<int> integers;
  for (double value : values) {
    if (value != std::floor(value) || value < std::numeric_limits<int>::min() ||
        value > std::numeric_limits<int>::max()) {
      fail(key, "must hold integers in the range of int");
    }
    integers.push_back(static_cast<int>(value));
  }
  *out = std::move(integers);
}

void YamlReader::allow(const std::string& key) { used_.insert(key); }

void YamlReader::renamed(const std::string& old_key, const std::string& new_key) {
  const YAML::Node old_node = findPath(old_key);
  if (!old_node.IsDefined()) return;
  used_.insert(old_key);
  if (findPath(new_key).IsDefined()) {
    fail(old_key, "was renamed to '" + new_key + "', which is set too: remove '" + old_key + "'");
  }
  old_names_[new_key] = old_key;
  configWarning(citation(old_node) + ": key '" + old_key + "' is deprecated, renamed to '" +
                new_key + "' (the old name is still accepted in this release)");
}

bool YamlReader::has(const std::string& key) { return lookup(key).IsDefined(); }

void YamlReader::collectKeys(const YAML::Node& node, const std::string& prefix,
                             std::vector<std::string>* keys) const {
  for (const auto& entry : node) {
    const std::string key = prefix + entry.first.as<std::string>();
    if (entry.second.IsMap() && !used_.count(key) && !used_.count(key + ".*")) {
      collectKeys(entry.second, key + ".", keys);
    } else {
      keys->push_back(key);
    }
  }
}

void YamlReader::rejectUnknown() const {
  std::vector<std::string> keys;
  collectKeys(root_, "", &keys);
  for (const std::string& key : keys) {
    if (used_.count(key) || used_.count(key + ".*")) continue;
    fail(key, "is not a known key");
  }
}

}  // namespace common
}  // namespace inekf_semantic_mapping
