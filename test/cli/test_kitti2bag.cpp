// kitti2bag end to end on a small synthetic drive written by the test (oxts + velodyne + image_02 +
// calibration): every sensor in the bag, consistent stamps and frames; bad arguments, a missing
// drive and a full disk fail cleanly.
#include <gtest/gtest.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <sys/wait.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_msgs/TFMessage.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>

#include "inekf_semantic_mapping/kitti/errors.h"
#include "inekf_semantic_mapping/ros/kitti_conversions.h"
#include "inekf_semantic_mapping/ros/names.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {
namespace {

namespace fs = std::filesystem;

void writeFile(const std::string& path, const std::string& content) {
  fs::create_directories(fs::path(path).parent_path());
  std::ofstream(path, std::ios::binary) << content;
}

kitti::OxtsRecord recordAt(int frame) {
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

std::string oxtsLine(const kitti::OxtsRecord& r) {
  char line[1024];
  std::snprintf(line, sizeof(line),
                "%.12f %.12f %.6f %.6f %.6f %.6f %.6f %.6f 0 0 %.6f %.6f %.6f %.6f %.6f 0 0 "
                "%.6f %.6f %.6f %.6f 0 0 %.6f 0.01 4 %d %d 5 5",
                r.lat, r.lon, r.alt, r.roll, r.pitch, r.yaw, r.vn, r.ve, r.vu, r.ax, r.ay, r.az,
                r.af, r.wx, r.wy, r.wz, r.wf, r.pos_accuracy, r.numsats, r.posmode);
  return line;
}

// A 3-ring "scan" sweeping counter-clockwise from the front, as the HDL-64E writes it.
std::vector<float> syntheticScan() {
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
std::string writeSyntheticDrive() {
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

TEST(KittiConversions, Kitti2bagWritesEverySensorConsistently) {
  const std::string drive = writeSyntheticDrive();
  const std::string bag_path = fs::path(drive).parent_path().string() + "/out.bag";
  const std::string command = std::string(KITTI2BAG_PATH) + " --drive " + drive + " --output " +
                              bag_path + " --gps-every 2 2>/dev/null";
  ASSERT_EQ(std::system(command.c_str()), 0) << command;
  EXPECT_FALSE(fs::exists(bag_path + ".partial"));

  rosbag::Bag bag(bag_path, rosbag::bagmode::Read);
  rosbag::View view(bag);
  std::map<std::string, int> counts;
  std::map<std::string, ros::Time> last_stamp;
  std::vector<sensor_msgs::NavSatFix> fixes;
  for (const rosbag::MessageInstance& m : view) {
    ++counts[m.getTopic()];
    EXPECT_GE(m.getTime(), last_stamp[m.getTopic()]) << m.getTopic();
    last_stamp[m.getTopic()] = m.getTime();
    if (m.getTopic() == "/tf_static") {
      const auto header = m.getConnectionHeader();
      ASSERT_TRUE(header);
      EXPECT_EQ(header->at("latching"), "1");
      const auto tf = m.instantiate<tf2_msgs::TFMessage>();
      ASSERT_TRUE(tf);
      // base->imu, imu->velo, velo->4 cameras.
      EXPECT_EQ(tf->transforms.size(), 6u);
    } else if (m.getTopic() == bag_topics::kImu) {
      const auto imu = m.instantiate<sensor_msgs::Imu>();
      const int frame = static_cast<int>(
          std::lround((imu->header.stamp.toSec() - ros::Time(1293876000, 5).toSec()) / 0.1));
      EXPECT_NEAR(imu->linear_acceleration.x, recordAt(frame).ax, 1e-6) << frame;
      EXPECT_EQ(imu->header.stamp, m.getTime());
    } else if (m.getTopic() == bag_topics::kGpsFix) {
      fixes.push_back(*m.instantiate<sensor_msgs::NavSatFix>());
    } else if (m.getTopic() == bag_topics::kVelodyne) {
      const auto cloud = m.instantiate<sensor_msgs::PointCloud2>();
      EXPECT_EQ(cloud->width, 108u);
    } else if (m.getTopic() == bag_topics::kCameraColorLeftImage) {
      const auto image = m.instantiate<sensor_msgs::Image>();
      EXPECT_EQ(image->encoding, "bgr8");
      EXPECT_EQ(image->width, 40u);
      EXPECT_EQ(image->height, 30u);
      EXPECT_EQ(image->header.frame_id, frames::kCameraColorLeft);
    } else if (m.getTopic() == bag_topics::kCameraColorLeftInfo) {
      const auto info = m.instantiate<sensor_msgs::CameraInfo>();
      EXPECT_EQ(info->P[0], 400);
      EXPECT_EQ(info->P[3], 0);  // the baseline is in the tf
      EXPECT_EQ(info->width, 40u);
    }
  }
  EXPECT_EQ(counts["/tf_static"], 1);
  EXPECT_EQ(counts[bag_topics::kImu], 5);
  EXPECT_EQ(counts[bag_topics::kGroundTruthOdometry], 5);
  EXPECT_EQ(counts[bag_topics::kGpsVelocity], 5);
  EXPECT_EQ(counts[bag_topics::kVelodyne], 5);
  EXPECT_EQ(counts[bag_topics::kCameraColorLeftImage], 5);
  EXPECT_EQ(counts[bag_topics::kCameraColorLeftInfo], 5);
  // --gps-every 2: frames 0, 2, 4; frame 2 has posmode 0 -> NO_FIX.
  ASSERT_EQ(fixes.size(), 3u);
  EXPECT_EQ(fixes[0].status.status, sensor_msgs::NavSatStatus::STATUS_GBAS_FIX);
  EXPECT_EQ(fixes[1].status.status, sensor_msgs::NavSatStatus::STATUS_NO_FIX);
  EXPECT_NEAR(fixes[2].latitude, recordAt(4).lat, 1e-10);
  bag.close();

  // Bad arguments and a missing drive fail with a message and leave no output behind.
  EXPECT_NE(std::system((std::string(KITTI2BAG_PATH) + " --drive /nonexistent --output " +
                         bag_path + ".2 2>/dev/null")
                            .c_str()),
            0);
  EXPECT_FALSE(fs::exists(bag_path + ".2"));
  EXPECT_FALSE(fs::exists(bag_path + ".2.partial"));
  EXPECT_NE(std::system((std::string(KITTI2BAG_PATH) + " --drive " + drive + " --output " +
                         bag_path + ".3 --gps-outage 5 2>/dev/null")
                            .c_str()),
            0);
  // A full disk (simulated with a file size limit) fails cleanly, naming the output, instead of
  // aborting inside rosbag's destructor; no partial bag stays behind.
  const std::string full_disk = "bash -c 'trap \"\" XFSZ; ulimit -f 64; " +
                                std::string(KITTI2BAG_PATH) + " --drive " + drive + " --output " +
                                bag_path + ".4 2>" + bag_path + ".4.log'";
  const int status = std::system(full_disk.c_str());
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 1) << "status " << status;
  EXPECT_FALSE(fs::exists(bag_path + ".4"));
  EXPECT_FALSE(fs::exists(bag_path + ".4.partial"));
  std::ifstream log(bag_path + ".4.log");
  const std::string message((std::istreambuf_iterator<char>(log)),
                            std::istreambuf_iterator<char>());
  EXPECT_NE(message.find("cannot write " + bag_path + ".4"), std::string::npos) << message;
  fs::remove_all(fs::path(drive).parent_path().parent_path());
}

}  // namespace
}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
