// OccupancyModel: octomap's occupancy sensor model (the update of a hit and of a miss, and the
// clamping bounds), one set of numbers for the mapping config (its sensor_model.* keys), the
// SemanticOcTree and the HashedVoxelGrid, so that both insertions apply the same model.
#pragma once

namespace inekf_semantic_mapping {
namespace mapping {

struct OccupancyModel {
  // Probabilities; octomap stores them as float log-odds, and so does the hashed grid.
  double prob_hit = 0.7;       // of an endpoint voxel, per scan
  double prob_miss = 0.4;      // of a voxel a free ray crosses, per scan
  double clamping_min = 0.12;  // a voxel's occupancy stays within [clamping_min, clamping_max]
  double clamping_max = 0.97;
};

}  // namespace mapping
}  // namespace inekf_semantic_mapping
