// semantic_map_offline: builds a semantic OctoMap from a SemanticKITTI-layout sequence (ground
// truth labels or any network's per-point predictions) and saves it as .ot (+ PLY).
//
//   semantic_map_offline --scans DIR --labels DIR --poses POSES.txt --calib CALIB.txt
//       --resolution R --output MAP.ot --export-ply MAP.ply [--max-range M] [--confusion P]
//       [--fusion bayes|dirichlet] [--max-scans N] [--classes semantickitti|cityscapes]
//       [--color-ot MAP_COLOR.ot] [--prob-hit P] [--prob-miss P]
#include <cstdlib>
#include <iostream>
#include <map>
#include <set>
#include <string>

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
    "         [--prob-hit P] [--prob-miss P]\n";

double parseNumber(const std::string& flag, const std::string& text) {
  try {
    std::size_t used = 0;
    const double value = std::stod(text, &used);
    if (used == text.size()) return value;
  } catch (const std::exception&) {
  }
  throw std::invalid_argument(flag + ": not a number: '" + text + "'");
}

}  // namespace

int main(int argc, char** argv) {
  using namespace inekf_semantic_mapping;
  std::map<std::string, std::string> args;
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (flag == "-h" || flag == "--help") {
      std::cout << kUsage;
      return 0;
    }
    if (flag.rfind("--", 0) != 0 || i + 1 >= argc) {
      std::cerr << "semantic_map_offline: bad argument '" << flag << "'\n" << kUsage;
      return 2;
    }
    args[flag] = argv[++i];
  }
  try {
    for (const char* required :
         {"--scans", "--labels", "--poses", "--calib", "--resolution", "--output"}) {
      if (!args.count(required)) throw std::invalid_argument(std::string("missing ") + required);
    }
    static const std::set<std::string> kKnown = {
        "--scans",     "--labels",     "--poses",     "--calib",     "--resolution",
        "--output",    "--export-ply", "--max-range", "--confusion", "--fusion",
        "--max-scans", "--classes",    "--color-ot",  "--prob-hit",  "--prob-miss"};
    for (const auto& [flag, value] : args) {
      if (!kKnown.count(flag)) throw std::invalid_argument("unknown option " + flag);
    }
    mapping::OfflineMappingOptions options;
    options.scans_dir = args["--scans"];
    options.labels_dir = args["--labels"];
    options.poses_path = args["--poses"];
    options.calib_path = args["--calib"];
    options.resolution_m = parseNumber("--resolution", args["--resolution"]);
    if (!(options.resolution_m > 0)) throw std::invalid_argument("--resolution must be > 0");
    if (args.count("--max-range")) {
      options.max_range_m = parseNumber("--max-range", args["--max-range"]);
    }
    if (args.count("--confusion")) {
      options.fusion.correct_probability = parseNumber("--confusion", args["--confusion"]);
      if (!(options.fusion.correct_probability > 0 && options.fusion.correct_probability < 1)) {
        throw std::invalid_argument("--confusion must be in (0, 1)");
      }
    }
    if (args.count("--prob-hit")) options.prob_hit = parseNumber("--prob-hit", args["--prob-hit"]);
    if (args.count("--prob-miss")) {
      options.prob_miss = parseNumber("--prob-miss", args["--prob-miss"]);
    }
    if (!(options.prob_hit > 0.5 && options.prob_hit < 1 && options.prob_miss > 0 &&
          options.prob_miss < 0.5)) {
      throw std::invalid_argument("--prob-hit must be in (0.5, 1) and --prob-miss in (0, 0.5)");
    }
    if (args.count("--fusion")) options.fusion.rule = mapping::parseFusionRule(args["--fusion"]);
    if (args.count("--max-scans")) {
      options.max_scans = static_cast<int>(parseNumber("--max-scans", args["--max-scans"]));
    }
    if (args.count("--classes")) {
      const std::string& set = args["--classes"];
      if (set == "cityscapes") {
        options.classes = mapping::ClassSet::cityscapes();
      } else if (set != "semantickitti") {
        throw std::invalid_argument("--classes must be semantickitti or cityscapes");
      }
    }

    std::unique_ptr<mapping::SemanticOcTree> tree =
        mapping::buildSemanticMapFromSequence(options, &std::cerr);
    {
      ScopedTimer timer("offline/save_ot");
      const std::size_t occupied =
          mapping::saveMap(*tree, args["--output"], mapping::MapFormat::kSemanticOt);
      std::cerr << "[semantic_map_offline] wrote " << args["--output"] << " (" << tree->size()
                << " nodes, " << occupied << " occupied leaves, " << tree->classSet().size()
                << " classes, " << tree->memoryUsage() / 1e6 << " MB in memory)\n";
    }
    if (args.count("--export-ply")) {
      ScopedTimer timer("offline/save_ply");
      const std::size_t vertices =
          mapping::saveMap(*tree, args["--export-ply"], mapping::MapFormat::kPly);
      std::cerr << "[semantic_map_offline] wrote " << args["--export-ply"] << " (" << vertices
                << " occupied voxels)\n";
    }
    if (args.count("--color-ot")) {
      mapping::saveMap(*tree, args["--color-ot"], mapping::MapFormat::kColorOt);
      std::cerr << "[semantic_map_offline] wrote " << args["--color-ot"] << "\n";
    }
  } catch (const std::exception& e) {
    std::cerr << "semantic_map_offline: error: " << e.what() << "\n";
    return 1;
  }
  std::cerr << TimingRegistry::instance().report();
  return 0;
}
