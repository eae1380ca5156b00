// The time-ordered list of sensor frames of a raw drive within a window, as kitti_player and
// kitti2bag replay it (one implementation, so the node and the bag carry the same messages).
#pragma once

#include <cstdint>
#include <vector>

#include "inekf_semantic_mapping/kitti/raw_drive.h"

namespace inekf_semantic_mapping {
namespace kitti {

enum class DriveSensor { kOxts, kVelodyne, kCamera0, kCamera1, kCamera2, kCamera3 };

struct TimelineEvent {
  std::int64_t stamp_ns = 0;
  DriveSensor sensor = DriveSensor::kOxts;
  std::size_t frame = 0;  // index into the sensor's data/ and timestamps.txt
};

struct TimelineOptions {
  double start_offset_s = 0;  // skip frames earlier than first stamp + offset
  double duration_s = 0;      // <= 0: to the end; else stop before first + offset + duration
  bool oxts = true, velodyne = true;
  bool cameras[RawDrive::kNumCameras] = {false, false, true, false};  // color left by default
};

// Events of the present (and selected) sensors inside the window, sorted by stamp; ties keep
// the order oxts, velodyne, cameras so that a frame's pose comes before its scan.
// std::invalid_argument for a negative offset.
std::vector<TimelineEvent> buildDriveTimeline(const RawDrive& drive,
                                              const TimelineOptions& options);

}  // namespace kitti
}  // namespace inekf_semantic_mapping
