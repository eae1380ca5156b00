// Velodyne HDL-64E scans of KITTI (.bin: float32 x y z reflectance per point) and SemanticKITTI
// .label files.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace inekf_semantic_mapping {
namespace kitti {

struct VelodyneScan {
  std::vector<float> xyzi;  // N*4 interleaved: x y z (m, velodyne frame) reflectance (0..1)
  std::size_t size() const { return xyzi.size() / 4; }
  const float* point(std::size_t i) const { return xyzi.data() + 4 * i; }
};

// Throws KittiFormatError naming the file when it is missing or its size is not a multiple of
// 16 bytes.
VelodyneScan readVelodyneBin(const std::string& path);

// The _extract layout stores scans as text, one "x y z r" per line. Throws KittiFormatError
// naming file:line on a bad line.
VelodyneScan readVelodyneText(const std::string& path);

// Dispatches on the extension (.bin or .txt).
VelodyneScan readVelodyneScan(const std::string& path);

// SemanticKITTI .label: one uint32 per point, semantic class = lower 16 bits, instance = upper
// 16 bits. Returned raw; use semanticClass()/instanceId(). Size not a multiple of 4 -> error.
std::vector<std::uint32_t> readLabelFile(const std::string& path);
inline std::uint16_t semanticClass(std::uint32_t label) { return label & 0xFFFFu; }
inline std::uint16_t instanceId(std::uint32_t label) { return label >> 16; }

// KITTI .bin files carry no laser (ring) index: recover it from the scan order. The HDL-64E
// driver writes the points laser by laser, each laser sweeping the azimuth once, so a new ring
// starts wherever the azimuth atan2(y, x) wraps from the negative half (just below +180 deg,
// i.e. clockwise past the rear) back to the positive half. Ring 0 is the first laser in the
// file (the top one in KITTI), rings are clamped to num_beams - 1. Works on full scans; on a
// cut or reordered cloud the result is meaningless (use elevation binning there instead).
std::vector<std::uint16_t> computeRings(const VelodyneScan& scan, int num_beams = 64);

}  // namespace kitti
}  // namespace inekf_semantic_mapping
