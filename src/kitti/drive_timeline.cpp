#include "inekf_semantic_mapping/kitti/drive_timeline.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace inekf_semantic_mapping {
namespace kitti {

std::vector<TimelineEvent> buildDriveTimeline(const RawDrive& drive,
                                              const TimelineOptions& options) {
  // Offsets beyond a century would overflow the nanosecond stamps (llround of 1e10 s * 1e9).
  constexpr double kMaxSeconds = 100.0 * 365 * 86400;
  if (!(options.start_offset_s >= 0 && options.start_offset_s <= kMaxSeconds) ||
      !(options.duration_s <= kMaxSeconds) || !std::isfinite(options.duration_s)) {
    throw std::invalid_argument(
        "drive timeline: start offset must be in [0, 3.15e9] s and duration at most 3.15e9 s");
  }
  const std::int64_t first_ns = drive.firstStampNs();
  const std::int64_t begin_ns = first_ns + std::llround(options.start_offset_s * 1e9);
  const std::int64_t end_ns = options.duration_s > 0
                                  ? begin_ns + std::llround(options.duration_s * 1e9)
                                  : std::numeric_limits<std::int64_t>::max();
  std::vector<TimelineEvent> events;
  auto add = [&](const SensorStream& stream, DriveSensor sensor) {
    if (!stream.present) return;
    for (std::size_t i = 0; i < stream.stamps_ns.size(); ++i) {
      const std::int64_t t = stream.stamps_ns[i];
      if (t >= begin_ns && t < end_ns) events.push_back({t, sensor, i});
    }
  };
  if (options.oxts) add(drive.oxts(), DriveSensor::kOxts);
  if (options.velodyne) add(drive.velodyne(), DriveSensor::kVelodyne);
  for (int c = 0; c < RawDrive::kNumCameras; ++c) {
    if (options.cameras[c]) {
      add(drive.camera(c), static_cast<DriveSensor>(static_cast<int>(DriveSensor::kCamera0) + c));
    }
  }
  std::stable_sort(
      events.begin(), events.end(),
      [](const TimelineEvent& a, const TimelineEvent& b) { return a.stamp_ns < b.stamp_ns; });
  return events;
}

}  // namespace kitti
}  // namespace inekf_semantic_mapping
