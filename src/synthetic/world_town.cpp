// SyntheticWorld::generateTown: the procedural town (streets, buildings, vegetation, cars, poles)
// of a seed. The world's geometry and queries are in world.cpp, its file format in world_io.cpp.
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include "inekf_semantic_mapping/perception/cityscapes.h"
#include "inekf_semantic_mapping/synthetic/route.h"
#include "inekf_semantic_mapping/synthetic/world.h"

namespace inekf_semantic_mapping {
namespace synthetic {
namespace cs = cityscapes;

// ---------------------------------------------------------------------------------------------
// Procedural town
// ---------------------------------------------------------------------------------------------
namespace {

class TownBuilder {
 public:
  TownBuilder(SyntheticWorld* world, std::uint64_t seed) : world_(world), rng_(seed) {}

  double uniform(double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng_); }
  bool chance(double p) { return uniform(0, 1) < p; }

  Eigen::Vector3f jitterColor(const Eigen::Vector3f& c, double amount) {
    Eigen::Vector3f out;
    const double common = uniform(-amount, amount);
    for (int i = 0; i < 3; ++i)
      out[i] = static_cast<float>(c[i] + common + uniform(-amount, amount) * 0.3);
    return out.cwiseMax(0.02f).cwiseMin(0.98f);
  }

  // Lowest ground under a rectangle, so that objects never float on the hills.
  double groundMin(double cx, double cy, double hx, double hy) {
    const GroundSurface& g = world_->ground();
    double z = std::numeric_limits<double>::infinity();
    for (double sx : {-1.0, 0.0, 1.0})
      for (double sy : {-1.0, 0.0, 1.0}) z = std::min(z, g.height(cx + sx * hx, cy + sy * hy));
    return z;
  }

  void box(std::uint8_t label, double cx, double cy, double hx, double hy, double z_bottom,
           double z_top, double yaw, const Eigen::Vector3f& albedo) {
    Primitive p;
    p.type = PrimitiveType::kBox;
    p.label_id = label;
    p.center = {cx, cy, 0.5 * (z_bottom + z_top)};
    p.half_size = {hx, hy, 0.5 * (z_top - z_bottom)};
    p.yaw = yaw;
    p.albedo = albedo;
    world_->addPrimitive(p);
  }
  // A box standing on the ground (base buried a little so that no gap shows on slopes).
  void standingBox(std::uint8_t label, double cx, double cy, double hx, double hy, double z0,
                   double height, double yaw, const Eigen::Vector3f& albedo) {
    const double ground = world_->ground().height(cx, cy);
    const double extent = std::max(hx, hy);
    box(label, cx, cy, hx, hy, groundMin(cx, cy, extent, extent) - 0.3, ground + z0 + height, yaw,
        albedo);
  }
  void cylinder(std::uint8_t label, double cx, double cy, double radius, double height,
                const Eigen::Vector3f& albedo) {
    Primitive p;
    p.type = PrimitiveType::kCylinder;
    p.label_id = label;
    const double ground = world_->ground().height(cx, cy);
    const double bottom = ground - 0.3, top = ground + height;
    p.center = {cx, cy, 0.5 * (bottom + top)};
    p.half_size = {radius, radius, 0.5 * (top - bottom)};
    p.albedo = albedo;
    world_->addPrimitive(p);
  }
  void ellipsoid(std::uint8_t label, const Eigen::Vector3d& center, const Eigen::Vector3d& radii,
                 const Eigen::Vector3f& albedo) {
    Primitive p;
    p.type = PrimitiveType::kEllipsoid;
    p.label_id = label;
    p.center = center;
    p.half_size = radii;
    p.albedo = albedo;
    world_->addPrimitive(p);
  }

  void tree(double x, double y) {
    const double trunk_height = uniform(2.0, 3.2);
    const Eigen::Vector3f bark = jitterColor({0.33f, 0.25f, 0.17f}, 0.05);
    cylinder(cs::kVegetation, x, y, uniform(0.15, 0.25), trunk_height + 0.5, bark);
    const double r = uniform(1.6, 2.8);
    const double ground = world_->ground().height(x, y);
    ellipsoid(cs::kVegetation, {x, y, ground + trunk_height + 0.8 * r},
              {r, r * uniform(0.85, 1.15), r * uniform(0.8, 1.1)},
              jitterColor({0.20f, 0.38f, 0.12f}, 0.06));
  }

  void streetLamp(double x, double y) {
    cylinder(cs::kPole, x, y, 0.1, uniform(6.5, 8.0), jitterColor({0.45f, 0.46f, 0.48f}, 0.04));
  }

  // A sign: a thin pole and a plate facing the traffic (plate normal along facing_yaw).
  void trafficSign(double x, double y, double facing_yaw) {
    cylinder(cs::kPole, x, y, 0.04, 2.9, {0.55f, 0.55f, 0.57f});
    const double ground = world_->ground().height(x, y);
    const double bottom = ground + 2.2;
    const Eigen::Vector3f plate =
        chance(0.5) ? Eigen::Vector3f(0.85f, 0.75f, 0.1f) : Eigen::Vector3f(0.15f, 0.3f, 0.75f);
    // Local x = plate normal: place the plate just in front of the pole.
    const double nx = std::cos(facing_yaw), ny = std::sin(facing_yaw);
    box(cs::kTrafficSign, x + 0.07 * nx, y + 0.07 * ny, 0.025, 0.33, bottom, bottom + 0.65,
        facing_yaw, plate);
  }

  // A parked car: body and cabin boxes, axis along yaw.
  void parkedCar(double x, double y, double yaw) {
    static const Eigen::Vector3f kPaints[] = {{0.75f, 0.1f, 0.1f},   {0.1f, 0.2f, 0.6f},
                                              {0.85f, 0.85f, 0.85f}, {0.12f, 0.12f, 0.13f},
                                              {0.5f, 0.52f, 0.55f},  {0.2f, 0.45f, 0.3f}};
    const Eigen::Vector3f paint = jitterColor(kPaints[rng_() % 6], 0.04);
    const double length = uniform(4.0, 4.8), width = uniform(1.7, 1.9);
    const double ground = world_->ground().height(x, y);
    const double c = std::cos(yaw), s = std::sin(yaw);
    box(cs::kCar, x, y, length / 2, width / 2, ground + 0.25, ground + 1.0, yaw, paint);
    const double cabin_shift = uniform(-0.3, 0.1);
    box(cs::kCar, x + cabin_shift * c, y + cabin_shift * s, length * 0.28, width / 2 - 0.08,
        ground + 1.0, ground + uniform(1.4, 1.55), yaw, paint * 0.8f);
  }

  // Buildings and front yards along one block edge. The edge runs along `axis` (0: x, 1: y) from
  // a to b at coordinate `front` (the sidewalk's outer edge); `inward` (+1/-1) points into the
  // block; `depth_limit` caps the building depth.
  void blockEdge(int axis, double a, double b, double front, double inward, double depth_limit) {
    auto at = [&](double along, double across) {
      return axis == 0 ? Eigen::Vector2d(along, across) : Eigen::Vector2d(across, along);
    };
    static const Eigen::Vector3f kFacades[] = {{0.72f, 0.66f, 0.55f},
                                               {0.55f, 0.55f, 0.56f},
                                               {0.62f, 0.32f, 0.25f},
                                               {0.85f, 0.83f, 0.78f},
                                               {0.45f, 0.42f, 0.38f}};
    double cursor = a + uniform(0.0, 3.0);
    while (cursor < b - 6.0) {
      const double width = std::min(uniform(8.0, 18.0), b - cursor);
      const double setback = uniform(2.0, 4.5);
      const double depth = std::min(uniform(8.0, 14.0), depth_limit - setback);
      if (depth > 3.0) {
        const Eigen::Vector2d c = at(cursor + width / 2, front + inward * (setback + depth / 2));
        const double hx = axis == 0 ? width / 2 : depth / 2;
        const double hy = axis == 0 ? depth / 2 : width / 2;
        standingBox(cs::kBuilding, c.x(), c.y(), hx, hy, 0.0, uniform(6.0, 22.0), 0.0,
                    jitterColor(kFacades[rng_() % 5], 0.06));
      }
      // Front yard: trees, hedges, fences between the sidewalk and the facade.
      const double yard_mid = front + inward * setback * 0.5;
      if (setback > 2.5 && chance(0.6)) {
        const Eigen::Vector2d t = at(cursor + uniform(1.5, width - 1.5), yard_mid);
        tree(t.x(), t.y());
      } else if (chance(0.35)) {
        const double len = width * uniform(0.4, 0.9);
        const Eigen::Vector2d f = at(cursor + width / 2, front + inward * 0.3);
        standingBox(cs::kFence, f.x(), f.y(), axis == 0 ? len / 2 : 0.04,
                    axis == 0 ? 0.04 : len / 2, 0.0, uniform(1.1, 1.8), 0.0,
                    jitterColor({0.45f, 0.36f, 0.26f}, 0.06));
      } else if (chance(0.4)) {
        const double len = width * uniform(0.3, 0.8);
        const Eigen::Vector2d h = at(cursor + width / 2, front + inward * 0.8);
        standingBox(cs::kVegetation, h.x(), h.y(), axis == 0 ? len / 2 : 0.4,
                    axis == 0 ? 0.4 : len / 2, 0.0, uniform(0.8, 1.4), 0.0,
                    jitterColor({0.18f, 0.34f, 0.12f}, 0.05));
      }
      cursor += width + (chance(0.35) ? 0.0 : uniform(1.5, 6.0));
    }
  }

  void park(double x0, double y0, double x1, double y1) {
    const int trees = static_cast<int>((x1 - x0) * (y1 - y0) / 60.0);
    for (int i = 0; i < trees; ++i) tree(uniform(x0 + 2, x1 - 2), uniform(y0 + 2, y1 - 2));
    // A low fence along the longer side.
    if (chance(0.6)) {
      standingBox(cs::kFence, 0.5 * (x0 + x1), y0 + 0.3, 0.5 * (x1 - x0) - 1.0, 0.04, 0.0, 1.0, 0.0,
                  jitterColor({0.4f, 0.4f, 0.38f}, 0.05));
    }
  }

  // Lamps, signs and parked cars along a street segment between two crossings. The street runs
  // along `axis` at centre line `centre`, between crossing centre lines a and b.
  void streetFurniture(int axis, double centre, double a, double b, const StreetGrid& grid) {
    auto at = [&](double along, double across) {
      return axis == 0 ? Eigen::Vector2d(along, across) : Eigen::Vector2d(across, along);
    };
    const double clear = grid.road_half_width + grid.sidewalk_width + 4.0;
    const double street_yaw = axis == 0 ? 0.0 : M_PI / 2;
    for (double side : {-1.0, 1.0}) {
      // Street lamps on the sidewalk near the curb.
      for (double s = a + clear + uniform(0, 6); s < b - clear; s += uniform(18, 28)) {
        const Eigen::Vector2d p = at(s, centre + side * (grid.road_half_width + 0.6));
        streetLamp(p.x(), p.y());
      }
      // A sign near the end of the segment, facing oncoming traffic on that side.
      if (chance(0.7)) {
        const double s = side > 0 ? a + clear - 1.0 : b - clear + 1.0;
        const Eigen::Vector2d p = at(s, centre + side * (grid.road_half_width + 1.0));
        trafficSign(p.x(), p.y(), street_yaw + (side > 0 ? M_PI : 0.0));
      }
      // Parked cars in the parking strip.
      const double lateral = centre + side * (grid.road_half_width - 1.2);
      for (double s = a + clear + uniform(0, 5); s < b - clear - 2.5; s += uniform(5.5, 9.0)) {
        if (!chance(0.55)) continue;
        const Eigen::Vector2d p = at(s, lateral);
        parkedCar(p.x(), p.y(), street_yaw + uniform(-0.03, 0.03));
      }
    }
  }

 private:
  SyntheticWorld* world_;
  std::mt19937_64 rng_;
};

}  // namespace

SyntheticWorld SyntheticWorld::generateTown(std::uint64_t seed) {
  SyntheticWorld world;
  world.seed_ = seed;
  const RouteLayout layout;

  // Gentle hills; the offset puts the route's start (the map origin) at IMU height above them.
  GroundSurface ground;
  ground.amplitude_x = 1.5;
  ground.wavenumber_x = 2 * M_PI / 140.0;
  ground.phase_x = 0.3;
  ground.amplitude_y = 0.8;
  ground.wavenumber_y = 2 * M_PI / 90.0;
  ground.phase_y = 1.1;
  ground.offset = 0;
  ground.offset = -layout.imu_height_m - ground.height(0, 0);
  world.ground_ = ground;

  // A street grid with the loop's block in the middle.
  const SyntheticRoute::LoopStreets loop = SyntheticRoute::loopStreets(layout);
  const double pitch_x = loop.right_x - loop.left_x;
  const double pitch_y = loop.top_y - loop.bottom_y;
  StreetGrid streets;
  for (int k = -2; k <= 3; ++k) {
    streets.vertical_x.push_back(loop.left_x + k * pitch_x);
    streets.horizontal_y.push_back(loop.bottom_y + k * pitch_y);
  }
  world.streets_ = streets;

  TownBuilder builder(&world, seed);
  const double margin = streets.road_half_width + streets.sidewalk_width;
  for (std::size_t i = 0; i + 1 < streets.vertical_x.size(); ++i) {
    for (std::size_t j = 0; j + 1 < streets.horizontal_y.size(); ++j) {
      const double x0 = streets.vertical_x[i] + margin, x1 = streets.vertical_x[i + 1] - margin;
      const double y0 = streets.horizontal_y[j] + margin;
      const double y1 = streets.horizontal_y[j + 1] - margin;
      const bool loop_block = i == 2 && j == 2;
      if (!loop_block && builder.chance(0.2)) {
        builder.park(x0, y0, x1, y1);
        continue;
      }
      const double half_y = 0.5 * (y1 - y0), half_x = 0.5 * (x1 - x0);
      builder.blockEdge(0, x0, x1, y0, +1, half_y);
      builder.blockEdge(0, x0, x1, y1, -1, half_y);
      // Side edges only between the corner buildings of the long edges.
      const double corner = std::min(half_y, 14.0);
      builder.blockEdge(1, y0 + corner, y1 - corner, x0, +1, half_x);
      builder.blockEdge(1, y0 + corner, y1 - corner, x1, -1, half_x);
    }
  }
  for (std::size_t i = 0; i < streets.vertical_x.size(); ++i) {
    for (std::size_t j = 0; j + 1 < streets.horizontal_y.size(); ++j) {
      builder.streetFurniture(1, streets.vertical_x[i], streets.horizontal_y[j],
                              streets.horizontal_y[j + 1], streets);
    }
  }
  for (std::size_t j = 0; j < streets.horizontal_y.size(); ++j) {
    for (std::size_t i = 0; i + 1 < streets.vertical_x.size(); ++i) {
      builder.streetFurniture(0, streets.horizontal_y[j], streets.vertical_x[i],
                              streets.vertical_x[i + 1], streets);
    }
  }
  world.buildIndex();
  return world;
}

}  // namespace synthetic
}  // namespace inekf_semantic_mapping
