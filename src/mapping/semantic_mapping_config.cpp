// The reader of SemanticMappingConfig: the YAML keys, their checks and the file loader.
#include "inekf_semantic_mapping/mapping/semantic_mapping_config.h"

#include <stdexcept>

#include "inekf_semantic_mapping/common/yaml_reader.h"

namespace inekf_semantic_mapping {
namespace mapping {
namespace {

void require(bool ok, const std::string& key, const std::string& what) {
  if (!ok) throw std::invalid_argument("semantic mapping config: '" + key + "' " + what);
}

}  // namespace

MapClassSet parseMapClassSet(const std::string& name) {
  if (name == "cityscapes") return MapClassSet::kCityscapes;
  if (name == "semantickitti") return MapClassSet::kSemanticKitti;
  throw std::invalid_argument("must be cityscapes or semantickitti, got '" + name + "'");
}

const char* mapClassSetName(MapClassSet set) {
  return set == MapClassSet::kCityscapes ? "cityscapes" : "semantickitti";
}

ClassSet classSetOf(MapClassSet set) {
  return set == MapClassSet::kCityscapes ? ClassSet::cityscapes() : ClassSet::semanticKitti();
}

InsertionStructure parseInsertionStructure(const std::string& name) {
  if (name == "hashed_grid") return InsertionStructure::kHashedGrid;
  if (name == "octree") return InsertionStructure::kOctree;
  throw std::invalid_argument("must be hashed_grid or octree, got '" + name + "'");
}

const char* insertionStructureName(InsertionStructure structure) {
  return structure == InsertionStructure::kHashedGrid ? "hashed_grid" : "octree";
}

void SemanticMappingConfig::validate() const {
  // Below 1 cm the octree (16 levels) spans less than +-330 m and a drive falls off it, which
  // was then reported against the poses.
  require(resolution_m >= 0.01 && resolution_m <= 100, "resolution_m", "must be in [0.01, 100] m");
  require(max_range_m >= 0, "max_range_m", "must be >= 0 (0: unlimited)");
  require(occupancy.prob_hit > 0.5 && occupancy.prob_hit < 1, "sensor_model.hit",
          "must be in (0.5, 1)");
  require(occupancy.prob_miss > 0 && occupancy.prob_miss < 0.5, "sensor_model.miss",
          "must be in (0, 0.5)");
  require(occupancy.clamping_min > 0 && occupancy.clamping_min < occupancy.clamping_max &&
              occupancy.clamping_max < 1,
          "sensor_model.clamping_min/clamping_max", "must satisfy 0 < min < max < 1");
  // The Bayes rule multiplies an observed class by c and every other by (1 - c) / (N - 1): at or
  // below 1/N an observation counts against its own class.
  const int classes = classSetOf(class_set).size();
  require(fusion.correct_probability > 1.0 / classes && fusion.correct_probability < 1,
          "confusion_probability",
          "must be in (1/N, 1) = (" + std::to_string(1.0 / classes) + ", 1) for the " +
              std::to_string(classes) + " " + mapClassSetName(class_set) +
              " classes: at or below 1/N an observation would count against its own class");
  require(fusion.dirichlet_prior > 0, "dirichlet_prior", "must be > 0");
  require(grazing_ray_truncation_voxels >= 0, "grazing_ray_truncation_voxels", "must be >= 0");
  require(ray_casting_threads >= 1 && ray_casting_threads <= 64, "ray_casting_threads",
          "must be in [1, 64]");
  require(early_ray_termination_voxels >= 0, "early_ray_termination_voxels", "must be >= 0");
  require(label_geometry_max_flat_height_m > 0 && label_geometry_max_flat_height_m <= 10,
          "label_geometry.max_flat_height_m", "must be in (0, 10] m");
  require(label_geometry_min_raised_height_m >= 0 && label_geometry_min_raised_height_m <= 10,
          "label_geometry.min_raised_height_m", "must be in [0, 10] m");
  require(label_stamp_tolerance_s >= 0 && label_stamp_tolerance_s <= 1.0, "label_stamp_tolerance_s",
          "must be in [0, 1] s");
  require(label_wait_s >= 0 && label_wait_s <= 30, "label_wait_s", "must be in [0, 30] s");
  require(label_neighbour_s >= 0 && label_neighbour_s <= 1.0, "label_neighbour_s",
          "must be in [0, 1] s");
  require(pose_wait_s >= 0 && pose_wait_s <= 30, "pose_wait_s", "must be in [0, 30] s");
}

const std::vector<std::string>& semanticMappingNodeKeys() {
  // grid.*: readGridProjectionConfig checks it; diagnostics.*: the node does. marker_rate,
  // autosave_period and log_period are old names the node still accepts (with a warning; it
  // reads them, not this reader). diagnostic_period
  // is diagnostic_updater's own, read from every node's private namespace; loaded_from names the
  // YAML file a launch loaded (ros/node_parameters.h).
  static const std::vector<std::string> keys = {"map_frame",        "marker_rate_hz",
                                                "marker_rate",      "max_display_cpu_fraction",
                                                "marker_depth",     "calib_dir",
                                                "camera_index",     "map_file",
                                                "autosave_path",    "autosave_period_s",
                                                "log_period_s",     "autosave_period",
                                                "log_period",       "grid.*",
                                                "diagnostics.*",    "diagnostic_period",
                                                "map_origin_param", "loaded_from"};
  return keys;
}

const std::vector<std::pair<std::string, std::string>>& renamedSemanticMappingKeys() {
  static const std::vector<std::pair<std::string, std::string>> keys = {
      {"resolution", "resolution_m"},
      {"max_range", "max_range_m"},
      {"label_geometry.max_flat_height", "label_geometry.max_flat_height_m"},
      {"label_geometry.min_raised_height", "label_geometry.min_raised_height_m"},
      {"label_stamp_tolerance", "label_stamp_tolerance_s"},
      {"label_wait", "label_wait_s"},
      {"pose_wait", "pose_wait_s"}};
  return keys;
}

SemanticMappingConfig readSemanticMappingConfig(const YAML::Node& root, const std::string& source) {
  common::YamlReader reader(source, root);
  SemanticMappingConfig config;
  // Times and lengths carry their unit in the name; an old name still works, with a warning.
  for (const auto& [old_key, new_key] : renamedSemanticMappingKeys()) {
    reader.renamed(old_key, new_key);
  }
  reader.read("resolution_m", &config.resolution_m);
  reader.read("max_range_m", &config.max_range_m);
  reader.read("sensor_model.hit", &config.occupancy.prob_hit);
  reader.read("sensor_model.miss", &config.occupancy.prob_miss);
  reader.read("sensor_model.clamping_min", &config.occupancy.clamping_min);
  reader.read("sensor_model.clamping_max", &config.occupancy.clamping_max);
  // Names of choices become enums here, once; a bad one names its key.
  reader.readChoice("class_set", parseMapClassSet, &config.class_set);
  reader.readChoice("fusion_rule", parseFusionRule, &config.fusion.rule);
  reader.read("confusion_probability", &config.fusion.correct_probability);
  reader.read("dirichlet_prior", &config.fusion.dirichlet_prior);
  reader.read("grazing_ray_truncation_voxels", &config.grazing_ray_truncation_voxels);
  reader.read("ray_casting_threads", &config.ray_casting_threads);
  reader.readChoice("insertion", parseInsertionStructure, &config.insertion);
  reader.read("early_ray_termination_voxels", &config.early_ray_termination_voxels);
  reader.read("insert_points_outside_image", &config.insert_points_outside_image);
  reader.read("reject_occluded_points", &config.reject_occluded_points);
  reader.read("label_geometry.enabled", &config.label_geometry_check);
  reader.read("label_geometry.max_flat_height_m", &config.label_geometry_max_flat_height_m);
  reader.read("label_geometry.min_raised_height_m", &config.label_geometry_min_raised_height_m);
  reader.read("label_geometry.high_terrain_is_vegetation",
              &config.label_geometry_high_terrain_is_vegetation);
  reader.read("label_geometry.curbs", &config.label_geometry_curbs);
  reader.read("label_stamp_tolerance_s", &config.label_stamp_tolerance_s);
  reader.read("label_wait_s", &config.label_wait_s);
  reader.read("label_neighbour_s", &config.label_neighbour_s);
  reader.read("pose_wait_s", &config.pose_wait_s);
  for (const std::string& key : semanticMappingNodeKeys()) reader.allow(key);
  reader.rejectUnknown();
  try {
    config.validate();
  } catch (const std::invalid_argument& e) {
    throw common::ConfigError(source + ": " + e.what());
  }
  return config;
}

SemanticMappingConfig loadSemanticMappingConfig(const std::string& yaml_path) {
  return readSemanticMappingConfig(common::loadYamlFile(yaml_path), yaml_path);
}

}  // namespace mapping
}  // namespace inekf_semantic_mapping
