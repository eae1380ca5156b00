#include "inekf_semantic_mapping/mapping/grid_projection.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "inekf_semantic_mapping/common/atomic_file.h"
#include "inekf_semantic_mapping/common/yaml_reader.h"
#include "inekf_semantic_mapping/mapping/semantic_octree.h"

namespace inekf_semantic_mapping {
namespace mapping {

namespace {

void require(bool ok, const std::string& key, const std::string& what) {
  if (!ok) throw std::invalid_argument("grid." + key + " " + what);
}

// The ground raster is this many cells coarser than the grid: the ground changes slowly, and a
// fine raster would cost a BFS over millions of cells per display.
constexpr int kGroundCellFactor = 8;
// A coarse cell's drivable voxels define its ground only when they cover this many of its 64
// columns: a few mislabelled voxels (a car roof called road) do not move the ground.
constexpr int kMinDrivableColumns = 3;

// Ground height per coarse cell. Seeds: the lowest drivable voxel of cells with enough of them
// (the road itself, also away from the path and in a loaded map), else the mean of the path
// samples in the cell (samples outside the grid seed the border cell nearest to them). Every other
// cell takes the height of its nearest seed (multi-source BFS, 8-connected: nearest in the
// Chebyshev sense); without any seed, the plane ground_z.
std::vector<float> groundRaster(const std::vector<float>& drivable_min_z,
                                const std::vector<int>& drivable_columns, int gw, int gh,
                                double origin_x, double origin_y, double step,
                                const std::vector<Eigen::Vector3d>& samples, double ground_z) {
  const std::size_t n = static_cast<std::size_t>(gw) * gh;
  std::vector<double> sum(n, 0.0);
  std::vector<int> count(n, 0);
  for (const Eigen::Vector3d& p : samples) {
    const int gx = std::clamp(static_cast<int>(std::floor((p.x() - origin_x) / step)), 0, gw - 1);
    const int gy = std::clamp(static_cast<int>(std::floor((p.y() - origin_y) / step)), 0, gh - 1);
    sum[static_cast<std::size_t>(gy) * gw + gx] += p.z();
    ++count[static_cast<std::size_t>(gy) * gw + gx];
  }
  std::vector<float> ground(n, std::numeric_limits<float>::quiet_NaN());
  std::deque<std::size_t> queue;
  for (std::size_t i = 0; i < n; ++i) {
    if (drivable_columns[i] >= kMinDrivableColumns) {
      ground[i] = drivable_min_z[i];
    } else if (count[i] > 0) {
      ground[i] = static_cast<float>(sum[i] / count[i]);
    } else {
      continue;
    }
    queue.push_back(i);
  }
  if (queue.empty()) return std::vector<float>(n, static_cast<float>(ground_z));
  while (!queue.empty()) {
    const std::size_t i = queue.front();
    queue.pop_front();
    const int gx = static_cast<int>(i % gw);
    const int gy = static_cast<int>(i / gw);
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        const int x = gx + dx;
        const int y = gy + dy;
        if (x < 0 || y < 0 || x >= gw || y >= gh) continue;
        const std::size_t j = static_cast<std::size_t>(y) * gw + x;
        if (!std::isnan(ground[j])) continue;
        ground[j] = ground[i];
        queue.push_back(j);
      }
    }
  }
  return ground;
}

}  // namespace

void GridProjectionConfig::validate() const {
  require(max_z > min_z, "max_z_m", "must be > grid.min_z_m");
  require(ground_min_z < min_z, "ground_min_z_m", "must be < grid.min_z_m");
  require(sensor_height >= 0 && sensor_height <= 10, "sensor_height_m", "must be in [0, 10] m");
  require(!drivable_classes.empty(), "drivable_classes", "must name at least one class");
}

GridProjectionConfig readGridProjectionConfig(const YAML::Node& root, const std::string& source) {
  common::YamlReader reader(source, root);
  GridProjectionConfig config;
  // Lengths carry their unit in the name; an old name still works, with a warning.
  for (const char* key : {"min_z", "max_z", "ground_min_z", "sensor_height", "ground_z"}) {
    reader.renamed(std::string("grid.") + key, std::string("grid.") + key + "_m");
  }
  reader.read("grid.min_z_m", &config.min_z);
  reader.read("grid.max_z_m", &config.max_z);
  reader.read("grid.ground_min_z_m", &config.ground_min_z);
  reader.read("grid.drivable_classes", &config.drivable_classes);
  reader.read("grid.sensor_height_m", &config.sensor_height);
  reader.read("grid.ground_z_m", &config.ground_z);
  // Only the grid section is this reader's: a misspelt key inside it is an error, the rest of
  // the file belongs to readSemanticMappingConfig.
  if (root.IsMap()) {
    for (const auto& entry : root) {
      const std::string key = entry.first.as<std::string>();
      if (key == "grid") continue;
      reader.allow(key);
      reader.allow(key + ".*");
    }
  }
  reader.rejectUnknown();
  try {
    config.validate();
  } catch (const std::invalid_argument& e) {
    throw common::ConfigError(source + ": " + e.what());
  }
  return config;
}

bool Grid2D::cellOf(double x, double y, int* ix, int* iy) const {
  if (resolution <= 0) return false;
  const double fx = std::floor((x - origin_x) / resolution);
  const double fy = std::floor((y - origin_y) / resolution);
  if (fx < 0 || fy < 0 || fx >= width || fy >= height) return false;
  *ix = static_cast<int>(fx);
  *iy = static_cast<int>(fy);
  return true;
}

ProjectedGrids projectGrids(const SemanticOcTree& tree, const GridProjectionConfig& config,
                            const std::vector<Eigen::Vector3d>& ground_samples) {
  config.validate();
  const ClassSet& classes = tree.classSet();
  std::vector<bool> drivable_class(kMaxClasses + 1, false);
  for (const std::string& name : config.drivable_classes) {
    bool found = false;
    for (int i = 0; i < classes.size(); ++i) {
      if (classes.info(static_cast<ClassIndex>(i)).name != name) continue;
      drivable_class[i] = true;
      found = true;
    }
    if (!found) {
      throw std::invalid_argument("grid.drivable_classes: class '" + name +
                                  "' is not in the map's class set");
    }
  }

  ProjectedGrids grids;
  const double resolution = tree.getResolution();
  grids.occupancy.resolution = grids.drivable.resolution = resolution;
  if (tree.getRoot() == nullptr) return grids;

  // Each leaf's footprint, height, occupancy and class. The tree is walked three times (bounds,
  // ground seeds, cells): a walk costs about 15 ns per node, less than keeping the leaves.
  struct Leaf {
    unsigned int kx, ky;  // corner key (lowest x and y)
    int span;             // cells per side (pruned leaves: more than one)
    bool occupied;
    ClassIndex cls;  // kNoClass for free leaves
    double z_low, z_high;
  };
  const unsigned int max_depth = tree.getTreeDepth();
  const auto for_each_leaf = [&tree, max_depth](const auto& visit) {
    for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
      const unsigned int span = 1u << (max_depth - it.getDepth());
      // A root leaf (span 65536) does not fit: such a map is one uniform block, nothing to show.
      if (span > 0x8000) continue;
      const octomap::OcTreeKey corner = it.getIndexKey();
      const bool occupied = tree.isNodeOccupied(*it);
      const double half = it.getSize() / 2;
      visit(Leaf{corner[0], corner[1], static_cast<int>(span), occupied,
                 occupied ? it->mostLikelyClass() : kNoClass, it.getZ() - half, it.getZ() + half});
    }
  };
  // Bounds in key space over every leaf (free ones too: the grid covers the known space).
  unsigned int kx_min = std::numeric_limits<unsigned int>::max(), ky_min = kx_min;
  unsigned int kx_max = 0, ky_max = 0;
  for_each_leaf([&](const Leaf& leaf) {
    kx_min = std::min(kx_min, leaf.kx);
    ky_min = std::min(ky_min, leaf.ky);
    kx_max = std::max(kx_max, leaf.kx + leaf.span - 1);
    ky_max = std::max(ky_max, leaf.ky + leaf.span - 1);
  });
  if (kx_max < kx_min) return grids;  // no leaves
  const int width = static_cast<int>(kx_max - kx_min + 1);
  const int height = static_cast<int>(ky_max - ky_min + 1);
  // About 8 bytes per cell while projecting: 2^26 cells (a 1.6 km square at 0.2 m) is 0.5 GB.
  constexpr std::size_t kMaxCells = std::size_t{1} << 26;
  if (static_cast<std::size_t>(width) * height > kMaxCells) {
    throw std::runtime_error("grid: the map's known space spans " + std::to_string(width) + " x " +
                             std::to_string(height) + " cells, more than " +
                             std::to_string(kMaxCells) + " (a coarser map resolution)");
  }
  const double origin_x = tree.keyToCoord(static_cast<octomap::key_type>(kx_min)) - resolution / 2;
  const double origin_y = tree.keyToCoord(static_cast<octomap::key_type>(ky_min)) - resolution / 2;
  for (Grid2D* grid : {&grids.occupancy, &grids.drivable}) {
    grid->width = width;
    grid->height = height;
    grid->origin_x = origin_x;
    grid->origin_y = origin_y;
    grid->cells.assign(static_cast<std::size_t>(width) * height, kGridUnknown);
  }

  // The drivable voxels of each coarse cell: lowest centre and how many columns they cover.
  const int raster_width = (width + kGroundCellFactor - 1) / kGroundCellFactor;
  const int raster_height = (height + kGroundCellFactor - 1) / kGroundCellFactor;
  const std::size_t raster_cells = static_cast<std::size_t>(raster_width) * raster_height;
  std::vector<float> drivable_min_z(raster_cells, std::numeric_limits<float>::infinity());
  std::vector<int> drivable_columns(raster_cells, 0);
  std::vector<std::uint8_t> counted(static_cast<std::size_t>(width) * height, 0);
  for_each_leaf([&](const Leaf& leaf) {
    if (leaf.cls == kNoClass || !drivable_class[leaf.cls]) return;
    const int ix0 = static_cast<int>(leaf.kx - kx_min);
    const int iy0 = static_cast<int>(leaf.ky - ky_min);
    const float z = (leaf.z_low + leaf.z_high) / 2;
    for (int iy = iy0; iy < iy0 + leaf.span; ++iy) {
      for (int ix = ix0; ix < ix0 + leaf.span; ++ix) {
        const std::size_t coarse = static_cast<std::size_t>(iy / kGroundCellFactor) * raster_width +
                                   ix / kGroundCellFactor;
        drivable_min_z[coarse] = std::min(drivable_min_z[coarse], z);
        std::uint8_t& column = counted[static_cast<std::size_t>(iy) * width + ix];
        if (!column) ++drivable_columns[coarse];
        column = 1;
      }
    }
  });
  const std::vector<float> ground =
      groundRaster(drivable_min_z, drivable_columns, raster_width, raster_height, origin_x,
                   origin_y, resolution * kGroundCellFactor, ground_samples, config.ground_z);
  // Per cell: top of the highest classed voxel in the ground band, and whether it is drivable.
  std::vector<float> surface_top(grids.drivable.cells.size(),
                                 -std::numeric_limits<float>::infinity());
  std::vector<std::uint8_t> surface_drivable(grids.drivable.cells.size(), 0);
  std::vector<std::int8_t>& occupancy = grids.occupancy.cells;

  // Leaves above or below every band (most of the free space) touch no cell.
  const auto [ground_low, ground_high] = std::minmax_element(ground.begin(), ground.end());
  const double lowest_band = *ground_low + std::min(config.ground_min_z, config.min_z);
  const double highest_band = *ground_high + config.max_z;
  grids.occupancy.origin_z = grids.drivable.origin_z = *ground_low;
  for_each_leaf([&](const Leaf& leaf) {
    if (leaf.z_high <= lowest_band || leaf.z_low >= highest_band) return;
    const bool occupied = leaf.occupied;
    const ClassIndex cls = leaf.cls;
    const double z_low = leaf.z_low;
    const double z_high = leaf.z_high;
    const int span = leaf.span;
    const int ix0 = static_cast<int>(leaf.kx - kx_min);
    const int iy0 = static_cast<int>(leaf.ky - ky_min);
    for (int iy = iy0; iy < iy0 + span; ++iy) {
      for (int ix = ix0; ix < ix0 + span; ++ix) {
        const std::size_t cell = static_cast<std::size_t>(iy) * width + ix;
        const double g = ground[static_cast<std::size_t>(iy / kGroundCellFactor) * raster_width +
                                ix / kGroundCellFactor];
        // Extent overlap, strict at both ends (octomap_server's test): a voxel that only
        // touches the band's edge is outside it.
        const bool in_band = z_high > g + config.min_z && z_low < g + config.max_z;
        if (in_band) {
          if (occupied) {
            occupancy[cell] = kGridOccupied;
          } else if (occupancy[cell] == kGridUnknown) {
            occupancy[cell] = kGridFree;
          }
        }
        if (cls != kNoClass && z_high > g + config.ground_min_z && z_low < g + config.min_z &&
            z_high > surface_top[cell]) {
          surface_top[cell] = static_cast<float>(z_high);
          surface_drivable[cell] = drivable_class[cls] ? 1 : 0;
        }
      }
    }
  });
  std::vector<std::int8_t>& drivable = grids.drivable.cells;
  for (std::size_t cell = 0; cell < drivable.size(); ++cell) {
    if (occupancy[cell] == kGridOccupied) {
      drivable[cell] = kGridOccupied;
    } else if (std::isfinite(surface_top[cell])) {
      drivable[cell] = surface_drivable[cell] ? kGridFree : kGridOccupied;
    }
  }
  return grids;
}

void GroundTrace::addSensorOrigin(const Eigen::Vector3d& origin_map) {
  const Eigen::Vector3d ground = origin_map - Eigen::Vector3d(0, 0, sensor_height_);
  if (!samples_.empty() && (ground.head<2>() - samples_.back().head<2>()).norm() < spacing_) {
    return;
  }
  samples_.push_back(ground);
}

std::vector<std::string> mapServerGridPaths(const std::string& stem) {
  return {stem + ".pgm", stem + ".yaml"};
}

namespace {

// A YAML double-quoted scalar: a file name with ": ", " #", "[" or "&" in it, written plain, did
// not parse or named another file (everything after " #" a comment).
std::string yamlQuoted(const std::string& text) {
  std::string quoted = "\"";
  for (const char c : text) {
    if (c == '"' || c == '\\') {
      quoted += '\\';
      quoted += c;
    } else if (static_cast<unsigned char>(c) < 0x20) {
      char escape[8];
      std::snprintf(escape, sizeof(escape), "\\x%02x", static_cast<unsigned char>(c));
      quoted += escape;
    } else {
      quoted += c;
    }
  }
  return quoted + "\"";
}

}  // namespace

std::vector<std::string> addMapServerGrid(const Grid2D& grid, const std::string& stem,
                                          common::AtomicFileSet* files) {
  const std::vector<std::string> paths = mapServerGridPaths(stem);
  const std::string& pgm_path = paths[0];
  const std::string& yaml_path = paths[1];
  // map_server with negate 0: p = (255 - value) / 255; occupied above occupied_thresh, free below
  // free_thresh, unknown between.
  files->addStream(pgm_path, [&](std::ostream& out) {
    out << "P5\n" << grid.width << " " << grid.height << "\n255\n";
    std::string row(static_cast<std::size_t>(grid.width), '\0');
    for (int iy = grid.height - 1; iy >= 0; --iy) {  // image top = largest y
      for (int ix = 0; ix < grid.width; ++ix) {
        const std::int8_t value = grid.at(ix, iy);
        row[ix] = static_cast<char>(value == kGridUnknown ? 205 : value >= kGridOccupied ? 0 : 254);
      }
      out.write(row.data(), static_cast<std::streamsize>(row.size()));
    }
  });
  files->addStream(yaml_path, [&](std::ostream& yaml) {
    yaml.precision(10);
    yaml << "image: " << yamlQuoted(std::filesystem::path(pgm_path).filename().string()) << "\n"
         << "resolution: " << grid.resolution << "\n"
         << "origin: [" << grid.origin_x << ", " << grid.origin_y << ", 0.0]\n"
         << "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n";
  });
  return paths;
}

std::vector<std::string> writeMapServerGrid(const Grid2D& grid, const std::string& stem) {
  common::AtomicFileSet files;
  const std::vector<std::string> paths = addMapServerGrid(grid, stem, &files);
  files.commit();
  return paths;
}

}  // namespace mapping
}  // namespace inekf_semantic_mapping
