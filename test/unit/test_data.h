// Where unit tests find data. Third-party data lives in ../shared beside the repository (never
// in it); a test that needs it calls ISM_REQUIRE_SHARED(...) and is skipped with a loud message
// when it is absent. ISM_SHARED_DIR in the environment overrides the compiled-in default.
#pragma once

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <utility>

namespace inekf_semantic_mapping {
namespace test {

inline std::string sharedDir() {
  const char* from_env = std::getenv("ISM_SHARED_DIR");
  return from_env && *from_env ? std::string(from_env) : std::string(ISM_SHARED_DIR_DEFAULT);
}

inline std::string sharedPath(const std::string& relative) { return sharedDir() + "/" + relative; }

inline std::string repoPath(const std::string& relative) {
  return std::string(ISM_REPO_ROOT) + "/" + relative;
}

// The network adapted to the KITTI camera (scripts/adapt_segmentation.sh) where one is kept:
// $ISM_ADAPTED_MODEL, output/models/kitti/ in the repository, ../shared/models/kitti-adapted/.
// The last candidate when there is none (the caller skips on a missing file).
inline std::string adaptedModelPath() {
  const char* from_env = std::getenv("ISM_ADAPTED_MODEL");
  if (from_env && *from_env) return from_env;
  const std::string in_repo = repoPath("output/models/kitti/kitti_adapted.onnx");
  if (std::filesystem::exists(in_repo)) return in_repo;
  return sharedPath("models/kitti-adapted/kitti_adapted.onnx");
}

// A fresh temporary directory for one test; removed by the caller if it wants to.
inline std::string makeTempDir(const std::string& tag) {
  namespace fs = std::filesystem;
  fs::path dir = fs::temp_directory_path() /
                 ("ism_" + tag + "_" + std::to_string(static_cast<long>(::getpid())));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir.string();
}

// Writes `content` to `path`, creating its folders.
inline void writeFile(const std::string& path, const std::string& content) {
  std::filesystem::create_directories(std::filesystem::path(path).parent_path());
  std::ofstream(path, std::ios::binary) << content;
}

// Runs a shell command (a tool under test); returns its exit status and what it printed, stdout
// and stderr together.
inline std::pair<int, std::string> runCommand(const std::string& command) {
  std::string output;
  FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  if (!pipe) return {-1, ""};
  char buffer[4096];
  while (std::fgets(buffer, sizeof(buffer), pipe)) output += buffer;
  const int status = pclose(pipe);
  return {WEXITSTATUS(status), output};
}

}  // namespace test
}  // namespace inekf_semantic_mapping

// Skips the current test, loudly, when ../shared/<relative> does not exist.
#define ISM_REQUIRE_SHARED(relative)                                                               \
  do {                                                                                             \
    const std::string ism_required_path = ::inekf_semantic_mapping::test::sharedPath(relative);    \
    if (!std::filesystem::exists(ism_required_path)) {                                             \
      std::cerr << "\n*** SKIPPED: shared data not found: " << ism_required_path                   \
                << "\n*** (put the shared/ data folder beside the repository to run this test)\n"; \
      GTEST_SKIP() << "shared data not found: " << ism_required_path;                              \
    }                                                                                              \
  } while (0)
