#include "inekf_semantic_mapping/synthetic/world.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "inekf_semantic_mapping/perception/cityscapes.h"

namespace inekf_semantic_mapping {
namespace synthetic {
namespace cs = cityscapes;

// ---------------------------------------------------------------------------------------------
// Ground
// ---------------------------------------------------------------------------------------------
namespace {

// sin and cos together, for the moderate arguments of the ground (|x| < 1e4): Cody-Waite
// reduction to [-pi/4, pi/4] and Taylor polynomials, accurate to ~2e-14 and several times
// cheaper than libm's sincos, which was a fifth of a camera frame's ray casting.
inline void fastSinCos(double x, double* sin_x, double* cos_x) {
  constexpr double kTwoOverPi = 0.63661977236758134308;
  constexpr double kPiOver2High = 1.57079632673412561417;  // first 33 bits of pi/2
  constexpr double kPiOver2Low = 6.07710050650619224932e-11;
  // Round to nearest by truncation (a libm rounding call would cost as much as sincos).
  const long long quadrant_index = static_cast<long long>(x * kTwoOverPi + (x >= 0 ? 0.5 : -0.5));
  const double quadrant = static_cast<double>(quadrant_index);
  const double r = (x - quadrant * kPiOver2High) - quadrant * kPiOver2Low;
  const double r2 = r * r;
  const double s =
      r *
      (1 + r2 * (-1.0 / 6 +
                 r2 * (1.0 / 120 + r2 * (-1.0 / 5040 +
                                         r2 * (1.0 / 362880 + r2 * (-1.0 / 39916800 +
                                                                    r2 * (1.0 / 6227020800.0)))))));
  const double c =
      1 + r2 * (-0.5 + r2 * (1.0 / 24 +
                             r2 * (-1.0 / 720 + r2 * (1.0 / 40320 +
                                                      r2 * (-1.0 / 3628800 +
                                                            r2 * (1.0 / 479001600.0 +
                                                                  r2 * (-1.0 / 87178291200.0)))))));
  switch (quadrant_index & 3) {
    case 0:
      *sin_x = s;
      *cos_x = c;
      break;
    case 1:
      *sin_x = c;
      *cos_x = -s;
      break;
    case 2:
      *sin_x = -s;
      *cos_x = -c;
      break;
    default:
      *sin_x = -c;
      *cos_x = s;
  }
}

}  // namespace

double GroundSurface::height(double x, double y) const {
  double sin_x, cos_x, sin_y, cos_y;
  fastSinCos(wavenumber_x * x + phase_x, &sin_x, &cos_x);
  fastSinCos(wavenumber_y * y + phase_y, &sin_y, &cos_y);
  return offset + amplitude_x * sin_x + amplitude_y * sin_y;
}

Eigen::Vector2d GroundSurface::gradient(double x, double y) const {
  double sin_x, cos_x, sin_y, cos_y;
  fastSinCos(wavenumber_x * x + phase_x, &sin_x, &cos_x);
  fastSinCos(wavenumber_y * y + phase_y, &sin_y, &cos_y);
  return {amplitude_x * wavenumber_x * cos_x, amplitude_y * wavenumber_y * cos_y};
}

Eigen::Matrix2d GroundSurface::hessian(double x, double y) const {
  double sin_x, cos_x, sin_y, cos_y;
  fastSinCos(wavenumber_x * x + phase_x, &sin_x, &cos_x);
  fastSinCos(wavenumber_y * y + phase_y, &sin_y, &cos_y);
  Eigen::Matrix2d h = Eigen::Matrix2d::Zero();
  h(0, 0) = -amplitude_x * wavenumber_x * wavenumber_x * sin_x;
  h(1, 1) = -amplitude_y * wavenumber_y * wavenumber_y * sin_y;
  return h;
}

double GroundSurface::maxSlope() const {
  return std::hypot(amplitude_x * wavenumber_x, amplitude_y * wavenumber_y);
}

double GroundSurface::maxCurvature() const {
  return std::max(std::abs(amplitude_x) * wavenumber_x * wavenumber_x,
                  std::abs(amplitude_y) * wavenumber_y * wavenumber_y);
}

// ---------------------------------------------------------------------------------------------
// Streets
// ---------------------------------------------------------------------------------------------
namespace {

// Signed offset of v from the nearest centre line (large when there is none).
double nearestOffset(const std::vector<double>& centres, double v) {
  double best = std::numeric_limits<double>::infinity();
  for (double c : centres) {
    if (std::abs(v - c) < std::abs(best)) best = v - c;
  }
  return best;
}

}  // namespace

double StreetGrid::distanceToNearestStreet(double x, double y) const {
  return std::min(std::abs(nearestOffset(vertical_x, x)), std::abs(nearestOffset(horizontal_y, y)));
}

std::uint8_t StreetGrid::groundLabel(double x, double y) const {
  const double d = distanceToNearestStreet(x, y);
  if (d < road_half_width) return cs::kRoad;
  if (d < road_half_width + sidewalk_width) return cs::kSidewalk;
  return cs::kTerrain;
}

bool StreetGrid::isLaneMarking(double x, double y) const {
  constexpr double kHalfLineWidth = 0.075;
  constexpr double kDashPeriod = 6.0, kDashLength = 3.0;
  const double dx = std::abs(nearestOffset(vertical_x, x));
  const double dy = std::abs(nearestOffset(horizontal_y, y));
  auto marked = [&](double across, double along, double other_across) {
    if (other_across < road_half_width) return false;  // no paint inside intersections
    if (std::abs(across - lane_half_width) < kHalfLineWidth) return true;
    const double phase = along - kDashPeriod * std::floor(along / kDashPeriod);
    return across < kHalfLineWidth && phase < kDashLength;
  };
  return (dx < road_half_width && marked(dx, y, dy)) || (dy < road_half_width && marked(dy, x, dx));
}

// ---------------------------------------------------------------------------------------------
// Primitives
// ---------------------------------------------------------------------------------------------
namespace {

inline Eigen::Vector3d rotateZ(const Eigen::Vector3d& v, double c, double s) {
  return {c * v.x() - s * v.y(), s * v.x() + c * v.y(), v.z()};
}

}  // namespace

namespace {

// Slab test for a box whose faces are aligned with the axes of o and inverse_d (the map's for
// buildings and most fences, with the inverse direction precomputed; the box's own for a rotated
// one). An infinite inverse is a ray parallel to the slab.
inline bool intersectAlignedBox(const Eigen::Vector3d& center, const Eigen::Vector3d& half,
                                const Eigen::Vector3d& o, const Eigen::Vector3d& inverse_d,
                                double t_min, double t_max, double* t_hit,
                                Eigen::Vector3d* normal) {
  double t_near = -std::numeric_limits<double>::infinity();
  double t_far = std::numeric_limits<double>::infinity();
  int axis = -1;
  for (int i = 0; i < 3; ++i) {
    const double lo = center[i] - half[i] - o[i], hi = center[i] + half[i] - o[i];
    if (std::isinf(inverse_d[i])) {  // parallel to the slab
      if (lo > 0 || hi < 0) return false;
      continue;
    }
    double t1 = lo * inverse_d[i], t2 = hi * inverse_d[i];
    if (t1 > t2) std::swap(t1, t2);
    if (t1 > t_near) {
      t_near = t1;
      axis = i;
    }
    t_far = std::min(t_far, t2);
    if (t_near > t_far) return false;
  }
  if (axis < 0 || t_near <= t_min || t_near >= t_max) return false;
  *t_hit = t_near;
  *normal = Eigen::Vector3d::Zero();
  (*normal)[axis] = inverse_d[axis] > 0 ? -1.0 : 1.0;
  return true;
}

// The intersection proper, with the box's cos/sin(yaw) precomputed (the world caches them: the
// trigonometry was a large part of a camera frame).
bool intersectPrimitive(const Primitive& primitive, double c, double s,
                        const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, double t_min,
                        double t_max, double* t_hit, Eigen::Vector3d* normal) {
  const Eigen::Vector3d& half_size = primitive.half_size;
  const Eigen::Vector3d o = origin - primitive.center;
  switch (primitive.type) {
    case PrimitiveType::kBox: {
      // In the box's own axes (rays starting inside a box, never the case for sensors, see
      // nothing of it).
      const Eigen::Vector3d lo = rotateZ(o, c, -s);
      const Eigen::Vector3d ld = rotateZ(dir, c, -s);
      Eigen::Vector3d n_local;
      if (!intersectAlignedBox(Eigen::Vector3d::Zero(), half_size, lo, ld.cwiseInverse(), t_min,
                               t_max, t_hit, &n_local)) {
        return false;
      }
      *normal = rotateZ(n_local, c, s);
      return true;
    }
    case PrimitiveType::kCylinder: {
      const double r = half_size.x(), hz = half_size.z();
      double best = t_max;
      bool found = false;
      const double a = dir.x() * dir.x() + dir.y() * dir.y();
      if (a > 1e-12) {
        const double b = o.x() * dir.x() + o.y() * dir.y();
        const double cc = o.x() * o.x() + o.y() * o.y() - r * r;
        const double disc = b * b - a * cc;
        if (disc >= 0) {
          const double t = (-b - std::sqrt(disc)) / a;
          if (t > t_min && t < best && std::abs(o.z() + t * dir.z()) <= hz) {
            best = t;
            found = true;
            *normal = Eigen::Vector3d(o.x() + t * dir.x(), o.y() + t * dir.y(), 0) / r;
          }
        }
      }
      if (std::abs(dir.z()) > 1e-12) {
        const double cap_z = dir.z() > 0 ? -hz : hz;  // the cap facing the ray
        const double t = (cap_z - o.z()) / dir.z();
        const double px = o.x() + t * dir.x(), py = o.y() + t * dir.y();
        if (t > t_min && t < best && px * px + py * py <= r * r) {
          best = t;
          found = true;
          *normal = Eigen::Vector3d(0, 0, cap_z > 0 ? 1.0 : -1.0);
        }
      }
      if (found) *t_hit = best;
      return found;
    }
    case PrimitiveType::kEllipsoid: {
      const Eigen::Vector3d os = o.cwiseQuotient(half_size);
      const Eigen::Vector3d ds = dir.cwiseQuotient(half_size);
      const double a = ds.squaredNorm();
      const double b = os.dot(ds);
      const double cc = os.squaredNorm() - 1;
      const double disc = b * b - a * cc;
      if (disc < 0) return false;
      const double t = (-b - std::sqrt(disc)) / a;
      if (t <= t_min || t >= t_max) return false;
      *t_hit = t;
      const Eigen::Vector3d p = o + t * dir;
      *normal = p.cwiseQuotient(half_size.cwiseProduct(half_size)).normalized();
      return true;
    }
  }
  return false;
}

}  // namespace

bool Primitive::intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, double t_min,
                          double t_max, double* t_hit, Eigen::Vector3d* normal) const {
  return intersectPrimitive(*this, std::cos(yaw), std::sin(yaw), origin, dir, t_min, t_max, t_hit,
                            normal);
}

double Primitive::surfaceDistance(const Eigen::Vector3d& p) const {
  const Eigen::Vector3d o = p - center;
  switch (type) {
    case PrimitiveType::kBox: {
      const Eigen::Vector3d q = rotateZ(o, std::cos(yaw), -std::sin(yaw)).cwiseAbs() - half_size;
      const double outside = q.cwiseMax(0.0).norm();
      const double inside = std::min(q.maxCoeff(), 0.0);
      return std::abs(outside + inside);
    }
    case PrimitiveType::kCylinder: {
      const Eigen::Vector2d q(std::hypot(o.x(), o.y()) - half_size.x(),
                              std::abs(o.z()) - half_size.z());
      const double outside = q.cwiseMax(0.0).norm();
      const double inside = std::min(q.maxCoeff(), 0.0);
      return std::abs(outside + inside);
    }
    case PrimitiveType::kEllipsoid: {
      // Quilez's first-order distance estimate; exact for spheres.
      const double k0 = o.cwiseQuotient(half_size).norm();
      const double k1 = o.cwiseQuotient(half_size.cwiseProduct(half_size)).norm();
      if (k1 < 1e-12) return half_size.minCoeff();
      return std::abs(k0 * (k0 - 1.0) / k1);
    }
  }
  return std::numeric_limits<double>::infinity();
}

Eigen::Vector4d Primitive::footprint() const {
  double ex = half_size.x(), ey = half_size.y();
  if (type == PrimitiveType::kBox) {
    const double c = std::abs(std::cos(yaw)), s = std::abs(std::sin(yaw));
    ex = c * half_size.x() + s * half_size.y();
    ey = s * half_size.x() + c * half_size.y();
  }
  return {center.x() - ex, center.y() - ey, center.x() + ex, center.y() + ey};
}

double Primitive::topZ() const { return center.z() + half_size.z(); }

// ---------------------------------------------------------------------------------------------
// Spatial index and queries
// ---------------------------------------------------------------------------------------------
void SyntheticWorld::buildIndex(double cell_size_m) {
  cell_size_ = cell_size_m;
  cell_begin_.clear();
  cell_items_.clear();
  cell_top_z_.clear();
  yaw_cos_sin_.clear();
  aligned_half_size_.clear();
  for (const Primitive& p : primitives_) {
    const double c = std::cos(p.yaw), s = std::sin(p.yaw);
    yaw_cos_sin_.emplace_back(c, s);
    // Boxes turned by a multiple of 90 degrees take the fast axis-aligned test.
    Eigen::Vector3d aligned = Eigen::Vector3d::Zero();
    if (p.type == PrimitiveType::kBox && std::min(std::abs(c), std::abs(s)) < 1e-12) {
      aligned = std::abs(c) > 0.5
                    ? p.half_size
                    : Eigen::Vector3d(p.half_size.y(), p.half_size.x(), p.half_size.z());
    }
    aligned_half_size_.push_back(aligned);
  }
  grid_nx_ = grid_ny_ = 0;
  max_top_z_ = -std::numeric_limits<double>::infinity();
  if (primitives_.empty()) return;
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector2d hi = -lo;
  for (const Primitive& p : primitives_) {
    const Eigen::Vector4d f = p.footprint();
    lo = lo.cwiseMin(f.head<2>());
    hi = hi.cwiseMax(f.tail<2>());
    max_top_z_ = std::max(max_top_z_, p.topZ());
  }
  grid_min_ = lo - Eigen::Vector2d::Constant(1e-6);
  // A world whose footprint would need more than kMaxGridCells cells gets coarser cells: the
  // index stays bounded in memory whatever the coordinates in world.txt.
  constexpr double kMaxGridCells = 4.0e6;
  const Eigen::Vector2d extent = hi - grid_min_;
  cell_size_ = std::max(cell_size_, std::sqrt(extent.x() * extent.y() / kMaxGridCells));
  cell_size_ = std::max(cell_size_, std::max(extent.x(), extent.y()) / kMaxGridCells);
  grid_nx_ = std::max(1, static_cast<int>(std::ceil((hi.x() - grid_min_.x()) / cell_size_)) + 1);
  grid_ny_ = std::max(1, static_cast<int>(std::ceil((hi.y() - grid_min_.y()) / cell_size_)) + 1);
  const std::size_t cells = static_cast<std::size_t>(grid_nx_) * grid_ny_;
  std::vector<std::uint32_t> counts(cells + 1, 0);
  auto for_each_cell = [&](const Primitive& p, auto&& fn) {
    const Eigen::Vector4d f = p.footprint();
    const int x0 =
        std::clamp(static_cast<int>((f[0] - grid_min_.x()) / cell_size_), 0, grid_nx_ - 1);
    const int y0 =
        std::clamp(static_cast<int>((f[1] - grid_min_.y()) / cell_size_), 0, grid_ny_ - 1);
    const int x1 =
        std::clamp(static_cast<int>((f[2] - grid_min_.x()) / cell_size_), 0, grid_nx_ - 1);
    const int y1 =
        std::clamp(static_cast<int>((f[3] - grid_min_.y()) / cell_size_), 0, grid_ny_ - 1);
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) fn(static_cast<std::size_t>(y) * grid_nx_ + x);
  };
  for (const Primitive& p : primitives_) for_each_cell(p, [&](std::size_t c) { ++counts[c + 1]; });
  for (std::size_t c = 0; c < cells; ++c) counts[c + 1] += counts[c];
  cell_begin_ = counts;
  cell_items_.resize(counts.back());
  std::vector<std::uint32_t> fill(counts.begin(), counts.end() - 1);
  cell_top_z_.assign(cells, -std::numeric_limits<double>::infinity());
  for (std::uint32_t i = 0; i < primitives_.size(); ++i) {
    for_each_cell(primitives_[i], [&](std::size_t c) {
      cell_items_[fill[c]++] = i;
      cell_top_z_[c] = std::max(cell_top_z_[c], primitives_[i].topZ());
    });
  }
}

bool SyntheticWorld::raycastGround(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t_max,
                                   double* t_hit) const {
  // f(t) = height of the ray above the ground. |f''| <= C |d_xy|^2, so from any t the parabola
  // f + f' s - C' s^2 / 2 is a lower bound of f: stepping to its root can never jump over the
  // first crossing, and near the root the step is Newton's (fast convergence).
  const GroundSurface& g = ground_;
  auto f_and_slope = [&](double t, double* slope) {
    double sin_x, cos_x, sin_y, cos_y;  // one sincos per axis: the march's main cost
    fastSinCos(g.wavenumber_x * (o.x() + t * d.x()) + g.phase_x, &sin_x, &cos_x);
    fastSinCos(g.wavenumber_y * (o.y() + t * d.y()) + g.phase_y, &sin_y, &cos_y);
    *slope = d.z() - g.amplitude_x * g.wavenumber_x * cos_x * d.x() -
             g.amplitude_y * g.wavenumber_y * cos_y * d.y();
    return o.z() + t * d.z() - (g.offset + g.amplitude_x * sin_x + g.amplitude_y * sin_y);
  };
  const double curvature_bound =
      ground_.maxCurvature() * (d.x() * d.x() + d.y() * d.y()) * 1.0001 + 1e-15;
  // Cheap outs before any trigonometry: the ray stays above the highest possible ground up to
  // t_max (rays that hit a wall or a car first, sky rays).
  const double highest_ground = g.offset + std::abs(g.amplitude_x) + std::abs(g.amplitude_y);
  if (o.z() + std::min(0.0, d.z()) * t_max > highest_ground) return false;
  double t = 0, slope;
  double f = f_and_slope(0, &slope);
  if (f <= 0) return false;  // the origin is under the ground
  for (int iteration = 0; iteration < 200; ++iteration) {
    if (f < 1e-6) {
      *t_hit = t;
      return true;
    }
    const double disc = slope * slope + 2 * curvature_bound * f;
    const double step = 2 * f / (std::sqrt(disc) - slope);
    t += step;
    if (!(t <= t_max)) return false;
    f = f_and_slope(t, &slope);
    if (f < 0) {  // can only be round-off at the root
      *t_hit = t;
      return true;
    }
  }
  return false;
}

bool SyntheticWorld::raycast(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double max_range,
                             RayHit* hit) const {
  double best_t = max_range;
  int best_index = -1;
  Eigen::Vector3d best_normal = Eigen::Vector3d::UnitZ();
  bool found = false;
  auto take_ground_hit = [&](double t_ground) {
    best_t = t_ground;
    best_index = -1;
    const Eigen::Vector3d p = o + t_ground * d;
    const Eigen::Vector2d g = ground_.gradient(p.x(), p.y());
    best_normal = Eigen::Vector3d(-g.x(), -g.y(), 1.0).normalized();
    found = true;
  };
  // A descending ray meets the ground soon: find that first, so that the grid walk stops there
  // instead of crossing the whole town under the ground. A climbing ray rarely hits the ground:
  // walk the grid first, whose hit then lets the ground test stop without trigonometry.
  const bool ground_first = d.z() < 0;
  double t_ground;
  if (ground_first && raycastGround(o, d, best_t, &t_ground)) take_ground_hit(t_ground);

  if (grid_nx_ > 0) {
    // Clip the ray's footprint to the grid rectangle, then walk the cells (Amanatides-Woo).
    const Eigen::Vector2d grid_max = grid_min_ + cell_size_ * Eigen::Vector2d(grid_nx_, grid_ny_);
    double t0 = 0, t1 = best_t;
    bool inside = true;
    for (int i = 0; i < 2 && inside; ++i) {
      if (std::abs(d[i]) < 1e-12) {
        inside = o[i] >= grid_min_[i] && o[i] <= grid_max[i];
      } else {
        double a = (grid_min_[i] - o[i]) / d[i], b = (grid_max[i] - o[i]) / d[i];
        if (a > b) std::swap(a, b);
        t0 = std::max(t0, a);
        t1 = std::min(t1, b);
        inside = t0 <= t1;
      }
    }
    if (inside) {
      const Eigen::Vector3d start = o + t0 * d;
      int cx =
          std::clamp(static_cast<int>((start.x() - grid_min_.x()) / cell_size_), 0, grid_nx_ - 1);
      int cy =
          std::clamp(static_cast<int>((start.y() - grid_min_.y()) / cell_size_), 0, grid_ny_ - 1);
      const double inf = std::numeric_limits<double>::infinity();
      const int step_x = d.x() > 0 ? 1 : -1, step_y = d.y() > 0 ? 1 : -1;
      const double delta_x = std::abs(d.x()) > 1e-12 ? cell_size_ / std::abs(d.x()) : inf;
      const double delta_y = std::abs(d.y()) > 1e-12 ? cell_size_ / std::abs(d.y()) : inf;
      double next_x = std::abs(d.x()) > 1e-12
                          ? (grid_min_.x() + (cx + (step_x > 0)) * cell_size_ - o.x()) / d.x()
                          : inf;
      double next_y = std::abs(d.y()) > 1e-12
                          ? (grid_min_.y() + (cy + (step_y > 0)) * cell_size_ - o.y()) / d.y()
                          : inf;
      double t_entry = t0;
      // Inverse direction for the axis-aligned slab test (zero components: +-inf, and the
      // slab test below handles them by comparing the origin with the slab).
      const Eigen::Vector3d inverse_d = d.cwiseInverse();
      // Mailbox: a primitive spanning several cells is tested once per ray.
      thread_local std::vector<std::uint32_t> tested_by_ray;
      thread_local std::uint32_t ray_id = 0;
      if (tested_by_ray.size() < primitives_.size()) tested_by_ray.assign(primitives_.size(), 0);
      if (++ray_id == 0) {
        std::fill(tested_by_ray.begin(), tested_by_ray.end(), 0);
        ray_id = 1;
      }
      while (true) {
        // Above every object and climbing: nothing more to hit but the sky.
        if (d.z() >= 0 && o.z() + t_entry * d.z() > max_top_z_) break;
        const std::size_t cell = static_cast<std::size_t>(cy) * grid_nx_ + cx;
        const double t_exit = std::min(next_x, next_y);
        // Skip the cell when the ray passes above everything in it.
        const double z_low = o.z() + (d.z() >= 0 ? t_entry : std::min(t_exit, best_t)) * d.z();
        if (z_low <= cell_top_z_[cell]) {
          for (std::uint32_t k = cell_begin_[cell]; k < cell_begin_[cell + 1]; ++k) {
            const std::uint32_t index = cell_items_[k];
            if (tested_by_ray[index] == ray_id) continue;
            tested_by_ray[index] = ray_id;
            double t;
            Eigen::Vector3d n;
            const bool hit_it =
                aligned_half_size_[index].x() > 0
                    ? intersectAlignedBox(primitives_[index].center, aligned_half_size_[index], o,
                                          inverse_d, 1e-9, best_t, &t, &n)
                    : intersectPrimitive(primitives_[index], yaw_cos_sin_[index].x(),
                                         yaw_cos_sin_[index].y(), o, d, 1e-9, best_t, &t, &n);
            if (hit_it) {
              best_t = t;
              best_index = static_cast<int>(index);
              best_normal = n;
              found = true;
            }
          }
        }
        if (best_t <= t_exit || t_exit >= t1) break;
        t_entry = t_exit;
        if (next_x < next_y) {
          cx += step_x;
          next_x += delta_x;
          if (cx < 0 || cx >= grid_nx_) break;
        } else {
          cy += step_y;
          next_y += delta_y;
          if (cy < 0 || cy >= grid_ny_) break;
        }
      }
    }
  }

  if (!ground_first && raycastGround(o, d, best_t, &t_ground) && t_ground < best_t) {
    take_ground_hit(t_ground);
  }
  if (!found) return false;
  hit->distance = best_t;
  hit->point = o + best_t * d;
  hit->primitive_index = best_index;
  hit->normal = best_normal.dot(d) > 0 ? Eigen::Vector3d(-best_normal) : best_normal;
  hit->label_id = best_index >= 0 ? primitives_[best_index].label_id
                                  : streets_.groundLabel(hit->point.x(), hit->point.y());
  return true;
}

std::uint8_t SyntheticWorld::labelAt(const Eigen::Vector3d& p, double tolerance) const {
  const Eigen::Vector2d g = ground_.gradient(p.x(), p.y());
  double best = std::abs(p.z() - ground_.height(p.x(), p.y())) / std::sqrt(1 + g.squaredNorm());
  std::uint8_t label = streets_.groundLabel(p.x(), p.y());
  if (grid_nx_ > 0) {
    const int x0 = static_cast<int>(std::floor((p.x() - tolerance - grid_min_.x()) / cell_size_));
    const int x1 = static_cast<int>(std::floor((p.x() + tolerance - grid_min_.x()) / cell_size_));
    const int y0 = static_cast<int>(std::floor((p.y() - tolerance - grid_min_.y()) / cell_size_));
    const int y1 = static_cast<int>(std::floor((p.y() + tolerance - grid_min_.y()) / cell_size_));
    for (int cy = std::max(0, y0); cy <= std::min(grid_ny_ - 1, y1); ++cy) {
      for (int cx = std::max(0, x0); cx <= std::min(grid_nx_ - 1, x1); ++cx) {
        const std::size_t cell = static_cast<std::size_t>(cy) * grid_nx_ + cx;
        for (std::uint32_t k = cell_begin_[cell]; k < cell_begin_[cell + 1]; ++k) {
          const Primitive& primitive = primitives_[cell_items_[k]];
          const double distance = primitive.surfaceDistance(p);
          if (distance < best) {
            best = distance;
            label = primitive.label_id;
          }
        }
      }
    }
  }
  return best <= tolerance ? label : static_cast<std::uint8_t>(cs::kUnlabeled);
}

// ---------------------------------------------------------------------------------------------
// Appearance
// ---------------------------------------------------------------------------------------------
namespace {

// Deterministic lattice hash -> [0, 1).
inline float hash3(std::int64_t x, std::int64_t y, std::int64_t z) {
  std::uint64_t h = static_cast<std::uint64_t>(x) * 0x9E3779B97F4A7C15ull ^
                    static_cast<std::uint64_t>(y) * 0xC2B2AE3D27D4EB4Full ^
                    static_cast<std::uint64_t>(z) * 0x165667B19E3779F9ull;
  h ^= h >> 29;
  h *= 0xBF58476D1CE4E5B9ull;
  h ^= h >> 32;
  return static_cast<float>(h >> 40) * (1.0f / 16777216.0f);
}

// Blocky multi-scale noise in [-1, 1]: cheap, and tied to the world so it moves with the scene.
inline float textureNoise(const Eigen::Vector3d& p) {
  const Eigen::Vector3d fine = p * 12.0, coarse = p * 1.5;
  const float n_fine = hash3(static_cast<std::int64_t>(std::floor(fine.x())),
                             static_cast<std::int64_t>(std::floor(fine.y())),
                             static_cast<std::int64_t>(std::floor(fine.z())));
  const float n_coarse = hash3(static_cast<std::int64_t>(std::floor(coarse.x())) + 7919,
                               static_cast<std::int64_t>(std::floor(coarse.y())),
                               static_cast<std::int64_t>(std::floor(coarse.z())));
  return 2.0f * (0.6f * n_fine + 0.4f * n_coarse) - 1.0f;
}

}  // namespace

Eigen::Vector3f SyntheticWorld::surfaceColor(const RayHit& hit) const {
  Eigen::Vector3f base;
  float texture_strength = 0.12f;
  if (hit.primitive_index >= 0) {
    base = primitives_[hit.primitive_index].albedo;
    if (hit.label_id == cs::kVegetation) texture_strength = 0.35f;
    if (hit.label_id == cs::kBuilding) texture_strength = 0.15f;
  } else if (streets_.isLaneMarking(hit.point.x(), hit.point.y())) {
    base = {0.85f, 0.85f, 0.82f};
    texture_strength = 0.05f;
  } else {
    switch (hit.label_id) {
      case cs::kRoad:
        base = {0.27f, 0.27f, 0.29f};
        break;
      case cs::kSidewalk:
        base = {0.58f, 0.54f, 0.52f};
        break;
      default:
        base = {0.42f, 0.50f, 0.24f};
        texture_strength = 0.3f;
    }
  }
  return (base * (1.0f + texture_strength * textureNoise(hit.point))).cwiseMax(0.0f).cwiseMin(1.0f);
}

}  // namespace synthetic
}  // namespace inekf_semantic_mapping
