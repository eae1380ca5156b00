// Saving and loading semantic maps. Every save is atomic: the file is written beside its
// destination under a temporary name, then renamed over it, so a reader never sees half a map.
// Failures throw MapIoError naming the path and the reason.
#pragma once

#include <cstddef>
#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace inekf_semantic_mapping {
namespace common {
class AtomicFileSet;
}  // namespace common
}  // namespace inekf_semantic_mapping

namespace inekf_semantic_mapping {
namespace mapping {

class SemanticOcTree;

class MapIoError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

enum class MapFormat {
  kSemanticOt,  // .ot with class evidence: loads back with loadSemanticOcTree
  kColorOt,     // octomap::ColorOcTree .ot colored by the most likely class (octovis)
  kPly,         // ASCII PLY: occupied leaves at finest resolution, x y z label red green blue
};

// "ot" | "color_ot" | "ply"; empty: from the extension (.ply -> ply, .ot -> ot; another one is
// refused). Throws MapIoError.
MapFormat parseMapFormat(const std::string& format, const std::string& path);

// Writes `tree` in `format` to `path`; returns the map's occupied voxels at the finest resolution
// (the same for every format; an .ot stores 8 equal ones as one pruned leaf). Refreshes inner
// nodes first.
std::size_t saveMap(SemanticOcTree& tree, const std::string& path, MapFormat format);
// Several formats of one map (a tool's --output, --export-ply, --color-ot) as a set: all are
// written, or none replaces its target; `stage_also` adds the tool's other outputs of the run
// (its grids) to the same set. Returns saveMap's count for each.
std::vector<std::size_t> saveMaps(
    SemanticOcTree& tree, const std::vector<std::pair<std::string, MapFormat>>& outputs,
    const std::function<void(common::AtomicFileSet*)>& stage_also = nullptr);

// Reads a .ot written by saveMap (through octomap's factory); throws MapIoError if the file is
// missing, unreadable or holds another tree type.
std::unique_ptr<SemanticOcTree> loadSemanticOcTree(const std::string& path);

// Number of occupied leaves at the finest resolution (pruned leaves expanded).
std::size_t countOccupiedFinestVoxels(const SemanticOcTree& tree);

}  // namespace mapping
}  // namespace inekf_semantic_mapping
