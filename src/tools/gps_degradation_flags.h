// The GPS degradation flags that kitti2bag and inekf_offline share (the evaluation protocol's
// knobs): --gps-sigma-h M, --gps-sigma-v M, --gps-every N, --gps-outage START:DURATION (repeatable)
// and --seed N, read into one kitti::GpsDegradationOptions.
#pragma once

#include <string>
#include <vector>

#include "inekf_semantic_mapping/common/cli_args.h"
#include "inekf_semantic_mapping/kitti/gps_degradation.h"

namespace inekf_semantic_mapping {
namespace tools {

inline const std::vector<std::string> kGpsRepeatableFlags = {"--gps-outage"};

// A tool's own value flags plus the GPS ones, for common::CommandLine.
inline std::vector<std::string> withGpsValueFlags(std::vector<std::string> value_flags) {
  for (const char* flag : {"--gps-sigma-h", "--gps-sigma-v", "--gps-every", "--seed"}) {
    value_flags.emplace_back(flag);
  }
  return value_flags;
}

// Overrides the fields of *gps that the command line sets; a malformed or invalid value throws
// common::UsageError naming the flag.
inline void readGpsDegradationFlags(const common::CommandLine& cli,
                                    kitti::GpsDegradationOptions* gps) {
  using common::UsageError;
  gps->sigma_horizontal_m = cli.getDouble("--gps-sigma-h", gps->sigma_horizontal_m);
  gps->sigma_vertical_m = cli.getDouble("--gps-sigma-v", gps->sigma_vertical_m);
  gps->every_n_frames = cli.getInt("--gps-every", gps->every_n_frames);
  if (gps->every_n_frames < 1) throw UsageError("--gps-every must be an integer >= 1");
  for (const std::string& outage : cli.getAll("--gps-outage")) {
    try {
      gps->outages_s.push_back(kitti::GpsDegradationOptions::parseOutage(outage));
    } catch (const std::exception& error) {
      throw UsageError(error.what());
    }
  }
  gps->seed = cli.getUint64("--seed", gps->seed);
  try {
    gps->validate();
  } catch (const std::exception& error) {
    throw UsageError(error.what());
  }
}

}  // namespace tools
}  // namespace inekf_semantic_mapping
