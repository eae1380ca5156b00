// Messages <-> the ROS-free mapping session: every incoming message is checked before a byte of
// it is read (sizes, steps, field offsets and datatypes), and the errors name the field.
#pragma once

#include <nav_msgs/OccupancyGrid.h>
#include <ros/node_handle.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <visualization_msgs/MarkerArray.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <stdexcept>
#include <string>

#include "inekf_semantic_mapping/SemanticMapInfo.h"
#include "inekf_semantic_mapping/mapping/grid_projection.h"
#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

// x y z of every point (FLOAT32 or FLOAT64 fields, little endian). Throws std::invalid_argument
// naming the field when the cloud is malformed: a missing or overlapping field, a point_step or
// row_step too small for its fields, data shorter than row_step * height.
Eigen::Matrix3Xf pointsFromCloud(const sensor_msgs::PointCloud2& cloud);

// A view of a mono8 / 8UC1 label image. Throws std::invalid_argument naming the encoding or the
// size field that is wrong (step < width, data shorter than step * height, without overflow).
mapping::LabelImageView labelImageView(const sensor_msgs::Image& image);

// The rectified camera of a CameraInfo (P; the camera frame's pose comes from tf). Throws for a
// non-finite P, P(2,2) == 0 or a zero size.
mapping::CameraModel cameraModelFromInfo(const sensor_msgs::CameraInfo& info,
                                         const Eigen::Isometry3d& T_camera_sensor);

inekf_semantic_mapping::SemanticMapInfo mapInfoMessage(
    const mapping::SemanticMappingSession& session, const std::string& frame,
    const ros::Time& stamp);

// Occupied voxels merged to `depth`, one CUBE_LIST per most likely class (DELETEALL first).
visualization_msgs::MarkerArray occupiedVoxelMarkers(const mapping::SemanticOcTree& tree, int depth,
                                                     const std::string& frame,
                                                     const ros::Time& stamp);

// A projected grid as nav_msgs/OccupancyGrid (same layout; origin at the lowest ground, no
// rotation).
nav_msgs::OccupancyGrid occupancyGridMessage(const mapping::Grid2D& grid, const std::string& frame,
                                             const ros::Time& stamp);

// x y z rgb label of a labeled scan in the map frame.
sensor_msgs::PointCloud2 labeledCloudMessage(const mapping::LabeledScan& scan,
                                             const mapping::ClassSet& classes,
                                             const std::string& frame, const ros::Time& stamp);

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
