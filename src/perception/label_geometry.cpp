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

namespace {

// The forward half of one ring: from the point straight ahead, walks sideways (step +1 or -1,
// the two ways along the ring) and returns the index in `forward` of the first point of a kerb's
// rise, or -1. The road's level is the mean height of the older half of its last 0.3 m of
// points: a ring meets a kerb's face at a slant and climbs it by about a centimetre per point, so
// against the point before, or a window that takes the face in as it climbs, the rise would never
// show; a gentle grade moves the window along with it.
int findCurb(const std::vector<Eigen::Index>& forward, const PointMatrixRef& points, int seed,
             int step, const CurbOptions& options) {
  const auto xy_distance = [&](int a, int b) {
    const Eigen::Index pa = forward[a], pb = forward[b];
    return std::hypot(points(0, pa) - points(0, pb), points(1, pa) - points(1, pb));
  };
  const auto z = [&](int i) { return points(2, forward[i]); };
  const auto inside = [&](int i) { return i >= 0 && i < static_cast<int>(forward.size()); };
  constexpr float kRoadWindow = 0.3f;  // m of road behind the walk
  std::vector<int> window{seed};       // recent road points, oldest first
  const auto road_level = [&] {        // the mean of the window's older half
    const std::size_t half = (window.size() + 1) / 2;
    float sum = 0.0f;
    for (std::size_t i = 0; i < half; ++i) sum += z(window[i]);
    return sum / static_cast<float>(half);
  };
  const auto restart = [&](int i) { window.assign(1, i); };
  int run_start = seed;  // where the current stretch of road began
  for (int j = seed + step; inside(j); j += step) {
    const int last_road = window.back();
    const float road_z = road_level();
    const float dxy = xy_distance(j, last_road);
    const float dz = z(j) - road_z;
    if (std::abs(dz) <= options.flat_tolerance_m) {
      if (dxy > options.max_step_run_m) {  // a gap in the ring: a new stretch
        restart(j);
        run_start = j;
        continue;
      }
      window.push_back(j);
      while (xy_distance(window.front(), j) > kRoadWindow) window.erase(window.begin());
    } else if (std::abs(dz) > options.max_step_m) {
      if (dxy < options.max_step_run_m) return -1;  // an obstacle before any kerb
      restart(j);                                   // a steady grade
      run_start = j;
    } else if (dz >= options.min_step_m && dxy < options.max_step_run_m) {
      // A kerb needs flat road before it and a flat raised surface after it: the level the
      // rise settles at, max_step_run_m on, held for min_top_run_m.
      int top = j;
      while (inside(top) && xy_distance(top, j) < options.max_step_run_m) top += step;
      bool top_is_flat = inside(top);
      const float top_z = top_is_flat ? z(top) : 0.0f;
      const float rise = top_z - road_z;
      top_is_flat = top_is_flat && rise >= options.min_step_m && rise <= options.max_step_m;
      int k = top;
      while (top_is_flat && inside(k) && xy_distance(k, top) < options.min_top_run_m) {
        top_is_flat = std::abs(z(k) - top_z) <= options.flat_tolerance_m;
        k += step;
      }
      top_is_flat = top_is_flat && inside(k);
      if (top_is_flat && xy_distance(last_road, run_start) >= options.min_road_run_m) return j;
      restart(j);
      run_start = j;
    } else if (dxy >= options.max_step_run_m) {
      restart(j);
      run_start = j;
    }
  }
  return -1;
}

float medianOf(std::vector<float> values) {
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

// Least squares y = a + b x over the kerbs whose residual under `previous` is below
// max_residual (all when previous is null). False when fewer than two remain or x does not vary.
bool fitKerbLine(const std::vector<Eigen::Vector3f>& kerbs, const Eigen::Vector2f* previous,
                 float max_residual, Eigen::Vector2f* line) {
  Eigen::Matrix2d normal = Eigen::Matrix2d::Zero();
  Eigen::Vector2d rhs = Eigen::Vector2d::Zero();
  int used = 0;
  for (const Eigen::Vector3f& kerb : kerbs) {
    if (previous && std::abs((*previous)(0) + (*previous)(1) * kerb.x() - kerb.y()) >= max_residual)
      continue;
    const Eigen::Vector2d row(1.0, kerb.x());
    normal += row * row.transpose();
    rhs += row * kerb.y();
    ++used;
  }
  if (used < 2 || std::abs(normal.determinant()) < 1e-6) return false;
  *line = normal.ldlt().solve(rhs).cast<float>();
  return true;
}

// The points beyond one side's kerb line (side +1: left, y above the line; -1: right).
void markBeyondKerbLine(const PointMatrixRef& points, const std::vector<Eigen::Vector3f>& kerbs,
                        float side, const CurbOptions& options, std::vector<std::uint8_t>* beyond) {
  if (static_cast<int>(kerbs.size()) < options.line_min_points) return;
  Eigen::Vector2f line;
  if (!fitKerbLine(kerbs, nullptr, 0.0f, &line)) return;
  std::vector<float> residuals, heights;
  float x_min = kInf, x_max = -kInf;
  for (const Eigen::Vector3f& kerb : kerbs) {
    residuals.push_back(std::abs(line(0) + line(1) * kerb.x() - kerb.y()));
    heights.push_back(kerb.z());
    x_min = std::min(x_min, kerb.x());
    x_max = std::max(x_max, kerb.x());
  }
  constexpr float kMaxMedianResidual = 0.3f, kMaxResidual = 0.5f;
  if (medianOf(residuals) > kMaxMedianResidual) return;  // the kerbs do not lie on a line
  const Eigen::Vector2f first = line;
  if (!fitKerbLine(kerbs, &first, kMaxResidual, &line)) return;
  const float kerb_height = medianOf(heights);
  x_min -= options.line_extension_m;
  x_max += options.line_extension_m;
  for (Eigen::Index i = 0; i < points.cols(); ++i) {
    const float x = points(0, i);
    if (!(x >= x_min && x <= x_max)) continue;
    if (std::abs(points(2, i) - kerb_height) >= options.line_height_tolerance_m) continue;
    if ((points(1, i) - (line(0) + line(1) * x)) * side > options.line_margin_m)
      (*beyond)[static_cast<std::size_t>(i)] = 1;
  }
}

}  // namespace

int markPointsBeyondCurbs(const PointMatrixRef& points, const CurbOptions& options,
                          std::vector<std::uint8_t>* beyond) {
  const Eigen::Index n = points.cols();
  beyond->assign(static_cast<std::size_t>(n), 0);
  // Ring boundaries: the azimuth rises within a ring (from -pi to +pi) and jumps back at its
  // end; a cloud cropped to the camera's view (the session keeps only those points of a scan
  // whose label image comes late) jumps back by the view's width. Gaps in the returns (sky) jump
  // forward. A lidar spinning the other way does all of it mirrored.
  constexpr float kPi = 3.14159265f;
  constexpr float kRingJump = kPi / 4;
  std::vector<float> azimuth(static_cast<std::size_t>(n));
  for (Eigen::Index i = 0; i < n; ++i) azimuth[i] = std::atan2(points(1, i), points(0, i));
  Eigen::Index rising = 0, falling = 0;
  for (Eigen::Index i = 1; i < n; ++i) {
    const float change = azimuth[i] - azimuth[i - 1];
    if (std::abs(change) < 0.01f) (change > 0.0f ? rising : falling) += 1;
  }
  const float direction = rising >= falling ? 1.0f : -1.0f;
  std::vector<Eigen::Index> ring_starts{0};
  for (Eigen::Index i = 1; i < n; ++i) {
    if ((azimuth[i] - azimuth[i - 1]) * direction < -kRingJump) ring_starts.push_back(i);
  }
  ring_starts.push_back(n);
  constexpr std::size_t kMinRings = 16;
  if (ring_starts.size() < kMinRings + 2) return 0;

  int rings_used = 0;
  std::vector<Eigen::Vector3f> kerbs[2];  // left (y > 0), right
  std::vector<Eigen::Index> forward;
  std::vector<float> ranges, heights;
  for (std::size_t r = 0; r + 1 < ring_starts.size(); ++r) {
    forward.clear();
    ranges.clear();
    heights.clear();
    for (Eigen::Index i = ring_starts[r]; i < ring_starts[r + 1]; ++i) {
      if (std::abs(azimuth[i]) >= kPi / 2 || !std::isfinite(points(2, i))) continue;
      forward.push_back(i);
      ranges.push_back(std::hypot(points(0, i), points(1, i)));
      heights.push_back(points(2, i));
    }
    if (forward.size() < 20) continue;
    if (medianOf(ranges) > options.max_ring_range_m ||
        medianOf(heights) > -options.min_ground_drop_m)
      continue;
    // The seed: the point straight ahead, on the road unless something stands there.
    int seed = 0;
    for (int i = 1; i < static_cast<int>(forward.size()); ++i) {
      if (std::abs(azimuth[forward[i]]) < std::abs(azimuth[forward[seed]])) seed = i;
    }
    std::vector<float> around;
    for (int i = std::max(0, seed - 3); i <= std::min<int>(forward.size() - 1, seed + 3); ++i)
      around.push_back(points(2, forward[i]));
    if (std::abs(points(2, forward[seed]) - medianOf(around)) > 0.1f) continue;
    ++rings_used;
    for (const int step : {+1, -1}) {
      const int curb = findCurb(forward, points, seed, step, options);
      if (curb < 0) continue;
      kerbs[points(1, forward[curb]) > 0.0f ? 0 : 1].push_back(points.col(forward[curb]));
      for (int i = curb; i >= 0 && i < static_cast<int>(forward.size()); i += step)
        (*beyond)[forward[i]] = 1;
    }
  }
  if (options.line_min_points > 0) {
    for (int side = 0; side < 2; ++side) {
      markBeyondKerbLine(points, kerbs[side], side == 0 ? 1.0f : -1.0f, options, beyond);
    }
  }
  return rings_used;
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
