// Curb detection on the laser rings of one lidar scan: the lidar's own evidence of where the road
// ends and the sidewalk begins (label_geometry.h turns it into a label rule). Eigen only, no ROS.
#pragma once

#include <cstdint>
#include <vector>

#include "inekf_semantic_mapping/perception/projection.h"

namespace inekf_semantic_mapping {
namespace perception {

// Curbs on the laser rings of one scan (sensor frame: x forward, z up). A spinning lidar's ring
// crosses the vehicle's own road straight ahead, then, walking sideways along it, the curb and
// the sidewalk: a curb is a rise of min_step_m..max_step_m within max_step_run_m horizontally,
// after a flat stretch of road at least min_road_run_m long and before a flat raised surface at
// least min_top_run_m wide (a sidewalk, not a bump or a drain's edge). Everything after it on
// that side of the ring's forward half is beyond the curb. A rise of more than max_step_m first
// (a parked car, a wall) ends the walk with nothing found: behind an obstacle the ring says
// nothing about the road. The camera's sidewalk and road look alike to a network trained
// elsewhere; the curb between them is plain in the lidar.
struct CurbOptions {
  float min_step_m = 0.06f;        // lower curbs than this are a road's roughness
  float max_step_m = 0.30f;        // higher is an obstacle, not a curb
  float max_step_run_m = 0.5f;     // the rise happens within this (horizontally)
  float flat_tolerance_m = 0.04f;  // the road continues within this of its last point
  float min_road_run_m = 0.5f;     // flat road before the curb
  float min_top_run_m = 0.6f;      // flat raised surface after it
  float max_ring_range_m = 25.0f;  // rings meeting the ground farther ahead are too sparse
  float min_ground_drop_m = 1.0f;  // a ring whose forward half is not this far below the
                                   // sensor does not reach the ground ahead
  // The curb as a line: with at least line_min_points curbs on one side, a straight line
  // y = a + b x through them (refitted without those more than 0.5 m off; none if the median
  // is more than 0.3 m off) also marks the points of rings whose walk stopped early (a parked
  // car, a gap): those more than line_margin_m beyond it, within line_height_tolerance_m of the
  // curbs' height, between the first and last curb +- line_extension_m along x. 0: no line.
  int line_min_points = 3;
  float line_margin_m = 0.5f;
  float line_height_tolerance_m = 0.15f;
  float line_extension_m = 2.0f;
};

// Per point: 1 when it lies beyond a curb on its ring, else 0 (`beyond` is resized). The rings
// come from the scan's point order: a KITTI HDL-64 scan (raw .bin files, kitti2bag's clouds)
// stores ring after ring, each once around in azimuth from behind the sensor, so a ring ends
// where the azimuth jumps back by more than 45 deg (from +pi to -pi, or by the view's width in a
// cloud cropped to the camera's view; mirrored for a lidar spinning the other way, as the
// synthetic drives'). Returns the number of rings used; a cloud with fewer than 16 such rings
// (another order) flags nothing.
int markPointsBeyondCurbs(const PointMatrixRef& points, const CurbOptions& options,
                          std::vector<std::uint8_t>* beyond);

}  // namespace perception
}  // namespace inekf_semantic_mapping
