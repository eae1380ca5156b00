// Degrades the OXTS fused RTK/INS position into what a plain GPS receiver would give a filter:
// Gaussian noise, a lower rate, outages. One implementation for kitti_player, kitti2bag and
// inekf_offline so that the three feed a filter the same fixes.
//
// Defaults (all zero / every frame / no outage) reproduce the OXTS position unchanged, minus the
// frames without a GPS solution (posmode <= 0).
#pragma once

#include <cstdint>
#include <optional>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "inekf_semantic_mapping/kitti/oxts.h"

namespace inekf_semantic_mapping {
namespace kitti {

struct GpsDegradationOptions {
  double sigma_horizontal_m = 0;  // std dev of the east and of the north noise, metres
  double sigma_vertical_m = 0;    // std dev of the up noise, metres
  int every_n_frames = 1;         // keep frames 0, N, 2N, ... (1 = every frame)
  // {start, duration} in seconds since the first frame: no fix in [start, start + duration).
  std::vector<std::pair<double, double>> outages_s;
  std::uint64_t seed = 0;

  // "START:DURATION" (seconds, both >= 0) -> {start, duration}; std::invalid_argument naming the
  // text otherwise.
  static std::pair<double, double> parseOutage(const std::string& start_colon_duration);
  // std::invalid_argument when a sigma is negative/non-finite or every_n_frames < 1.
  void validate() const;
};

struct GeodeticFix {
  double lat_deg = 0, lon_deg = 0, alt_m = 0;
  // What a receiver would report: max(noise sigma, record.pos_accuracy).
  double sigma_horizontal_m = 0, sigma_vertical_m = 0;
};

class GpsDegrader {
 public:
  explicit GpsDegrader(GpsDegradationOptions options);

  // nullopt = no fix this frame: posmode <= 0, non-finite lat/lon/alt, not an N-th frame, or
  // inside an outage. Draws noise only for frames that produce a fix, so the noise sequence
  // for a seed depends only on the fixes produced.
  std::optional<GeodeticFix> degrade(std::size_t frame_index, double seconds_since_first_frame,
                                     const OxtsRecord& record);

  const GpsDegradationOptions& options() const { return options_; }
  bool inOutage(double seconds_since_first_frame) const;

 private:
  double standardNormal();  // Box-Muller on mt19937_64: the same numbers on every platform

  GpsDegradationOptions options_;
  std::mt19937_64 random_engine_;
  bool has_spare_normal_ = false;
  double spare_normal_ = 0;
};

}  // namespace kitti
}  // namespace inekf_semantic_mapping
