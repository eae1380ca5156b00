// KITTI timestamps ("2011-09-26 13:02:25.964389445") as integer nanoseconds since the Unix epoch.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace inekf_semantic_mapping {
namespace kitti {

// Parses "YYYY-MM-DD HH:MM:SS[.fraction]" (fraction up to 9 digits) as UTC with a
// days-from-civil computation: no mktime, so the result does not depend on the machine's
// timezone. Throws KittiFormatError (file "<timestamp>") on malformed text.
std::int64_t parseKittiTimestampNs(const std::string& text);

// The inverse of parseKittiTimestampNs: "YYYY-MM-DD HH:MM:SS.nnnnnnnnn" (UTC), as KITTI writes it.
std::string formatKittiTimestamp(std::int64_t stamp_ns);

// One entry per line of a timestamps file, nullopt for a blank line: KITTI keeps the line of a
// frame the recorder dropped, blank (2011_09_26_drive_0009_sync's velodyne frames 177-180), so
// line n stays the stamp of data file n. Blank lines at the end are not frames and are dropped.
// Throws KittiFormatError naming path:line on a bad line and path on a missing file.
std::vector<std::optional<std::int64_t>> readTimestampLines(const std::string& path);

// The steps of a timestamps file that a recording should not have, one message each:
// "<path>:<line>: 4251.276 s before the line above" (time goes back) or "... after the line
// above" (a jump of more than max_gap_s), "... the same stamp as the line above" (a repeated
// stamp: consumers drop its message as out of order). lines: each stamp's 0-based line in the
// file (empty: stamp i on line i); a step over skipped lines names the earlier line ("... after
// line 177"). At most max_messages, then one saying how many more. Empty for a clean file.
std::vector<std::string> timestampWarnings(const std::vector<std::int64_t>& stamps_ns,
                                           const std::string& path, double max_gap_s = 1.0,
                                           std::size_t max_messages = 5,
                                           const std::vector<std::size_t>& lines = {});

// The frames whose stamps alone are off (bad lines of timestamps.txt, up to max_run in a row):
// each more than max_gap_s away from the frames on either side of the run while those two are in
// order within max_gap_s of each other. A recording's real jumps (a gap, a second recording) move
// every stamp after them and are not listed; the first and last frames, with one neighbour,
// cannot be judged.
std::vector<bool> isolatedMisstampedFrames(const std::vector<std::int64_t>& stamps_ns,
                                           double max_gap_s = 1.0, std::size_t max_run = 5);

// Seconds between two nanosecond stamps, without the precision loss of converting each first.
inline double secondsBetween(std::int64_t from_ns, std::int64_t to_ns) {
  return static_cast<double>(to_ns - from_ns) * 1e-9;
}

}  // namespace kitti
}  // namespace inekf_semantic_mapping
