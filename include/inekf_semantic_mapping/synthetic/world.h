// The synthetic town: analytic surfaces, each tagged with a Cityscapes labelId, that the
// generator ray casts (lidar, camera) and that the evaluation asks for the true label of a point.
//
// Coordinates are the `map` frame (x east, y north, z up, metres): the generated drive's first
// IMU pose is the map origin, so the world needs no transform of its own.
//
// Surfaces:
//  - the ground: a smooth heightfield z = groundHeight(x, y) (sum of two long-wave sinusoids:
//    gentle hills), whose label depends on (x, y): road inside an axis-aligned street grid,
//    sidewalk along it, terrain elsewhere. Lane markings are road (they only change the colour).
//  - primitives: z-rotated boxes (buildings, parked cars, fences, sign plates), vertical
//    cylinders (poles, tree trunks) and axis-aligned ellipsoids (tree crowns), found through a
//    uniform 2D grid so that a ray only tests what lies along its footprint.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

namespace inekf_semantic_mapping {
namespace synthetic {

// Where a ray first meets a surface.
struct RayHit {
  double distance = 0;  // along the (unit) ray, metres
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit, facing the ray origin
  std::uint8_t label_id = 0;                          // Cityscapes labelId
  int primitive_index = -1;                           // -1: the ground
};

// z = offset + a_x sin(k_x x + phase_x) + a_y sin(k_y y + phase_y).
struct GroundSurface {
  double offset = 0;
  double amplitude_x = 0, wavenumber_x = 0, phase_x = 0;
  double amplitude_y = 0, wavenumber_y = 0, phase_y = 0;

  double height(double x, double y) const;
  Eigen::Vector2d gradient(double x, double y) const;
  Eigen::Matrix2d hessian(double x, double y) const;
  // Bounds used by the ray marcher: max |gradient| and max spectral norm of the Hessian.
  double maxSlope() const;
  double maxCurvature() const;
};

// Axis-aligned streets: vertical ones (running north-south) at x = c, horizontal ones at y = c.
struct StreetGrid {
  std::vector<double> vertical_x;    // centre lines x = c
  std::vector<double> horizontal_y;  // centre lines y = c
  double road_half_width = 6.0;      // two lanes + a parking strip each side
  double sidewalk_width = 3.0;
  double lane_half_width = 3.5;  // edge line between driving lane and parking strip

  // Distance of (x, y) to the nearest street centre line of either direction.
  double distanceToNearestStreet(double x, double y) const;
  std::uint8_t groundLabel(double x, double y) const;  // road / sidewalk / terrain
  // Painted lane marking (centre dashes, lane edge lines): white in the camera, road label.
  bool isLaneMarking(double x, double y) const;
};

enum class PrimitiveType : std::uint8_t { kBox = 0, kCylinder = 1, kEllipsoid = 2 };

struct Primitive {
  PrimitiveType type = PrimitiveType::kBox;
  std::uint8_t label_id = 0;
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  // Box: half extents along its own x y z. Cylinder: (radius, radius, half height).
  // Ellipsoid: semi-axes along x y z.
  Eigen::Vector3d half_size = Eigen::Vector3d::Ones();
  double yaw = 0;                                              // boxes only: rotation about z
  Eigen::Vector3f albedo = Eigen::Vector3f(0.5f, 0.5f, 0.5f);  // RGB 0..1, for the camera

  // Ray intersection in (t_min, t_max); fills distance/normal (normal not yet flipped).
  bool intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, double t_min,
                 double t_max, double* t_hit, Eigen::Vector3d* normal) const;
  // Unsigned distance of p to the surface (exact for boxes and cylinders, a close
  // approximation for ellipsoids).
  double surfaceDistance(const Eigen::Vector3d& p) const;
  // xy bounding rectangle (min_x, min_y, max_x, max_y) and top z.
  Eigen::Vector4d footprint() const;
  double topZ() const;
};

class SyntheticWorld {
 public:
  SyntheticWorld() = default;

  // The procedural town around the default route (see route.h): the street grid is laid out
  // so that the route drives in the right-hand lane; the seed draws buildings, trees, poles,
  // signs, fences, parked cars and their colours. Deterministic for a seed.
  static SyntheticWorld generateTown(std::uint64_t seed);

  // Text format written by save(): one surface per line (see world.cpp). load() throws
  // std::runtime_error naming path:line and the field on malformed input.
  static SyntheticWorld load(const std::string& path);
  void save(const std::string& path) const;  // atomic (tmp file + rename)

  // Nearest hit along origin + t * unit_dir, 0 < t <= max_range. Thread-safe.
  bool raycast(const Eigen::Vector3d& origin, const Eigen::Vector3d& unit_dir, double max_range,
               RayHit* hit) const;

  // Label of the surface nearest to p_map if it is within tolerance metres, 0 otherwise.
  std::uint8_t labelAt(const Eigen::Vector3d& p_map, double tolerance) const;

  // Colour (RGB 0..1, before shading) of a hit: per-surface albedo, lane markings, ground
  // regions, plus deterministic texture noise tied to the world position.
  Eigen::Vector3f surfaceColor(const RayHit& hit) const;

  const GroundSurface& ground() const { return ground_; }
  const StreetGrid& streets() const { return streets_; }
  const std::vector<Primitive>& primitives() const { return primitives_; }
  std::uint64_t seed() const { return seed_; }

  // Building blocks for tests and custom worlds; call buildIndex() after adding primitives.
  void setGround(const GroundSurface& ground) { ground_ = ground; }
  void setStreets(const StreetGrid& streets) { streets_ = streets; }
  void addPrimitive(const Primitive& primitive) { primitives_.push_back(primitive); }
  void buildIndex(double cell_size_m = 4.0);

 private:
  bool raycastGround(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, double t_max,
                     double* t_hit) const;

  GroundSurface ground_;
  StreetGrid streets_;
  std::vector<Primitive> primitives_;
  std::uint64_t seed_ = 0;

  // Uniform 2D grid over the primitives' footprints (CSR layout: cell -> primitive indices).
  double cell_size_ = 4.0;
  Eigen::Vector2d grid_min_ = Eigen::Vector2d::Zero();
  int grid_nx_ = 0, grid_ny_ = 0;
  std::vector<std::uint32_t> cell_begin_;
  std::vector<std::uint32_t> cell_items_;
  std::vector<double> cell_top_z_;                  // highest primitive top per cell
  std::vector<Eigen::Vector2d> yaw_cos_sin_;        // per primitive
  std::vector<Eigen::Vector3d> aligned_half_size_;  // map-axis half sizes; x = 0: not aligned
  double max_top_z_ = 0;
};

}  // namespace synthetic
}  // namespace inekf_semantic_mapping
