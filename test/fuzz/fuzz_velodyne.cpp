// Velodyne scans (.bin float32 x y z r, and the text format) and SemanticKITTI .label files.
#include "fuzz_support.h"
#include "inekf_semantic_mapping/kitti/velodyne.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  namespace kitti = inekf_semantic_mapping::kitti;
  try {
    const kitti::VelodyneScan scan =
        kitti::readVelodyneBin(ism_fuzz::writeInput(data, size, "s.bin"));
    kitti::computeRings(scan);
  } catch (const std::exception&) {
  }
  try {
    kitti::readVelodyneText(ism_fuzz::writeInput(data, size, "s.txt"));
  } catch (const std::exception&) {
  }
  try {
    kitti::readLabelFile(ism_fuzz::writeInput(data, size, "s.label"));
  } catch (const std::exception&) {
  }
  return 0;
}
