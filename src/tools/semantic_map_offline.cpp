// semantic_map_offline: builds a semantic OctoMap from a SemanticKITTI-layout sequence (ground
// truth labels or any network's per-point predictions) and saves it as .ot (+ PLY).
//
//   semantic_map_offline --scans DIR --labels DIR --poses POSES.txt --calib CALIB.txt
//       --resolution R --output MAP.ot --export-ply MAP.ply [--max-range M] [--confusion P]
//       [--fusion bayes|dirichlet] [--max-scans N] [--classes semantickitti|cityscapes]
//       [--color-ot MAP_COLOR.ot] [--prob-hit P] [--prob-miss P] [--grazing-truncation VOXELS]
#include <iostream>
#include <string>

#include "inekf_semantic_mapping/common/cli_args.h"
#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/mapping/map_io.h"
#include "inekf_semantic_mapping/mapping/offline_mapping.h"
#include "inekf_semantic_mapping/mapping/semantic_octree.h"

namespace {

constexpr char kUsage[] =
    "usage: semantic_map_offline --scans DIR --labels DIR --poses POSES.txt --calib CALIB.txt\n"
    "         --resolution R --output MAP.ot --export-ply MAP.ply [--max-range M]\n"
    "         [--confusion P] [--fusion bayes|dirichlet] [--max-scans N]\n"
    "         [--classes semantickitti|cityscapes] [--color-ot MAP_COLOR.ot]\n"
    "         [--prob-hit P] [--prob-miss P] [--grazing-truncation VOXELS (1; 0: plain octomap)]\n";

// Builds and saves the map (errors propagate to runCli: exit 1).
int run(const inekf_semantic_mapping::mapping::OfflineMappingOptions& options,
        const std::string& output, const std::string& export_ply, const std::string& color_ot) {
  using namespace inekf_semantic_mapping;
  std::unique_ptr<mapping::SemanticOcTree> tree =
      mapping::buildSemanticMapFromSequence(options, &std::cerr);
  {
    ScopedTimer timer("offline/save_ot");
    const std::size_t occupied = mapping::saveMap(*tree, output, mapping::MapFormat::kSemanticOt);
    std::cerr << "[semantic_map_offline] wrote " << output << " (" << tree->size() << " nodes, "
              << occupied << " occupied leaves, " << tree->classSet().size() << " classes, "
              << tree->memoryUsage() / 1e6 << " MB in memory)\n";
  }
  if (!export_ply.empty()) {
    ScopedTimer timer("offline/save_ply");
    const std::size_t vertices = mapping::saveMap(*tree, export_ply, mapping::MapFormat::kPly);
    std::cerr << "[semantic_map_offline] wrote " << export_ply << " (" << vertices
              << " occupied voxels)\n";
  }
  if (!color_ot.empty()) {
    mapping::saveMap(*tree, color_ot, mapping::MapFormat::kColorOt);
    std::cerr << "[semantic_map_offline] wrote " << color_ot << "\n";
  }
  std::cerr << TimingRegistry::instance().report();
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace inekf_semantic_mapping;
  using common::UsageError;
  return common::runCli("semantic_map_offline", kUsage, [&] {
    const common::CommandLine cli(
        argc, argv,
        {"--scans", "--labels", "--poses", "--calib", "--resolution", "--output", "--export-ply",
         "--max-range", "--confusion", "--fusion", "--max-scans", "--classes", "--color-ot",
         "--prob-hit", "--prob-miss", "--grazing-truncation"});
    if (cli.helpRequested()) return common::printUsage(kUsage);
    mapping::OfflineMappingOptions options;
    options.scans_dir = cli.require("--scans");
    options.labels_dir = cli.require("--labels");
    options.poses_path = cli.require("--poses");
    options.calib_path = cli.require("--calib");
    options.resolution_m = cli.parseDouble("--resolution", cli.require("--resolution"));
    const std::string output = cli.require("--output");
    if (!(options.resolution_m > 0)) throw UsageError("--resolution must be > 0");
    options.max_range_m = cli.getDouble("--max-range", options.max_range_m);
    if (cli.has("--confusion")) {
      options.fusion.correct_probability = cli.getDouble("--confusion", 0);
      if (!(options.fusion.correct_probability > 0 && options.fusion.correct_probability < 1)) {
        throw UsageError("--confusion must be in (0, 1)");
      }
    }
    options.prob_hit = cli.getDouble("--prob-hit", options.prob_hit);
    options.prob_miss = cli.getDouble("--prob-miss", options.prob_miss);
    options.grazing_truncation_voxels =
        cli.getDouble("--grazing-truncation", options.grazing_truncation_voxels);
    if (!(options.grazing_truncation_voxels >= 0)) {
      throw UsageError("--grazing-truncation must be >= 0 (voxels)");
    }
    if (!(options.prob_hit > 0.5 && options.prob_hit < 1 && options.prob_miss > 0 &&
          options.prob_miss < 0.5)) {
      throw UsageError("--prob-hit must be in (0.5, 1) and --prob-miss in (0, 0.5)");
    }
    if (cli.has("--fusion")) {
      try {
        options.fusion.rule = mapping::parseFusionRule(cli.get("--fusion"));
      } catch (const std::exception& error) {
        throw UsageError(error.what());
      }
    }
    options.max_scans = cli.getInt("--max-scans", options.max_scans);
    if (cli.has("--classes")) {
      const std::string set = cli.get("--classes");
      if (set == "cityscapes") {
        options.classes = mapping::ClassSet::cityscapes();
      } else if (set != "semantickitti") {
        throw UsageError("--classes must be semantickitti or cityscapes");
      }
    }
    return run(options, output, cli.get("--export-ply"), cli.get("--color-ot"));
  });
}
