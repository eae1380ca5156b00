// Curb detection: walks each laser ring sideways from straight ahead to the first curb's rise,
// then fits a line through each side's curbs for the rings whose walk stopped early.
#include "inekf_semantic_mapping/perception/curb_detection.h"

#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <limits>

namespace inekf_semantic_mapping {
namespace perception {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

// The forward half of one ring: from the point straight ahead, walks sideways (step +1 or -1,
// the two ways along the ring) and returns the index in `forward` of the first point of a curb's
// rise, or -1. The road's level is the mean height of the older half of its last 0.3 m of
// points: a ring meets a curb's face at a slant and climbs it by about a centimetre per point, so
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
      if (dxy < options.max_step_run_m) return -1;  // an obstacle before any curb
      restart(j);                                   // a steady grade
      run_start = j;
    } else if (dz >= options.min_step_m && dxy < options.max_step_run_m) {
      // A curb needs flat road before it and a flat raised surface after it: the level the
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

// Least squares y = a + b x over the curbs whose residual under `previous` is below
// max_residual (all when previous is null). False when fewer than two remain or x does not vary.
bool fitCurbLine(const std::vector<Eigen::Vector3f>& curbs, const Eigen::Vector2f* previous,
                 float max_residual, Eigen::Vector2f* line) {
  Eigen::Matrix2d normal = Eigen::Matrix2d::Zero();
  Eigen::Vector2d rhs = Eigen::Vector2d::Zero();
  int used = 0;
  for (const Eigen::Vector3f& curb : curbs) {
    if (previous && std::abs((*previous)(0) + (*previous)(1) * curb.x() - curb.y()) >= max_residual)
      continue;
    const Eigen::Vector2d row(1.0, curb.x());
    normal += row * row.transpose();
    rhs += row * curb.y();
    ++used;
  }
  if (used < 2 || std::abs(normal.determinant()) < 1e-6) return false;
  *line = normal.ldlt().solve(rhs).cast<float>();
  return true;
}

// The points beyond one side's curb line (side +1: left, y above the line; -1: right).
void markBeyondCurbLine(const PointMatrixRef& points, const std::vector<Eigen::Vector3f>& curbs,
                        float side, const CurbOptions& options, std::vector<std::uint8_t>* beyond) {
  if (static_cast<int>(curbs.size()) < options.line_min_points) return;
  Eigen::Vector2f line;
  if (!fitCurbLine(curbs, nullptr, 0.0f, &line)) return;
  std::vector<float> residuals, heights;
  float x_min = kInf, x_max = -kInf;
  for (const Eigen::Vector3f& curb : curbs) {
    residuals.push_back(std::abs(line(0) + line(1) * curb.x() - curb.y()));
    heights.push_back(curb.z());
    x_min = std::min(x_min, curb.x());
    x_max = std::max(x_max, curb.x());
  }
  constexpr float kMaxMedianResidual = 0.3f, kMaxResidual = 0.5f;
  if (medianOf(residuals) > kMaxMedianResidual) return;  // the curbs do not lie on a line
  const Eigen::Vector2f first = line;
  if (!fitCurbLine(curbs, &first, kMaxResidual, &line)) return;
  const float curb_height = medianOf(heights);
  x_min -= options.line_extension_m;
  x_max += options.line_extension_m;
  for (Eigen::Index i = 0; i < points.cols(); ++i) {
    const float x = points(0, i);
    if (!(x >= x_min && x <= x_max)) continue;
    // Written so that a NaN height fails it too.
    if (!(std::abs(points(2, i) - curb_height) < options.line_height_tolerance_m)) continue;
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
  // Points without a finite coordinate (an organized cloud's no-returns) take no part: compared
  // with the last finite point's azimuth, so that they hide no ring's end.
  std::vector<std::uint8_t> finite(static_cast<std::size_t>(n));
  std::vector<float> azimuth(static_cast<std::size_t>(n));
  for (Eigen::Index i = 0; i < n; ++i) {
    finite[i] = points.col(i).allFinite();
    azimuth[i] = finite[i] ? std::atan2(points(1, i), points(0, i)) : 0.0f;
  }
  Eigen::Index rising = 0, falling = 0;
  for (Eigen::Index i = 0, last = -1; i < n; ++i) {
    if (!finite[i]) continue;
    if (last >= 0) {
      const float change = azimuth[i] - azimuth[last];
      if (std::abs(change) < 0.01f) (change > 0.0f ? rising : falling) += 1;
    }
    last = i;
  }
  const float direction = rising >= falling ? 1.0f : -1.0f;
  std::vector<Eigen::Index> ring_starts{0};
  for (Eigen::Index i = 0, last = -1; i < n; ++i) {
    if (!finite[i]) continue;
    if (last >= 0 && (azimuth[i] - azimuth[last]) * direction < -kRingJump) {
      ring_starts.push_back(i);
    }
    last = i;
  }
  ring_starts.push_back(n);
  constexpr std::size_t kMinRings = 16;
  if (ring_starts.size() < kMinRings + 2) return 0;

  int rings_used = 0;
  std::vector<Eigen::Vector3f> curbs[2];  // left (y > 0), right
  std::vector<Eigen::Index> forward;
  std::vector<float> ranges, heights;
  for (std::size_t r = 0; r + 1 < ring_starts.size(); ++r) {
    forward.clear();
    ranges.clear();
    heights.clear();
    for (Eigen::Index i = ring_starts[r]; i < ring_starts[r + 1]; ++i) {
      if (!finite[i] || std::abs(azimuth[i]) >= kPi / 2) continue;
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
      curbs[points(1, forward[curb]) > 0.0f ? 0 : 1].push_back(points.col(forward[curb]));
      for (int i = curb; i >= 0 && i < static_cast<int>(forward.size()); i += step)
        (*beyond)[forward[i]] = 1;
    }
  }
  if (options.line_min_points > 0) {
    for (int side = 0; side < 2; ++side) {
      markBeyondCurbLine(points, curbs[side], side == 0 ? 1.0f : -1.0f, options, beyond);
    }
  }
  return rings_used;
}

}  // namespace perception
}  // namespace inekf_semantic_mapping
