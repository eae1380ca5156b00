// evaluate_semantics: how well camera labels fit the human labels of real lidar scans. For each
// SemanticKITTI frame it segments image_2, projects the scan into it, reads the camera label at
// each point (after the confidence / boundary filter and the occlusion test) and scores it
// against the point's human label mapped to Cityscapes (perception/semantickitti_to_cityscapes.h):
// point accuracy over labelled points, coverage (labelled / scored points in the image), IoU per
// class; per sequence and in total.
//
//   evaluate_semantics --sequence DIR [--sequence DIR ...] --model MODEL [--model-card CARD]
//       [--max-frames N] [--threads 2] [--json FILE]
//       [card overrides: --policy P --input WxH --tile-scale S --network-focal F --tile-overlap PX
//        --tile-max-width PX (0: tiles input-wide)
//       --flip 0|1 --suppress-unlabeled 0|1 --gamma G
//        --color none|standardize --no-focal]
//       [labelling variants, each repeatable, scored in every combination:
//        --min-confidence C --boundary-radius PX --occlusion off|CWxCH:RX:UP:DOWN:REL:ABS
//        --geometry off|FLAT:RAISED:SLOPE[:SUPPORT[:VEG]]]
//       [--map-config YAML: the mapping config of the maps, default the built-in defaults]
//
// Variant "raw" (no filter, no occlusion test, no geometry check) is always scored first. The last
// line printed is `RESULT <json>` (the same JSON --json writes).
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/common/atomic_file.h"
#include "inekf_semantic_mapping/common/cli_args.h"
#include "inekf_semantic_mapping/common/progress_log.h"
#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/evaluation/semantic_evaluation.h"
#include "inekf_semantic_mapping/kitti/poses.h"
#include "inekf_semantic_mapping/perception/cityscapes.h"
#include "inekf_semantic_mapping/perception/model_card.h"
#include "inekf_semantic_mapping/perception/segmenter.h"
#include "inekf_semantic_mapping/perception/semantickitti_to_cityscapes.h"

namespace ism = inekf_semantic_mapping;
namespace perception = inekf_semantic_mapping::perception;
namespace evaluation = inekf_semantic_mapping::evaluation;
using ism::common::UsageError;

namespace {

constexpr char kUsage[] =
    "usage: evaluate_semantics --sequence DIR [--sequence DIR ...] --model MODEL\n"
    "         [--model-card CARD] [--max-frames N] [--threads 2] [--json FILE]\n"
    "         [--policy resize|letterbox|pad_to_multiple|tiles] [--input WxH] [--tile-scale S]\n"
    "         [--network-focal F] [--tile-overlap PX] [--tile-max-width PX]\n"
    "         [--bottom-margin PX] [--flip 0|1] [--gamma G]\n"
    "         [--color none|standardize] [--color-mean R,G,B] [--color-std R,G,B]\n"
    "         [--suppress-unlabeled 0|1] [--no-focal] [--min-confidence C]...\n"
    "         [--boundary-radius PX]...\n"
    "         [--occlusion off|CWxCH:RX:UP:DOWN:REL:ABS]... [--geometry off|F:R:S[:K[:V]]]...\n"
    "         [--map-config YAML] [--map-label-every N] [--no-map] [--curbs 0|1]\n"
    "  --sequence         SemanticKITTI sequence folder (velodyne/, labels/, image_2/, calib.txt)\n"
    "  --no-focal         do not give the segmenter the camera's focal length (P2)\n"
    "  --min-confidence, --boundary-radius, --occlusion: labelling variants (default: the\n"
    "                     library defaults), scored in every combination besides 'raw'\n"
    "  --occlusion        e.g. 4x1:2:6:0:0.1:0.3 = cells 4x1 px, window 2 cells to each side,\n"
    "                     6 up, 0 down, margins 10 % + 0.3 m (the default)\n"
    "  --geometry         lidar geometry check (perception/label_geometry.h; default: the\n"
    "                     library's, as the session): flat classes more than F m above the\n"
    "                     local ground and signs/lights less than R m above it lose their\n"
    "                     label; ground cone slope S (0: none), optionally the points a cell's\n"
    "                     ground needs (:K) and whether high terrain becomes vegetation (:V,\n"
    "                     0 or 1); e.g. off, 0.3:0.2:0 or 0.2:0.2:0:5:1.\n"
    "                     Each such variant also prints the labels it rejected\n"
    "  --map-config       semantic mapping YAML (config/semantic_mapping.yaml keys) for the maps\n"
    "  --map-label-every  segment only every N-th frame for the camera map, as a segmentation\n"
    "                     slower than the lidar does (default 1: every frame); the scans then\n"
    "                     stream through the node's pairing, and those without a label image\n"
    "                     borrow a neighbour's (label_neighbour_s of --map-config)\n"
    "  --no-map           skip the maps: by default each sequence is also mapped (ground-truth\n"
    "                     poses, 0.2 m, the node's labelling path) from the camera labels and\n"
    "                     from the human labels (the ceiling), scored at the lidar points\n";

struct Variant {
  std::string name;
  evaluation::PointLabellingOptions options;
};

// "default" keeps the library defaults (the session's).
void parseGeometry(const std::string& text, evaluation::PointLabellingOptions* options) {
  if (text == "default") return;
  options->check_geometry = text != "off";
  if (!options->check_geometry) return;
  perception::LabelGeometryOptions& g = options->geometry;
  int vegetation = options->high_terrain_is_vegetation ? 1 : 0;
  int consumed[5] = {0, 0, 0, 0, 0};
  const int fields =
      std::sscanf(text.c_str(), "%f%n:%f%n:%f%n:%d%n:%d%n", &g.max_flat_height_m, &consumed[0],
                  &g.min_raised_height_m, &consumed[1], &g.ground.max_slope, &consumed[2],
                  &g.ground.min_support, &consumed[3], &vegetation, &consumed[4]);
  options->high_terrain_is_vegetation = vegetation != 0;
  // The whole text, finite numbers: "nan" and trailing junk were taken and failed later without
  // naming the flag.
  if (fields < 3 || consumed[fields - 1] != static_cast<int>(text.size()) ||
      !std::isfinite(g.max_flat_height_m) || !std::isfinite(g.min_raised_height_m) ||
      !std::isfinite(g.ground.max_slope))
    throw UsageError("--geometry expects off or FLAT:RAISED:SLOPE[:SUPPORT[:VEG]], got '" + text +
                     "'");
}

perception::OcclusionOptions parseOcclusion(const std::string& text, bool* enabled) {
  perception::OcclusionOptions options;
  *enabled = text != "off";
  if (!*enabled) return options;
  int cw = 0, ch = 0, rx = 0, up = 0, down = 0, consumed = 0;
  float rel = 0.f, abs_m = 0.f;
  if (std::sscanf(text.c_str(), "%dx%d:%d:%d:%d:%f:%f%n", &cw, &ch, &rx, &up, &down, &rel, &abs_m,
                  &consumed) != 7 ||
      consumed != static_cast<int>(text.size()) || cw <= 0 || ch <= 0 || rx < 0 || up < 0 ||
      down < 0 || !(rel >= 0.f) || !(abs_m >= 0.f) || !std::isfinite(rel) || !std::isfinite(abs_m))
    throw UsageError(
        "--occlusion expects off or CWxCH:RX:UP:DOWN:REL:ABS (cells > 0, the rest >= 0), got '" +
        text + "'");
  options.cell_width_px = cw;
  options.cell_height_px = ch;
  options.window_radius_x = rx;
  options.window_up = up;
  options.window_down = down;
  options.relative_margin = rel;
  options.absolute_margin_m = abs_m;
  return options;
}

std::string occlusionName(bool enabled, const perception::OcclusionOptions& o) {
  if (!enabled) return "off";
  std::ostringstream out;
  out << o.cell_width_px << "x" << o.cell_height_px << ":" << o.window_radius_x << ":"
      << o.window_up << ":" << o.window_down << ":" << o.relative_margin << ":"
      << o.absolute_margin_m;
  return out.str();
}

std::vector<Variant> makeVariants(const ism::common::CommandLine& cli) {
  const evaluation::PointLabellingOptions defaults;
  std::vector<double> confidences;
  for (const std::string& text : cli.getAll("--min-confidence"))
    confidences.push_back(ism::common::CommandLine::parseDouble("--min-confidence", text));
  if (confidences.empty()) confidences.push_back(defaults.filter.min_confidence);
  std::vector<int> radii;
  for (const std::string& text : cli.getAll("--boundary-radius"))
    radii.push_back(ism::common::CommandLine::parseInt("--boundary-radius", text));
  if (radii.empty()) radii.push_back(defaults.filter.boundary_radius_px);
  std::vector<std::string> occlusions = cli.getAll("--occlusion");
  if (occlusions.empty())
    occlusions.push_back(defaults.reject_occluded ? occlusionName(true, defaults.occlusion)
                                                  : "off");

  std::vector<std::string> geometries = cli.getAll("--geometry");
  if (geometries.empty()) geometries.push_back("default");

  std::vector<Variant> variants;
  Variant raw;
  raw.name = "raw";
  raw.options.filter = perception::LabelFilterOptions{0.0, 0};
  raw.options.reject_occluded = false;
  raw.options.check_geometry = false;
  raw.options.check_curbs = false;
  variants.push_back(raw);
  const bool curbs = cli.getBool("--curbs", true);
  for (double confidence : confidences) {
    for (int radius : radii) {
      for (const std::string& occlusion : occlusions) {
        for (const std::string& geometry : geometries) {
          Variant variant;
          variant.options.filter = perception::LabelFilterOptions{confidence, radius};
          variant.options.occlusion = parseOcclusion(occlusion, &variant.options.reject_occluded);
          parseGeometry(geometry, &variant.options);
          variant.options.check_curbs = curbs && variant.options.check_geometry;
          std::ostringstream name;
          name << "conf=" << confidence << ",boundary=" << radius << ",occlusion="
               << occlusionName(variant.options.reject_occluded, variant.options.occlusion);
          if (variant.options.check_geometry) {
            const perception::LabelGeometryOptions& g = variant.options.geometry;
            name << ",geometry=" << g.max_flat_height_m << ":" << g.min_raised_height_m << ":"
                 << g.ground.max_slope << ":" << g.ground.min_support << ":"
                 << (variant.options.high_terrain_is_vegetation ? 1 : 0);
          }
          if (variant.options.check_curbs) name << ",curbs";
          variant.name = name.str();
          variants.push_back(variant);
        }
      }
    }
  }
  return variants;
}

perception::ModelCard applyOverrides(perception::ModelCard card,
                                     const ism::common::CommandLine& cli) {
  if (cli.has("--policy")) {
    const std::string policy = cli.get("--policy");
    if (policy == "resize") {
      card.resize_policy = perception::ResizePolicy::kResize;
    } else if (policy == "letterbox") {
      card.resize_policy = perception::ResizePolicy::kLetterbox;
    } else if (policy == "pad_to_multiple") {
      card.resize_policy = perception::ResizePolicy::kPadToMultiple;
    } else if (policy == "tiles") {
      card.resize_policy = perception::ResizePolicy::kTiles;
    } else {
      throw UsageError("--policy: unknown policy '" + policy + "'");
    }
  }
  if (cli.has("--input")) {
    const std::string size = cli.get("--input");
    int used = 0;
    if (std::sscanf(size.c_str(), "%dx%d%n", &card.input_width, &card.input_height, &used) != 2 ||
        used != static_cast<int>(size.size()) || card.input_width <= 0 || card.input_height <= 0)
      throw UsageError("--input expects WxH, got '" + size + "'");
  }
  card.tile_scale = cli.getDouble("--tile-scale", card.tile_scale);
  card.network_focal_px = cli.getDouble("--network-focal", card.network_focal_px);
  card.tile_overlap = cli.getInt("--tile-overlap", card.tile_overlap);
  card.tile_max_width = cli.getInt("--tile-max-width", card.tile_max_width);
  card.tile_bottom_margin = cli.getInt("--bottom-margin", card.tile_bottom_margin);
  card.flip_average = cli.getBool("--flip", card.flip_average);
  card.gamma = cli.getDouble("--gamma", card.gamma);
  if (!(card.gamma >= perception::ModelCard::kMinGamma &&
        card.gamma <= perception::ModelCard::kMaxGamma))
    throw UsageError("--gamma must be in [0.2, 5]");
  card.suppress_unlabeled = cli.getBool("--suppress-unlabeled", card.suppress_unlabeled);
  if (cli.has("--color")) {
    const std::string color = cli.get("--color");
    if (color == "none") {
      card.color_normalization = perception::ColorNormalization::kNone;
    } else if (color == "standardize") {
      card.color_normalization = perception::ColorNormalization::kStandardize;
      if (card.color_std == std::array<double, 3>{{1.0, 1.0, 1.0}}) {
        // Cards without targets of their own get Cityscapes' (in the network's channel order).
        for (int c = 0; c < 3; ++c) {
          const int rgb = card.swap_rb ? c : 2 - c;
          card.color_mean[c] = perception::kCityscapesRgbMean[rgb];
          card.color_std[c] = perception::kCityscapesRgbStd[rgb];
        }
      }
    } else {
      throw UsageError("--color must be none or standardize, not '" + color + "'");
    }
  }
  // Standardization targets in RGB order (experiments with other colour statistics).
  for (const char* flag : {"--color-mean", "--color-std"}) {
    if (!cli.has(flag)) continue;
    double rgb[3];
    int consumed = 0;
    const std::string text = cli.get(flag);
    if (std::sscanf(text.c_str(), "%lf,%lf,%lf%n", &rgb[0], &rgb[1], &rgb[2], &consumed) != 3 ||
        consumed != static_cast<int>(text.size()))
      throw UsageError(std::string(flag) + " expects R,G,B, got '" + text + "'");
    std::array<double, 3>& target =
        std::string(flag) == "--color-mean" ? card.color_mean : card.color_std;
    for (int c = 0; c < 3; ++c) target[c] = rgb[card.swap_rb ? c : 2 - c];
  }
  // The card's own checks, on the card as overridden (--color-std 0,0,0 scored 0.0004).
  perception::checkModelCard(card, [](const std::string& key, const std::string& why) {
    throw UsageError("the model card with this command line's overrides: '" + key + "' " + why);
  });
  return card;
}

void printScore(const std::string& title, const evaluation::PointLabelScore& score,
                bool per_class) {
  std::printf(
      "%-58s acc %.4f  coverage %.4f  mIoU %.4f (with misses %.4f)  (%llu of %llu points "
      "labelled)\n",
      title.c_str(), score.accuracy(), score.coverage(), score.meanIoU(), score.meanIoUWithMisses(),
      static_cast<unsigned long long>(score.labelled()),
      static_cast<unsigned long long>(score.scored()));
  if (!per_class) return;
  std::printf("    %-14s %9s %9s %9s %7s %7s  %s\n", "class", "truth", "predicted", "no label",
              "acc", "IoU", "mistaken for");
  for (std::uint8_t label : perception::kScoredCityscapesLabels) {
    const std::uint64_t truth = score.truthCount(label);
    if (truth + score.predictedCount(label) + score.unlabelledCount(label) == 0) continue;
    // The two classes this one is most often mistaken for.
    int first = -1, second = -1;
    for (int p = 1; p < 256; ++p) {
      if (p == label || score.count(label, p) == 0) continue;
      if (first < 0 || score.count(label, p) > score.count(label, first)) {
        second = first;
        first = p;
      } else if (second < 0 || score.count(label, p) > score.count(label, second)) {
        second = p;
      }
    }
    std::string confusions;
    for (int p : {first, second}) {
      if (p < 0) continue;
      char text[64];
      std::snprintf(text, sizeof(text), "  %s %.2f", ism::cityscapes::labelName(p),
                    truth ? static_cast<double>(score.count(label, p)) / truth : 0.0);
      confusions += text;
    }
    std::printf("    %-14s %9llu %9llu %9llu %7.3f %7.3f %s\n", ism::cityscapes::labelName(label),
                static_cast<unsigned long long>(truth),
                static_cast<unsigned long long>(score.predictedCount(label)),
                static_cast<unsigned long long>(score.unlabelledCount(label)),
                truth ? static_cast<double>(score.truePositives(label)) / truth : 0.0,
                score.iou(label), confusions.c_str());
  }
  // Points given a class that is never scored (sky, wall, traffic light...): all wrong.
  std::uint64_t other = 0;
  for (int label = 1; label < ism::cityscapes::kNumLabelIds; ++label) {
    bool scored = false;
    for (std::uint8_t s : perception::kScoredCityscapesLabels) scored |= s == label;
    if (!scored && score.predictedCount(static_cast<std::uint8_t>(label)) > 0) {
      std::printf(
          "    predicted %-12s %llu\n", ism::cityscapes::labelName(label),
          static_cast<unsigned long long>(score.predictedCount(static_cast<std::uint8_t>(label))));
      other += score.predictedCount(static_cast<std::uint8_t>(label));
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  return ism::common::runCli("evaluate_semantics", kUsage, [&] {
    const ism::common::CommandLine cli(
        argc, argv,
        {"--model",
         "--model-card",
         "--max-frames",
         "--threads",
         "--json",
         "--policy",
         "--input",
         "--tile-scale",
         "--network-focal",
         "--tile-overlap",
         "--tile-max-width",
         "--flip",
         "--gamma",
         "--color",
         "--color-mean",
         "--color-std",
         "--suppress-unlabeled",
         "--bottom-margin",
         "--map-config",
         "--map-label-every",
         "--curbs"},
        {"--no-focal", "--no-map"},
        {"--sequence", "--min-confidence", "--boundary-radius", "--occlusion", "--geometry"});
    if (cli.helpRequested()) return ism::common::printUsage(kUsage);
    const std::vector<std::string> sequences = cli.getAll("--sequence");
    if (sequences.empty()) throw UsageError("--sequence is required");
    const std::string model = cli.require("--model");
    const int max_frames = cli.getInt("--max-frames", 0);
    const int map_label_every = cli.getInt("--map-label-every", 1);
    if (map_label_every < 1) throw UsageError("--map-label-every must be >= 1");
    if (cli.has("--json")) {  // before the run
      ism::common::checkOutputPath(cli.get("--json"));
      ism::common::checkOutputsAreNotInputs(
          {cli.get("--json")},
          cli.valuesOf({"--sequence", "--model", "--model-card", "--map-config"}));
    }
    const bool use_focal = !cli.has("--no-focal");
    const perception::ModelCard card =
        applyOverrides(cli.has("--model-card") ? perception::loadModelCard(cli.get("--model-card"))
                                               : perception::defaultModelCardFor(model),
                       cli);
    const std::vector<Variant> variants = makeVariants(cli);
    ism::mapping::SemanticMappingConfig map_config =
        cli.has("--map-config") ? ism::mapping::loadSemanticMappingConfig(cli.get("--map-config"))
                                : ism::mapping::SemanticMappingConfig();
    map_config.label_geometry_curbs = cli.getBool("--curbs", map_config.label_geometry_curbs);
    if (!cli.has("--no-map")) {
      std::printf(
          "maps: label_geometry %s (max flat %.2f m, min raised %.2f m, high terrain is "
          "vegetation %d, curbs %d)\n",
          map_config.label_geometry_check ? "on" : "off",
          map_config.label_geometry_max_flat_height_m,
          map_config.label_geometry_min_raised_height_m,
          map_config.label_geometry_high_terrain_is_vegetation ? 1 : 0,
          map_config.label_geometry_curbs ? 1 : 0);
    }

    perception::Segmenter segmenter(model, card, cli.getInt("--threads", 2));
    std::printf(
        "model %s, card %s: policy %s, tile_scale %g, network_focal_px %g, overlap %d, "
        "max width %d, bottom margin %d, flip %d, gamma %g, color %s, suppress unlabeled %d, "
        "focal given %d\n",
        model.c_str(), card.source.c_str(), perception::resizePolicyName(card.resize_policy),
        card.tile_scale, card.network_focal_px, card.tile_overlap, card.tile_max_width,
        card.tile_bottom_margin, card.flip_average ? 1 : 0, card.gamma,
        perception::colorNormalizationName(card.color_normalization),
        card.suppress_unlabeled ? 1 : 0, use_focal ? 1 : 0);

    // Every sequence's frames and poses before the first is labelled: a bad name or a missing
    // poses.txt in the last sequence surfaced after all the others had run.
    for (const std::string& dir : sequences) {
      evaluation::listSemanticKittiFrames(dir);
      if (!cli.has("--no-map")) ism::kitti::readKittiPoses(dir + "/poses.txt");
    }

    ism::TimingRegistry::instance().reset();  // the warm-up pass is not part of the figures
    std::vector<evaluation::PointLabelScore> totals(variants.size());
    evaluation::PointLabelScore map_totals, ceiling_totals;
    std::ostringstream json;
    json << "{\"sequences\":{";
    double total_ms = 0.0;
    int total_frames = 0;
    for (std::size_t s = 0; s < sequences.size(); ++s) {
      const std::string& dir = sequences[s];
      std::vector<std::string> incomplete;
      std::vector<std::string> frames = evaluation::listSemanticKittiFrames(dir, &incomplete);
      if (!incomplete.empty()) {
        // A sequence downloaded in parts (labels for some scans, images for others) is scored
        // on what it has; the user hears which scans that leaves out.
        std::printf(
            "note: %s: %zu scan(s) in velodyne/ skipped, without labels/NAME.label or "
            "image_2/NAME.png (first %s)\n",
            dir.c_str(), incomplete.size(), incomplete.front().c_str());
      }
      if (max_frames > 0 && static_cast<int>(frames.size()) > max_frames) frames.resize(max_frames);
      std::vector<evaluation::PointLabelScore> scores(variants.size());
      // Per geometry variant: the labels the geometry check took away (truth vs the label).
      std::vector<evaluation::PointLabelScore> rejected(variants.size());
      double sequence_ms = 0.0;
      double scale = 1.0;
      const std::string sequence_name = std::filesystem::path(dir).filename().string();
      // The map pass builds its camera map from the label images made here (the card's label
      // filter applied), so each frame is segmented once: a whole sequence took twice as long.
      // PNG-encoded (about 15 kB a frame): a sequence of 4,500 frames holds about 70 MB, not 2 GB.
      // A frame whose scale the focal length changes (--network-focal) is segmented again, as the
      // node would.
      const bool score_map = !cli.has("--no-map");
      std::map<std::string, std::vector<uchar>> map_label_images;
      ism::common::ProgressLog label_progress("evaluate_semantics: " + sequence_name + " labels",
                                              frames.size(), "frames");
      for (std::size_t f = 0; f < frames.size(); ++f) {
        const evaluation::SemanticKittiFrame frame =
            evaluation::readSemanticKittiFrame(dir, frames[f]);
        const ism::kitti::CameraProjection camera =
            evaluation::readSemanticKittiCamera(dir, frame.image.cols, frame.image.rows);
        const double focal = use_focal ? camera.P_rect(0, 0) : 0.0;
        scale = segmenter.tileScaleFor(frame.image.size(), focal);
        const auto start = std::chrono::steady_clock::now();
        const perception::Segmentation segmentation = segmenter.segment(frame.image, focal);
        sequence_ms +=
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
                .count();
        const perception::PointProjector projector(camera.P_rect, camera.R_rect, camera.T_cam0_velo,
                                                   frame.image.cols, frame.image.rows);
        if (score_map && scale == segmenter.tileScaleFor(frame.image.size(), 0.0)) {
          cv::imencode(".png",
                       perception::filterLabels(segmentation, segmenter.card().label_filter),
                       map_label_images[frames[f]], {cv::IMWRITE_PNG_COMPRESSION, 1});
        }
        perception::ProjectedPoints projected;
        for (std::size_t v = 0; v < variants.size(); ++v) {
          const std::vector<std::uint32_t> labels = evaluation::labelScanPoints(
              segmentation, projector, frame.scan, variants[v].options, &projected);
          for (std::size_t i = 0; i < labels.size(); ++i) {
            if (projected.valid[i]) scores[v].add(frame.truth[i], labels[i]);
          }
          if (variants[v].options.check_geometry) {
            evaluation::PointLabellingOptions unchecked = variants[v].options;
            unchecked.check_geometry = false;
            const std::vector<std::uint32_t> before = evaluation::labelScanPoints(
                segmentation, projector, frame.scan, unchecked, &projected);
            for (std::size_t i = 0; i < labels.size(); ++i) {
              if (projected.valid[i] && before[i] != labels[i])
                rejected[v].add(frame.truth[i], before[i]);
            }
          }
        }
        label_progress.update(f + 1);
      }
      const double ms_per_image = sequence_ms / frames.size();
      total_ms += sequence_ms;
      total_frames += static_cast<int>(frames.size());
      std::printf("\n== %s: %zu frames, %.0f ms per image (segmentation), image scale %.3f\n",
                  dir.c_str(), frames.size(), ms_per_image, scale);
      json << (s ? "," : "") << "\"" << dir << "\":{\"frames\":" << frames.size()
           << ",\"ms_per_image\":" << ms_per_image << ",\"variants\":{";
      for (std::size_t v = 0; v < variants.size(); ++v) {
        printScore(variants[v].name, scores[v], v <= 1);
        if (variants[v].options.check_geometry)
          printScore("  labels it rejected (acc: share that was right)", rejected[v], true);
        totals[v].merge(scores[v]);
        json << (v ? "," : "") << "\"" << variants[v].name << "\":" << scores[v].toJson();
      }
      json << "}";
      if (score_map) {
        // The maps of the sequence (ground-truth poses, 0.2 m): camera labels and the ceiling.
        ism::common::ProgressLog map_progress("evaluate_semantics: " + sequence_name + " maps",
                                              frames.size(), "frames");
        const evaluation::LabelImageSource label_image_of = [&](const std::string& name,
                                                                const cv::Mat& image) {
          const auto kept = map_label_images.find(name);
          if (kept != map_label_images.end())
            return cv::imdecode(kept->second, cv::IMREAD_UNCHANGED);
          return perception::filterLabels(segmenter.segment(image), segmenter.card().label_filter);
        };
        const evaluation::SequenceMapScores maps = evaluation::scoreSequenceMaps(
            dir, label_image_of, max_frames, map_config, map_label_every,
            [&](std::size_t done, std::size_t) { map_progress.update(done); });
        printScore("map from the camera labels (voxel class at each point)", maps.camera, true);
        printScore("map from the human labels (ceiling)", maps.ceiling, false);
        std::printf(
            "map: mIoU %.3f (ceiling %.3f; with misses %.3f), accuracy %.3f, coverage "
            "%.3f, %zu voxels\n",
            maps.camera.meanIoU(), maps.ceiling.meanIoU(), maps.camera.meanIoUWithMisses(),
            maps.camera.accuracy(), maps.camera.coverage(), maps.map_voxels);
        map_totals.merge(maps.camera);
        ceiling_totals.merge(maps.ceiling);
        json << ",\"map\":" << maps.camera.toJson() << ",\"map_ceiling\":" << maps.ceiling.toJson();
      }
      json << "}";
    }
    std::printf("\n== total: %d frames, %.0f ms per image\n", total_frames,
                total_ms / total_frames);
    json << "},\"total\":{\"frames\":" << total_frames
         << ",\"ms_per_image\":" << total_ms / total_frames << ",\"variants\":{";
    for (std::size_t v = 0; v < variants.size(); ++v) {
      printScore(variants[v].name, totals[v], false);
      json << (v ? "," : "") << "\"" << variants[v].name << "\":" << totals[v].toJson();
    }
    json << "}";
    if (!cli.has("--no-map")) {
      std::printf(
          "\n== total map: mIoU %.3f (ceiling %.3f; with misses %.3f), accuracy %.3f, "
          "coverage %.3f\n",
          map_totals.meanIoU(), ceiling_totals.meanIoU(), map_totals.meanIoUWithMisses(),
          map_totals.accuracy(), map_totals.coverage());
      json << ",\"map\":" << map_totals.toJson() << ",\"map_ceiling\":" << ceiling_totals.toJson();
    }
    json << "}}";
    // Stage timing (all frames and variants; the segmenter's warm-up pass excluded).
    std::printf("\n%s", ism::TimingRegistry::instance().report().c_str());
    if (cli.has("--json")) ism::common::writeTextAtomically(cli.get("--json"), json.str() + "\n");
    std::printf("RESULT %s\n", json.str().c_str());
    return 0;
  });
}
