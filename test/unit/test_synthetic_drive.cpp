// generateSyntheticDrive: a short drive written to a temp folder and read back with the KITTI
// I/O library (layout, calibration, timestamps, Mercator, IMU, lidar labels, label images).
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <sstream>

#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/kitti/mercator.h"
#include "inekf_semantic_mapping/kitti/oxts.h"
#include "inekf_semantic_mapping/kitti/raw_drive.h"
#include "inekf_semantic_mapping/kitti/timestamps.h"
#include "inekf_semantic_mapping/kitti/velodyne.h"
#include "inekf_semantic_mapping/perception/cityscapes.h"
#include "inekf_semantic_mapping/synthetic/drive_generator.h"
#include "inekf_semantic_mapping/synthetic/route.h"
#include "inekf_semantic_mapping/synthetic/world.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace synthetic {
namespace {
namespace fs = std::filesystem;

constexpr int kWidth = 621, kHeight = 188;

// KITTI 12-number poses, one per line.
std::vector<Eigen::Isometry3d> readPoses(const std::string& path) {
  std::ifstream in(path);
  std::vector<Eigen::Isometry3d> poses;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream fields(line);
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) fields >> T.matrix()(r, c);
    if (fields) poses.push_back(T);
  }
  return poses;
}

class SyntheticDrive : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    output_ = new std::string(test::makeTempDir("synthetic_drive"));
    DriveOptions options;
    options.output_dir = *output_;
    options.seed = 42;
    options.duration_s = 3.0;
    options.image_width = kWidth;
    options.image_height = kHeight;
    options.lidar.azimuth_step_deg = 0.4;  // fewer rays: the test stays fast
    options.imu_noise = ImuNoiseModel::none();
    options.threads = 2;
    summary_ = new DriveSummary(generateSyntheticDrive(options));
  }
  static void TearDownTestSuite() {
    fs::remove_all(*output_);
    delete summary_;
    delete output_;
  }
  static std::string* output_;
  static DriveSummary* summary_;
};
std::string* SyntheticDrive::output_ = nullptr;
DriveSummary* SyntheticDrive::summary_ = nullptr;

TEST_F(SyntheticDrive, HasTheKittiRawLayout) {
  const std::string date_dir = *output_ + "/2011_09_26";
  EXPECT_EQ(summary_->sync_dir, date_dir + "/2011_09_26_drive_0001_sync");
  EXPECT_TRUE(kitti::hasRawCalibration(date_dir));
  const kitti::RawDrive drive(summary_->sync_dir);
  ASSERT_TRUE(drive.hasOxts());
  ASSERT_TRUE(drive.hasVelodyne());
  ASSERT_TRUE(drive.hasCamera(2));
  ASSERT_TRUE(drive.hasCalibration());
  EXPECT_FALSE(drive.isExtract());
  const std::size_t frames = drive.oxts().size();
  EXPECT_GE(frames, 29u);
  EXPECT_LE(frames, 33u);
  EXPECT_EQ(drive.velodyne().size(), frames);
  EXPECT_EQ(drive.velodyne().start_stamps_ns.size(), frames);
  EXPECT_EQ(drive.velodyne().end_stamps_ns.size(), frames);
  EXPECT_EQ(drive.camera(2).size(), frames);
  EXPECT_EQ(drive.readOxts().size(), frames);
  for (std::size_t k = 0; k < frames; ++k) {
    char name[32];
    std::snprintf(name, sizeof(name), "%010zu", k);
    const std::string gt = summary_->sync_dir + "/ground_truth/";
    EXPECT_TRUE(fs::exists(gt + "velodyne_labels/" + name + ".label")) << name;
    EXPECT_TRUE(fs::exists(gt + "image_02_labels/" + name + ".png")) << name;
  }
  EXPECT_EQ(readPoses(summary_->sync_dir + "/ground_truth/poses_imu_map.txt").size(), frames);

  const kitti::RawDrive extract(summary_->extract_dir);
  EXPECT_TRUE(extract.isExtract());
  ASSERT_TRUE(extract.hasOxts());
  EXPECT_GE(extract.oxts().size(), 300u);
  // 100 Hz with sub-millisecond jitter.
  const auto& stamps = extract.oxts().stamps_ns;
  for (std::size_t i = 1; i < stamps.size(); ++i) {
    const double dt = kitti::secondsBetween(stamps[i - 1], stamps[i]);
    ASSERT_GT(dt, 0.0085);
    ASSERT_LT(dt, 0.0115);
  }
}

TEST_F(SyntheticDrive, TimestampsAreIncreasingWithJitterAndSynchronized) {
  const kitti::RawDrive drive(summary_->sync_dir);
  const auto& velo = drive.velodyne().stamps_ns;
  const auto& oxts = drive.oxts().stamps_ns;
  const auto& image = drive.camera(2).stamps_ns;
  double min_dt = 1, max_dt = 0;
  for (std::size_t k = 0; k < velo.size(); ++k) {
    if (k > 0) {
      const double dt = kitti::secondsBetween(velo[k - 1], velo[k]);
      min_dt = std::min(min_dt, dt);
      max_dt = std::max(max_dt, dt);
    }
    // The OXTS frame is the 100 Hz sample nearest the sweep; the camera fires with the sweep.
    EXPECT_LT(std::abs(kitti::secondsBetween(velo[k], oxts[k])), 0.0056);
    const double camera_delay = kitti::secondsBetween(velo[k], image[k]);
    EXPECT_GE(camera_delay, 0.0);
    EXPECT_LT(camera_delay, 0.002);
    EXPECT_LT(drive.velodyne().start_stamps_ns[k], velo[k]);
    EXPECT_GT(drive.velodyne().end_stamps_ns[k], velo[k]);
  }
  EXPECT_GT(min_dt, 0.069);
  EXPECT_LT(max_dt, 0.131);
  EXPECT_GT(max_dt - min_dt, 1e-4);  // not a perfect clock
}

TEST_F(SyntheticDrive, CalibrationRoundTripsTheKittiRig) {
  const kitti::RawCalibration calibration = kitti::readRawCalibration(summary_->date_dir);
  const KittiRig rig = KittiRig::kitti2011_09_26();
  EXPECT_LT((calibration.T_velo_imu.linear() - rig.R_velo_imu).norm(), 1e-6);
  EXPECT_LT((calibration.T_velo_imu.translation() - rig.t_velo_imu).norm(), 1e-9);
  EXPECT_LT((calibration.T_cam0_velo.translation() - rig.t_cam0_velo).norm(), 1e-9);
  const kitti::CameraProjection projection = calibration.projection(2);
  EXPECT_EQ(projection.width, kWidth);
  EXPECT_EQ(projection.height, kHeight);
  EXPECT_LT((projection.P_rect - rig.scaledProjection(2, kWidth, kHeight)).cwiseAbs().maxCoeff(),
            1e-3);
  EXPECT_LT((projection.R_rect - rig.cameras[0].R_rect).norm(), 1e-9);
  // The velodyne sits ~1.73 m above the ground, 0.8 m above the IMU (KITTI rig).
  EXPECT_NEAR(calibration.T_velo_imu.inverse().translation().z(), 0.8, 0.05);
}

TEST_F(SyntheticDrive, MercatorOfTheWrittenFixesGivesTheTruePositions) {
  const kitti::RawDrive drive(summary_->sync_dir);
  const std::vector<kitti::OxtsFrame> frames = drive.readOxts();
  const std::vector<Eigen::Isometry3d> truth =
      readPoses(summary_->sync_dir + "/ground_truth/poses_imu_map.txt");
  ASSERT_EQ(frames.size(), truth.size());
  const kitti::MercatorProjection mercator =
      kitti::MercatorProjection::atFirstFix(frames.front().record);
  double max_position_error = 0, max_rotation_error = 0, travelled = 0;
  for (std::size_t k = 0; k < frames.size(); ++k) {
    const Eigen::Isometry3d T = mercator.poseInMap(frames[k].record);
    max_position_error =
        std::max(max_position_error, (T.translation() - truth[k].translation()).norm());
    max_rotation_error =
        std::max(max_rotation_error, (T.linear() - truth[k].linear()).cwiseAbs().maxCoeff());
    travelled = std::max(travelled, truth[k].translation().norm());
  }
  std::printf("[ figure ] Mercator round trip: max position error %.2e m\n", max_position_error);
  EXPECT_LT(max_position_error, 1e-3);
  EXPECT_LT(max_rotation_error, 1e-9);
  EXPECT_LT(truth.front().translation().norm(), 1e-9);  // the map origin is the first fix
  EXPECT_GT(travelled, 3.0);                            // it drove off
}

TEST_F(SyntheticDrive, IntegratingTheNoiseFreeExtractImuReproducesTheTrajectory) {
  const kitti::RawDrive extract(summary_->extract_dir);
  const std::vector<kitti::OxtsFrame> frames = extract.readOxts();
  const std::vector<Eigen::Isometry3d> truth =
      readPoses(summary_->extract_dir + "/ground_truth/poses_imu_map.txt");
  ASSERT_EQ(frames.size(), truth.size());
  ASSERT_GT(frames.size(), 250u);
  auto body = [](const kitti::OxtsRecord& r, Eigen::Vector3d* f, Eigen::Vector3d* w) {
    *f = {r.ax, r.ay, r.az};
    *w = {r.wx, r.wy, r.wz};
  };
  const Eigen::Vector3d gravity(0, 0, -kGravity);
  Eigen::Matrix3d R = truth[0].linear();
  Eigen::Vector3d p = truth[0].translation();
  Eigen::Vector3d v(frames[0].record.ve, frames[0].record.vn, frames[0].record.vu);
  for (std::size_t i = 0; i + 1 < frames.size(); ++i) {
    const double dt = kitti::secondsBetween(frames[i].stamp_ns, frames[i + 1].stamp_ns);
    Eigen::Vector3d f0, w0, f1, w1;
    body(frames[i].record, &f0, &w0);
    body(frames[i + 1].record, &f1, &w1);
    const Eigen::Vector3d w = 0.5 * (w0 + w1) * dt;
    const Eigen::Matrix3d R_next =
        R * (w.norm() > 1e-15 ? Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix()
                              : Eigen::Matrix3d::Identity());
    const Eigen::Vector3d a0 = R * f0 + gravity, a1 = R_next * f1 + gravity;
    p += v * dt + (a0 / 3 + a1 / 6) * dt * dt;
    v += 0.5 * (a0 + a1) * dt;
    R = R_next;
  }
  std::printf("[ figure ] integrated extract IMU over %.1f s: position error %.2e m\n",
              kitti::secondsBetween(frames.front().stamp_ns, frames.back().stamp_ns),
              (p - truth.back().translation()).norm());
  EXPECT_LT((p - truth.back().translation()).norm(), 0.03);
  EXPECT_LT(Eigen::AngleAxisd(R.transpose() * truth.back().linear()).angle(), 1e-3);
  // The OXTS velocity (vn ve vu) agrees with the integrated one.
  const kitti::OxtsRecord& last = frames.back().record;
  EXPECT_LT((v - Eigen::Vector3d(last.ve, last.vn, last.vu)).norm(), 0.01);
}

TEST_F(SyntheticDrive, LidarPointsLieOnSurfacesOfTheirLabel) {
  const SyntheticWorld world = SyntheticWorld::load(summary_->sync_dir + "/ground_truth/world.txt");
  const kitti::RawDrive drive(summary_->sync_dir);
  const std::vector<Eigen::Isometry3d> T_map_velo =
      readPoses(summary_->sync_dir + "/ground_truth/poses_velodyne_map.txt");
  ASSERT_EQ(T_map_velo.size(), drive.velodyne().size());
  std::size_t points = 0, agree = 0;
  for (std::size_t k = 0; k < drive.velodyne().size(); k += 10) {
    const kitti::VelodyneScan scan = kitti::readVelodyneBin(drive.velodyne().framePath(k));
    char name[32];
    std::snprintf(name, sizeof(name), "%010zu.label", k);
    const std::vector<std::uint32_t> labels =
        kitti::readLabelFile(summary_->sync_dir + "/ground_truth/velodyne_labels/" + name);
    ASSERT_EQ(labels.size(), scan.size());
    ASSERT_GT(scan.size(), 10000u);
    for (std::size_t i = 0; i < scan.size(); ++i) {
      const float* q = scan.point(i);
      const Eigen::Vector3d p_map = T_map_velo[k] * Eigen::Vector3d(q[0], q[1], q[2]);
      ++points;
      if (world.labelAt(p_map, 0.1) == kitti::semanticClass(labels[i])) ++agree;
    }
  }
  std::printf("[ figure ] lidar label = labelAt(point): %.4f of %zu points\n",
              static_cast<double>(agree) / points, points);
  EXPECT_GT(static_cast<double>(agree) / points, 0.99) << agree << " / " << points;
}

TEST_F(SyntheticDrive, ProjectedLidarLabelsAgreeWithTheLabelImages) {
  const SyntheticWorld world = SyntheticWorld::load(summary_->sync_dir + "/ground_truth/world.txt");
  const kitti::RawDrive drive(summary_->sync_dir);
  const kitti::CameraProjection projection = drive.readCalibration().projection(2);
  const std::vector<Eigen::Isometry3d> T_map_velo =
      readPoses(summary_->sync_dir + "/ground_truth/poses_velodyne_map.txt");
  const std::vector<Eigen::Isometry3d> T_map_camera =
      readPoses(summary_->sync_dir + "/ground_truth/poses_image_02_map.txt");
  std::size_t visible = 0, agree = 0, all_in_image = 0;
  std::map<int, int> visible_per_class;
  for (std::size_t k = 0; k < drive.velodyne().size(); k += 7) {
    const kitti::VelodyneScan scan = kitti::readVelodyneBin(drive.velodyne().framePath(k));
    char name[32];
    std::snprintf(name, sizeof(name), "%010zu", k);
    const std::vector<std::uint32_t> labels = kitti::readLabelFile(
        summary_->sync_dir + "/ground_truth/velodyne_labels/" + name + ".label");
    const cv::Mat label_image =
        cv::imread(summary_->sync_dir + "/ground_truth/image_02_labels/" + name + ".png",
                   cv::IMREAD_UNCHANGED);
    ASSERT_EQ(label_image.type(), CV_8UC1);
    ASSERT_EQ(label_image.cols, kWidth);
    const Eigen::Vector3d camera_centre = T_map_camera[k].translation();
    for (std::size_t i = 0; i < scan.size(); ++i) {
      const float* q = scan.point(i);
      const Eigen::Vector3d x_velo(q[0], q[1], q[2]);
      const Eigen::Vector3d h = projection.projectHomogeneous(x_velo);
      if (h.z() <= 0.5) continue;
      const long u = std::lround(h.x() / h.z()), v = std::lround(h.y() / h.z());
      if (u < 0 || v < 0 || u >= kWidth || v >= kHeight) continue;
      // Visible from the camera: nothing in front of the point along the camera ray (the
      // lidar sits 0.3 m behind and 0.08 m above the camera and sees round some corners).
      const Eigen::Vector3d p_map = T_map_velo[k] * x_velo;
      const Eigen::Vector3d ray = p_map - camera_centre;
      RayHit hit;
      if (world.raycast(camera_centre, ray.normalized(), ray.norm() + 1.0, &hit) &&
          hit.distance < ray.norm() - 0.1) {
        continue;
      }
      // Away from label edges: a point within half a pixel of a silhouette may fall either
      // side of it (a thin pole is 2..7 pixels wide here).
      if (u < 1 || v < 1 || u + 1 >= kWidth || v + 1 >= kHeight) continue;
      const std::uint8_t centre = label_image.at<std::uint8_t>(v, u);
      bool edge = false;
      for (int dv = -1; dv <= 1 && !edge; ++dv)
        for (int du = -1; du <= 1; ++du)
          edge |= label_image.at<std::uint8_t>(v + dv, u + du) != centre;
      ++all_in_image;
      if (edge) continue;
      ++visible;
      const int label = kitti::semanticClass(labels[i]);
      ++visible_per_class[label];
      if (centre == label) ++agree;
    }
  }
  ASSERT_GT(visible, 5000u);
  EXPECT_GT(static_cast<double>(visible) / all_in_image, 0.7);  // edges are a minority
  std::printf("[ figure ] lidar/label-image agreement %.4f of %zu visible non-edge points\n",
              static_cast<double>(agree) / visible, visible);
  EXPECT_GT(static_cast<double>(agree) / visible, 0.99) << agree << " / " << visible;
  EXPECT_GT(visible_per_class[cityscapes::kRoad], 500);
  EXPECT_GT(visible_per_class[cityscapes::kBuilding], 100);
}

TEST_F(SyntheticDrive, ImagesAreColourWithTexture) {
  const kitti::RawDrive drive(summary_->sync_dir);
  const cv::Mat image = cv::imread(drive.camera(2).framePath(5), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(image.type(), CV_8UC3);
  ASSERT_EQ(image.cols, kWidth);
  ASSERT_EQ(image.rows, kHeight);
  const cv::Mat labels = cv::imread(
      summary_->sync_dir + "/ground_truth/image_02_labels/0000000005.png", cv::IMREAD_UNCHANGED);
  // Road pixels vary (texture, shading, noise) but stay road-grey on average; sky is on top.
  double sum = 0, sum_sq = 0;
  int road = 0;
  for (int v = 0; v < image.rows; ++v) {
    for (int u = 0; u < image.cols; ++u) {
      if (labels.at<std::uint8_t>(v, u) != cityscapes::kRoad) continue;
      const double g = image.at<cv::Vec3b>(v, u)[1];
      sum += g;
      sum_sq += g * g;
      ++road;
    }
  }
  ASSERT_GT(road, 1000);
  const double mean = sum / road, stddev = std::sqrt(sum_sq / road - mean * mean);
  EXPECT_GT(stddev, 3.0);
  EXPECT_LT(mean, 140.0);
  EXPECT_EQ(labels.at<std::uint8_t>(0, kWidth / 2), cityscapes::kSky);
}

TEST(SyntheticDriveDeterminism, SameSeedSameFilesWhateverTheThreads) {
  const std::string a = test::makeTempDir("synthetic_det_a"),
                    b = test::makeTempDir("synthetic_det_b");
  DriveOptions options;
  options.seed = 9;
  options.duration_s = 0.35;
  options.write_images = true;
  options.image_width = 160;
  options.image_height = 48;
  options.lidar.azimuth_step_deg = 2.0;
  options.output_dir = a;
  options.threads = 1;
  generateSyntheticDrive(options);
  options.output_dir = b;
  options.threads = 3;
  // The progress callback: once per scan and image, one call at a time, counting up to the total.
  std::vector<std::pair<std::size_t, std::size_t>> progress;
  options.on_progress = [&progress](std::size_t done, std::size_t total) {
    progress.emplace_back(done, total);
  };
  const DriveSummary summary = generateSyntheticDrive(options);
  ASSERT_EQ(progress.size(), static_cast<std::size_t>(summary.scans + summary.images));
  for (std::size_t i = 0; i < progress.size(); ++i) {
    EXPECT_EQ(progress[i].first, i + 1);
    EXPECT_EQ(progress[i].second, progress.size());
  }
  auto slurp = [](const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  const std::string rel = "/2011_09_26/2011_09_26_drive_0001_sync/";
  for (const char* file :
       {"oxts/data/0000000002.txt", "oxts/timestamps.txt", "velodyne_points/data/0000000003.bin",
        "image_02/data/0000000001.png", "ground_truth/velodyne_labels/0000000003.label",
        "ground_truth/world.txt"}) {
    const std::string content = slurp(a + rel + file);
    EXPECT_FALSE(content.empty()) << file;
    EXPECT_EQ(content, slurp(b + rel + file)) << file;
  }
  EXPECT_GE(summary.scans, 3);
  fs::remove_all(a);
  fs::remove_all(b);
}

TEST(SyntheticDriveOptions, RejectsBadOptionsWithAClearMessage) {
  DriveOptions options;
  options.output_dir = test::makeTempDir("synthetic_bad");
  options.date = "2011-09-26";
  EXPECT_THROW(generateSyntheticDrive(options), std::invalid_argument);
  options.date = "2011_09_26";
  options.duration_s = -1;
  EXPECT_THROW(generateSyntheticDrive(options), std::invalid_argument);
  // An output that is a file: named, not a filesystem error from deep inside.
  options.duration_s = 0.3;
  const std::string file = options.output_dir + "/a_file";
  std::ofstream(file) << "x";
  const std::string folder = options.output_dir;
  options.output_dir = file;
  try {
    generateSyntheticDrive(options);
    ADD_FAILURE() << "a file was taken for the output folder";
  } catch (const std::invalid_argument& error) {
    EXPECT_EQ(std::string(error.what()), "--output " + file + ": not a folder");
  }
  fs::remove_all(folder);
}

// A full disk half way (simulated in a child process with a file size limit) leaves neither a
// half drive nor the staging folder; generating again replaces a drive whole.
TEST(SyntheticDriveOptions, AFailureHalfWayLeavesNoHalfDrive) {
  DriveOptions options;
  options.output_dir = test::makeTempDir("synthetic_full_disk");
  options.duration_s = 1.0;
  options.lidar.beams = 8;
  options.image_width = 64;
  options.image_height = 32;
  options.threads = 1;
  std::fflush(nullptr);
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    std::signal(SIGXFSZ, SIG_IGN);  // a write past the limit fails with EFBIG instead
    const rlimit limit{16 * 1024, 16 * 1024};
    setrlimit(RLIMIT_FSIZE, &limit);
    try {
      generateSyntheticDrive(options);
    } catch (const std::exception&) {
      _exit(1);
    }
    _exit(0);
  }
  int status = 0;
  ASSERT_EQ(waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 1) << "the generator did not notice the full disk";
  EXPECT_TRUE(fs::is_empty(options.output_dir)) << "left behind in " << options.output_dir;

  const DriveSummary first = generateSyntheticDrive(options);
  options.duration_s = 0.5;
  const DriveSummary second = generateSyntheticDrive(options);
  EXPECT_EQ(second.sync_dir, first.sync_dir);
  EXPECT_LT(second.scans, first.scans);
  const kitti::RawDrive drive(second.sync_dir);
  std::size_t files = 0;
  for (const auto& entry : fs::directory_iterator(second.sync_dir + "/velodyne_points/data")) {
    files += entry.is_regular_file();
  }
  EXPECT_EQ(files, static_cast<std::size_t>(second.scans)) << "old scans mixed into the new drive";
  std::size_t hidden = 0;
  for (const auto& entry : fs::directory_iterator(options.output_dir)) {
    hidden += entry.path().filename().string().front() == '.';
  }
  EXPECT_EQ(hidden, 0u);
  fs::remove_all(options.output_dir);
}

}  // namespace
}  // namespace synthetic
}  // namespace inekf_semantic_mapping
