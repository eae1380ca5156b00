// KITTI calibration files: the raw-data date folder (calib_cam_to_cam.txt, calib_imu_to_velo.txt,
// calib_velo_to_cam.txt) and the object/odometry benchmark calib.txt.
//
// Conventions (the devkit's): T_a_b maps points from frame b into frame a (x_a = T_a_b * x_b).
// A velodyne point projects into rectified camera i as
//   pixel ~ P_rect_i * [R_rect_00 * (T_cam0_velo * x_velo); 1]
// R_rect_00 (not R_rect_i) is used for every camera: all rectified images share the rectified
// cam0 orientation, and P_rect_i carries camera i's baseline in its 4th column.
#pragma once

#include <Eigen/Geometry>
#include <array>
#include <string>
#include <vector>

namespace inekf_semantic_mapping {
namespace kitti {

// What a projection needs, whatever file it came from.
struct CameraProjection {
  Eigen::Matrix<double, 3, 4> P_rect = Eigen::Matrix<double, 3, 4>::Zero();
  Eigen::Matrix3d R_rect = Eigen::Matrix3d::Identity();
  Eigen::Isometry3d T_cam0_velo = Eigen::Isometry3d::Identity();  // velodyne -> unrectified cam0
  int width = 0, height = 0;  // rectified image size (0 when unknown)

  // Homogeneous image point (u*w, v*w, w) of a velodyne point; w <= 0 means behind the camera.
  Eigen::Vector3d projectHomogeneous(const Eigen::Vector3d& x_velo) const {
    const Eigen::Vector3d x_rect = R_rect * (T_cam0_velo * x_velo);
    return P_rect * x_rect.homogeneous();
  }
  // Pose of the rectified camera-i optical frame (origin at camera i's optical centre, axes of
  // rectified cam0: x right, y down, z forward) relative to the velodyne: T_cami_velo.
  // P_rect = K [I | b] with b = K^-1 P_rect.col(3), so x_cami = x_rect0 + b.
  Eigen::Isometry3d T_rectified_camera_velo() const;
  // K of the rectified image (the left 3x3 block of P_rect).
  Eigen::Matrix3d rectifiedIntrinsics() const { return P_rect.leftCols<3>(); }
  // Throws KittiFormatError naming image_path unless a width x height image is the rectified
  // size stated (unchecked when none is): projected with P_rect, another image (an _extract
  // drive's unrectified 1392x512) is labelled from the wrong pixels, with no error.
  void checkRectifiedImageSize(const std::string& image_path, int image_width,
                               int image_height) const;
};

// One camera of calib_cam_to_cam.txt (suffix _00.._03).
struct CameraCalibration {
  bool present = false;
  Eigen::Vector2d S = Eigen::Vector2d::Zero();      // image size before rectification (w, h)
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();  // intrinsics before rectification
  Eigen::Matrix<double, 5, 1> D = Eigen::Matrix<double, 5, 1>::Zero();  // distortion
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();       // rotation cam0 -> this camera
  Eigen::Vector3d T = Eigen::Vector3d::Zero();           // translation cam0 -> this camera
  Eigen::Vector2d S_rect = Eigen::Vector2d::Zero();      // image size after rectification (w, h)
  Eigen::Matrix3d R_rect = Eigen::Matrix3d::Identity();  // rectifying rotation
  Eigen::Matrix<double, 3, 4> P_rect = Eigen::Matrix<double, 3, 4>::Zero();  // after rectif.
};

struct RawCalibration {
  Eigen::Isometry3d T_velo_imu = Eigen::Isometry3d::Identity();   // calib_imu_to_velo.txt
  Eigen::Isometry3d T_cam0_velo = Eigen::Isometry3d::Identity();  // calib_velo_to_cam.txt
  std::array<CameraCalibration, 4> cameras;                       // calib_cam_to_cam.txt
  std::string cam_to_cam_path;  // where the cameras were read (named when one is missing)

  // P_rect_i, R_rect_00, T_cam0_velo, size S_rect_i. Throws std::out_of_range for a bad index
  // or a camera absent from the file.
  CameraProjection projection(int camera_index) const;
};

// Reads the three raw calibration files of a date folder ("calib_time:" and other unknown keys
// are ignored). Throws KittiFormatError naming the file (and line) when a file is missing or a
// required key is missing/malformed.
RawCalibration readRawCalibration(const std::string& date_dir);

// True when all three raw calibration files exist in dir.
bool hasRawCalibration(const std::string& dir);
// The raw calibration files (calib_cam_to_cam.txt, calib_imu_to_velo.txt,
// calib_velo_to_cam.txt) that dir lacks.
std::vector<std::string> missingRawCalibrationFiles(const std::string& dir);

// Object benchmark calib/%06d.txt (P0..P3, R0_rect, Tr_velo_to_cam, Tr_imu_to_velo) or the
// odometry/SemanticKITTI calib.txt (P0..P3, Tr = velo -> cam0, no R0_rect -> identity).
struct ObjectCalibration {
  std::array<Eigen::Matrix<double, 3, 4>, 4> P;
  Eigen::Matrix3d R0_rect = Eigen::Matrix3d::Identity();
  Eigen::Isometry3d Tr_velo_to_cam = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d Tr_imu_to_velo = Eigen::Isometry3d::Identity();
  bool has_imu_to_velo = false;

  CameraProjection projection(int camera_index, int width, int height) const;
};

ObjectCalibration readObjectCalibration(const std::string& calib_txt);

}  // namespace kitti
}  // namespace inekf_semantic_mapping
