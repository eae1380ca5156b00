#include "inekf_semantic_mapping/ros/kitti_conversions.h"

#include <cv_bridge/cv_bridge.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <tf2_eigen/tf2_eigen.h>

#include <cmath>
#include <ctime>
#include <opencv2/imgcodecs.hpp>
#include <stdexcept>
#include <string>
#include <utility>

#include "inekf_semantic_mapping/kitti/errors.h"
#include "inekf_semantic_mapping/ros/names.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

namespace {

constexpr std::int64_t kMaxRosTimeNs = 4294967295LL * 1000000000LL + 999999999LL;

// "2106-02-08" for a stamp, for messages: the day (UTC) of a nanosecond stamp.
std::string utcDay(std::int64_t stamp_ns) {
  const std::time_t seconds = static_cast<std::time_t>(stamp_ns / 1000000000LL);
  std::tm day{};
  if (!gmtime_r(&seconds, &day)) return std::to_string(stamp_ns) + " ns";
  char text[32];
  std::strftime(text, sizeof(text), "%Y-%m-%d", &day);
  return text;
}

}  // namespace

bool fitsRosTime(std::int64_t stamp_ns) { return stamp_ns >= 0 && stamp_ns <= kMaxRosTimeNs; }

ros::Time toRosTime(std::int64_t stamp_ns) {
  if (!fitsRosTime(stamp_ns)) {
    throw std::out_of_range("stamp " + utcDay(stamp_ns) +
                            " is outside ROS time (1970-01-01 to 2106-02-07)");
  }
  ros::Time time;
  time.fromNSec(static_cast<std::uint64_t>(stamp_ns));
  return time;
}

void checkTimelineFitsRosTime(const std::string& drive_dir, std::int64_t first_stamp_ns,
                              std::int64_t last_stamp_ns) {
  for (const std::int64_t stamp_ns : {first_stamp_ns, last_stamp_ns}) {
    if (!fitsRosTime(stamp_ns)) {
      throw std::out_of_range(drive_dir + ": timestamps.txt holds " + utcDay(stamp_ns) +
                              ", outside what ROS time can hold (1970-01-01 to 2106-02-07)");
    }
  }
}

sensor_msgs::Imu toImuMessage(const kitti::OxtsRecord& r, const ros::Time& stamp,
                              const OxtsImuNoise& noise) {
  sensor_msgs::Imu msg;
  msg.header.stamp = stamp;
  msg.header.frame_id = frames::kImu;
  const Eigen::Quaterniond q(kitti::rotationFromRollPitchYaw(r.roll, r.pitch, r.yaw));
  msg.orientation = tf2::toMsg(q.normalized());
  msg.angular_velocity.x = r.wx;
  msg.angular_velocity.y = r.wy;
  msg.angular_velocity.z = r.wz;
  msg.linear_acceleration.x = r.ax;
  msg.linear_acceleration.y = r.ay;
  msg.linear_acceleration.z = r.az;
  const double rp = noise.roll_pitch_rad * noise.roll_pitch_rad;
  msg.orientation_covariance = {rp, 0, 0, 0, rp, 0, 0, 0, noise.yaw_rad * noise.yaw_rad};
  // A frame without an INS solution (attitude and velocity columns all zero) has no
  // orientation: sensor_msgs/Imu says so with -1, and inekf_node then levels from gravity.
  if (!kitti::carriesAttitude(r)) msg.orientation_covariance[0] = -1.0;
  const double g = noise.gyro_rad_s * noise.gyro_rad_s;
  msg.angular_velocity_covariance = {g, 0, 0, 0, g, 0, 0, 0, g};
  const double a = noise.accel_m_s2 * noise.accel_m_s2;
  msg.linear_acceleration_covariance = {a, 0, 0, 0, a, 0, 0, 0, a};
  return msg;
}

std::int8_t navSatStatusFromOxts(const kitti::OxtsRecord& r) {
  using Status = sensor_msgs::NavSatStatus;
  if (r.posmode <= 0 || r.numsats < 4) return Status::STATUS_NO_FIX;
  if (r.posmode <= 3) return Status::STATUS_FIX;
  if (r.posmode == 4) return Status::STATUS_SBAS_FIX;
  return Status::STATUS_GBAS_FIX;
}

sensor_msgs::NavSatFix toNavSatFixMessage(const kitti::OxtsRecord& r,
                                          const std::optional<kitti::GeodeticFix>& fix,
                                          const ros::Time& stamp) {
  sensor_msgs::NavSatFix msg;
  msg.header.stamp = stamp;
  msg.header.frame_id = frames::kImu;  // the antenna offset is not in the KITTI calibration
  msg.status.service = sensor_msgs::NavSatStatus::SERVICE_GPS;
  if (fix) {
    msg.status.status = navSatStatusFromOxts(r);
    msg.latitude = fix->lat_deg;
    msg.longitude = fix->lon_deg;
    msg.altitude = fix->alt_m;
    const double h = fix->sigma_horizontal_m * fix->sigma_horizontal_m;
    const double v = fix->sigma_vertical_m * fix->sigma_vertical_m;
    msg.position_covariance = {h, 0, 0, 0, h, 0, 0, 0, v};
    msg.position_covariance_type = sensor_msgs::NavSatFix::COVARIANCE_TYPE_DIAGONAL_KNOWN;
  } else {
    msg.status.status = sensor_msgs::NavSatStatus::STATUS_NO_FIX;
    msg.latitude = r.lat;
    msg.longitude = r.lon;
    msg.altitude = r.alt;
    msg.position_covariance_type = sensor_msgs::NavSatFix::COVARIANCE_TYPE_UNKNOWN;
  }
  return msg;
}

geometry_msgs::TwistStamped toGpsVelocityMessage(const kitti::OxtsRecord& r,
                                                 const ros::Time& stamp) {
  geometry_msgs::TwistStamped msg;
  msg.header.stamp = stamp;
  msg.header.frame_id = frames::kMap;
  msg.twist.linear.x = r.ve;
  msg.twist.linear.y = r.vn;
  msg.twist.linear.z = r.vu;
  return msg;
}

nav_msgs::Odometry toGroundTruthMessage(const kitti::OxtsRecord& r,
                                        const kitti::MercatorProjection& projection,
                                        const ros::Time& stamp) {
  nav_msgs::Odometry msg;
  msg.header.stamp = stamp;
  msg.header.frame_id = frames::kMap;
  msg.child_frame_id = frames::kBaseLink;
  const Eigen::Isometry3d pose = projection.poseInMap(r);
  msg.pose.pose = tf2::toMsg(pose);
  const Eigen::Vector3d velocity_body =
      pose.linear().transpose() * Eigen::Vector3d(r.ve, r.vn, r.vu);
  msg.twist.twist.linear.x = velocity_body.x();
  msg.twist.twist.linear.y = velocity_body.y();
  msg.twist.twist.linear.z = velocity_body.z();
  msg.twist.twist.angular.x = r.wx;
  msg.twist.twist.angular.y = r.wy;
  msg.twist.twist.angular.z = r.wz;
  const double p = r.pos_accuracy * r.pos_accuracy;
  for (int i = 0; i < 3; ++i) msg.pose.covariance[7 * i] = p;
  return msg;
}

sensor_msgs::PointCloud2 toPointCloudMessage(const kitti::VelodyneScan& scan,
                                             const ros::Time& stamp) {
  sensor_msgs::PointCloud2 msg;
  msg.header.stamp = stamp;
  msg.header.frame_id = frames::kVelodyne;
  sensor_msgs::PointCloud2Modifier modifier(msg);
  modifier.setPointCloud2Fields(
      5, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1, sensor_msgs::PointField::FLOAT32, "z", 1,
      sensor_msgs::PointField::FLOAT32, "intensity", 1, sensor_msgs::PointField::FLOAT32, "ring", 1,
      sensor_msgs::PointField::UINT16);
  modifier.resize(scan.size());
  msg.height = 1;
  msg.width = static_cast<std::uint32_t>(scan.size());
  // Dense means every point is finite (PCL then skips its own checks): said only when true.
  msg.is_dense = true;
  const std::vector<std::uint16_t> rings = kitti::computeRings(scan);
  sensor_msgs::PointCloud2Iterator<float> x(msg, "x"), y(msg, "y"), z(msg, "z"),
      intensity(msg, "intensity");
  sensor_msgs::PointCloud2Iterator<std::uint16_t> ring(msg, "ring");
  for (std::size_t i = 0; i < scan.size(); ++i, ++x, ++y, ++z, ++intensity, ++ring) {
    const float* p = scan.point(i);
    *x = p[0];
    *y = p[1];
    *z = p[2];
    *intensity = p[3];
    *ring = rings[i];
    if (!(std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]))) msg.is_dense = false;
  }
  return msg;
}

sensor_msgs::CameraInfo toCameraInfoMessage(const kitti::CameraProjection& projection,
                                            const std::string& frame_id, const ros::Time& stamp) {
  sensor_msgs::CameraInfo msg;
  msg.header.stamp = stamp;
  msg.header.frame_id = frame_id;
  msg.width = static_cast<std::uint32_t>(projection.width);
  msg.height = static_cast<std::uint32_t>(projection.height);
  msg.distortion_model = "plumb_bob";
  msg.D.assign(5, 0.0);  // rectified image
  const Eigen::Matrix3d K = projection.rectifiedIntrinsics();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      msg.K[3 * r + c] = K(r, c);
      msg.R[3 * r + c] = r == c ? 1.0 : 0.0;
      msg.P[4 * r + c] = K(r, c);
    }
    msg.P[4 * r + 3] = 0.0;  // the baseline lives in the tf (see the header)
  }
  return msg;
}

sensor_msgs::Image readImageMessage(const std::string& png_path, bool color,
                                    const std::string& frame_id, const ros::Time& stamp) {
  const cv::Mat image = cv::imread(png_path, color ? cv::IMREAD_COLOR : cv::IMREAD_GRAYSCALE);
  if (image.empty()) throw kitti::KittiFormatError(png_path, "cannot read image");
  std_msgs::Header header;
  header.stamp = stamp;
  header.frame_id = frame_id;
  sensor_msgs::Image msg;
  cv_bridge::CvImage(header, color ? "bgr8" : "mono8", image).toImageMsg(msg);
  return msg;
}

const char* cameraFrameId(int camera_index) {
  switch (camera_index) {
    case 0:
      return frames::kCameraGrayLeft;
    case 1:
      return frames::kCameraGrayRight;
    case 2:
      return frames::kCameraColorLeft;
    case 3:
      return frames::kCameraColorRight;
  }
  throw std::out_of_range("camera index " + std::to_string(camera_index));
}

geometry_msgs::TransformStamped toTransformMessage(const Eigen::Isometry3d& T_parent_child,
                                                   const std::string& parent,
                                                   const std::string& child,
                                                   const ros::Time& stamp) {
  geometry_msgs::TransformStamped msg = tf2::eigenToTransform(T_parent_child);
  msg.header.stamp = stamp;
  msg.header.frame_id = parent;
  msg.child_frame_id = child;
  return msg;
}

std::vector<geometry_msgs::TransformStamped> staticTransforms(
    const std::optional<kitti::RawCalibration>& calibration, const ros::Time& stamp) {
  std::vector<geometry_msgs::TransformStamped> transforms;
  transforms.push_back(
      toTransformMessage(Eigen::Isometry3d::Identity(), frames::kBaseLink, frames::kImu, stamp));
  if (!calibration) return transforms;
  transforms.push_back(toTransformMessage(calibration->T_velo_imu.inverse(), frames::kImu,
                                          frames::kVelodyne, stamp));
  for (int i = 0; i < kitti::RawDrive::kNumCameras; ++i) {
    if (!calibration->cameras[i].present) continue;
    const Eigen::Isometry3d T_cam_velo = calibration->projection(i).T_rectified_camera_velo();
    transforms.push_back(
        toTransformMessage(T_cam_velo.inverse(), frames::kVelodyne, cameraFrameId(i), stamp));
  }
  return transforms;
}

DriveMessageFactory::DriveMessageFactory(const kitti::RawDrive& drive,
                                         kitti::GpsDegradationOptions gps_options)
    : drive_(drive), gps_options_(std::move(gps_options)) {
  if (drive_.hasOxts()) {
    oxts_frames_ = drive_.readOxts();
    if (!oxts_frames_.empty()) {
      projection_ = kitti::MercatorProjection::atFirstFix(oxts_frames_.front().record);
    }
  }
  if (drive_.hasCalibration()) calibration_ = drive_.readCalibration();
  restart();
}

void DriveMessageFactory::restart() {
  degrader_ = std::make_unique<kitti::GpsDegrader>(gps_options_);
}

OxtsMessages DriveMessageFactory::oxtsMessages(std::size_t frame) {
  const kitti::OxtsFrame& oxts = oxts_frames_.at(frame);
  const ros::Time stamp = toRosTime(oxts.stamp_ns);
  OxtsMessages messages;
  messages.imu = toImuMessage(oxts.record, stamp);
  // Frames the lower GPS rate drops produce no message; the others a fix or a NO_FIX status.
  if (frame % static_cast<std::size_t>(gps_options_.every_n_frames) == 0) {
    const double seconds = kitti::secondsBetween(oxts_frames_.front().stamp_ns, oxts.stamp_ns);
    messages.gps_fix =
        toNavSatFixMessage(oxts.record, degrader_->degrade(frame, seconds, oxts.record), stamp);
  }
  messages.gps_velocity = toGpsVelocityMessage(oxts.record, stamp);
  messages.ground_truth = toGroundTruthMessage(oxts.record, *projection_, stamp);
  return messages;
}

sensor_msgs::PointCloud2 DriveMessageFactory::velodyneMessage(std::size_t frame) const {
  const kitti::SensorStream& velodyne = drive_.velodyne();
  return toPointCloudMessage(kitti::readVelodyneScan(velodyne.framePath(frame)),
                             toRosTime(velodyne.stamps_ns.at(frame)));
}

std::pair<sensor_msgs::Image, sensor_msgs::CameraInfo> DriveMessageFactory::cameraMessages(
    int camera_index, std::size_t frame) const {
  if (!calibration_) throw std::logic_error("camera messages need the calibration");
  const kitti::SensorStream& camera = drive_.camera(camera_index);
  const ros::Time stamp = toRosTime(camera.stamps_ns.at(frame));
  const char* frame_id = cameraFrameId(camera_index);
  const bool color = camera_index >= 2;
  const kitti::CameraProjection projection = calibration_->projection(camera_index);
  const std::string path = camera.framePath(frame);
  sensor_msgs::Image image = readImageMessage(path, color, frame_id, stamp);
  // Its camera_info says the calibration's size: an image of another size would be projected
  // with the wrong intrinsics by everything downstream.
  projection.checkRectifiedImageSize(path, static_cast<int>(image.width),
                                     static_cast<int>(image.height));
  return {std::move(image), toCameraInfoMessage(projection, frame_id, stamp)};
}

void DriveMessageFactory::checkCameraImageSize(int camera_index) const {
  if (!calibration_) throw std::logic_error("camera messages need the calibration");
  const kitti::SensorStream& camera = drive_.camera(camera_index);
  const kitti::CameraProjection projection = calibration_->projection(camera_index);
  for (std::size_t frame = 0; frame < camera.size(); ++frame) {
    const std::string path = camera.framePath(frame);
    const cv::Mat image = cv::imread(path, cv::IMREAD_UNCHANGED);
    if (image.empty()) continue;
    projection.checkRectifiedImageSize(path, image.cols, image.rows);
    return;
  }
}

std::vector<geometry_msgs::TransformStamped> DriveMessageFactory::staticTransformMessages(
    const ros::Time& stamp) const {
  return staticTransforms(calibration_, stamp);
}

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
