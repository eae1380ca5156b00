// Calibration files: the odometry/object calib.txt, and the three raw calib_*.txt files (the
// input is split at the first two '\f' into the three files).
#include <filesystem>
#include <fstream>
#include <string>

#include "fuzz_support.h"
#include "inekf_semantic_mapping/kitti/calibration.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  namespace kitti = inekf_semantic_mapping::kitti;
  try {
    kitti::readObjectCalibration(ism_fuzz::writeInput(data, size, "calib.txt"));
  } catch (const std::exception&) {
  }
  const std::string text(reinterpret_cast<const char*>(data), size);
  const std::string dir = "/dev/shm/ism_fuzz_raw_calib_" + std::to_string(::getpid());
  std::filesystem::create_directories(dir);
  const std::size_t first = text.find('\f');
  const std::size_t second = first == std::string::npos ? first : text.find('\f', first + 1);
  std::ofstream(dir + "/calib_cam_to_cam.txt") << text.substr(0, first);
  std::ofstream(dir + "/calib_imu_to_velo.txt")
      << (first == std::string::npos ? "" : text.substr(first + 1, second - first - 1));
  std::ofstream(dir + "/calib_velo_to_cam.txt")
      << (second == std::string::npos ? "" : text.substr(second + 1));
  try {
    const kitti::RawCalibration calib = kitti::readRawCalibration(dir);
    for (int i = 0; i < 4; ++i) {
      if (calib.cameras[i].present) calib.projection(i).T_rectified_camera_velo();
    }
  } catch (const std::exception&) {
  }
  return 0;
}
