// LabelCamera, semantic_octomap_node's camera of the label images, with the raw calibration files
// (~calib_dir): a label image of another size than the calibration's rectified one is refused,
// naming the file and both sizes. Found by review: the node took the label image's size over
// the file's, so another recording day's calibration (1242x375 for 1226x370 images) put every
// label 10 px / 5 px off without a word, while kitti2bag, kitti_player and semantic_map_offline
// refused the same mismatch.
#include <gtest/gtest.h>
#include <ros/time.h>
#include <tf2_ros/buffer.h>

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"
#include "inekf_semantic_mapping/ros/label_camera.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {
namespace {

mapping::CameraModel kittiCamera(int width, int height) {
  mapping::CameraModel camera;
  camera.P << 721.5, 0.0, 609.6, 44.9, 0.0, 721.5, 172.9, 0.2, 0.0, 0.0, 1.0, 0.003;
  camera.width = width;
  camera.height = height;
  return camera;
}

// What addLabelImage throws for a width x height label image ("" when it takes it).
std::string refusal(mapping::SemanticMappingSession* session, int width, int height) {
  const std::vector<std::uint8_t> pixels(static_cast<std::size_t>(width * height), 7);
  const mapping::LabelImageView view{pixels.data(), width, height, static_cast<std::size_t>(width)};
  try {
    session->addLabelImage(1.0, view, "camera_color_left");
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

TEST(LabelCamera, ALabelImageOfAnotherSizeThanTheCalibrationsIsRefusedNamingTheFile) {
  ros::Time::init();
  const tf2_ros::Buffer tf;
  const LabelCamera camera(tf, kittiCamera(1242, 375), "/data/2011_09_26/calib_cam_to_cam.txt");
  mapping::SemanticMappingSession session{mapping::SemanticMappingConfig()};
  camera.serve(&session);
  const std::string why = refusal(&session, 1226, 370);
  EXPECT_NE(why.find("label image is 1226x370"), std::string::npos) << why;
  EXPECT_NE(why.find("/data/2011_09_26/calib_cam_to_cam.txt says 1242x375"), std::string::npos)
      << why;
  EXPECT_EQ(session.statistics().label_images_refused, 1u);
  EXPECT_EQ(refusal(&session, 1242, 375), "");
  EXPECT_EQ(session.statistics().label_images_refused, 1u);
  // A calibration without a rectified size takes the images' own.
  const LabelCamera sizeless(tf, kittiCamera(0, 0), "calib");
  const auto at_image_size = sizeless.cameraFor("", 1226, 370);
  ASSERT_TRUE(at_image_size.has_value());
  EXPECT_EQ(at_image_size->width, 1226);
  EXPECT_EQ(at_image_size->height, 370);
}

}  // namespace
}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
