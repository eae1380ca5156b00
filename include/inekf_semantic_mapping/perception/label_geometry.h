// Lidar geometry as a consistency check on camera labels: a label that contradicts where the
// point is relative to the local ground (road on a hedge, a traffic sign on the asphalt) is
// physically impossible whatever the image says, so it gives no class evidence. Eigen only, no
// ROS; the class knowledge comes in as a table per label id.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <vector>

#include "inekf_semantic_mapping/perception/curb_detection.h"
#include "inekf_semantic_mapping/perception/projection.h"

namespace inekf_semantic_mapping {
namespace perception {

// Local ground height from one scan (sensor frame, z up: the lidar sits level on the vehicle, so
// the road under and around it is near z = const even on a hill). A square grid of cell_size_m
// over |x|, |y| <= range_m holds the lowest supported z of each cell: the lowest point with at
// least min_support - 1 others within support_band_m above it (real scans hold clusters of
// spurious returns metres below the road, reflections that SemanticKITTI labels "outlier"; a
// single one would sink the ground of its cell). Optionally (max_slope > 0), cells whose lowest
// point is not the ground (a parked car's roof, a facade whose foot a car hides) are capped by a
// cone from their neighbours: ground(c) = min over cells c' of lowest(c') + max_slope *
// distance(c, c'). A point's ground is the bilinear blend of the values
// of the supported cells around it, so a steady grade (a ramp) is followed rather than seen as
// steps; a point with no supported cell around it gets no estimate.
struct GroundGridOptions {
  float cell_size_m = 1.0f;
  float range_m = 40.0f;  // points farther (in x or y) get no ground estimate
  // The cone's slope (0.5: a 27 deg embankment; roads rise at most about 0.15); 0: no cone,
  // each cell keeps its own lowest supported z. Off by default: on SemanticKITTI 08 real drops
  // beside the road (a bank falling away, walls) and clusters of spurious returns that pass the
  // support test pulled the road's ground down through the cone (8k road and sidewalk points
  // over 10 frames read more than 0.5 m above it at 0.5, 1.4k at 1.0, 26 without), while it
  // found only 20-64 more wrong labels on 05 than no cone.
  float max_slope = 0.0f;
  int min_support = 5;
  float support_band_m = 0.2f;
};

// Per point: its height above the local ground (m), NaN for points with no estimate (beyond the
// range, non-finite). `heights` is resized to the number of points. Throws std::invalid_argument
// for options out of range.
void heightAboveGround(const PointMatrixRef& points, const GroundGridOptions& options,
                       Eigen::VectorXf* heights);

// What the geometry allows for a class: kAny (no check), kFlat (a surface that is the ground:
// road, sidewalk, terrain...; never well above it), kRaised (mounted or tall things whose points
// are never at ground level: traffic signs and lights).
enum class SurfaceKind : std::uint8_t { kAny = 0, kFlat = 1, kRaised = 2 };
using SurfaceKindTable = std::array<SurfaceKind, 256>;  // per label id

// Cityscapes labelIds: category "flat" (road, sidewalk, parking, rail track), ground and terrain
// are kFlat; traffic light and traffic sign kRaised; the rest kAny.
const SurfaceKindTable& cityscapesSurfaceKinds();

// Per label id: what a kFlat label well above the ground becomes instead of no label
// (kNoRelabel: no label).
constexpr std::uint32_t kNoRelabel = 0xFFFFFFFF;
using RelabelTable = std::array<std::uint32_t, 256>;

// Cityscapes: terrain -> vegetation (Cityscapes tells the two apart by orientation: terrain is
// horizontal ground cover, vegetation the vertical kind; green well above the ground is
// vegetation by that definition), every other id kNoRelabel.
const RelabelTable& cityscapesHighFlatRelabels();

struct LabelGeometryOptions {
  GroundGridOptions ground;
  // A kFlat label on a point more than this above the local ground is rejected. 0.2 m: the
  // highest curbs; a steady grade reads about half a cell of it above the ground (the gtest's
  // 20 deg grass bank stays below it).
  float max_flat_height_m = 0.2f;
  // A kRaised label on a point less than this above the local ground is rejected.
  float min_raised_height_m = 0.2f;
};

// Sets labels[i] = unknown_label where the label's SurfaceKind contradicts heights[i] (points
// with a NaN height are left alone), or, for a kFlat label above the ground with a
// `relabel_high` entry, that entry. rejected (optional): how many it changed. Throws
// std::invalid_argument when the sizes differ.
void rejectGeometricallyInconsistentLabels(const Eigen::VectorXf& heights,
                                           const SurfaceKindTable& kinds,
                                           const LabelGeometryOptions& options,
                                           std::uint32_t unknown_label,
                                           std::vector<std::uint32_t>* labels,
                                           std::size_t* rejected = nullptr,
                                           const RelabelTable* relabel_high = nullptr);

// Cityscapes: road -> sidewalk for a point beyond a curb (every other id kNoRelabel).
const RelabelTable& cityscapesBeyondCurbRelabels();

// labels[i] = relabel[labels[i]] where beyond[i] and there is an entry. changed (optional): how
// many. Throws std::invalid_argument when the sizes differ.
void relabelBeyondCurbs(const std::vector<std::uint8_t>& beyond, const RelabelTable& relabel,
                        std::vector<std::uint32_t>* labels, std::size_t* changed = nullptr);

// The lidar's checks on one scan's Cityscapes camera labels, as the mapping session and
// evaluate_semantics apply them: rejectGeometricallyInconsistentLabels (terrain well above the
// ground becomes vegetation when high_terrain_is_vegetation), then, with curbs, road beyond a
// curb becomes sidewalk.
struct CityscapesLidarChecks {
  LabelGeometryOptions geometry;
  bool high_terrain_is_vegetation = true;
  bool curbs = true;
  CurbOptions curb;
};
void applyCityscapesLidarChecks(const PointMatrixRef& points, const CityscapesLidarChecks& checks,
                                std::uint32_t unknown_label, std::vector<std::uint32_t>* labels);

}  // namespace perception
}  // namespace inekf_semantic_mapping
