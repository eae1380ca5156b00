// Atomic file writes for the generator (write a temporary file beside the target, rename).
#pragma once

#include <cstdio>
#include <filesystem>
#include <stdexcept>
#include <string>

namespace inekf_semantic_mapping {
namespace synthetic {
namespace internal {

inline void writeFileAtomic(const std::string& path, const void* data, std::size_t size) {
  const std::string tmp = path + ".tmp";
  std::FILE* file = std::fopen(tmp.c_str(), "wb");
  if (!file) throw std::runtime_error(tmp + ": cannot open for writing");
  const bool ok = (size == 0 || std::fwrite(data, 1, size, file) == size) && std::fflush(file) == 0;
  std::fclose(file);
  if (!ok) throw std::runtime_error(tmp + ": write failed (disk full?)");
  std::filesystem::rename(tmp, path);
}

inline void writeFileAtomic(const std::string& path, const std::string& text) {
  writeFileAtomic(path, text.data(), text.size());
}

}  // namespace internal
}  // namespace synthetic
}  // namespace inekf_semantic_mapping
