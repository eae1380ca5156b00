// Input validation on a real drive of ../shared: drive-timeline offsets that would overflow are
// refused.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/kitti/drive_timeline.h"
#include "inekf_semantic_mapping/kitti/errors.h"
#include "inekf_semantic_mapping/kitti/oxts.h"
#include "inekf_semantic_mapping/kitti/poses.h"
#include "inekf_semantic_mapping/kitti/timestamps.h"
#include "inekf_semantic_mapping/mapping/offline_mapping.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace {

// The message of what `call` throws, or "no error".

TEST(InputValidation, DriveTimelineOffsetsThatWouldOverflowAreRefused) {
  ISM_REQUIRE_SHARED("data/kitti_raw/2011_09_26/2011_09_26_drive_0013_sync");
  const kitti::RawDrive drive(
      test::sharedPath("data/kitti_raw/2011_09_26/2011_09_26_drive_0013_sync"));
  kitti::TimelineOptions options;
  options.start_offset_s = 1e10;
  EXPECT_THROW(kitti::buildDriveTimeline(drive, options), std::invalid_argument);
  options.start_offset_s = 2.0;
  options.duration_s = 1.0;
  const auto events = kitti::buildDriveTimeline(drive, options);
  EXPECT_FALSE(events.empty());
  EXPECT_LT(events.back().stamp_ns - events.front().stamp_ns, 1'000'000'001);
}

}  // namespace
}  // namespace inekf_semantic_mapping
