// The small camera scene the mapping tests share: a 100 x 100 pinhole camera at the sensor
// origin looking along +z, and its label image (left half road, right half building, the top
// rows without a class).
#pragma once

#include <cstdint>
#include <vector>

#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"

namespace inekf_semantic_mapping {
namespace mapping {
namespace test_scene {

inline CameraModel testCamera() {
  CameraModel camera;
  camera.P << 50, 0, 50, 0, 0, 50, 50, 0, 0, 0, 1, 0;
  camera.width = 100;
  camera.height = 100;
  return camera;
}

// Cityscapes labelIds: road (7) left, building (11) right, "unlabeled" (0: no evidence) in the
// rows above 48.
inline std::vector<std::uint8_t> testLabels() {
  std::vector<std::uint8_t> pixels(100 * 100);
  for (int r = 0; r < 100; ++r) {
    for (int c = 0; c < 100; ++c) pixels[r * 100 + c] = r < 48 ? 0 : (c < 50 ? 7 : 11);
  }
  return pixels;
}

}  // namespace test_scene
}  // namespace mapping
}  // namespace inekf_semantic_mapping
