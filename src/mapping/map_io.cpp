#include "inekf_semantic_mapping/mapping/map_io.h"

#include <octomap/AbstractOcTree.h>
#include <octomap/ColorOcTree.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/common/atomic_file.h"
#include "inekf_semantic_mapping/common/decimal_text.h"
#include "inekf_semantic_mapping/mapping/semantic_octree.h"

namespace inekf_semantic_mapping {
namespace mapping {
namespace {

// Writes through `write_body` into a temporary file beside `path`, then renames it over `path`
// (at once, or with the rest of `set` when one is given).
void writeAtomically(const std::string& path, const std::function<void(std::ostream&)>& write_body,
                     common::AtomicFileSet* set) {
  if (path.empty()) throw MapIoError("cannot save map: empty output path");
  try {
    if (set) {
      set->addStream(path, write_body);
    } else {
      common::writeStreamAtomically(path, write_body);
    }
  } catch (const common::AtomicWriteError& error) {
    throw MapIoError("cannot write map to '" + path + "': " + error.reason());
  }
}

// A ColorOcTree that can be built as a node-by-node mirror of a SemanticOcTree (same structure
// and occupancy, color = palette color of the most likely class).
class MirrorColorOcTree : public octomap::ColorOcTree {
 public:
  explicit MirrorColorOcTree(double resolution) : ColorOcTree(resolution) {}

  void mirror(const SemanticOcTree& source) {
    clear();
    if (!source.getRoot()) return;
    root = new octomap::ColorOcTreeNode();
    tree_size = 1;
    copyRecurs(source, source.getRoot(), root);
  }

 private:
  void copyRecurs(const SemanticOcTree& source, const SemanticOcTreeNode* from,
                  octomap::ColorOcTreeNode* to) {
    to->setLogOdds(from->getLogOdds());
    const ClassIndex index = from->mostLikelyClass();
    if (index != kNoClass && index < source.classSet().size()) {
      const auto& rgb = source.classSet().info(index).rgb;
      to->setColor(rgb[0], rgb[1], rgb[2]);
    } else {
      to->setColor(128, 128, 128);  // occupied, no class evidence
    }
    for (unsigned int i = 0; i < 8; ++i) {
      if (source.nodeChildExists(from, i)) {
        copyRecurs(source, source.getNodeChild(from, i), createNodeChild(to, i));
      }
    }
  }
};

}  // namespace

MapFormat parseMapFormat(const std::string& format, const std::string& path) {
  const std::string extension = std::filesystem::path(path).extension().string();
  // A format asked for by name under another format's extension (.bt: octomap's binary format)
  // gave a file every tool that goes by the name fails to read (PLY text named .ot, an octree
  // named .ply); another extension (or none) is the user's choice.
  const auto named = [&](MapFormat chosen, const char* own) {
    const bool other = extension == ".ot" || extension == ".ply" || extension == ".bt";
    if (other && extension != own) {
      throw MapIoError(path + ": format '" + format + "' under the extension '" + extension +
                       "', which other tools read as another format (name it " + own + ")");
    }
    return chosen;
  };
  if (format == "ot") return named(MapFormat::kSemanticOt, ".ot");
  if (format == "color_ot") return named(MapFormat::kColorOt, ".ot");
  if (format == "ply") return named(MapFormat::kPly, ".ply");
  if (format.empty()) {
    // From the extension; another one (.bt: octomap's own binary format, which tools would try
    // and fail to read) is refused rather than given a semantic octree under its name.
    if (extension == ".ply") return MapFormat::kPly;
    if (extension == ".ot") return MapFormat::kSemanticOt;
    throw MapIoError(path + ": no format given and the extension '" + extension +
                     "' is not .ot or .ply (format: ot, color_ot or ply)");
  }
  throw MapIoError("unknown map format '" + format + "' (expected ot, color_ot or ply)");
}

std::size_t countOccupiedFinestVoxels(const SemanticOcTree& tree) {
  std::size_t count = 0;
  const unsigned int max_depth = tree.getTreeDepth();
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    if (tree.isNodeOccupied(*it)) count += std::size_t{1} << (3 * (max_depth - it.getDepth()));
  }
  return count;
}

namespace {

// One output of saveMap / saveMaps (inner nodes already refreshed).
std::size_t saveMapInto(SemanticOcTree& tree, const std::string& path, MapFormat format,
                        common::AtomicFileSet* set) {
  switch (format) {
    case MapFormat::kSemanticOt: {
      writeAtomically(
          path,
          [&](std::ostream& out) {
            out.precision(17);  // octomap writes "res" as text: all of a double's digits
            tree.write(out);
          },
          set);
      return countOccupiedFinestVoxels(tree);
    }
    case MapFormat::kColorOt: {
      MirrorColorOcTree color(tree.getResolution());
      color.mirror(tree);
      writeAtomically(
          path,
          [&](std::ostream& out) {
            out.precision(17);
            color.write(out);
          },
          set);
      return countOccupiedFinestVoxels(tree);
    }
    case MapFormat::kPly: {
      const std::size_t vertex_count = countOccupiedFinestVoxels(tree);
      const unsigned int max_depth = tree.getTreeDepth();
      writeAtomically(
          path,
          [&](std::ostream& out) {
            out << "ply\nformat ascii 1.0\ncomment inekf_semantic_mapping semantic map, resolution "
                << tree.getResolution() << " m\nelement vertex " << vertex_count
                << "\nproperty float x\nproperty float y\nproperty float z\nproperty uint label\n"
                   "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n";
            // Lines gather in a buffer written in large pieces; each line is at most 3 numbers of
            // appendFixed4 (320 chars in its slowest case) and 4 of appendUnsigned.
            std::vector<char> text(std::size_t{1} << 16);
            std::size_t used = 0;
            const auto flush = [&] {
              out.write(text.data(), static_cast<std::streamsize>(used));
              used = 0;
            };
            for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
              if (!tree.isNodeOccupied(*it)) continue;
              const ClassIndex index = it->mostLikelyClass();
              const bool known = index != kNoClass && index < tree.classSet().size();
              const std::uint32_t label = known ? tree.classSet().info(index).label_id : 0;
              const std::array<std::uint8_t, 3> rgb =
                  known ? tree.classSet().info(index).rgb
                        : std::array<std::uint8_t, 3>{{128, 128, 128}};
              // A pruned leaf stands for 2^(3k) finest voxels: one vertex for each.
              const unsigned int cells = 1u << (max_depth - it.getDepth());
              const octomap::OcTreeKey base_key = it.getIndexKey();
              for (unsigned int dx = 0; dx < cells; ++dx) {
                for (unsigned int dy = 0; dy < cells; ++dy) {
                  for (unsigned int dz = 0; dz < cells; ++dz) {
                    const octomap::OcTreeKey key(base_key[0] + dx, base_key[1] + dy,
                                                 base_key[2] + dz);
                    const octomap::point3d center = tree.keyToCoord(key);
                    if (used + 1200 > text.size()) flush();
                    char* line = text.data() + used;
                    char* cursor = line;
                    for (const float coordinate : {center.x(), center.y(), center.z()}) {
                      cursor = common::appendFixed4(cursor, coordinate);
                      *cursor++ = ' ';
                    }
                    cursor = common::appendUnsigned(cursor, label);
                    for (const std::uint8_t channel : rgb) {
                      *cursor++ = ' ';
                      cursor = common::appendUnsigned(cursor, channel);
                    }
                    *cursor++ = '\n';
                    used += static_cast<std::size_t>(cursor - line);
                  }
                }
              }
            }
            flush();
          },
          set);
      return vertex_count;
    }
  }
  throw MapIoError("unhandled map format");
}

}  // namespace

std::size_t saveMap(SemanticOcTree& tree, const std::string& path, MapFormat format) {
  tree.updateInnerOccupancy();
  return saveMapInto(tree, path, format, nullptr);
}

std::vector<std::size_t> saveMaps(SemanticOcTree& tree,
                                  const std::vector<std::pair<std::string, MapFormat>>& outputs,
                                  const std::function<void(common::AtomicFileSet*)>& stage_also) {
  tree.updateInnerOccupancy();
  common::AtomicFileSet set;
  std::vector<std::size_t> counts;
  for (const auto& [path, format] : outputs)
    counts.push_back(saveMapInto(tree, path, format, &set));
  try {
    if (stage_also) stage_also(&set);
    set.commit();
  } catch (const common::AtomicWriteError& error) {
    throw MapIoError("cannot write map to '" + error.path() + "': " + error.reason());
  }
  return counts;
}

std::unique_ptr<SemanticOcTree> loadSemanticOcTree(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw MapIoError("cannot read map '" + path + "': " + std::strerror(errno));
  if (std::filesystem::is_directory(path)) {
    throw MapIoError("cannot read map '" + path + "': it is a directory");
  }
  // Check the tree type in the header before octomap's factory builds anything: octomap's own
  // readers recurse without a depth limit.
  std::string line;
  std::string id, size_text;
  for (int i = 0; i < 12 && std::getline(in, line) && line != "data"; ++i) {
    if (line.rfind("id ", 0) == 0) id = line.substr(3);
    if (line.rfind("size ", 0) == 0) size_text = line.substr(5);
  }
  if (id != "SemanticOcTree") {
    throw MapIoError("map '" + path + "' holds " + (id.empty() ? "no octomap header" : "a " + id) +
                     ", not a SemanticOcTree");
  }
  in.clear();
  in.seekg(0);
  std::unique_ptr<octomap::AbstractOcTree> tree(octomap::AbstractOcTree::read(in));
  if (!tree) throw MapIoError("cannot read map '" + path + "': not a valid octomap .ot file");
  auto* semantic = dynamic_cast<SemanticOcTree*>(tree.get());
  if (!semantic) {
    throw MapIoError("map '" + path + "' holds a " + tree->getTreeType() +
                     ", not a SemanticOcTree");
  }
  // octomap reads the node data only when the header's size is above 0: a file claiming 0
  // would load as an empty map whatever follows, unchecked. Its class table and integrity
  // record are read here, and must say 0 nodes too.
  std::uint64_t header_size = 0;
  std::istringstream size_reader(size_text);
  if (!(size_reader >> header_size)) {
    throw MapIoError("cannot read map '" + path + "': its header's size '" + size_text +
                     "' is not a number");
  }
  const bool header_says_empty = header_size == 0;
  if (header_says_empty && !in.fail()) semantic->readData(in);
  if (in.fail() || !semantic->readError().empty()) {
    throw MapIoError(
        "cannot read map '" + path + "': " +
        (semantic->readError().empty() ? "truncated or corrupt data" : semantic->readError()));
  }
  if (semantic->size() != header_size) {
    throw MapIoError("cannot read map '" + path + "': its header says size " +
                     std::to_string(header_size) + ", its data holds " +
                     std::to_string(semantic->size()) + " nodes");
  }
  tree.release();
  return std::unique_ptr<SemanticOcTree>(semantic);
}

}  // namespace mapping
}  // namespace inekf_semantic_mapping
