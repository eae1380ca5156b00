// Saved semantic maps (.ot): the hardened reader must refuse, never crash or recurse unbounded.
#include "fuzz_support.h"
#include "inekf_semantic_mapping/mapping/map_io.h"
#include "inekf_semantic_mapping/mapping/semantic_octree.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    auto tree = inekf_semantic_mapping::mapping::loadSemanticOcTree(
        ism_fuzz::writeInput(data, size, "m.ot"));
    tree->updateInnerOccupancy();
    inekf_semantic_mapping::mapping::countOccupiedFinestVoxels(*tree);
  } catch (const std::exception&) {
  }
  return 0;
}
