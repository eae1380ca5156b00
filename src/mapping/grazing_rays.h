// Grazing-ray truncation, private to the mapping sources: SemanticOcTree and HashedVoxelGrid cut
// a downward ray short of its hit by the same rule, so the two insertions give the same map.
#pragma once

#include <algorithm>

namespace inekf_semantic_mapping {
namespace mapping {

// Grazing-ray truncation never withholds more than this fraction of a ray from clearing.
constexpr double kMaxGrazingCutFraction = 0.25;

// How much of a downward ray of `length` metres, `sin_elevation` (> 0) below the horizontal, is
// withheld from clearing: truncation_m / sin_elevation, the stretch within truncation_m of a
// horizontal surface at its end (for a hit on flat ground truncation_m / (sensor height) of the
// ray: 12 % for 1 voxel of 0.2 m at 1.73 m), capped so that a nearly level ray to a wall or a car
// loses at most kMaxGrazingCutFraction of its length.
inline double grazingRayCut(double length, double sin_elevation, double truncation_m) {
  return std::min(kMaxGrazingCutFraction * length, truncation_m / sin_elevation);
}

}  // namespace mapping
}  // namespace inekf_semantic_mapping
