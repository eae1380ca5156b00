#include "inekf_semantic_mapping/kitti/oxts.h"

#include <cmath>
#include <cstdio>

#include "inekf_semantic_mapping/kitti/errors.h"
#include "inekf_semantic_mapping/kitti/sensor_stream.h"
#include "inekf_semantic_mapping/kitti/timestamps.h"
#include "text_parsing.h"

namespace inekf_semantic_mapping {
namespace kitti {
namespace {

constexpr const char* kFieldNames[kOxtsFieldCount] = {
    "lat",          "lon",     "alt",     "roll",    "pitch",   "yaw",    "vn", "ve",
    "vf",           "vl",      "vu",      "ax",      "ay",      "az",     "af", "al",
    "au",           "wx",      "wy",      "wz",      "wf",      "wl",     "wu", "pos_accuracy",
    "vel_accuracy", "navstat", "numsats", "posmode", "velmode", "orimode"};

}  // namespace

OxtsRecord parseOxtsLine(const std::string& line, const std::string& file_for_errors,
                         int line_number) {
  const std::vector<std::string> tokens = detail::splitWhitespace(line);
  if (tokens.size() != kOxtsFieldCount) {
    throw KittiFormatError(file_for_errors, line_number,
                           "expected " + std::to_string(kOxtsFieldCount) + " OXTS values, found " +
                               std::to_string(tokens.size()));
  }
  double values[kOxtsFieldCount];
  for (int i = 0; i < kOxtsFieldCount; ++i) {
    if (!detail::parseDouble(tokens[i], &values[i])) {
      throw KittiFormatError(file_for_errors, line_number,
                             std::string("field ") + std::to_string(i + 1) + " (" + kFieldNames[i] +
                                 ") is not a number: '" + tokens[i] + "'");
    }
  }
  // strtod accepts "nan" and "inf": reject them here so that no NaN reaches a filter.
  for (int i = 0; i < kOxtsFieldCount; ++i) {
    if (!std::isfinite(values[i])) {
      throw KittiFormatError(
          file_for_errors, line_number,
          std::string("field ") + kFieldNames[i] + " is not finite: '" + tokens[i] + "'");
    }
  }
  // A latitude at or beyond a pole would make the Mercator poses infinite or NaN downstream (the
  // projection's own range, isGeodeticInRange).
  if (!(std::fabs(values[0]) < 90.0) || std::fabs(values[1]) > 180.0 ||
      std::fabs(values[2]) > 100000.0) {
    throw KittiFormatError(file_for_errors, line_number,
                           "lat/lon/alt out of range (|lat| < 90, |lon| <= 180, |alt| <= 1e5): '" +
                               tokens[0] + " " + tokens[1] + " " + tokens[2] + "'");
  }
  int flags[5];
  for (int i = 0; i < 5; ++i) {
    const double v = values[25 + i];
    // 2011_10_03 prints the flags as "4.00000000000000": accept integral values only.
    if (!std::isfinite(v) || v != std::round(v) || std::fabs(v) > 1e6) {
      throw KittiFormatError(file_for_errors, line_number,
                             std::string("field ") + kFieldNames[25 + i] +
                                 " must be an integer, got '" + tokens[25 + i] + "'");
    }
    flags[i] = static_cast<int>(std::lround(v));
  }
  OxtsRecord r;
  double* doubles[25] = {&r.lat, &r.lon, &r.alt,          &r.roll,        &r.pitch, &r.yaw, &r.vn,
                         &r.ve,  &r.vf,  &r.vl,           &r.vu,          &r.ax,    &r.ay,  &r.az,
                         &r.af,  &r.al,  &r.au,           &r.wx,          &r.wy,    &r.wz,  &r.wf,
                         &r.wl,  &r.wu,  &r.pos_accuracy, &r.vel_accuracy};
  for (int i = 0; i < 25; ++i) *doubles[i] = values[i];
  r.navstat = flags[0];
  r.numsats = flags[1];
  r.posmode = flags[2];
  r.velmode = flags[3];
  r.orimode = flags[4];
  return r;
}

OxtsRecord readOxtsFile(const std::string& path) {
  std::ifstream stream = detail::openOrThrow(path);
  std::string line;
  int line_number = 0;
  while (std::getline(stream, line)) {
    ++line_number;
    if (!detail::trim(line).empty()) return parseOxtsLine(line, path, line_number);
  }
  throw KittiFormatError(path, "empty OXTS file");
}

std::vector<OxtsFrame> readOxtsFolder(const std::string& oxts_dir,
                                      std::vector<std::string>* warnings) {
  const SensorStream stream = readSensorStream(oxts_dir, "oxts");
  if (!stream.present) throw KittiFormatError(oxts_dir + "/data", "OXTS data folder is missing");
  if (stream.size() == 0) {
    throw KittiFormatError(oxts_dir,
                           "no frames (timestamps.txt is empty or no data/ file fits it)");
  }
  if (stream.extension != ".txt") {
    throw KittiFormatError(oxts_dir, "data/ holds " + stream.extension + " files, not .txt");
  }
  if (warnings) {
    warnings->insert(warnings->end(), stream.warnings.begin(), stream.warnings.end());
    for (std::string& step : timestampWarnings(stream.stamps_ns, oxts_dir + "/timestamps.txt", 1.0,
                                               5, stream.file_numbers)) {
      warnings->push_back(std::move(step));
    }
  }
  return readOxtsFrames(stream);
}

std::vector<OxtsFrame> readOxtsFrames(const SensorStream& stream) {
  std::vector<OxtsFrame> frames(stream.size());
  for (std::size_t i = 0; i < frames.size(); ++i) {
    frames[i].stamp_ns = stream.stamps_ns[i];
    frames[i].file_number = stream.file_numbers[i];
    frames[i].record = readOxtsFile(stream.framePath(i));
  }
  return frames;
}

}  // namespace kitti
}  // namespace inekf_semantic_mapping
