// The Python kitti2bag's IMU message, built the way it writes one (orientation from roll, pitch,
// yaw; vectors in the levelled frame), and the small Eigen helpers the convention tests share.
#pragma once

#include <geometry_msgs/Vector3.h>
#include <sensor_msgs/Imu.h>

#include <Eigen/Geometry>

namespace inekf_semantic_mapping {
namespace test_imu {

inline Eigen::Matrix3d rpy(double roll, double pitch, double yaw) {
  return (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

inline Eigen::Vector3d toEigen(const geometry_msgs::Vector3& v) { return {v.x, v.y, v.z}; }

inline void setVector(const Eigen::Vector3d& in, geometry_msgs::Vector3* out) {
  out->x = in.x();
  out->y = in.y();
  out->z = in.z();
}

// An Imu message the way the Python kitti2bag writes it: orientation from roll, pitch, yaw
// (tf quaternion_from_euler, static xyz = Rz Ry Rx), vectors in the levelled frame.
inline sensor_msgs::Imu pythonKitti2bagImu(const Eigen::Matrix3d& R, const Eigen::Vector3d& f_level,
                                           const Eigen::Vector3d& w_level) {
  sensor_msgs::Imu imu;
  imu.header.frame_id = "imu_link";
  const Eigen::Quaterniond q(R);
  imu.orientation.w = q.w();
  imu.orientation.x = q.x();
  imu.orientation.y = q.y();
  imu.orientation.z = q.z();
  setVector(f_level, &imu.linear_acceleration);
  setVector(w_level, &imu.angular_velocity);
  return imu;
}

}  // namespace test_imu
}  // namespace inekf_semantic_mapping
