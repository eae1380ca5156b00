#include "inekf_semantic_mapping/kitti/raw_drive.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <stdexcept>

#include "inekf_semantic_mapping/kitti/errors.h"
#include "inekf_semantic_mapping/kitti/timestamps.h"

namespace inekf_semantic_mapping {
namespace kitti {
namespace fs = std::filesystem;

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

  oxts_ = readSensorStream(drive_dir_ + "/oxts", "oxts");
  velodyne_ = readSensorStream(drive_dir_ + "/velodyne_points", "velodyne_points");
  for (int i = 0; i < kNumCameras; ++i) {
    char name[16];
    std::snprintf(name, sizeof(name), "image_%02d", i);
    cameras_[i] = readSensorStream(drive_dir_ + "/" + name, name);
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

const SensorStream& RawDrive::camera(int index) const {
  if (index < 0 || index >= kNumCameras) {
    throw std::out_of_range("RawDrive::camera: index " + std::to_string(index));
  }
  return cameras_[index];
}

std::vector<OxtsFrame> RawDrive::readOxts() const {
  if (!oxts_.present) throw KittiFormatError(drive_dir_, "drive has no oxts/ folder");
  return readOxtsFrames(oxts_);
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
  if (!hasCalibration()) missing.push_back("calibration (" + calibrationProblem() + ")");
  return missing;
}

std::string RawDrive::calibrationProblem() const {
  if (hasCalibration()) return "";
  // Which of the three files, where some are there (a drive written without one had been
  // reported as having none).
  const std::vector<std::string> files = missingRawCalibrationFiles(calibration_search_dir_);
  std::string which = "no calib_*.txt";
  if (files.size() < 3) {
    which.clear();
    for (const std::string& file : files) which += (which.empty() ? "" : ", ") + file + " missing";
  }
  return which + " in " + calibration_search_dir_;
}

void RawDrive::requireCalibrationFor(bool velodyne, bool camera, const std::string& calib_option,
                                     const std::string& leave_out) const {
  if (hasCalibration()) return;
  std::vector<std::string> parts;
  if (velodyne && hasVelodyne()) parts.push_back("velodyne_points/");
  if (camera && hasCamera(2)) parts.push_back("image_02/");
  if (parts.empty()) return;
  const std::string what = parts.size() == 2 ? parts[0] + " and " + parts[1] : parts[0];
  std::string message = what + " need" + (parts.size() == 2 ? "" : "s") +
                        " the calibration to be placed, and there is none (" +
                        calibrationProblem() + "): give the drive's date folder with " +
                        calib_option;
  if (!leave_out.empty()) {
    message +=
        std::string(", or leave ") + (parts.size() == 2 ? "them" : "it") + " out with " + leave_out;
  }
  throw KittiFormatError(drive_dir_, message);
}

std::vector<std::string> RawDrive::frameWarnings() const {
  std::vector<std::string> warnings = oxts_.warnings;
  warnings.insert(warnings.end(), velodyne_.warnings.begin(), velodyne_.warnings.end());
  for (const SensorStream& camera : cameras_) {
    warnings.insert(warnings.end(), camera.warnings.begin(), camera.warnings.end());
  }
  return warnings;
}

std::vector<std::string> RawDrive::stampWarnings() const {
  std::vector<std::string> warnings;
  const auto check = [&warnings](const SensorStream& stream) {
    if (!stream.present) return;
    for (std::string& warning : timestampWarnings(stream.stamps_ns, stream.dir + "/timestamps.txt",
                                                  1.0, 5, stream.file_numbers)) {
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
