// SemanticMappingSession: one config for node and tools (the YAML's defaults are the struct's),
// scans paired with label images in any arrival order, every scan in the map, poses that come
// late or never, time jumps, and the same map whether scans stream in or are inserted directly.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <memory>
#include <sstream>

#include "camera_test_scene.h"
#include "inekf_semantic_mapping/common/yaml_reader.h"
#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace mapping {
namespace {

using test_scene::testCamera;
using test_scene::testLabels;

// A wall 10 m ahead (x in [-2, 2], y in [-1, 1]) and a few points behind the camera.
Eigen::Matrix3Xf testScan() {
  std::vector<Eigen::Vector3f> points;
  for (float x = -1.95f; x < 2.f; x += 0.1f) {
    for (float y = -0.95f; y < 1.f; y += 0.1f) points.emplace_back(x, y, 10.05f);
  }
  for (float x = -1.95f; x < 2.f; x += 0.5f) points.emplace_back(x, 0.05f, -8.05f);
  Eigen::Matrix3Xf matrix(3, static_cast<Eigen::Index>(points.size()));
  for (std::size_t i = 0; i < points.size(); ++i)
    matrix.col(static_cast<Eigen::Index>(i)) = points[i];
  return matrix;
}

Eigen::Isometry3d poseAt(double stamp) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() << 0.0, 0.0, stamp;  // 1 m/s along the camera axis
  return pose;
}

SemanticMappingConfig testConfig(double label_wait_s = SemanticMappingConfig().label_wait_s) {
  SemanticMappingConfig config;
  config.resolution_m = 0.1;
  config.label_wait_s = label_wait_s;
  config.label_neighbour_s = 0.0;  // the pairing rules alone (NeighbouringScans... turns it on)
  return config;
}

std::string serialized(SemanticMappingSession& session) {
  session.tree().updateInnerOccupancy();
  std::ostringstream out;
  session.tree().write(out);
  return out.str();
}

std::uint32_t labelAt(const SemanticMappingSession& session, double x, double y, double z) {
  const SemanticOcTreeNode* node = session.tree().search(x, y, z);
  return node ? session.tree().mostLikelyLabel(*node, 999) : 1000;
}

TEST(SemanticMappingConfigTest, TheShippedYamlHoldsTheDefaults) {
  const SemanticMappingConfig from_yaml =
      loadSemanticMappingConfig(test::repoPath("config/semantic_mapping.yaml"));
  const SemanticMappingConfig defaults;
  EXPECT_EQ(from_yaml.resolution_m, defaults.resolution_m);
  EXPECT_EQ(from_yaml.max_range_m, defaults.max_range_m);
  EXPECT_EQ(from_yaml.occupancy.prob_hit, defaults.occupancy.prob_hit);
  EXPECT_EQ(from_yaml.occupancy.prob_miss, defaults.occupancy.prob_miss);
  EXPECT_EQ(from_yaml.occupancy.clamping_min, defaults.occupancy.clamping_min);
  EXPECT_EQ(from_yaml.occupancy.clamping_max, defaults.occupancy.clamping_max);
  EXPECT_EQ(from_yaml.class_set, defaults.class_set);
  EXPECT_EQ(from_yaml.fusion.rule, defaults.fusion.rule);
  EXPECT_EQ(from_yaml.fusion.correct_probability, defaults.fusion.correct_probability);
  EXPECT_EQ(from_yaml.fusion.dirichlet_prior, defaults.fusion.dirichlet_prior);
  EXPECT_EQ(from_yaml.grazing_ray_truncation_voxels, defaults.grazing_ray_truncation_voxels);
  EXPECT_EQ(from_yaml.ray_casting_threads, defaults.ray_casting_threads);
  EXPECT_EQ(from_yaml.insert_points_outside_image, defaults.insert_points_outside_image);
  EXPECT_EQ(from_yaml.reject_occluded_points, defaults.reject_occluded_points);
  EXPECT_EQ(from_yaml.label_geometry_check, defaults.label_geometry_check);
  EXPECT_DOUBLE_EQ(from_yaml.label_geometry_max_flat_height_m,
                   defaults.label_geometry_max_flat_height_m);
  EXPECT_DOUBLE_EQ(from_yaml.label_geometry_min_raised_height_m,
                   defaults.label_geometry_min_raised_height_m);
  EXPECT_EQ(from_yaml.label_geometry_high_terrain_is_vegetation,
            defaults.label_geometry_high_terrain_is_vegetation);
  EXPECT_EQ(from_yaml.label_stamp_tolerance_s, defaults.label_stamp_tolerance_s);
  EXPECT_EQ(from_yaml.label_wait_s, defaults.label_wait_s);
  EXPECT_EQ(from_yaml.label_neighbour_s, defaults.label_neighbour_s);
  EXPECT_EQ(from_yaml.pose_wait_s, defaults.pose_wait_s);
}

TEST(SemanticMappingConfigTest, ErrorsNameTheSourceAndTheKey) {
  const auto message = [](const std::string& yaml) {
    try {
      readSemanticMappingConfig(YAML::Load(yaml), "test.yaml");
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message("resolutoin: 0.2").find("test.yaml: key 'resolutoin' is not a known key"),
            std::string::npos);
  EXPECT_NE(message("sensor_model: {hit: 0.3}").find("sensor_model.hit"), std::string::npos);
  EXPECT_NE(message("sensor_model: {hitt: 0.7}").find("'sensor_model.hitt'"), std::string::npos);
  EXPECT_NE(message("max_range_m: fifty").find("'max_range_m' is not a number"), std::string::npos);
  EXPECT_NE(message("label_wait_s: [1, 2]").find("'label_wait_s'"), std::string::npos);
  EXPECT_NE(message("ray_casting_threads: 1.5").find("'ray_casting_threads'"), std::string::npos);
  EXPECT_NE(message("class_set: coco").find("class_set"), std::string::npos);
  EXPECT_NE(message("fusion_rule: vote").find("fusion_rule"), std::string::npos);
  // Below 1/N (34 Cityscapes classes) the Bayes rule favoured the least-observed class.
  EXPECT_NE(message("confusion_probability: 0.02").find("confusion_probability"),
            std::string::npos);
  EXPECT_EQ(message("confusion_probability: 0.05"), "no error");
  // Choices are parsed once, into enums; a bad name lists the good ones.
  EXPECT_NE(message("insertion: voxblox")
                .find("key 'insertion' must be hashed_grid or octree, got 'voxblox'"),
            std::string::npos);
  EXPECT_EQ(readSemanticMappingConfig(YAML::Load("class_set: semantickitti\ninsertion: octree"),
                                      "test.yaml")
                .insertion,
            InsertionStructure::kOctree);
  EXPECT_EQ(message("resolution_m: 0.1\nlabel_wait_s: 0.5"), "no error");
  // The node's private namespace also holds diagnostic_updater's own ~diagnostic_period.
  EXPECT_EQ(message("diagnostic_period: 2"), "no error");
  // Keys that gained their unit: the old name is still read (with a warning), both is an error.
  const SemanticMappingConfig old_names = readSemanticMappingConfig(
      YAML::Load("resolution: 0.1\nlabel_wait: 0.5\nmax_range: 40\n"
                 "label_geometry: {max_flat_height: 0.3}\nmarker_rate: 2"),
      "old.yaml");
  EXPECT_DOUBLE_EQ(old_names.resolution_m, 0.1);
  EXPECT_DOUBLE_EQ(old_names.label_wait_s, 0.5);
  EXPECT_DOUBLE_EQ(old_names.max_range_m, 40.0);
  EXPECT_DOUBLE_EQ(old_names.label_geometry_max_flat_height_m, 0.3);
  EXPECT_NE(message("label_wait: 0.5\nlabel_wait_s: 1")
                .find("'label_wait' was renamed to "
                      "'label_wait_s', which is set too"),
            std::string::npos);
  EXPECT_NE(message("resolution: 0.1\nresolution_m: 0.2").find("'resolution_m'"),
            std::string::npos);
  EXPECT_THROW(loadSemanticMappingConfig("/nonexistent/semantic_mapping.yaml"),
               common::ConfigError);
}

TEST(SemanticMappingSessionTest, LabelledScansCarryClassesAndStayInTheCameraView) {
  SemanticMappingSession session(testConfig());
  const std::vector<std::uint8_t> pixels = testLabels();
  const LabelImageView view{pixels.data(), 100, 100, 100};
  const CameraModel camera = testCamera();
  session.insertScan(testScan(), Eigen::Isometry3d::Identity(), &view, &camera);
  EXPECT_EQ(labelAt(session, -1.05, 0.55, 10.05), 7u);    // left half, lower rows: road
  EXPECT_EQ(labelAt(session, 1.05, 0.55, 10.05), 11u);    // right half: building
  EXPECT_EQ(labelAt(session, 1.05, -0.55, 10.05), 999u);  // "unlabeled" pixels: occupied, no class
  EXPECT_TRUE(session.tree().isNodeOccupied(session.tree().search(1.05, -0.55, 10.05)));
  EXPECT_EQ(session.tree().search(0.05, 0.05, -8.05), nullptr);  // behind the camera: left out

  SemanticMappingConfig whole = testConfig();
  whole.insert_points_outside_image = true;
  SemanticMappingSession everything(whole);
  everything.insertScan(testScan(), Eigen::Isometry3d::Identity(), &view, &camera);
  EXPECT_EQ(labelAt(everything, 0.05, 0.05, -8.05), 999u);  // occupancy only
}

// label_geometry: a lidar z-up scan (road 1.65 m below the sensor, a 1.65 m hedge across it 12 m
// ahead) seen by a camera whose every pixel says terrain. The hedge's terrain is impossible and
// gives no class (or vegetation, with high_terrain_is_vegetation); the road keeps it.
TEST(SemanticMappingSessionTest, LabelGeometryVetoesTerrainOnAHedge) {
  std::vector<Eigen::Vector3f> points;
  for (float x = 4.05f; x < 20.f; x += 0.1f)
    for (float y = -2.95f; y < 3.f; y += 0.1f) points.emplace_back(x, y, -1.65f);
  for (float y = -2.95f; y < 3.f; y += 0.1f)
    for (float z = -1.65f; z < 0.f; z += 0.1f) points.emplace_back(12.05f, y, z);
  Eigen::Matrix3Xf scan(3, static_cast<Eigen::Index>(points.size()));
  for (std::size_t i = 0; i < points.size(); ++i)
    scan.col(static_cast<Eigen::Index>(i)) = points[i];
  CameraModel camera = testCamera();
  // Lidar x forward, y left, z up -> camera x right, y down, z forward.
  Eigen::Matrix3d R;
  R << 0, -1, 0, 0, 0, -1, 1, 0, 0;
  camera.T_camera_sensor.linear() = R;
  const std::vector<std::uint8_t> terrain(100 * 100, 22);
  const LabelImageView view{terrain.data(), 100, 100, 100};

  const auto mapWith = [&](bool check, bool vegetation) {
    SemanticMappingConfig config = testConfig();
    config.label_geometry_check = check;
    config.label_geometry_high_terrain_is_vegetation = vegetation;
    auto session = std::make_unique<SemanticMappingSession>(config);
    session->insertScan(scan, Eigen::Isometry3d::Identity(), &view, &camera);
    return session;
  };
  const auto off = mapWith(false, false);
  const auto on = mapWith(true, false);
  const auto vegetation = mapWith(true, true);
  EXPECT_EQ(labelAt(*off, 12.05, 0.05, -0.45), 22u);  // the hedge, 1.2 m up
  EXPECT_EQ(labelAt(*on, 12.05, 0.05, -0.45), 999u);  // occupied, no class
  EXPECT_TRUE(on->tree().isNodeOccupied(on->tree().search(12.05, 0.05, -0.45)));
  EXPECT_EQ(labelAt(*vegetation, 12.05, 0.05, -0.45), 21u);
  EXPECT_EQ(labelAt(*on, 12.05, 0.05, -1.55), 22u);  // its foot, 0.1 m up: could be terrain
  for (const auto* session : {off.get(), on.get(), vegetation.get()}) {
    EXPECT_EQ(labelAt(*session, 8.05, 0.05, -1.65), 22u);  // the road in front of it
  }
}

// The streaming face (scans and labels in mixed order, late poses) builds the map the direct
// face builds from the same pairs.
TEST(SemanticMappingSessionTest, StreamingEqualsDirectInsertion) {
  const std::vector<std::uint8_t> pixels = testLabels();
  const LabelImageView view{pixels.data(), 100, 100, 100};
  const CameraModel camera = testCamera();
  const Eigen::Matrix3Xf scan = testScan();

  SemanticMappingSession streaming(testConfig());
  double pose_known_until = 0.25;
  streaming.setPoseLookup([&](double stamp, const std::string& frame) {
    EXPECT_EQ(frame, "velo_link");
    return stamp <= pose_known_until ? std::optional<Eigen::Isometry3d>(poseAt(stamp))
                                     : std::nullopt;
  });
  // Labels of 0.0 before the scan; scan 0.1 before its labels; 0.2 never gets labels (the
  // labels of 0.3 show it); 0.3's pose comes late.
  EXPECT_EQ(streaming.addLabelImage(0.01, view, camera), 0u);
  EXPECT_EQ(streaming.addScan(0.0, "velo_link", scan), 1u);
  EXPECT_EQ(streaming.addScan(0.1, "velo_link", scan), 0u);
  EXPECT_EQ(streaming.addLabelImage(0.11, view, camera), 1u);
  EXPECT_EQ(streaming.addScan(0.2, "velo_link", scan), 0u);  // waits for its labels
  EXPECT_EQ(streaming.addScan(0.3, "velo_link", scan), 0u);
  EXPECT_EQ(streaming.addLabelImage(0.31, view, camera), 1u);  // 0.2 goes in; 0.3 has no pose
  EXPECT_EQ(streaming.pendingScans(), 1u);
  pose_known_until = 1.0;
  EXPECT_EQ(streaming.advanceTo(0.4), 1u);
  EXPECT_EQ(streaming.pendingScans(), 0u);
  const MappingStatistics& stats = streaming.statistics();
  EXPECT_EQ(stats.scans_received, 4u);
  EXPECT_EQ(stats.scans_inserted, 4u);
  EXPECT_EQ(stats.scans_with_labels, 3u);
  EXPECT_EQ(stats.label_images_used, 3u);

  SemanticMappingSession direct(testConfig());
  direct.insertScan(scan, poseAt(0.0), &view, &camera);
  direct.insertScan(scan, poseAt(0.1), &view, &camera);
  direct.insertScan(scan, poseAt(0.2));
  direct.insertScan(scan, poseAt(0.3), &view, &camera);
  EXPECT_EQ(serialized(streaming), serialized(direct));
}

// The node hands over label images before camera_info and tf have come: they wait in the
// session, and their scans wait for the camera as for a pose.
TEST(SemanticMappingSessionTest, ALabelImageWaitsForItsCameraAndItsScanWaitsWithIt) {
  const std::vector<std::uint8_t> pixels = testLabels();
  const LabelImageView view{pixels.data(), 100, 100, 100};
  SemanticMappingConfig config = testConfig(1.0);
  config.pose_wait_s = 1.0;
  SemanticMappingSession session(config);
  session.setPoseLookup([](double stamp, const std::string&) { return poseAt(stamp); });
  bool camera_known = false;
  std::vector<std::string> frames_asked;
  session.setCameraLookup([&](const std::string& frame, int width, int height) {
    frames_asked.push_back(frame);
    EXPECT_EQ(width, 100);
    EXPECT_EQ(height, 100);
    return camera_known ? std::optional<CameraModel>(testCamera()) : std::nullopt;
  });
  int warnings = 0;
  session.setLabelWarningCallback([&](double, const std::string&) { ++warnings; });

  EXPECT_EQ(session.addLabelImage(0.0, view, std::string("camera_color_left")), 0u);
  EXPECT_EQ(session.statistics().label_images_received, 1u);  // counted as it comes
  EXPECT_EQ(session.addScan(0.0, "velo", testScan()), 0u);    // paired; its camera is unknown
  EXPECT_EQ(session.advanceTo(1.5), 0u);                      // within label + pose wait
  EXPECT_EQ(session.pendingScans(), 1u);
  camera_known = true;
  EXPECT_EQ(session.advanceTo(1.6), 1u);
  EXPECT_EQ(session.statistics().scans_with_labels, 1u);
  EXPECT_EQ(session.statistics().label_images_without_camera, 0u);
  EXPECT_EQ(labelAt(session, -1.05, 0.55, 10.05), 7u);  // the test labels' road on the wall
  EXPECT_EQ(frames_asked.front(), "camera_color_left");
  EXPECT_EQ(warnings, 0);

  // A camera that never comes: the scan goes in without classes after label + pose wait.
  camera_known = false;
  EXPECT_EQ(session.addLabelImage(5.0, view, std::string()), 0u);
  EXPECT_EQ(session.addScan(5.0, "velo", testScan()), 0u);
  EXPECT_EQ(session.advanceTo(6.9), 0u);
  EXPECT_EQ(session.advanceTo(7.1), 1u);
  EXPECT_EQ(session.statistics().scans_inserted, 2u);
  EXPECT_EQ(session.statistics().scans_with_labels, 1u);
  EXPECT_EQ(session.statistics().label_images_without_camera, 1u);
  EXPECT_EQ(warnings, 1);
}

TEST(SemanticMappingSessionTest, ALabelImageThatDoesNotFitItsKnownCameraIsRefusedAsItComes) {
  const std::vector<std::uint8_t> pixels(100 * 50, 21);
  SemanticMappingSession session(testConfig());
  session.setCameraLookup([](const std::string&, int, int) {
    return std::optional<CameraModel>(testCamera());  // 100 x 100, whatever the image
  });
  EXPECT_THROW(session.addLabelImage(0.0, LabelImageView{pixels.data(), 100, 50, 100},
                                     std::string("camera")),
               std::invalid_argument);
  EXPECT_EQ(session.statistics().label_images_received, 0u);
  // An unusable camera found later: the scan goes in without classes, the reason told.
  SemanticMappingSession later(testConfig());
  later.setPoseLookup([](double stamp, const std::string&) { return poseAt(stamp); });
  bool known = false;
  later.setCameraLookup([&](const std::string&, int, int) -> std::optional<CameraModel> {
    if (!known) return std::nullopt;
    throw std::invalid_argument("camera_info P is not finite");
  });
  std::string why;
  later.setLabelWarningCallback([&](double, const std::string& w) { why = w; });
  later.addLabelImage(0.0, LabelImageView{pixels.data(), 100, 50, 100}, std::string("camera"));
  known = true;
  EXPECT_EQ(later.addScan(0.0, "velo", testScan()), 1u);
  EXPECT_EQ(later.statistics().scans_with_labels, 0u);
  EXPECT_EQ(later.statistics().label_images_without_camera, 1u);
  EXPECT_NE(why.find("not finite"), std::string::npos);
}

TEST(SemanticMappingSessionTest, EveryScanGoesInWhenSegmentationIsSlowOrAbsent) {
  const std::vector<std::uint8_t> pixels = testLabels();
  const LabelImageView view{pixels.data(), 100, 100, 100};
  SemanticMappingConfig config = testConfig();
  config.label_wait_s = 1.0;
  SemanticMappingSession session(config);
  session.setPoseLookup([](double stamp, const std::string&) { return poseAt(stamp); });
  // At the start scans wait for the first label image; none for a whole wait: lidar only, and
  // from then on scans go in at once.
  EXPECT_EQ(session.addScan(0.0, "velo", testScan()), 0u);
  EXPECT_EQ(session.advanceTo(1.01), 1u);
  EXPECT_EQ(session.addScan(1.1, "velo", testScan()), 1u);
  // Segmentation starts, at 1 Hz: scans between label images wait at most label_wait.
  EXPECT_EQ(session.addLabelImage(1.5, view, testCamera()), 0u);  // no scan of that stamp yet
  std::size_t inserted = 0;
  for (int k = 1; k <= 30; ++k) {
    const double stamp = 1.4 + 0.1 * k;
    inserted += session.addScan(stamp, "velo", testScan());
    if (k % 10 == 0) inserted += session.addLabelImage(stamp + 0.01, view, testCamera());
  }
  inserted += session.advanceTo(10.0);
  EXPECT_EQ(inserted, 30u);
  EXPECT_EQ(session.statistics().scans_inserted, 32u);
  EXPECT_EQ(session.statistics().scans_with_labels, 4u);  // 1.5, 2.4, 3.4, 4.4
  EXPECT_EQ(session.statistics().label_images_used, 4u);
  EXPECT_EQ(session.statistics().label_images_unmatched, 0u);
}

// Segmentation at 0.9 Hz with 1.2 s latency (ENet on 2 cores): the gap between a label image's
// stamp and the next one's arrival exceeds label_wait, yet segmentation is running and every
// label image finds its scan.
TEST(SemanticMappingSessionTest, SlowSegmentationStillPairsEveryLabelImage) {
  const std::vector<std::uint8_t> pixels = testLabels();
  const LabelImageView view{pixels.data(), 100, 100, 100};
  SemanticMappingConfig config = testConfig();
  config.label_wait_s = 2.0;
  SemanticMappingSession session(config);
  session.setPoseLookup([](double stamp, const std::string&) { return poseAt(stamp); });
  std::vector<double> label_stamps;
  for (int k = 0; k < 100; k += 11) label_stamps.push_back(0.1 * k);
  std::size_t next_label = 0;
  for (int k = 0; k < 100; ++k) {
    const double now = 0.1 * k;
    while (next_label < label_stamps.size() && label_stamps[next_label] + 1.2 <= now + 1e-9) {
      session.addLabelImage(label_stamps[next_label++], view, testCamera());
    }
    session.addScan(now, "velo", testScan());
  }
  session.advanceTo(20.0);
  EXPECT_EQ(session.statistics().scans_inserted, 100u);
  EXPECT_EQ(session.statistics().label_images_used, next_label);
  EXPECT_EQ(session.statistics().scans_with_labels, next_label);
  EXPECT_EQ(session.statistics().label_images_unmatched, 0u);
}

// Segmentation slower than the lidar: a scan without a label image of its own borrows the one
// within label_neighbour_s, its map points projected from the sensor's pose at the image's stamp.
// The sensor moves sideways at 5 m/s, so the scan's own pose would put the road / building split
// 0.4 m off: the voxels between show which pose was used. Both orders: the label image before
// the scan goes in (borrowed), and after (lent).
TEST(SemanticMappingSessionTest, NeighbouringScansBorrowALabelImageFromItsPose) {
  const std::vector<std::uint8_t> pixels = testLabels();
  const LabelImageView view{pixels.data(), 100, 100, 100};
  const auto sideways = [](double stamp, const std::string&) {
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.translation() << 5.0 * stamp, 0.0, 0.0;
    return std::optional<Eigen::Isometry3d>(pose);
  };
  for (const bool label_first : {true, false}) {
    for (const double window_s : {0.1, 0.0}) {
      SemanticMappingConfig config = testConfig(/*label_wait_s=*/0.3);
      config.label_neighbour_s = window_s;
      SemanticMappingSession session(config);
      session.setPoseLookup(sideways);
      session.setCameraView(testCamera());
      if (label_first) {
        session.addLabelImage(0.0, view, testCamera());  // its own scan never comes
        session.addScan(0.08, "velo", testScan());       // 0.08 s later: not its own
        session.advanceTo(1.0);
      } else {
        session.addScan(0.08, "velo", testScan());
        session.advanceTo(1.0);  // in without labels: no label image is coming
        session.addLabelImage(0.0, view, testCamera());
      }
      SCOPED_TRACE(std::string(label_first ? "label image first" : "scan first") + ", window " +
                   std::to_string(window_s));
      EXPECT_EQ(session.statistics().scans_inserted, 1u);
      EXPECT_EQ(session.statistics().scans_with_labels, 0u);
      // The wall's points at map x = sensor x + 0.4; seen from x = 0 at the image's stamp.
      if (window_s > 0.0) {
        EXPECT_EQ(session.statistics().scans_with_neighbour_labels, 1u);
        EXPECT_EQ(labelAt(session, -0.25, 0.55, 10.05), 7u);
        EXPECT_EQ(labelAt(session, 0.25, 0.55, 10.05), 11u);  // road from the scan's own pose
        EXPECT_EQ(labelAt(session, 0.35, 0.55, 10.05), 11u);
      } else {
        EXPECT_EQ(session.statistics().scans_with_neighbour_labels, 0u);
        EXPECT_EQ(labelAt(session, 0.25, 0.55, 10.05), 999u);  // occupied, no class
      }
    }
  }
  // Farther than the window: nothing borrowed.
  SemanticMappingConfig config = testConfig(0.3);
  config.label_neighbour_s = 0.1;
  SemanticMappingSession session(config);
  session.setPoseLookup(sideways);
  session.setCameraView(testCamera());
  session.addLabelImage(0.0, view, testCamera());
  session.addScan(0.15, "velo", testScan());
  session.advanceTo(1.0);
  EXPECT_EQ(session.statistics().scans_with_neighbour_labels, 0u);
}

// A label image coming after a scan farther than the window from it lends that scan nothing.
TEST(SemanticMappingSessionTest, ALabelImageLendsNothingToAScanFartherThanTheWindow) {
  const std::vector<std::uint8_t> pixels = testLabels();
  const LabelImageView view{pixels.data(), 100, 100, 100};
  SemanticMappingConfig config = testConfig(/*label_wait_s=*/0.3);
  config.label_neighbour_s = 0.1;
  SemanticMappingSession session(config);
  session.setPoseLookup([](double, const std::string&) { return Eigen::Isometry3d::Identity(); });
  session.setCameraView(testCamera());
  session.addScan(0.15, "velo", testScan());
  session.advanceTo(1.0);  // in without labels: no label image is coming
  session.addLabelImage(0.0, view, testCamera());
  EXPECT_EQ(session.statistics().scans_inserted, 1u);
  EXPECT_EQ(session.statistics().scans_with_neighbour_labels, 0u);
}

// Label images later than label_wait: their scans went in without labels, and the labels still
// add class evidence (no second occupancy update).
TEST(SemanticMappingSessionTest, LateLabelImagesAddClassEvidenceToTheirScans) {
  const std::vector<std::uint8_t> pixels = testLabels();
  const LabelImageView view{pixels.data(), 100, 100, 100};
  SemanticMappingConfig config = testConfig();
  config.label_wait_s = 0.3;
  SemanticMappingSession session(config);
  session.setPoseLookup([](double, const std::string&) { return Eigen::Isometry3d::Identity(); });
  session.setCameraView(testCamera());
  // Segmentation is running (a label image came), then scan 1.0 times out before its labels.
  session.addLabelImage(0.0, view, testCamera());
  session.addScan(0.0, "velo", testScan());
  session.addScan(1.0, "velo", testScan());
  session.addScan(1.5, "velo", testScan());  // 1.0 waited longer than label_wait: in, unlabelled
  EXPECT_EQ(labelAt(session, -1.05, 0.55, 10.05), 7u);  // from the labels of 0.0
  const std::size_t nodes_before = session.tree().size();
  // The labels of 1.0 arrive now: class evidence for the scan that is already in.
  const std::vector<std::uint8_t> building(100 * 100, 11);
  session.addLabelImage(1.0, LabelImageView{building.data(), 100, 100, 100}, testCamera());
  EXPECT_EQ(session.statistics().label_images_used, 2u);
  EXPECT_EQ(session.statistics().label_images_late, 1u);
  EXPECT_EQ(session.statistics().label_images_unmatched, 0u);
  EXPECT_EQ(session.statistics().scans_inserted, 3u);
  EXPECT_EQ(session.tree().size(), nodes_before);  // no occupancy update, no new voxel
  const SemanticOcTreeNode* node = session.tree().search(-1.05, 0.55, 10.05);
  ASSERT_NE(node, nullptr);
  bool has_building = false;
  for (int slot = 0; slot < SemanticOcTreeNode::kSlots; ++slot) {
    has_building |=
        node->slotClass(slot) == session.tree().classSet().indexOf(11) && node->slotCount(slot) > 0;
  }
  EXPECT_TRUE(has_building);
  // A label image with no scan of its stamp anywhere stays unmatched.
  session.addLabelImage(1.25, view, testCamera());
  session.advanceTo(10.0);
  EXPECT_EQ(session.statistics().label_images_unmatched, 1u);
}

// The session's callback tells an insertion from late class evidence: the node counts and traces
// the ground from insertions only (a late label image once added a sample at the map's origin and
// a second "insertion" of its scan). Late evidence reports its scan's stamp and lidar origin.
TEST(SemanticMappingSessionTest, LateLabelsAreReportedAsClassEvidenceNotAsAnInsertion) {
  const std::vector<std::uint8_t> pixels = testLabels();
  const LabelImageView view{pixels.data(), 100, 100, 100};
  SemanticMappingConfig config = testConfig();
  config.label_wait_s = 0.3;
  SemanticMappingSession session(config);
  const Eigen::Vector3d origin(100.0, 50.0, 10.0);
  session.setPoseLookup([&origin](double stamp, const std::string&) {
    return Eigen::Isometry3d(Eigen::Translation3d(origin + Eigen::Vector3d(stamp, 0, 0)));
  });
  session.setCameraView(testCamera());
  struct Update {
    double stamp;
    Eigen::Vector3f sensor_origin;
    SemanticMappingSession::MapUpdate kind;
  };
  std::vector<Update> updates;
  session.setInsertedCallback(
      [&updates](double stamp, const LabeledScan& scan, SemanticMappingSession::MapUpdate kind) {
        updates.push_back({stamp, scan.sensor_origin_map, kind});
      });
  session.addLabelImage(0.0, view, testCamera());
  session.addScan(0.0, "velo", testScan());
  session.addScan(1.0, "velo", testScan());
  session.addScan(1.5, "velo", testScan());         // 1.0 goes in unlabelled
  session.addLabelImage(1.02, view, testCamera());  // within the stamp tolerance of 1.0: late
  ASSERT_EQ(session.statistics().label_images_late, 1u);
  using Kind = SemanticMappingSession::MapUpdate;
  std::size_t insertions = 0, late = 0;
  for (const Update& update : updates) {
    if (update.kind == Kind::kScanInserted) {
      ++insertions;
      EXPECT_TRUE(update.sensor_origin.isApprox(
          (origin + Eigen::Vector3d(update.stamp, 0, 0)).cast<float>()))
          << update.stamp << ": " << update.sensor_origin.transpose();
      continue;
    }
    ++late;
    EXPECT_EQ(update.stamp, 1.0);  // the scan's stamp, not the label image's
    EXPECT_TRUE(update.sensor_origin.isApprox(Eigen::Vector3f(101.0f, 50.0f, 10.0f)))
        << update.sensor_origin.transpose();
  }
  EXPECT_EQ(insertions, session.statistics().scans_inserted);
  EXPECT_EQ(late, 1u);
}

// The clock stops (a bag ended or paused): data time will not end the label wait. The scans whose
// pose is known go in now, a scan without one waits on, and a label image that comes later still
// reaches its scan.
TEST(SemanticMappingSessionTest, AStoppedClockEndsTheLabelWaitOfPosedScansOnly) {
  const std::vector<std::uint8_t> pixels = testLabels();
  const LabelImageView view{pixels.data(), 100, 100, 100};
  SemanticMappingSession session(testConfig(1.0));
  session.setPoseLookup([](double, const std::string& frame) {
    return frame == "velo" ? std::optional<Eigen::Isometry3d>(Eigen::Isometry3d::Identity())
                           : std::nullopt;
  });
  session.setCameraView(testCamera());
  session.addLabelImage(0.0, view, testCamera());  // segmentation is running
  EXPECT_EQ(session.addScan(0.0, "velo", testScan()), 1u);
  EXPECT_EQ(session.addScan(0.1, "velo", testScan()), 0u);     // waits for its label image
  EXPECT_EQ(session.addScan(0.2, "nowhere", testScan()), 0u);  // and for a pose
  EXPECT_EQ(session.advanceTo(0.3), 0u);
  ASSERT_EQ(session.oldestPendingStamp(), std::optional<double>(0.1));

  EXPECT_EQ(session.insertWithoutWaiting(), 1u);
  EXPECT_EQ(session.pendingScans(), 1u);
  EXPECT_EQ(session.oldestPendingStamp(), std::optional<double>(0.2));
  EXPECT_EQ(session.statistics().scans_inserted, 2u);
  EXPECT_EQ(session.statistics().scans_without_pose, 0u);  // not dropped: it may still come
  const std::vector<std::uint8_t> building(100 * 100, 11);
  session.addLabelImage(0.1, LabelImageView{building.data(), 100, 100, 100}, testCamera());
  EXPECT_EQ(session.statistics().label_images_late, 1u);
  EXPECT_EQ(session.statistics().scans_with_labels, 2u);
  EXPECT_EQ(session.insertWithoutWaiting(), 0u);  // again: the scan without pose waits on
  EXPECT_EQ(session.pendingScans(), 1u);
}

// Found by review: label images in another id scheme (SemanticKITTI's, an "ignore" 255) gave no
// class evidence, were counted as used and nothing said so. They are counted apart now.
TEST(SemanticMappingSessionTest, LabelIdsTheClassSetDoesNotKnowAreCounted) {
  SemanticMappingSession session(testConfig());
  std::vector<std::uint8_t> pixels = testLabels();
  session.addLabelImage(0.0, LabelImageView{pixels.data(), 100, 100, 100}, testCamera());
  EXPECT_EQ(session.statistics().label_images_with_unknown_ids, 0u);
  pixels[4321] = 250;  // one pixel is enough to say so
  session.addLabelImage(0.1, LabelImageView{pixels.data(), 100, 100, 100}, testCamera());
  EXPECT_EQ(session.statistics().label_images_with_unknown_ids, 1u);
  EXPECT_EQ(session.statistics().last_unknown_label_id, 250u);
}

// A busy node: the scans sit in their subscriber queue 3 s behind the clock (longer than
// label_wait), while label images come before their scans. No label image is lost, and a lagging
// scan is no bag loop.
TEST(SemanticMappingSessionTest, AScanQueueLaggingTheClockLosesNoLabelImage) {
  const std::vector<std::uint8_t> pixels = testLabels();
  const LabelImageView view{pixels.data(), 100, 100, 100};
  SemanticMappingSession session(testConfig(/*label_wait_s=*/1.0));
  session.setPoseLookup([](double stamp, const std::string&) { return poseAt(stamp); });
  constexpr double kQueueLag_s = 3.0;
  std::size_t labels_sent = 0;
  for (int k = 0; k < 60; ++k) {
    const double stamp = 0.1 * k;
    session.advanceTo(stamp + kQueueLag_s);  // the node's timer runs on the clock
    if (k % 5 == 0) {
      session.addLabelImage(stamp + 0.01, view, testCamera());
      ++labels_sent;
    }
    session.addScan(stamp, "velo", testScan());
  }
  session.advanceTo(20.0);
  const MappingStatistics& stats = session.statistics();
  EXPECT_EQ(stats.scans_inserted, 60u);
  EXPECT_EQ(stats.label_images_used, labels_sent);
  EXPECT_EQ(stats.scans_with_labels, labels_sent);
  EXPECT_EQ(stats.label_images_late, 0u);  // each found its scan before that went in
  EXPECT_EQ(stats.label_images_unmatched, 0u);
}

// Label images whose scans never come (the lidar stopped) do not pile up: once newer scans have
// come, or after a long time on the clock, they are counted unmatched and freed.
TEST(SemanticMappingSessionTest, LabelImagesWithoutScansAreReleased) {
  const std::vector<std::uint8_t> pixels = testLabels();
  const LabelImageView view{pixels.data(), 100, 100, 100};
  SemanticMappingSession session(testConfig());
  session.setPoseLookup([](double stamp, const std::string&) { return poseAt(stamp); });
  session.addScan(0.0, "velo", testScan());
  session.addLabelImage(0.5, view, testCamera());  // no scan of 0.5: the next is 2.0
  session.addLabelImage(3.0, view, testCamera());  // the lidar stops after 2.0
  session.advanceTo(1.0);
  EXPECT_EQ(session.statistics().label_images_unmatched, 0u);
  session.addScan(2.0, "velo", testScan());
  EXPECT_EQ(session.statistics().label_images_unmatched, 1u);
  session.advanceTo(20.0);
  EXPECT_EQ(session.statistics().label_images_unmatched, 1u);  // 3.0 may still find its scan
  session.advanceTo(40.0);
  EXPECT_EQ(session.statistics().label_images_unmatched, 2u);
}

TEST(SemanticMappingSessionTest, ScansWithoutPoseAreDroppedAfterTheWaitAndTimeJumpsFlush) {
  SemanticMappingConfig config = testConfig();
  config.label_wait_s = 0.5;
  config.pose_wait_s = 0.5;
  SemanticMappingSession session(config);
  bool have_pose = false;
  session.setPoseLookup([&](double stamp, const std::string&) {
    return have_pose ? std::optional<Eigen::Isometry3d>(poseAt(stamp)) : std::nullopt;
  });
  EXPECT_EQ(session.addScan(5.0, "velo", testScan()), 0u);
  EXPECT_EQ(session.advanceTo(5.9), 0u);
  EXPECT_EQ(session.pendingScans(), 1u);
  EXPECT_EQ(session.advanceTo(6.1), 0u);
  EXPECT_EQ(session.pendingScans(), 0u);
  EXPECT_EQ(session.statistics().scans_without_pose, 1u);
  // A bag loop: stamps go back. The pending scan of 7.0 goes in, the clock restarts.
  have_pose = true;
  session.addLabelImage(7.0, LabelImageView{testLabels().data(), 100, 100, 100}, testCamera());
  EXPECT_EQ(session.statistics().label_images_received, 1u);
  // The old label image is dropped; the new timeline starts: the scan waits for labels.
  EXPECT_EQ(session.addScan(0.0, "velo", testScan()), 0u);
  EXPECT_EQ(session.statistics().label_images_unmatched, 1u);
  EXPECT_EQ(session.advanceTo(0.6), 1u);
  EXPECT_EQ(session.statistics().scans_inserted, 1u);
}

// tf clears its buffer when the clock goes back (a bag loop): the scans then still waiting for
// their label images lost their poses and were dropped. The pose is taken while it waits.
TEST(SemanticMappingSessionTest, APoseFoundWhileTheScanWaitsSurvivesTfForgettingIt) {
  SemanticMappingConfig config = testConfig();
  config.label_wait_s = 0.5;
  config.pose_wait_s = 0.5;
  SemanticMappingSession session(config);
  bool tf_has_it = true;
  int lookups = 0;
  session.setPoseLookup([&](double stamp, const std::string&) {
    ++lookups;
    return tf_has_it ? std::optional<Eigen::Isometry3d>(poseAt(stamp)) : std::nullopt;
  });
  const std::vector<std::uint8_t> pixels = testLabels();  // alive as long as the view
  const LabelImageView view{pixels.data(), 100, 100, 100};
  session.addLabelImage(10.0, view, testCamera());  // segmentation runs
  EXPECT_EQ(session.addScan(10.0, "velo", testScan()), 1u);
  EXPECT_EQ(session.addScan(10.1, "velo", testScan()), 0u);  // waits for its label image
  EXPECT_EQ(session.pendingScans(), 1u);
  const int before_tick = lookups;
  EXPECT_EQ(session.advanceTo(10.2), 0u);  // a tick of the clock: its pose is taken ahead
  EXPECT_EQ(lookups, before_tick + 1);
  EXPECT_EQ(session.advanceTo(10.3), 0u);  // once
  EXPECT_EQ(lookups, before_tick + 1);
  tf_has_it = false;  // the bag loops: tf's buffer cleared
  EXPECT_EQ(session.addScan(5.0, "velo", testScan()), 0u);
  EXPECT_EQ(session.statistics().scans_inserted, 2u);
  EXPECT_EQ(session.statistics().scans_without_pose, 0u);
}

TEST(SemanticMappingSessionTest, AScanTheMapCannotTakeIsDroppedAndTheScansBehindItGoOn) {
  SemanticMappingConfig config = testConfig(0.5);
  for (const InsertionStructure insertion :
       {InsertionStructure::kHashedGrid, InsertionStructure::kOctree}) {
    config.insertion = insertion;
    SemanticMappingSession session(config);
    // 1.0: a pose that is not finite; 1.1: one beyond the map's +-6.5 km at 0.2 m voxels.
    session.setPoseLookup([](double stamp, const std::string&) {
      Eigen::Isometry3d pose = poseAt(stamp);
      if (stamp == 1.0) pose.translation().x() = std::nan("");
      if (stamp == 1.1) pose.translation().x() = 1e5;
      return std::optional<Eigen::Isometry3d>(pose);
    });
    std::vector<double> warned;
    session.setScanWarningCallback([&](double stamp, const std::string& why) {
      warned.push_back(stamp);
      EXPECT_FALSE(why.empty());
    });
    for (const double stamp : {1.0, 1.1, 1.2}) session.addScan(stamp, "velo", testScan());
    EXPECT_EQ(session.advanceTo(2.0), 1u);  // the two bad ones are not counted as inserted
    EXPECT_EQ(session.pendingScans(), 0u);
    EXPECT_EQ(session.statistics().scans_rejected, 2u);
    EXPECT_EQ(session.statistics().scans_inserted, 1u);
    EXPECT_EQ(warned, (std::vector<double>{1.0, 1.1}));
    // No label image has come for a whole wait: segmentation is not running, in at once.
    EXPECT_EQ(session.addScan(2.1, "velo", testScan()), 1u);
    // Back in time (a bag loop) in this lidar-only run: the bad scan is rejected at once (no
    // label image to wait for), and the scans after it still go in.
    EXPECT_EQ(session.addScan(1.0, "velo", testScan()), 0u);
    EXPECT_EQ(session.statistics().scans_rejected, 3u);
    EXPECT_EQ(session.flush(), 0u);
    EXPECT_EQ(session.addScan(1.2, "velo", testScan()), 1u);
    EXPECT_EQ(session.statistics().scans_inserted, 3u);
  }
}

TEST(SemanticMappingSessionTest, BadLabelImagesAreRejectedAndTheMapIsKept) {
  SemanticMappingSession session(testConfig());
  session.insertScan(testScan(), Eigen::Isometry3d::Identity());
  const std::size_t nodes = session.tree().size();
  const std::vector<std::uint8_t> pixels(50 * 100);
  EXPECT_THROW(
      session.addLabelImage(0.0, LabelImageView{pixels.data(), 100, 50, 100}, testCamera()),
      std::invalid_argument);  // size differs from the camera
  EXPECT_THROW(session.addLabelImage(0.0, LabelImageView{pixels.data(), 100, 50, 10}, testCamera()),
               std::invalid_argument);  // step < width
  EXPECT_THROW(session.addLabelImage(0.0, LabelImageView{nullptr, 100, 100, 100}, testCamera()),
               std::invalid_argument);
  EXPECT_EQ(session.tree().size(), nodes);
  // Counted as refused (they were counted nowhere: the map's figures showed nothing had come).
  EXPECT_EQ(session.statistics().label_images_refused, 3u);
  EXPECT_EQ(session.statistics().label_images_received, 0u);
  EXPECT_THROW(SemanticMappingSession([] {
                 SemanticMappingConfig c;
                 c.occupancy.prob_hit = 0.4;
                 return c;
               }()),
               std::invalid_argument);
  // A resolution the octree cannot hold a drive at is named as such (1e-9 m was blamed on the
  // poses when the first scan fell off the map).
  try {
    SemanticMappingConfig c;
    c.resolution_m = 1e-9;
    SemanticMappingSession tiny(c);
    ADD_FAILURE() << "a resolution of 1e-9 m was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("resolution_m"), std::string::npos) << e.what();
  }
}

TEST(SemanticMappingSessionTest, SaveLoadAndReset) {
  SemanticMappingSession session(testConfig());
  const std::vector<std::uint8_t> pixels = testLabels();
  const LabelImageView view{pixels.data(), 100, 100, 100};
  const CameraModel camera = testCamera();
  session.insertScan(testScan(), Eigen::Isometry3d::Identity(), &view, &camera);
  const std::string dir = test::makeTempDir("session_io");
  EXPECT_GT(session.save(dir + "/map.ot", MapFormat::kSemanticOt), 0u);
  SemanticMappingSession resumed(testConfig());
  resumed.load(dir + "/map.ot");
  EXPECT_EQ(serialized(resumed), serialized(session));
  EXPECT_EQ(labelAt(resumed, -1.05, 0.55, 10.05), 7u);
  SemanticMappingConfig coarse = testConfig();
  coarse.resolution_m = 0.2;
  SemanticMappingSession other(coarse);
  EXPECT_THROW(other.load(dir + "/map.ot"), MapIoError);
  session.reset();
  EXPECT_EQ(session.tree().size(), 0u);
  EXPECT_EQ(session.statistics().scans_inserted, 0u);
  std::filesystem::remove_all(dir);
}

// A map remembers where its frame lies on the Earth: a map built here takes the localization's
// origin and saves it; resumed under another origin (a new launch starts at its own first fix),
// its scans would be mapped a second time a few metres off, so the session says why they must
// not go in and which origin to start the localization with.
TEST(SemanticMappingSessionTest, AResumedMapRefusesAnotherGeodeticOrigin) {
  const GeodeticOrigin first{49.0131623, 8.4378408, 117.818};
  SemanticMappingSession session(testConfig());
  EXPECT_EQ(session.agreeOnGeodeticOrigin(first), "");
  ASSERT_TRUE(session.geodeticOrigin());
  session.insertScan(testScan(), Eigen::Isometry3d::Identity());
  const std::string dir = test::makeTempDir("session_origin");
  ASSERT_GT(session.save(dir + "/map.ot", MapFormat::kSemanticOt), 0u);

  SemanticMappingSession same(testConfig());
  same.load(dir + "/map.ot");
  ASSERT_TRUE(same.geodeticOrigin());
  EXPECT_EQ(same.geodeticOrigin()->lat_deg, first.lat_deg);
  EXPECT_EQ(same.agreeOnGeodeticOrigin(first), "");

  SemanticMappingSession other(testConfig());
  other.load(dir + "/map.ot");
  const GeodeticOrigin second{49.013137, 8.4378193, 115.934};  // 2.8 m S, 1.6 m W, 1.9 m down
  const std::string refusal = other.agreeOnGeodeticOrigin(second);
  EXPECT_NE(refusal.find(" 3.7"), std::string::npos) << refusal;
  // East, north and up of the new origin in the map's frame (the projection of inekf_node's map).
  EXPECT_NE(refusal.find("(east -1.57, north -2.82, up -1.88)"), std::string::npos) << refusal;
  EXPECT_NE(refusal.find("origin_lat:=49.0131623 origin_lon:=8.4378408 origin_alt:=117.818"),
            std::string::npos)
      << refusal;
  EXPECT_EQ(other.geodeticOrigin()->lat_deg, first.lat_deg);  // the map keeps its own
  try {
    other.addScan(1.0, "velo", testScan());
    ADD_FAILURE() << "a scan was taken under another origin";
  } catch (const std::invalid_argument& e) {
    EXPECT_EQ(std::string(e.what()), refusal);
  }
  EXPECT_EQ(other.statistics().scans_received, 0u);
  other.reset();  // an empty map takes the new origin
  EXPECT_EQ(other.agreeOnGeodeticOrigin(second), "");
  EXPECT_EQ(other.geodeticOrigin()->lat_deg, second.lat_deg);
  EXPECT_NO_THROW(other.addScan(1.0, "velo", testScan()));

  // A map loaded without an origin (saved before one was known) stays unknown: nothing is made up.
  SemanticMappingSession unknown(testConfig());
  unknown.insertScan(testScan(), Eigen::Isometry3d::Identity());
  ASSERT_GT(unknown.save(dir + "/unknown.ot", MapFormat::kSemanticOt), 0u);
  SemanticMappingSession resumed(testConfig());
  resumed.load(dir + "/unknown.ot");
  EXPECT_EQ(resumed.agreeOnGeodeticOrigin(second), "");
  EXPECT_FALSE(resumed.geodeticOrigin());
  std::filesystem::remove_all(dir);
}

// A map saved at a resolution of more digits than a stream prints by default (6) loads back into
// the session that saved it (it was refused: "0.123457 m differs from the configured 0.123457 m").
TEST(SemanticMappingSessionTest, AMapAtAnyResolutionLoadsBackAndAnotherIsNamed) {
  SemanticMappingConfig config = testConfig();
  config.resolution_m = 0.1234567;
  SemanticMappingSession session(config);
  session.insertScan(testScan(), Eigen::Isometry3d::Identity());
  const std::string dir = test::makeTempDir("session_resolution");
  ASSERT_GT(session.save(dir + "/map.ot", MapFormat::kSemanticOt), 0u);
  SemanticMappingSession resumed(config);
  ASSERT_NO_THROW(resumed.load(dir + "/map.ot"));
  EXPECT_EQ(resumed.tree().getResolution(), 0.1234567);
  EXPECT_EQ(serialized(resumed), serialized(session));
  EXPECT_EQ(loadSemanticOcTree(dir + "/map.ot")->getResolution(), 0.1234567);
  config.resolution_m = 0.12346;  // differs in the fifth digit: another map's resolution
  SemanticMappingSession other(config);
  try {
    other.load(dir + "/map.ot");
    ADD_FAILURE() << "a map of 0.1234567 m was loaded at 0.12346 m";
  } catch (const MapIoError& e) {
    EXPECT_NE(std::string(e.what()).find("0.1234567 m differs from the configured 0.12346 m"),
              std::string::npos)
        << e.what();
  }
  std::filesystem::remove_all(dir);
}

// The end of a run hands the grid's memory to the tree: the same map (saved bytes included), held
// once; an insertion afterwards rebuilds the grid and the map goes on as if it had stayed.
TEST(SemanticMappingSessionTest, ReleasingTheGridKeepsTheMapAndHoldsItOnce) {
  SemanticMappingConfig config = testConfig();
  ASSERT_EQ(config.insertion, InsertionStructure::kHashedGrid);
  SemanticMappingSession kept(config);
  SemanticMappingSession released(config);
  const std::vector<std::uint8_t> pixels = testLabels();
  const LabelImageView view{pixels.data(), 100, 100, 100};
  const CameraModel camera = testCamera();
  for (SemanticMappingSession* session : {&kept, &released}) {
    session->insertScan(testScan(), poseAt(0.0), &view, &camera);
    session->insertScan(testScan(), poseAt(0.5));
  }
  kept.tree();  // synced: grid and tree both hold the map
  EXPECT_FALSE(kept.gridReleased());
  released.treeReleasingGrid();
  EXPECT_TRUE(released.gridReleased());
  EXPECT_EQ(released.grid()->blockCount(), 0u);
  EXPECT_EQ(released.mapSizeText(), std::to_string(released.tree().size()) + " nodes");
  EXPECT_EQ(serialized(released), serialized(kept));
  EXPECT_LT(released.mapMemoryUsage(), kept.mapMemoryUsage());
  // What is left of the grid: an empty hash table.
  EXPECT_LT(released.mapMemoryUsage(), released.tree().memoryUsage() + 65536);
  const std::string dir = test::makeTempDir("session_release");
  kept.save(dir + "/kept.ot", MapFormat::kSemanticOt);
  released.save(dir + "/released.ot", MapFormat::kSemanticOt);
  std::ifstream a(dir + "/kept.ot", std::ios::binary), b(dir + "/released.ot", std::ios::binary);
  const std::string kept_file((std::istreambuf_iterator<char>(a)), {});
  const std::string released_file((std::istreambuf_iterator<char>(b)), {});
  EXPECT_GT(kept_file.size(), 1000u);
  EXPECT_TRUE(kept_file == released_file);
  std::filesystem::remove_all(dir);

  // Late labels and scans after the release: the grid comes back from the tree.
  for (SemanticMappingSession* session : {&kept, &released}) {
    session->insertScan(testScan(), poseAt(1.0), &view, &camera);
  }
  EXPECT_FALSE(released.gridReleased());
  EXPECT_EQ(released.grid()->knownVoxels(), kept.grid()->knownVoxels());
  EXPECT_EQ(serialized(released), serialized(kept));
  EXPECT_EQ(labelAt(released, -1.05, 0.55, 11.05), 7u);
}

// A map saved from one labelled scan, its bytes, and what loading a crafted file gives.
class SemanticMapFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::vector<std::uint8_t> pixels = testLabels();
    const LabelImageView view{pixels.data(), 100, 100, 100};
    const CameraModel camera = testCamera();
    session_.insertScan(testScan(), Eigen::Isometry3d::Identity(), &view, &camera);
    dir_ = test::makeTempDir("map_file");
    good_ = dir_ + "/map.ot";
    session_.save(good_, MapFormat::kSemanticOt);
    std::ifstream in(good_, std::ios::binary);
    bytes_.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  std::string write(const std::string& name, const std::string& content) const {
    std::ofstream(dir_ + "/" + name, std::ios::binary) << content;
    return dir_ + "/" + name;
  }
  // The load's error message, or "loaded".
  static std::string refusal(const std::string& path,
                             const SemanticMappingConfig& config = testConfig()) {
    SemanticMappingSession target(config);
    try {
      target.load(path);
    } catch (const MapIoError& e) {
      return std::string(e.what());
    }
    return std::string("loaded");
  }
  // An octomap header and a V1 semantic header (no integrity record, no classes) for `nodes`.
  static std::string v1Header(int nodes) {
    std::string header = "# Octomap OcTree file\nid SemanticOcTree\nsize " + std::to_string(nodes) +
                         "\nres 0.1\ndata\n";
    header += std::string("ISM_SEMANTIC_OCTREE_V1") + '\0';
    header += '\0';  // bayes
    const double probability = 0.8, prior = 0.5;
    header.append(reinterpret_cast<const char*>(&probability), sizeof(probability));
    header.append(reinterpret_cast<const char*>(&prior), sizeof(prior));
    header.append(4, '\0');  // no classes
    return header;
  }
  // One node of the file format: log-odds, no classes in its slots, no counts, child bits.
  static std::string node(float log_odds, char children) {
    std::string bytes(reinterpret_cast<const char*>(&log_odds), sizeof(log_odds));
    bytes.append(4, '\xff');
    bytes.append(8, '\0');
    return bytes + children;
  }

  SemanticMappingSession session_{testConfig()};
  std::string dir_, good_, bytes_;
};

// The hardened .ot reader: corruption anywhere in the node data, truncation, other tree types and
// crafted depth bombs are refused with a reason; the map in memory is untouched.
TEST_F(SemanticMapFileTest, CorruptOrCraftedMapsAreRefusedWithAReason) {
  // Ten single-byte corruptions spread over the node data (the last 40 % of the file).
  for (int k = 0; k < 10; ++k) {
    std::string corrupt = bytes_;
    const std::size_t at = bytes_.size() - 1 - k * (bytes_.size() * 2 / 5) / 10;
    corrupt[at] = static_cast<char>(corrupt[at] ^ 0x5A);
    const std::string why = refusal(write("corrupt.ot", corrupt));
    EXPECT_NE(why, "loaded") << "byte " << at;
    EXPECT_NE(why.find("corrupt.ot"), std::string::npos) << why;
  }
  EXPECT_NE(refusal(write("truncated.ot", bytes_.substr(0, bytes_.size() - 100))).find("truncated"),
            std::string::npos);
  EXPECT_NE(refusal(write("other.ot", "# Octomap OcTree file\nid OcTree\nsize 1\nres 0.1\ndata\n"))
                .find("not a SemanticOcTree"),
            std::string::npos);
  EXPECT_NE(refusal(dir_).find("directory"), std::string::npos);
  // A V1 file (no integrity record) whose nodes each claim one child, 40 levels deep.
  std::string bomb = v1Header(40);
  for (int level = 0; level < 40; ++level) bomb += node(0.0f, 0x01);
  EXPECT_NE(refusal(write("bomb.ot", bomb)).find("finest level"), std::string::npos);
  // The intact file still loads, and equals the map it came from.
  SemanticMappingSession loaded(testConfig());
  loaded.load(good_);
  EXPECT_EQ(serialized(loaded), serialized(session_));
}

// What the octomap header, the class table and the leaves say must be what the reader builds
// from: each case here loaded before as another map (or ran out of memory).
TEST_F(SemanticMapFileTest, HeaderClassTableAndLeavesCannotStandForAnotherMap) {
  const std::size_t size_at = bytes_.find("\nsize ") + 6;
  const std::size_t size_end = bytes_.find('\n', size_at);
  const std::size_t data_at = bytes_.find("\ndata\n") + 6;
  ASSERT_NE(bytes_.find("\nsize "), std::string::npos);

  // A header saying size 0 made octomap skip the node data and every check of it.
  const std::string size0 = bytes_.substr(0, size_at) + "0" + bytes_.substr(size_end);
  EXPECT_NE(refusal(write("size0.ot", size0)).find("header says size 0"), std::string::npos);
  EXPECT_NE(refusal(write("size0_cut.ot", size0.substr(0, size0.find("\ndata\n") + 46))), "loaded");

  // The class table: a label id listed twice would have shifted every later class.
  std::string twice = bytes_;
  const std::size_t table_at = data_at + sizeof("ISM_SEMANTIC_OCTREE_V2") + 1 + 16 + 4;
  std::uint32_t first_id = 0, name_length = 0;
  std::memcpy(&first_id, &twice[table_at], 4);
  std::memcpy(&name_length, &twice[table_at + 7], 4);
  std::memcpy(&twice[table_at + 11 + name_length], &first_id, 4);  // the second entry's id
  EXPECT_NE(refusal(write("twice.ot", twice)).find("listed twice"), std::string::npos);

  // The integrity record announcing 64 GB in a file of a few hundred bytes: refused as
  // truncated, without reserving the memory first.
  std::string huge = bytes_.substr(0, bytes_.size() - 17 * session_.tree().size());
  const std::uint64_t nodes = (std::uint64_t{1} << 36) / 17, length = nodes * 17;
  const std::size_t record_at = huge.size() - 24;
  std::memcpy(&huge[record_at], &nodes, 8);
  std::memcpy(&huge[record_at + 8], &length, 8);
  huge = huge.substr(0, size_at) + std::to_string(nodes) + huge.substr(size_end);
  EXPECT_NE(refusal(write("huge.ot", huge + std::string(1000, '\0'))).find("truncated node data"),
            std::string::npos);

  // One occupied leaf at the root: 2^48 voxels for the grid or the PLY writer to expand.
  EXPECT_NE(refusal(write("root_leaf.ot", v1Header(1) + node(2.0f, 0))).find("voxels a side"),
            std::string::npos);

  // A map of another class set: its stored class indices would stand for other label ids.
  SemanticMappingConfig kitti_classes = testConfig();
  kitti_classes.class_set = MapClassSet::kSemanticKitti;
  const std::string why = refusal(good_, kitti_classes);
  EXPECT_NE(why.find("not the configured class set"), std::string::npos) << why;
  // An empty map keeps its class table too (its header says size 0).
  SemanticMappingSession empty(kitti_classes);
  empty.save(dir_ + "/empty.ot", MapFormat::kSemanticOt);
  EXPECT_NE(refusal(dir_ + "/empty.ot").find("not the configured class set"), std::string::npos);
  SemanticMappingSession empty_again(kitti_classes);
  empty_again.load(dir_ + "/empty.ot");
  EXPECT_EQ(empty_again.tree().size(), 0u);
  // The intact file still loads.
  EXPECT_EQ(refusal(good_), "loaded");
}

// The reader's limits are where a map may really go: a pruned leaf of 256 voxels a side (free
// space) loads, and a stored class index one past the class table is refused.
TEST_F(SemanticMapFileTest, ALeafOfTheLargestSpanLoadsAndAClassIndexPastTheTableIsRefused) {
  // Eight nodes with one child each, then a leaf at depth 8 of 16: 2^8 voxels a side.
  std::string chain;
  for (int level = 0; level < 8; ++level) chain += node(0.0f, 0x01);
  const std::unique_ptr<SemanticOcTree> tree =
      loadSemanticOcTree(write("span.ot", v1Header(9) + chain + node(-2.0f, 0)));
  ASSERT_TRUE(tree);
  EXPECT_EQ(tree->size(), 9u);
  // The same leaf naming class 0 of a table without classes.
  std::string classed = node(2.0f, 0);
  classed[sizeof(float)] = '\0';
  EXPECT_NE(
      refusal(write("class.ot", v1Header(9) + chain + classed)).find("outside the class table"),
      std::string::npos);
}

}  // namespace
}  // namespace mapping
}  // namespace inekf_semantic_mapping
