#include "inekf_semantic_mapping/perception/label_geometry.h"

#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <limits>
#include <stdexcept>
#include <string>

#include "inekf_semantic_mapping/perception/cityscapes.h"

namespace inekf_semantic_mapping {
namespace perception {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// Per-thread buffers kept from scan to scan: fresh ones cost more than the work (a scan's
// half-megabyte buffers came from the kernel zeroed, page by page, each time).
struct Scratch {
  std::vector<int> point_cell;
  std::vector<std::size_t> begin, next;
  std::vector<float> z_by_cell, lowest, ground;
};

}  // namespace

void heightAboveGround(const PointMatrixRef& points, const GroundGridOptions& options,
                       Eigen::VectorXf* heights) {
  if (!(options.cell_size_m > 0.05f && options.cell_size_m <= 20.0f) ||
      !(options.range_m > 0.0f && options.range_m <= 500.0f) ||
      !(options.range_m / options.cell_size_m <= 2000.0f) ||
      !(options.max_slope >= 0.0f && options.max_slope <= 10.0f) ||
      !(options.min_support >= 1 && options.min_support <= 1000) ||
      !(options.support_band_m >= 0.0f && options.support_band_m <= 10.0f)) {
    throw std::invalid_argument(
        "heightAboveGround: cell_size_m in (0.05, 20], range_m in (0, 500] with at most 2000 "
        "cells across, max_slope in [0, 10], min_support in [1, 1000], support_band_m in "
        "[0, 10]");
  }
  const Eigen::Index n = points.cols();
  heights->resize(n);
  const float cell = options.cell_size_m;
  const int size = static_cast<int>(std::ceil(2.0f * options.range_m / cell));
  const float origin = -0.5f * static_cast<float>(size) * cell;  // grid corner (x and y)
  const std::size_t cells = static_cast<std::size_t>(size) * static_cast<std::size_t>(size);

  thread_local Scratch scratch;
  // The cell of each point (-1: none), then the points' z grouped by cell (a counting sort).
  std::vector<int>& point_cell = scratch.point_cell;
  std::vector<std::size_t>& begin = scratch.begin;
  point_cell.resize(static_cast<std::size_t>(n));
  begin.assign(cells + 1, 0);
  const float inverse_cell = 1.0f / cell;
  for (Eigen::Index i = 0; i < n; ++i) {
    const float x = points(0, i), y = points(1, i), z = points(2, i);
    int& index = point_cell[static_cast<std::size_t>(i)];
    index = -1;
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) continue;
    const int cx = static_cast<int>(std::floor((x - origin) * inverse_cell));
    const int cy = static_cast<int>(std::floor((y - origin) * inverse_cell));
    if (cx < 0 || cy < 0 || cx >= size || cy >= size) continue;
    index = cy * size + cx;
    ++begin[static_cast<std::size_t>(index) + 1];
  }
  for (std::size_t c = 0; c < cells; ++c) begin[c + 1] += begin[c];
  std::vector<float>& z_by_cell = scratch.z_by_cell;
  z_by_cell.resize(begin[cells]);
  {
    std::vector<std::size_t>& next = scratch.next;
    next.assign(begin.begin(), begin.end() - 1);
    for (Eigen::Index i = 0; i < n; ++i) {
      const int c = point_cell[static_cast<std::size_t>(i)];
      if (c >= 0) z_by_cell[next[static_cast<std::size_t>(c)]++] = points(2, i);
    }
  }
  // Lowest supported z per cell (inf: none).
  std::vector<float>& lowest = scratch.lowest;
  lowest.assign(cells, kInf);
  const std::size_t support = static_cast<std::size_t>(options.min_support);
  for (std::size_t c = 0; c < cells; ++c) {
    if (begin[c + 1] - begin[c] < support) continue;
    float* first = z_by_cell.data() + begin[c];
    float* last = z_by_cell.data() + begin[c + 1];
    // Usually the lowest point is the ground and has its support: one pass, no sort.
    const float minimum = *std::min_element(first, last);
    const auto near_minimum =
        std::count_if(first, last, [&](float z) { return z <= minimum + options.support_band_m; });
    if (static_cast<std::size_t>(near_minimum) >= support) {
      lowest[c] = minimum;
      continue;
    }
    std::sort(first, last);
    for (float* z = first; z + (support - 1) < last; ++z) {
      if (z[support - 1] - z[0] <= options.support_band_m) {
        lowest[c] = z[0];
        break;
      }
    }
  }

  // The slope-limited lower envelope (a chamfer distance transform with 8 neighbours: two passes
  // give min over all cells of lowest + slope * path length, within 8 % of the Euclidean cone).
  std::vector<float>& ground = scratch.ground;
  ground = lowest;
  const float step = options.max_slope * cell;
  const float diagonal = step * std::sqrt(2.0f);
  const auto relax = [&](int x, int y, int dx, int dy, float cost) {
    const int nx = x + dx, ny = y + dy;
    if (nx < 0 || ny < 0 || nx >= size || ny >= size) return;
    float& g = ground[static_cast<std::size_t>(y * size + x)];
    g = std::min(g, ground[static_cast<std::size_t>(ny * size + nx)] + cost);
  };
  for (int y = 0; y < size && options.max_slope > 0.0f; ++y) {
    for (int x = 0; x < size; ++x) {
      relax(x, y, -1, -1, diagonal);
      relax(x, y, 0, -1, step);
      relax(x, y, 1, -1, diagonal);
      relax(x, y, -1, 0, step);
    }
  }
  for (int y = size - 1; y >= 0 && options.max_slope > 0.0f; --y) {
    for (int x = size - 1; x >= 0; --x) {
      relax(x, y, 1, 1, diagonal);
      relax(x, y, 0, 1, step);
      relax(x, y, -1, 1, diagonal);
      relax(x, y, 1, 0, step);
    }
  }

  // Bilinear blend between the centres of the four cells around the point, over the supported
  // ones (an empty cell's envelope value is only an upper bound of its ground).
  for (Eigen::Index i = 0; i < n; ++i) {
    (*heights)(i) = kNaN;
    if (point_cell[static_cast<std::size_t>(i)] < 0) continue;
    const float fx = (points(0, i) - origin) * inverse_cell - 0.5f;
    const float fy = (points(1, i) - origin) * inverse_cell - 0.5f;
    const int x0 = static_cast<int>(std::floor(fx)), y0 = static_cast<int>(std::floor(fy));
    const float tx = fx - static_cast<float>(x0), ty = fy - static_cast<float>(y0);
    float sum = 0.0f, weight = 0.0f, nearest = kInf, nearest_weight = -1.0f;
    for (int dy = 0; dy <= 1; ++dy) {
      for (int dx = 0; dx <= 1; ++dx) {
        const int x = x0 + dx, y = y0 + dy;
        if (x < 0 || y < 0 || x >= size || y >= size) continue;
        const std::size_t c = static_cast<std::size_t>(y * size + x);
        if (!std::isfinite(lowest[c])) continue;
        const float w = (dx ? tx : 1.0f - tx) * (dy ? ty : 1.0f - ty);
        sum += w * ground[c];
        weight += w;
        if (w > nearest_weight) {
          nearest_weight = w;
          nearest = ground[c];
        }
      }
    }
    // A point on a cell centre's row or column has zero weight on the far cells: the nearest
    // supported cell's value then.
    if (weight > 1e-6f) {
      (*heights)(i) = points(2, i) - sum / weight;
    } else if (std::isfinite(nearest)) {
      (*heights)(i) = points(2, i) - nearest;
    }
  }
}

const SurfaceKindTable& cityscapesSurfaceKinds() {
  static const SurfaceKindTable table = [] {
    SurfaceKindTable t;
    t.fill(SurfaceKind::kAny);
    for (int id : std::initializer_list<int>{cityscapes::kGround, cityscapes::kRoad,
                                             cityscapes::kSidewalk, cityscapes::kParking,
                                             10 /* rail track */, cityscapes::kTerrain}) {
      t[static_cast<std::size_t>(id)] = SurfaceKind::kFlat;
    }
    for (int id : std::initializer_list<int>{cityscapes::kTrafficLight, cityscapes::kTrafficSign}) {
      t[static_cast<std::size_t>(id)] = SurfaceKind::kRaised;
    }
    return t;
  }();
  return table;
}

const RelabelTable& cityscapesHighFlatRelabels() {
  static const RelabelTable table = [] {
    RelabelTable t;
    t.fill(kNoRelabel);
    t[cityscapes::kTerrain] = cityscapes::kVegetation;
    return t;
  }();
  return table;
}

void rejectGeometricallyInconsistentLabels(
    const Eigen::VectorXf& heights, const SurfaceKindTable& kinds,
    const LabelGeometryOptions& options, std::uint32_t unknown_label,
    std::vector<std::uint32_t>* labels, std::size_t* rejected, const RelabelTable* relabel_high) {
  if (static_cast<std::size_t>(heights.size()) != labels->size()) {
    throw std::invalid_argument(
        "rejectGeometricallyInconsistentLabels: " + std::to_string(heights.size()) +
        " heights for " + std::to_string(labels->size()) + " labels");
  }
  std::size_t count = 0;
  for (std::size_t i = 0; i < labels->size(); ++i) {
    std::uint32_t& label = (*labels)[i];
    if (label == unknown_label || label >= kinds.size()) continue;
    const float h = heights(static_cast<Eigen::Index>(i));
    if (!std::isfinite(h)) continue;
    const SurfaceKind kind = kinds[label];
    if (kind == SurfaceKind::kFlat && h > options.max_flat_height_m) {
      const std::uint32_t other = relabel_high ? (*relabel_high)[label] : kNoRelabel;
      label = other == kNoRelabel ? unknown_label : other;
      ++count;
    } else if (kind == SurfaceKind::kRaised && h < options.min_raised_height_m) {
      label = unknown_label;
      ++count;
    }
  }
  if (rejected) *rejected = count;
}

const RelabelTable& cityscapesBeyondCurbRelabels() {
  static const RelabelTable table = [] {
    RelabelTable t;
    t.fill(kNoRelabel);
    t[cityscapes::kRoad] = cityscapes::kSidewalk;
    return t;
  }();
  return table;
}

void relabelBeyondCurbs(const std::vector<std::uint8_t>& beyond, const RelabelTable& relabel,
                        std::vector<std::uint32_t>* labels, std::size_t* changed) {
  if (beyond.size() != labels->size()) {
    throw std::invalid_argument("relabelBeyondCurbs: " + std::to_string(beyond.size()) +
                                " flags for " + std::to_string(labels->size()) + " labels");
  }
  std::size_t count = 0;
  for (std::size_t i = 0; i < labels->size(); ++i) {
    std::uint32_t& label = (*labels)[i];
    if (!beyond[i] || label >= relabel.size() || relabel[label] == kNoRelabel) continue;
    label = relabel[label];
    ++count;
  }
  if (changed) *changed = count;
}

void applyCityscapesLidarChecks(const PointMatrixRef& points, const CityscapesLidarChecks& checks,
                                std::uint32_t unknown_label, std::vector<std::uint32_t>* labels) {
  Eigen::VectorXf heights;
  heightAboveGround(points, checks.geometry.ground, &heights);
  rejectGeometricallyInconsistentLabels(
      heights, cityscapesSurfaceKinds(), checks.geometry, unknown_label, labels, nullptr,
      checks.high_terrain_is_vegetation ? &cityscapesHighFlatRelabels() : nullptr);
  if (checks.curbs) {
    std::vector<std::uint8_t> beyond;
    markPointsBeyondCurbs(points, checks.curb, &beyond);
    relabelBeyondCurbs(beyond, cityscapesBeyondCurbRelabels(), labels);
  }
}

}  // namespace perception
}  // namespace inekf_semantic_mapping
