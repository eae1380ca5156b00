// KITTI timestamps ("2011-09-26 13:02:25.964389445") as integer nanoseconds since the Unix epoch.
#pragma once

#include <cstdint>
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

// One timestamp per non-empty line. Throws KittiFormatError naming path:line on a bad line
// and path on a missing file.
std::vector<std::int64_t> readTimestampsFile(const std::string& path);

// Seconds between two nanosecond stamps, without the precision loss of converting each first.
inline double secondsBetween(std::int64_t from_ns, std::int64_t to_ns) {
  return static_cast<double>(to_ns - from_ns) * 1e-9;
}

}  // namespace kitti
}  // namespace inekf_semantic_mapping
