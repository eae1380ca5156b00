// A small synthetic KITTI raw drive that the conversion and kitti2bag tests write themselves:
// five frames of OXTS records with known values, velodyne scans, image_02 and the calibration.
#pragma once

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/kitti/oxts.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace test_drive {

namespace fs = std::filesystem;

using test::writeFile;

inline kitti::OxtsRecord recordAt(int frame) {
  kitti::OxtsRecord r;
  r.lat = 49.0 + 1e-5 * frame;
  r.lon = 8.4 + 2e-5 * frame;
  r.alt = 100.0 + 0.1 * frame;
  r.roll = 0.01;
  r.pitch = -0.02;
  r.yaw = 0.5 + 0.01 * frame;
  r.vn = 1.0;
  r.ve = 2.0;
  r.vu = 0.1;
  r.ax = 0.3 + frame;  // distinct from af below, so a swap is caught
  r.ay = -0.2;
  r.az = 9.8;
  r.af = -7.0;
  r.wx = 0.01;
  r.wy = 0.02;
  r.wz = 0.03 * frame;
  r.wf = -5.0;
  r.pos_accuracy = 0.05;
  r.numsats = 8;
  r.posmode = frame == 2 ? 0 : 5;  // frame 2 has no GPS solution
  return r;
}

inline std::string oxtsLine(const kitti::OxtsRecord& r) {
  char line[1024];
  std::snprintf(line, sizeof(line),
                "%.12f %.12f %.6f %.6f %.6f %.6f %.6f %.6f 0 0 %.6f %.6f %.6f %.6f %.6f 0 0 "
                "%.6f %.6f %.6f %.6f 0 0 %.6f 0.01 4 %d %d 5 5",
                r.lat, r.lon, r.alt, r.roll, r.pitch, r.yaw, r.vn, r.ve, r.vu, r.ax, r.ay, r.az,
                r.af, r.wx, r.wy, r.wz, r.wf, r.pos_accuracy, r.numsats, r.posmode);
  return line;
}

// A 3-ring "scan" sweeping counter-clockwise from the front, as the HDL-64E writes it.
inline std::vector<float> syntheticScan() {
  std::vector<float> xyzi;
  for (int ring = 0; ring < 3; ++ring) {
    for (int k = 0; k < 36; ++k) {
      const double azimuth = (k * 10.0 + 1.0) * M_PI / 180.0;  // 1 .. 351 deg
      const double elevation = (2.0 - 2.0 * ring) * M_PI / 180.0;
      xyzi.insert(xyzi.end(), {static_cast<float>(10 * std::cos(azimuth)),
                               static_cast<float>(10 * std::sin(azimuth)),
                               static_cast<float>(10 * std::tan(elevation)), 0.25f * ring});
    }
  }
  return xyzi;
}

// <tmp>/2011_01_01/2011_01_01_drive_0001_sync with 5 OXTS frames, 5 scans, 5 images and the
// three calibration files in the date folder.
inline std::string writeSyntheticDrive() {
  const std::string date_dir = test::makeTempDir("kitti_conv") + "/2011_01_01";
  const std::string drive = date_dir + "/2011_01_01_drive_0001_sync";
  std::string stamps;
  for (int i = 0; i < 5; ++i) {
    char name[32], stamp[64];
    std::snprintf(name, sizeof(name), "/data/%010d", i);
    std::snprintf(stamp, sizeof(stamp), "2011-01-01 10:00:00.%09d\n", 100000000 * i + 5);
    stamps += stamp;
    writeFile(drive + "/oxts" + name + ".txt", oxtsLine(recordAt(i)) + "\n");
    const std::vector<float> scan = syntheticScan();
    writeFile(drive + "/velodyne_points" + name + ".bin",
              std::string(reinterpret_cast<const char*>(scan.data()), scan.size() * 4));
    fs::create_directories(drive + "/image_02/data");
    cv::Mat image(30, 40, CV_8UC3, cv::Scalar(10, 20, 30 + i));
    cv::imwrite(drive + "/image_02" + name + ".png", image);
  }
  for (const char* sensor : {"oxts", "velodyne_points", "image_02"}) {
    writeFile(drive + "/" + sensor + "/timestamps.txt", stamps);
  }
  writeFile(date_dir + "/calib_imu_to_velo.txt",
            "calib_time: x\nR: 1 0 0 0 1 0 0 0 1\nT: -0.8 0.3 -0.8\n");
  writeFile(date_dir + "/calib_velo_to_cam.txt",
            "calib_time: x\nR: 0 -1 0 0 0 -1 1 0 0\nT: 0 -0.08 -0.27\n");
  std::string cam;
  for (int i = 0; i < 4; ++i) {
    const std::string s = "_0" + std::to_string(i) + ": ";
    const double fx_tx = i == 2 ? 40.0 : 0.0;  // camera 2 sits 0.1 m left of cam0 (fx = 400)
    cam += "S" + s + "40 30\nK" + s + "400 0 20 0 400 15 0 0 1\nD" + s + "0 0 0 0 0\n";
    cam += "R" + s + "1 0 0 0 1 0 0 0 1\nT" + s + "0 0 0\nS_rect" + s + "40 30\n";
    cam += "R_rect" + s + "1 0 0 0 1 0 0 0 1\n";
    cam += "P_rect" + s + "400 0 20 " + std::to_string(fx_tx) + " 0 400 15 0 0 0 1 0\n";
  }
  writeFile(date_dir + "/calib_cam_to_cam.txt", "calib_time: x\ncorner_dist: 0.1\n" + cam);
  return drive;
}

}  // namespace test_drive
}  // namespace inekf_semantic_mapping
