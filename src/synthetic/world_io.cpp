// SyntheticWorld::save / load: the world.txt format (atomic writes; every value checked on
// reading, with file and line in the errors).
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "inekf_semantic_mapping/common/atomic_file.h"
#include "inekf_semantic_mapping/perception/cityscapes.h"
#include "inekf_semantic_mapping/synthetic/world.h"

namespace inekf_semantic_mapping {
namespace synthetic {
namespace cs = cityscapes;

// ---------------------------------------------------------------------------------------------
// world.txt
// ---------------------------------------------------------------------------------------------
// One record per line, '#' comments:
//   seed S
//   ground OFFSET AMPLITUDE_X WAVENUMBER_X PHASE_X AMPLITUDE_Y WAVENUMBER_Y PHASE_Y
//   streets ROAD_HALF_WIDTH SIDEWALK_WIDTH LANE_HALF_WIDTH
//   street_x X          (a north-south street centre line)
//   street_y Y          (an east-west street centre line)
//   box LABEL CX CY CZ HALF_X HALF_Y HALF_Z YAW R G B
//   cylinder LABEL CX CY CZ RADIUS HALF_HEIGHT R G B
//   ellipsoid LABEL CX CY CZ RX RY RZ R G B
void SyntheticWorld::save(const std::string& path) const {
  common::commitFileAtomically(path, [&](const std::string& tmp) {
    std::FILE* file = std::fopen(tmp.c_str(), "w");
    if (!file) {
      throw common::AtomicWriteError(path, "cannot create '" + tmp + "': " + std::strerror(errno));
    }
    std::fprintf(file,
                 "# inekf_semantic_mapping synthetic world v1: map frame (x east, y north, z up), "
                 "metres, labels = Cityscapes labelIds, colours RGB 0..1\n");
    std::fprintf(file, "seed %llu\n", static_cast<unsigned long long>(seed_));
    std::fprintf(file, "ground %.17g %.17g %.17g %.17g %.17g %.17g %.17g\n", ground_.offset,
                 ground_.amplitude_x, ground_.wavenumber_x, ground_.phase_x, ground_.amplitude_y,
                 ground_.wavenumber_y, ground_.phase_y);
    std::fprintf(file, "streets %.17g %.17g %.17g\n", streets_.road_half_width,
                 streets_.sidewalk_width, streets_.lane_half_width);
    for (double x : streets_.vertical_x) std::fprintf(file, "street_x %.17g\n", x);
    for (double y : streets_.horizontal_y) std::fprintf(file, "street_y %.17g\n", y);
    for (const Primitive& p : primitives_) {
      const Eigen::Vector3d& c = p.center;
      const Eigen::Vector3d& h = p.half_size;
      const Eigen::Vector3f& a = p.albedo;
      switch (p.type) {
        case PrimitiveType::kBox:
          std::fprintf(file, "box %d %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.9g %.9g %.9g\n",
                       p.label_id, c.x(), c.y(), c.z(), h.x(), h.y(), h.z(), p.yaw, a.x(), a.y(),
                       a.z());
          break;
        case PrimitiveType::kCylinder:
          std::fprintf(file, "cylinder %d %.17g %.17g %.17g %.17g %.17g %.9g %.9g %.9g\n",
                       p.label_id, c.x(), c.y(), c.z(), h.x(), h.z(), a.x(), a.y(), a.z());
          break;
        case PrimitiveType::kEllipsoid:
          std::fprintf(file, "ellipsoid %d %.17g %.17g %.17g %.17g %.17g %.17g %.9g %.9g %.9g\n",
                       p.label_id, c.x(), c.y(), c.z(), h.x(), h.y(), h.z(), a.x(), a.y(), a.z());
          break;
      }
    }
    const bool ok = std::fflush(file) == 0 && !std::ferror(file);
    if (std::fclose(file) != 0 || !ok) {
      throw common::AtomicWriteError(path, "write failed (disk full?)");
    }
  });
}

namespace {
constexpr double kMaxWorldValue = 1e5;
}  // namespace

SyntheticWorld SyntheticWorld::load(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open the world file");
  SyntheticWorld world;
  bool has_ground = false;
  std::string line;
  int line_number = 0;
  while (std::getline(in, line)) {
    ++line_number;
    const std::size_t start = line.find_first_not_of(" \t\r");
    if (start == std::string::npos || line[start] == '#') continue;
    std::istringstream fields(line);
    std::string kind;
    fields >> kind;
    auto fail = [&](const std::string& what) {
      throw std::runtime_error(path + ":" + std::to_string(line_number) + ": " + what + " in '" +
                               line + "'");
    };
    auto read = [&](const char* field_name) {
      double v;
      if (!(fields >> v) || !std::isfinite(v)) fail(std::string("bad or missing ") + field_name);
      // A synthetic town is a few km across: a larger value is a broken file.
      if (std::abs(v) > kMaxWorldValue) {
        fail(std::string(field_name) + " out of range (|value| <= 1e5)");
      }
      return v;
    };
    auto read_label = [&]() {
      const double v = read("label");
      if (v < 0 || v >= cs::kNumLabelIds || v != std::floor(v))
        fail("label must be a labelId 0..33");
      return static_cast<std::uint8_t>(v);
    };
    auto read_albedo = [&]() {
      Eigen::Vector3f a;
      a.x() = static_cast<float>(read("red"));
      a.y() = static_cast<float>(read("green"));
      a.z() = static_cast<float>(read("blue"));
      return a;
    };
    auto read_positive = [&](const char* field_name) {
      const double v = read(field_name);
      if (v <= 0) fail(std::string(field_name) + " must be > 0");
      return v;
    };
    if (kind == "seed") {
      unsigned long long seed;
      if (!(fields >> seed)) fail("bad seed");
      world.seed_ = seed;
    } else if (kind == "ground") {
      GroundSurface& g = world.ground_;
      g.offset = read("offset");
      g.amplitude_x = read("amplitude_x");
      g.wavenumber_x = read("wavenumber_x");
      g.phase_x = read("phase_x");
      g.amplitude_y = read("amplitude_y");
      g.wavenumber_y = read("wavenumber_y");
      g.phase_y = read("phase_y");
      has_ground = true;
    } else if (kind == "streets") {
      world.streets_.road_half_width = read_positive("road_half_width");
      world.streets_.sidewalk_width = read_positive("sidewalk_width");
      world.streets_.lane_half_width = read_positive("lane_half_width");
    } else if (kind == "street_x") {
      world.streets_.vertical_x.push_back(read("x"));
    } else if (kind == "street_y") {
      world.streets_.horizontal_y.push_back(read("y"));
    } else if (kind == "box" || kind == "cylinder" || kind == "ellipsoid") {
      Primitive p;
      p.label_id = read_label();
      p.center.x() = read("center_x");
      p.center.y() = read("center_y");
      p.center.z() = read("center_z");
      if (kind == "box") {
        p.type = PrimitiveType::kBox;
        p.half_size.x() = read_positive("half_x");
        p.half_size.y() = read_positive("half_y");
        p.half_size.z() = read_positive("half_z");
        p.yaw = read("yaw");
      } else if (kind == "cylinder") {
        p.type = PrimitiveType::kCylinder;
        p.half_size.x() = p.half_size.y() = read_positive("radius");
        p.half_size.z() = read_positive("half_height");
      } else {
        p.type = PrimitiveType::kEllipsoid;
        p.half_size.x() = read_positive("radius_x");
        p.half_size.y() = read_positive("radius_y");
        p.half_size.z() = read_positive("radius_z");
      }
      p.albedo = read_albedo();
      world.primitives_.push_back(p);
    } else {
      fail("unknown record '" + kind + "'");
    }
    std::string extra;
    if (fields >> extra) fail("unexpected extra value '" + extra + "'");
  }
  if (!has_ground) throw std::runtime_error(path + ": no 'ground' record");
  world.buildIndex();
  return world;
}

}  // namespace synthetic
}  // namespace inekf_semantic_mapping
