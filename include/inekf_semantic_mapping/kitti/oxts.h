// OXTS RT3003 GPS/IMU records of KITTI raw drives (oxts/dataformat.txt).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/kitti/sensor_stream.h"

namespace inekf_semantic_mapping {
namespace kitti {

// The 30 fields of one oxts/data/%010d.txt line, named and ordered as in dataformat.txt.
struct OxtsRecord {
  double lat = 0, lon = 0, alt = 0;           // deg, deg, m (WGS84)
  double roll = 0, pitch = 0, yaw = 0;        // rad; yaw 0 = east, positive counter-clockwise
  double vn = 0, ve = 0;                      // m/s north, east
  double vf = 0, vl = 0, vu = 0;              // m/s forward, left, up (body frame)
  double ax = 0, ay = 0, az = 0;              // m/s^2 body frame x y z (specific force)
  double af = 0, al = 0, au = 0;              // m/s^2 levelled forward/left/up (NOT body frame)
  double wx = 0, wy = 0, wz = 0;              // rad/s body frame
  double wf = 0, wl = 0, wu = 0;              // rad/s levelled (NOT body frame)
  double pos_accuracy = 0, vel_accuracy = 0;  // m, m/s
  int navstat = 0, numsats = 0, posmode = 0, velmode = 0, orimode = 0;
};

struct OxtsFrame {
  std::int64_t stamp_ns = 0;  // from oxts/timestamps.txt
  // Its data file's number, which a sync drive's scan and images of the same frame share (a
  // frame the recorder dropped leaves a number out).
  std::size_t file_number = 0;
  OxtsRecord record;
  double stampSeconds() const { return static_cast<double>(stamp_ns) * 1e-9; }
};

constexpr int kOxtsFieldCount = 30;

// Whether the frame carries an INS solution's attitude and velocity: a frame whose roll, pitch,
// yaw and velocity columns (vn ve vf vl vu) are all exactly zero has none (an IMU without an
// INS behind it, or a file with those columns blanked). A real solution is never exactly zero in
// all eight: even a car at rest on a level road has some roll and pitch.
inline bool carriesAttitude(const OxtsRecord& r) {
  return !(r.roll == 0.0 && r.pitch == 0.0 && r.yaw == 0.0 && r.vn == 0.0 && r.ve == 0.0 &&
           r.vf == 0.0 && r.vl == 0.0 && r.vu == 0.0);
}

// The frame as an IMU without an INS gives it: attitude and velocity columns zero.
inline OxtsRecord withoutAttitude(OxtsRecord r) {
  r.roll = r.pitch = r.yaw = 0.0;
  r.vn = r.ve = r.vf = r.vl = r.vu = 0.0;
  return r;
}

// Parses one line of 30 whitespace-separated numbers. The integer flags are accepted as
// "4" or "4.00000000000000" (2011_10_03 files) but not as "4.5". Throws KittiFormatError
// naming file_for_errors:line_number and the field on a short line, an extra value or a
// non-numeric or non-finite (nan, inf) value.
OxtsRecord parseOxtsLine(const std::string& line, const std::string& file_for_errors,
                         int line_number);

// Reads the first line of one oxts/data/%010d.txt file.
OxtsRecord readOxtsFile(const std::string& path);

// Reads the frames of oxts/ (readSensorStream: file data/%010d.txt stamped by line n of
// timestamps.txt; a frame with a blank line or without its file is left out). warnings (optional):
// one message per run of frames left out and per step of timestamps.txt that goes back or jumps
// (timestampWarnings). KittiFormatError naming the folder when it has no data/, no .txt frame
// or no frame at all.
std::vector<OxtsFrame> readOxtsFolder(const std::string& oxts_dir,
                                      std::vector<std::string>* warnings = nullptr);

// Reads every frame of an oxts stream (its data files, stamped by its timestamps).
std::vector<OxtsFrame> readOxtsFrames(const SensorStream& stream);

}  // namespace kitti
}  // namespace inekf_semantic_mapping
