#include "inekf_semantic_mapping/kitti/raw_drive.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <map>
#include <stdexcept>

#include "inekf_semantic_mapping/kitti/errors.h"
#include "inekf_semantic_mapping/kitti/timestamps.h"

namespace inekf_semantic_mapping {
namespace kitti {
namespace fs = std::filesystem;

std::string SensorStream::framePath(std::size_t frame) const {
  char name[32];
  std::snprintf(name, sizeof(name), "%010zu", frame);
  return dir + "/data/" + name + extension;
}

RawDrive::RawDrive(const std::string& drive_dir, const std::string& calib_dir) {
  fs::path path(drive_dir);
  while (!path.empty() && path.filename().empty()) path = path.parent_path();  // trailing '/'
  drive_dir_ = path.string();
  if (!fs::is_directory(path)) {
    throw KittiFormatError(drive_dir_, "drive folder does not exist");
  }
  const std::string folder_name = path.filename().string();
  is_extract_ =
      folder_name.size() >= 8 && folder_name.compare(folder_name.size() - 8, 8, "_extract") == 0;

  oxts_ = openSensor("oxts");
  velodyne_ = openSensor("velodyne_points");
  for (int i = 0; i < kNumCameras; ++i) {
    char name[16];
    std::snprintf(name, sizeof(name), "image_%02d", i);
    cameras_[i] = openSensor(name);
  }
  if (!oxts_.present && !velodyne_.present &&
      std::none_of(cameras_, cameras_ + kNumCameras,
                   [](const SensorStream& s) { return s.present; })) {
    throw KittiFormatError(drive_dir_,
                           "no sensor folder found (expected oxts/, velodyne_points/ or "
                           "image_0N/ each with data/ and timestamps.txt)");
  }

  // Missing calibration is not an error (IMU/GPS-only drives); missingParts() names the folder
  // that was searched so that a mistyped --calib-dir shows up in the warning.
  calibration_search_dir_ =
      calib_dir.empty() ? fs::absolute(path).parent_path().string() : calib_dir;
  if (hasRawCalibration(calibration_search_dir_)) calibration_dir_ = calibration_search_dir_;
}

SensorStream RawDrive::openSensor(const std::string& name) const {
  SensorStream stream;
  stream.name = name;
  stream.dir = drive_dir_ + "/" + name;
  const fs::path data_dir = fs::path(stream.dir) / "data";
  const fs::path timestamps = fs::path(stream.dir) / "timestamps.txt";
  if (!fs::is_directory(data_dir)) return stream;
  if (!fs::is_regular_file(timestamps)) {
    throw KittiFormatError(stream.dir, "has data/ but no timestamps.txt");
  }
  stream.present = true;
  stream.stamps_ns = readTimestampsFile(timestamps.string());

  // Count the data files per extension; the most common one is the sensor's format.
  std::map<std::string, std::size_t> count_by_extension;
  for (const auto& entry : fs::directory_iterator(data_dir)) {
    if (entry.is_regular_file()) ++count_by_extension[entry.path().extension().string()];
  }
  std::size_t file_count = 0;
  for (const auto& [extension, count] : count_by_extension) {
    if (count > file_count) {
      file_count = count;
      stream.extension = extension;
    }
  }
  if (file_count != stream.stamps_ns.size()) {
    throw KittiFormatError(
        stream.dir, "frame count mismatch: " + std::to_string(file_count) + " files in data/ but " +
                        std::to_string(stream.stamps_ns.size()) + " lines in timestamps.txt");
  }
  if (file_count > 0 && !fs::exists(stream.framePath(0))) {
    throw KittiFormatError(stream.framePath(0),
                           "first frame missing (data files must be "
                           "numbered %010d from 0)");
  }
  for (const char* which : {"start", "end"}) {
    const fs::path extra = fs::path(stream.dir) / (std::string("timestamps_") + which + ".txt");
    if (!fs::is_regular_file(extra)) continue;
    auto stamps = readTimestampsFile(extra.string());
    if (stamps.size() != stream.stamps_ns.size()) {
      throw KittiFormatError(extra.string(), "has " + std::to_string(stamps.size()) +
                                                 " lines, timestamps.txt " +
                                                 std::to_string(stream.stamps_ns.size()));
    }
    (std::string(which) == "start" ? stream.start_stamps_ns : stream.end_stamps_ns) =
        std::move(stamps);
  }
  return stream;
}

const SensorStream& RawDrive::camera(int index) const {
  if (index < 0 || index >= kNumCameras) {
    throw std::out_of_range("RawDrive::camera: index " + std::to_string(index));
  }
  return cameras_[index];
}

std::vector<OxtsFrame> RawDrive::readOxts() const {
  if (!oxts_.present) throw KittiFormatError(drive_dir_, "drive has no oxts/ folder");
  std::vector<OxtsFrame> frames(oxts_.size());
  for (std::size_t i = 0; i < frames.size(); ++i) {
    frames[i].stamp_ns = oxts_.stamps_ns[i];
    frames[i].record = readOxtsFile(oxts_.framePath(i));
  }
  return frames;
}

RawCalibration RawDrive::readCalibration() const {
  if (!hasCalibration()) {
    throw KittiFormatError(drive_dir_, "no calibration found beside the drive (calib_*.txt)");
  }
  return readRawCalibration(calibration_dir_);
}

std::vector<std::string> RawDrive::missingParts() const {
  std::vector<std::string> missing;
  // A folder with data/ and timestamps.txt but no frame is as good as missing (a bag without IMU
  // was written without a word).
  const auto check = [&missing](const SensorStream& stream) {
    if (!stream.present) {
      missing.push_back(stream.name);
    } else if (stream.size() == 0) {
      missing.push_back(stream.name + " (no frames in " + stream.dir + ")");
    }
  };
  check(oxts_);
  check(velodyne_);
  for (const auto& camera : cameras_) check(camera);
  if (!hasCalibration()) {
    // Which of the three files, where some are there (a drive written without one had been
    // reported as having none).
    const std::vector<std::string> files = missingRawCalibrationFiles(calibration_search_dir_);
    std::string which = "no calib_*.txt";
    if (files.size() < 3) {
      which.clear();
      for (const std::string& file : files)
        which += (which.empty() ? "" : ", ") + file + " missing";
    }
    missing.push_back("calibration (" + which + " in " + calibration_search_dir_ + ")");
  }
  return missing;
}

std::vector<std::string> RawDrive::stampWarnings() const {
  std::vector<std::string> warnings;
  const auto check = [&warnings](const SensorStream& stream) {
    if (!stream.present) return;
    for (std::string& warning :
         timestampWarnings(stream.stamps_ns, stream.dir + "/timestamps.txt")) {
      warnings.push_back(std::move(warning));
    }
  };
  check(oxts_);
  check(velodyne_);
  for (const SensorStream& camera : cameras_) check(camera);
  return warnings;
}

std::int64_t RawDrive::firstStampNs() const {
  std::int64_t first = 0;
  bool found = false;
  auto consider = [&](const SensorStream& s) {
    if (s.present && !s.stamps_ns.empty() && (!found || s.stamps_ns.front() < first)) {
      first = s.stamps_ns.front();
      found = true;
    }
  };
  consider(oxts_);
  consider(velodyne_);
  for (const auto& camera : cameras_) consider(camera);
  return first;
}

}  // namespace kitti
}  // namespace inekf_semantic_mapping
