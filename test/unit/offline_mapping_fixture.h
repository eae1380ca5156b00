// The small labelled scan sequence (SemanticKITTI layout: velodyne/, labels/, poses.txt,
// calib.txt) that the offline mapping tests write in a temporary folder, and a map built from it.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/mapping/offline_mapping.h"
#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace mapping {

template <typename T>
inline void writeBinary(const std::string& path, const std::vector<T>& values) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(values.data()),
            static_cast<std::streamsize>(values.size() * sizeof(T)));
}

// Velodyne -> cam0 of KITTI: x_cam = -y_velo, y_cam = -z_velo, z_cam = x_velo, plus an offset.
const char kCalib[] =
    "P0: 700 0 600 0 0 700 180 0 0 0 1 0\n"
    "P1: 700 0 600 -380 0 700 180 0 0 0 1 0\n"
    "P2: 700 0 600 45 0 700 180 0 0 0 1 0\n"
    "P3: 700 0 600 -330 0 700 180 0 0 0 1 0\n"
    "Tr: 0 -1 0 0.1 0 0 -1 -0.2 1 0 0 -0.3\n";

class OfflineMappingTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = test::makeTempDir("offline_mapping");
    std::filesystem::create_directories(dir_ + "/velodyne");
    std::filesystem::create_directories(dir_ + "/labels");
    std::ofstream(dir_ + "/calib.txt") << kCalib;
    // Scan 0 at the origin; scan 1 with cam0 moved 3 m forward (cam z) and 1 m right (cam x).
    std::ofstream(dir_ + "/poses.txt") << "1 0 0 0 0 1 0 0 0 0 1 0\n"
                                          "1 0 0 1 0 1 0 0 0 0 1 3\n";
    // Each scan: a wall point straight ahead labeled 50 (building), one labeled 300 (an id
    // outside the configured set), one unlabeled (0).
    for (int scan = 0; scan < 2; ++scan) {
      writeBinary<float>(
          dir_ + "/velodyne/00000" + std::to_string(scan) + ".bin",
          {10.05f, 0.05f, 0.05f, 0.5f, 5.05f, 4.05f, 0.05f, 0.5f, 6.05f, -3.05f, 0.05f, 0.5f});
      writeBinary<std::uint32_t>(dir_ + "/labels/00000" + std::to_string(scan) + ".label",
                                 {50u | (7u << 16), 300u, 0u});
    }
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  OfflineSequence options() const {
    OfflineSequence o;
    o.scans_dir = dir_ + "/velodyne";
    o.labels_dir = dir_ + "/labels";
    o.poses_path = dir_ + "/poses.txt";
    o.calib_path = dir_ + "/calib.txt";
    return o;
  }
  static std::unique_ptr<SemanticMappingSession> buildMap(const OfflineSequence& sequence) {
    SemanticMappingConfig config;
    config.resolution_m = 0.1;
    config.max_range_m = 30;
    config.class_set = mapping::MapClassSet::kSemanticKitti;
    auto session = std::make_unique<SemanticMappingSession>(config);
    mapSequence(sequence, session.get(), nullptr, nullptr);
    return session;
  }
  std::string dir_;
};

}  // namespace mapping
}  // namespace inekf_semantic_mapping
