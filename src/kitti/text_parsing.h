// Small helpers shared by the KITTI readers (private to src/kitti).
#pragma once

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/kitti/errors.h"

namespace inekf_semantic_mapping {
namespace kitti {
namespace detail {

inline std::vector<std::string> splitWhitespace(const std::string& line) {
  std::vector<std::string> tokens;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    const std::size_t start = i;
    while (i < line.size() && !std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    if (i > start) tokens.push_back(line.substr(start, i - start));
  }
  return tokens;
}

// Whole-token strtod: "1.5x" and "" are errors, not 1.5 and 0.
inline bool parseDouble(const std::string& token, double* value) {
  if (token.empty()) return false;
  errno = 0;
  char* end = nullptr;
  *value = std::strtod(token.c_str(), &end);
  return end == token.c_str() + token.size() && errno != ERANGE;
}

inline std::ifstream openOrThrow(const std::string& path) {
  if (std::filesystem::is_directory(path)) {
    throw KittiFormatError(path, "is a directory, expected a file");
  }
  std::ifstream stream(path);
  if (!stream) throw KittiFormatError(path, "cannot open file (missing or unreadable)");
  return stream;
}

inline std::string trim(const std::string& text) {
  const auto first = text.find_first_not_of(" \t\r\n");
  if (first == std::string::npos) return "";
  const auto last = text.find_last_not_of(" \t\r\n");
  return text.substr(first, last - first + 1);
}

}  // namespace detail
}  // namespace kitti
}  // namespace inekf_semantic_mapping
