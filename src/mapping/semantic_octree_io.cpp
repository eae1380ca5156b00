// SemanticOcTree's file format: the class table and fusion model before octomap's node data, an
// integrity record (node count, length, checksum) and a reader that refuses what it cannot trust.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <istream>
#include <iterator>
#include <ostream>
#include <sstream>
#include <stdexcept>

#include "inekf_semantic_mapping/mapping/semantic_octree.h"

namespace inekf_semantic_mapping {
namespace mapping {

std::istream& SemanticOcTreeNode::readData(std::istream& s) {
  s.read(reinterpret_cast<char*>(&value), sizeof(value));
  s.read(reinterpret_cast<char*>(classes_.data()), sizeof(ClassIndex) * kSlots);
  s.read(reinterpret_cast<char*>(counts_.data()), sizeof(std::uint16_t) * kSlots);
  return s;
}

std::ostream& SemanticOcTreeNode::writeData(std::ostream& s) const {
  s.write(reinterpret_cast<const char*>(&value), sizeof(value));
  s.write(reinterpret_cast<const char*>(classes_.data()), sizeof(ClassIndex) * kSlots);
  s.write(reinterpret_cast<const char*>(counts_.data()), sizeof(std::uint16_t) * kSlots);
  return s;
}

namespace {
// V1: class table, then octomap's node data. V2 adds an integrity record before the node data:
// node count, byte length and an FNV-1a checksum, so a corrupt file is refused, never loaded as
// a silently different map.
// V1: no integrity record. V2: an integrity record whose checksum covers the node data. V3: the
// checksum covers the fusion model and the class table too (a flipped bit in a label id loaded as
// a map of another class). V4 (what is written): the resolution follows the class table, in
// binary and under the checksum; octomap's text header ("res 0.2") is outside it and was loaded
// as whatever it said (an edited 0.3 gave a map 1.5 times the size, 1e-30 one nothing could
// search). The text must agree to its printed digits, and the exact value holds. Then the
// geodetic origin: a byte (1: known) and latitude, longitude, altitude as doubles.
constexpr char kSemanticHeaderMagicV1[] = "ISM_SEMANTIC_OCTREE_V1";
constexpr char kSemanticHeaderMagicV2[] = "ISM_SEMANTIC_OCTREE_V2";
constexpr char kSemanticHeaderMagicV3[] = "ISM_SEMANTIC_OCTREE_V3";
constexpr char kSemanticHeaderMagicV4[] = "ISM_SEMANTIC_OCTREE_V4";
static_assert(sizeof(kSemanticHeaderMagicV1) == sizeof(kSemanticHeaderMagicV2) &&
              sizeof(kSemanticHeaderMagicV2) == sizeof(kSemanticHeaderMagicV3) &&
              sizeof(kSemanticHeaderMagicV3) == sizeof(kSemanticHeaderMagicV4));
// Bytes of one node in octomap's full format: value, class slots, counts, child bits.
constexpr std::size_t kSerializedNodeBytes =
    sizeof(float) + SemanticOcTreeNode::kSlots * (sizeof(ClassIndex) + sizeof(std::uint16_t)) + 1;

template <typename T>
void writePod(std::ostream& s, const T& value) {
  s.write(reinterpret_cast<const char*>(&value), sizeof(T));
}
template <typename T>
bool readPod(std::istream& s, T* value) {
  return static_cast<bool>(s.read(reinterpret_cast<char*>(value), sizeof(T)));
}

// V4's origin record: 1 byte (known or not) and three doubles (zeros when unknown).
std::string originBytes(const std::optional<GeodeticOrigin>& origin) {
  const GeodeticOrigin value = origin.value_or(GeodeticOrigin());
  std::string bytes(1, origin ? '\1' : '\0');
  for (const double d : {value.lat_deg, value.lon_deg, value.alt_m}) {
    bytes.append(reinterpret_cast<const char*>(&d), sizeof(d));
  }
  return bytes;
}

// FNV-1a, 64 bit, fed piecewise (the writer streams the node data, the reader has it whole).
class Fnv1a {
 public:
  void add(const char* bytes, std::size_t n) {
    std::uint64_t hash = hash_;
    for (std::size_t i = 0; i < n; ++i) {
      hash ^= static_cast<std::uint8_t>(bytes[i]);
      hash *= 1099511628211ull;
    }
    hash_ = hash;
  }
  std::uint64_t value() const { return hash_; }

 private:
  std::uint64_t hash_ = 1469598103934665603ull;
};

// The fusion model and the class table as they are stored after the magic (written, and hashed
// again from what was read).
std::string fusionAndClassBytes(const FusionModel& fusion, const ClassSet& classes) {
  std::ostringstream s;
  writePod(s, static_cast<std::uint8_t>(fusion.rule));
  writePod(s, fusion.correct_probability);
  writePod(s, fusion.dirichlet_prior);
  writePod(s, static_cast<std::uint32_t>(classes.size()));
  for (const ClassInfo& info : classes.classes()) {
    writePod(s, info.label_id);
    s.write(reinterpret_cast<const char*>(info.rgb.data()), 3);
    writePod(s, static_cast<std::uint32_t>(info.name.size()));
    s.write(info.name.data(), static_cast<std::streamsize>(info.name.size()));
  }
  return s.str();
}

// The node data in octomap's full format, byte for byte what OcTreeBaseImpl::writeNodesRecurs
// writes (each node's value, class slots and counts, then a byte of child bits; depth first),
// but serialised into one fixed buffer handed to `sink` as it fills: octomap's writer makes
// four stream calls per node, which cost more than the rest of a save.
class NodeDataWriter {
 public:
  using Sink = std::function<void(const char* bytes, std::size_t n)>;
  NodeDataWriter(const SemanticOcTree& tree, Sink sink) : tree_(tree), sink_(std::move(sink)) {
    buffer_.resize(std::size_t{1} << 20);
  }
  void write(const SemanticOcTreeNode* root) {
    if (root != nullptr) writeNode(root);
    flush();
  }

 private:
  void writeNode(const SemanticOcTreeNode* node) {
    if (used_ + kSerializedNodeBytes > buffer_.size()) flush();
    char* out = buffer_.data() + used_;
    const float value = node->getValue();
    std::memcpy(out, &value, sizeof(value));
    out += sizeof(value);
    std::memcpy(out, node->slotClasses().data(), sizeof(ClassIndex) * SemanticOcTreeNode::kSlots);
    out += sizeof(ClassIndex) * SemanticOcTreeNode::kSlots;
    std::memcpy(out, node->slotCounts().data(), sizeof(std::uint16_t) * SemanticOcTreeNode::kSlots);
    out += sizeof(std::uint16_t) * SemanticOcTreeNode::kSlots;
    unsigned int children = 0;
    for (unsigned int i = 0; i < 8; ++i) {
      if (tree_.nodeChildExists(node, i)) children |= 1u << i;
    }
    *out = static_cast<char>(children);
    used_ += kSerializedNodeBytes;
    for (unsigned int i = 0; i < 8; ++i) {
      if (children & (1u << i)) writeNode(tree_.getNodeChild(node, i));
    }
  }
  void flush() {
    if (used_ > 0) sink_(buffer_.data(), used_);
    used_ = 0;
  }

  const SemanticOcTree& tree_;
  Sink sink_;
  std::vector<char> buffer_;
  std::size_t used_ = 0;
};

static_assert(sizeof(ClassSlotIndices) == sizeof(ClassIndex) * SemanticOcTreeNode::kSlots &&
                  sizeof(ClassSlotCounts) == sizeof(std::uint16_t) * SemanticOcTreeNode::kSlots,
              "the node format is the slot arrays' bytes");
}  // namespace

// The class table and fusion model go before octomap's node data, so a loaded map knows which
// label id each stored class index stands for.
std::ostream& SemanticOcTree::writeData(std::ostream& s) const {
  s.write(kSemanticHeaderMagicV4, sizeof(kSemanticHeaderMagicV4));
  std::string fusion_and_classes = fusionAndClassBytes(fusion_, classes_);
  fusion_and_classes.append(reinterpret_cast<const char*>(&resolution), sizeof(resolution));
  fusion_and_classes += originBytes(geodetic_origin_);
  s.write(fusion_and_classes.data(), static_cast<std::streamsize>(fusion_and_classes.size()));
  // The integrity record goes before the node data. Its length follows from the node count;
  // the checksum is patched in after one pass over the tree where the stream can seek (files),
  // else learnt in a first pass (no copy of the node data in memory either way).
  const std::uint64_t node_count = root ? size() : 0;
  writePod(s, node_count);
  writePod(s, node_count * kSerializedNodeBytes);
  const std::streampos checksum_at = s.tellp();
  Fnv1a hash;
  hash.add(fusion_and_classes.data(), fusion_and_classes.size());
  if (checksum_at != std::streampos(-1)) {
    writePod(s, std::uint64_t{0});
    NodeDataWriter(*this, [&](const char* bytes, std::size_t n) {
      hash.add(bytes, n);
      s.write(bytes, static_cast<std::streamsize>(n));
    }).write(root);
    const std::streampos end = s.tellp();
    s.seekp(checksum_at);
    writePod(s, hash.value());
    s.seekp(end);
  } else {
    NodeDataWriter(*this, [&](const char* bytes, std::size_t n) {
      hash.add(bytes, n);
    }).write(root);
    writePod(s, hash.value());
    NodeDataWriter(*this, [&](const char* bytes, std::size_t n) {
      s.write(bytes, static_cast<std::streamsize>(n));
    }).write(root);
  }
  return s;
}

bool SemanticOcTree::fail(std::istream& s, const std::string& why) {
  read_error_ = why;
  s.setstate(std::ios::failbit);
  return false;
}

std::istream& SemanticOcTree::refuse(std::istream& s, const std::string& why) {
  fail(s, why);
  return s;
}

std::istream& SemanticOcTree::readData(std::istream& s) {
  read_error_.clear();
  char magic[sizeof(kSemanticHeaderMagicV3)] = {};
  if (!s.read(magic, sizeof(magic))) return refuse(s, "truncated header");
  const bool v4 = std::memcmp(magic, kSemanticHeaderMagicV4, sizeof(magic)) == 0;
  const bool v3 = v4 || std::memcmp(magic, kSemanticHeaderMagicV3, sizeof(magic)) == 0;
  const bool v2 = std::memcmp(magic, kSemanticHeaderMagicV2, sizeof(magic)) == 0;
  if (!v3 && !v2 && std::memcmp(magic, kSemanticHeaderMagicV1, sizeof(magic)) != 0) {
    return refuse(s, "not a semantic octree (bad magic)");
  }
  const bool has_integrity_record = v2 || v3;
  std::uint8_t rule = 0;
  std::uint32_t num_classes = 0;
  FusionModel fusion;
  if (!(readPod(s, &rule) && rule <= 1 && readPod(s, &fusion.correct_probability) &&
        readPod(s, &fusion.dirichlet_prior) && readPod(s, &num_classes) &&
        num_classes <= static_cast<std::uint32_t>(kMaxClasses))) {
    return refuse(s, "bad fusion model or class count");
  }
  if (!(fusion.correct_probability > 0 && fusion.correct_probability < 1 &&
        fusion.dirichlet_prior > 0 && std::isfinite(fusion.dirichlet_prior))) {
    return refuse(s, "fusion model out of range");
  }
  std::vector<ClassInfo> classes;
  for (std::uint32_t i = 0; i < num_classes; ++i) {
    ClassInfo info;
    std::uint32_t name_length = 0;
    if (!(readPod(s, &info.label_id) && s.read(reinterpret_cast<char*>(info.rgb.data()), 3) &&
          readPod(s, &name_length) && name_length < 4096)) {
      return refuse(s, "bad class table entry " + std::to_string(i));
    }
    info.name.resize(name_length);
    if (!s.read(info.name.data(), name_length)) return refuse(s, "truncated class table");
    classes.push_back(std::move(info));
  }
  try {
    classes_ = ClassSet(std::move(classes));
  } catch (const std::exception& e) {
    return refuse(s, std::string("bad class table: ") + e.what());
  }
  fusion.rule = static_cast<FusionRule>(rule);
  fusion_ = fusion;
  double recorded_resolution = resolution;  // before V4: the text header's
  std::optional<GeodeticOrigin> origin;
  if (v4) {
    std::uint8_t known = 0;
    GeodeticOrigin read_origin;
    if (!(readPod(s, &recorded_resolution) && readPod(s, &known) &&
          readPod(s, &read_origin.lat_deg) && readPod(s, &read_origin.lon_deg) &&
          readPod(s, &read_origin.alt_m))) {
      return refuse(s, "truncated resolution and origin");
    }
    if (known > 1 || !(std::abs(read_origin.lat_deg) <= 90 &&
                       std::abs(read_origin.lon_deg) <= 180 && std::isfinite(read_origin.alt_m))) {
      return refuse(s, "bad geodetic origin");
    }
    if (known) origin = read_origin;
  }

  std::string bytes;
  std::uint64_t node_count = 0;
  if (has_integrity_record) {
    std::uint64_t length = 0, checksum = 0;
    if (!(readPod(s, &node_count) && readPod(s, &length) && readPod(s, &checksum))) {
      return refuse(s, "truncated integrity record");
    }
    if (length != node_count * kSerializedNodeBytes || length > (std::uint64_t{1} << 36)) {
      return refuse(s, "integrity record: " + std::to_string(length) + " bytes for " +
                           std::to_string(node_count) + " nodes");
    }
    // Read in chunks: the memory follows the bytes that are there, not the length a (crafted)
    // record announces.
    constexpr std::uint64_t kChunk = std::uint64_t{1} << 24;
    while (bytes.size() < length) {
      const std::size_t before = bytes.size();
      const std::size_t chunk = static_cast<std::size_t>(std::min(kChunk, length - before));
      bytes.resize(before + chunk);
      if (!s.read(bytes.data() + before, static_cast<std::streamsize>(chunk))) {
        return refuse(s, "truncated node data (" + std::to_string(length) + " bytes announced, " +
                             std::to_string(before + static_cast<std::size_t>(s.gcount())) +
                             " there)");
      }
    }
    Fnv1a hash;
    if (v3) {
      std::string fusion_and_classes = fusionAndClassBytes(fusion_, classes_);
      if (v4) {
        fusion_and_classes.append(reinterpret_cast<const char*>(&recorded_resolution),
                                  sizeof(recorded_resolution));
        fusion_and_classes += originBytes(origin);
      }
      hash.add(fusion_and_classes.data(), fusion_and_classes.size());
    }
    hash.add(bytes.data(), bytes.size());
    if (hash.value() != checksum) {
      return refuse(s, v3 ? "checksum mismatch: the class table or the node data is corrupt"
                          : "checksum mismatch: the node data is corrupt");
    }
    // The text carries at least 6 significant digits (octomap's stream default).
    if (!(recorded_resolution > 0 && std::isfinite(recorded_resolution) &&
          std::abs(resolution - recorded_resolution) <= 1e-5 * recorded_resolution)) {
      std::ostringstream why;
      why.precision(10);
      why << "octomap header's res " << resolution << " differs from the map's resolution "
          << recorded_resolution << " (the header was edited or is corrupt)";
      return refuse(s, why.str());
    }
    if (recorded_resolution != resolution) setResolution(recorded_resolution);
    geodetic_origin_ = origin;
  } else {
    // V1 files carry no length: the rest of the stream is node data.
    bytes.assign(std::istreambuf_iterator<char>(s), std::istreambuf_iterator<char>());
    node_count = bytes.size() / kSerializedNodeBytes;
  }
  if (root) return refuse(s, "reading into a tree that is not empty");
  if (node_count == 0) {  // an empty map: its class table and fusion model, no node
    tree_size = 0;
    size_changed = true;
    return s;
  }
  std::istringstream nodes(bytes);
  root = new SemanticOcTreeNode();
  std::uint64_t nodes_read = 0, voxels = 0;
  if (!readNodesChecked(root, nodes, 0, node_count, &nodes_read, &voxels)) {
    clear();
    return refuse(s, read_error_);
  }
  if (has_integrity_record && nodes_read != node_count) {
    clear();
    return refuse(s, "node count " + std::to_string(nodes_read) + " differs from the recorded " +
                         std::to_string(node_count));
  }
  tree_size = nodes_read;
  size_changed = true;
  return s;
}

// octomap's readNodesRecurs without its dangers: the depth is bounded by the tree depth, the
// node count by the file, and every stored class index and count is checked. A leaf stands for
// 8^(tree depth - its depth) voxels, which the grid and the PLY writer expand: a leaf coarser
// than kMaxLeafSpanLevels (256 voxels a side: no lidar sees such a block all free or all
// occupied) or more than kMaxMapVoxels in all (2^36: known free space included, some 8 times a
// 0.05 m map of a 4 km drive) are refused (a 237-byte file held 2^48).
bool SemanticOcTree::readNodesChecked(SemanticOcTreeNode* node, std::istream& s, unsigned int depth,
                                      std::uint64_t max_nodes, std::uint64_t* nodes_read,
                                      std::uint64_t* voxels) {
  if (++*nodes_read > max_nodes) return fail(s, "more nodes than the file records");
  node->readData(s);
  std::uint8_t children = 0;
  if (!readPod(s, &children)) return fail(s, "truncated node data");
  if (!std::isfinite(node->getValue())) return fail(s, "non-finite occupancy");
  for (int slot = 0; slot < SemanticOcTreeNode::kSlots; ++slot) {
    const ClassIndex index = node->slotClass(slot);
    if (index != kNoClass && index >= classes_.size()) {
      return fail(s, "class index " + std::to_string(index) + " outside the class table");
    }
  }
  if (children != 0 && depth >= tree_depth) {
    return fail(s, "children below the finest level (depth " + std::to_string(depth) + ")");
  }
  if (children == 0) {
    const unsigned int levels = tree_depth - depth;
    if (levels > kMaxLeafSpanLevels) {
      return fail(s, "a leaf at depth " + std::to_string(depth) + " stands for " +
                         std::to_string(1u << levels) + " voxels a side (at most " +
                         std::to_string(1u << kMaxLeafSpanLevels) + ")");
    }
    *voxels += std::uint64_t{1} << (3 * levels);
    if (*voxels > kMaxMapVoxels) {
      return fail(s, "the leaves stand for more than " + std::to_string(kMaxMapVoxels) + " voxels");
    }
  }
  for (unsigned int i = 0; i < 8; ++i) {
    if (children & (1u << i)) {
      if (!readNodesChecked(createNodeChild(node, i), s, depth + 1, max_nodes, nodes_read,
                            voxels)) {
        return false;
      }
    }
  }
  return true;
}

}  // namespace mapping
}  // namespace inekf_semantic_mapping
