// OXTS lines (30 numbers) and timestamps.txt lines.
#include <cstdint>
#include <string>

#include "inekf_semantic_mapping/kitti/errors.h"
#include "inekf_semantic_mapping/kitti/oxts.h"
#include "inekf_semantic_mapping/kitti/timestamps.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    inekf_semantic_mapping::kitti::parseOxtsLine(text, "fuzz.txt", 1);
  } catch (const std::exception&) {
  }
  try {
    inekf_semantic_mapping::kitti::parseKittiTimestampNs(text);
  } catch (const std::exception&) {
  }
  return 0;
}
