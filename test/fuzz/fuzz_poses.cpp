// KITTI pose files (12 numbers per line).
#include "fuzz_support.h"
#include "inekf_semantic_mapping/kitti/poses.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    inekf_semantic_mapping::kitti::readKittiPoses(ism_fuzz::writeInput(data, size, "poses.txt"));
  } catch (const std::exception&) {
  }
  return 0;
}
