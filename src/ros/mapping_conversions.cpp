#include "inekf_semantic_mapping/ros/mapping_conversions.h"

#include <sensor_msgs/image_encodings.h>
#include <sensor_msgs/point_cloud2_iterator.h>

#include <cstring>
#include <limits>
#include <map>

#include "inekf_semantic_mapping/mapping/map_io.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {
namespace {

using mapping::ClassIndex;

std::string pointFieldTypeName(std::uint8_t datatype) {
  static const char* const kNames[] = {"INT8",  "UINT8",  "INT16",   "UINT16",
                                       "INT32", "UINT32", "FLOAT32", "FLOAT64"};
  if (datatype >= 1 && datatype <= 8) return kNames[datatype - 1];
  return std::to_string(datatype) + " (not a sensor_msgs/PointField type)";
}

struct FieldReader {
  std::uint32_t offset = 0;
  bool is_double = false;
};

FieldReader findCoordinate(const sensor_msgs::PointCloud2& cloud, const std::string& name) {
  for (const sensor_msgs::PointField& field : cloud.fields) {
    if (field.name != name) continue;
    FieldReader reader;
    reader.offset = field.offset;
    if (field.datatype == sensor_msgs::PointField::FLOAT64) {
      reader.is_double = true;
    } else if (field.datatype != sensor_msgs::PointField::FLOAT32) {
      throw std::invalid_argument("field '" + name + "' has datatype " +
                                  pointFieldTypeName(field.datatype) + ", need FLOAT32 or FLOAT64");
    }
    const std::uint64_t end = std::uint64_t{field.offset} + (reader.is_double ? 8 : 4);
    if (end > cloud.point_step) {
      throw std::invalid_argument("field '" + name + "' at offset " + std::to_string(field.offset) +
                                  " does not fit point_step " + std::to_string(cloud.point_step));
    }
    return reader;
  }
  throw std::invalid_argument("no field '" + name + "' (fields x y z are needed)");
}

float readCoordinate(const std::uint8_t* point, const FieldReader& field) {
  if (field.is_double) {
    double value;
    std::memcpy(&value, point + field.offset, sizeof(value));
    return static_cast<float>(value);
  }
  float value;
  std::memcpy(&value, point + field.offset, sizeof(value));
  return value;
}

}  // namespace

Eigen::Matrix3Xf pointsFromCloud(const sensor_msgs::PointCloud2& cloud) {
  if (cloud.is_bigendian)
    throw std::invalid_argument("is_bigendian: big-endian clouds are not supported");
  const FieldReader x = findCoordinate(cloud, "x");
  const FieldReader y = findCoordinate(cloud, "y");
  const FieldReader z = findCoordinate(cloud, "z");
  const std::uint64_t width = cloud.width, height = cloud.height;
  if (width * cloud.point_step > cloud.row_step) {
    throw std::invalid_argument("row_step " + std::to_string(cloud.row_step) + " < width " +
                                std::to_string(width) + " * point_step " +
                                std::to_string(cloud.point_step));
  }
  if (std::uint64_t{cloud.row_step} * height > cloud.data.size()) {
    throw std::invalid_argument("data holds " + std::to_string(cloud.data.size()) +
                                " bytes, row_step * height needs " +
                                std::to_string(std::uint64_t{cloud.row_step} * height));
  }
  Eigen::Matrix3Xf points(3, static_cast<Eigen::Index>(width * height));
  Eigen::Index n = 0;
  for (std::uint64_t row = 0; row < height; ++row) {
    const std::uint8_t* point = cloud.data.data() + row * cloud.row_step;
    for (std::uint64_t col = 0; col < width; ++col, point += cloud.point_step, ++n) {
      points.col(n) << readCoordinate(point, x), readCoordinate(point, y), readCoordinate(point, z);
    }
  }
  return points;
}

mapping::LabelImageView labelImageView(const sensor_msgs::Image& image) {
  namespace enc = sensor_msgs::image_encodings;
  if (image.encoding != enc::MONO8 && image.encoding != enc::TYPE_8UC1) {
    throw std::invalid_argument("encoding '" + image.encoding + "', need mono8 label ids");
  }
  if (image.width == 0 || image.height == 0 ||
      image.width > static_cast<std::uint32_t>(std::numeric_limits<int>::max()) ||
      image.height > static_cast<std::uint32_t>(std::numeric_limits<int>::max())) {
    throw std::invalid_argument("size " + std::to_string(image.width) + "x" +
                                std::to_string(image.height) + " is empty or too large");
  }
  if (image.step < image.width) {
    throw std::invalid_argument("step " + std::to_string(image.step) + " < width " +
                                std::to_string(image.width));
  }
  if (std::uint64_t{image.step} * image.height > image.data.size()) {
    throw std::invalid_argument("data holds " + std::to_string(image.data.size()) +
                                " bytes, step * height needs " +
                                std::to_string(std::uint64_t{image.step} * image.height));
  }
  return mapping::LabelImageView{image.data.data(), static_cast<int>(image.width),
                                 static_cast<int>(image.height), image.step};
}

mapping::CameraModel cameraModelFromInfo(const sensor_msgs::CameraInfo& info,
                                         const Eigen::Isometry3d& T_camera_sensor) {
  mapping::CameraModel camera;
  for (int i = 0; i < 12; ++i) camera.P(i / 4, i % 4) = info.P[i];
  if (!camera.P.allFinite() || camera.P(2, 2) == 0.0) {
    throw std::invalid_argument("P is not a finite projection matrix");
  }
  if (info.width == 0 || info.height == 0 ||
      info.width > static_cast<std::uint32_t>(std::numeric_limits<int>::max()) ||
      info.height > static_cast<std::uint32_t>(std::numeric_limits<int>::max())) {
    throw std::invalid_argument("width/height is zero or too large");
  }
  camera.width = static_cast<int>(info.width);
  camera.height = static_cast<int>(info.height);
  camera.T_camera_sensor = T_camera_sensor;
  return camera;
}

nav_msgs::OccupancyGrid occupancyGridMessage(const mapping::Grid2D& grid, const std::string& frame,
                                             const ros::Time& stamp) {
  nav_msgs::OccupancyGrid message;
  message.header.frame_id = frame;
  message.header.stamp = stamp;
  message.info.map_load_time = stamp;
  message.info.resolution = static_cast<float>(grid.resolution);
  message.info.width = static_cast<std::uint32_t>(grid.width);
  message.info.height = static_cast<std::uint32_t>(grid.height);
  message.info.origin.position.x = grid.origin_x;
  message.info.origin.position.y = grid.origin_y;
  message.info.origin.position.z = grid.origin_z;
  message.info.origin.orientation.w = 1.0;
  message.data = grid.cells;
  return message;
}

inekf_semantic_mapping::SemanticMapInfo mapInfoMessage(
    const mapping::SemanticMappingSession& session, const std::string& frame,
    const ros::Time& stamp) {
  const mapping::SemanticOcTree& tree = session.tree();
  const mapping::MappingStatistics& stats = session.statistics();
  inekf_semantic_mapping::SemanticMapInfo info;
  info.header.frame_id = frame;
  info.header.stamp = stamp;
  info.scans_received = static_cast<std::uint32_t>(stats.scans_received);
  info.scans_inserted = static_cast<std::uint32_t>(stats.scans_inserted);
  info.scans_with_labels = static_cast<std::uint32_t>(stats.scans_with_labels);
  info.scans_without_pose = static_cast<std::uint32_t>(stats.scans_without_pose);
  info.label_images_received = static_cast<std::uint32_t>(stats.label_images_received);
  info.label_images_used = static_cast<std::uint32_t>(stats.label_images_used);
  info.label_images_late = static_cast<std::uint32_t>(stats.label_images_late);
  info.resolution = tree.getResolution();
  info.nodes = tree.size();
  info.memory_bytes = tree.memoryUsage();
  std::map<std::string, std::uint64_t> class_voxels;
  const unsigned int max_depth = tree.getTreeDepth();
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    if (!tree.isNodeOccupied(*it)) continue;
    const std::uint64_t cells = std::uint64_t{1} << (3 * (max_depth - it.getDepth()));
    info.occupied_voxels += cells;
    const ClassIndex index = it->mostLikelyClass();
    class_voxels[index == mapping::kNoClass ? "unlabeled" : tree.classSet().info(index).name] +=
        cells;
  }
  for (const auto& [name, count] : class_voxels) {
    info.class_names.push_back(name);
    info.class_voxels.push_back(count);
  }
  return info;
}

visualization_msgs::MarkerArray occupiedVoxelMarkers(const mapping::SemanticOcTree& tree, int depth,
                                                     const std::string& frame,
                                                     const ros::Time& stamp) {
  const unsigned int marker_depth = static_cast<unsigned int>(std::clamp(depth, 1, 16));
  const double size = tree.getNodeSize(marker_depth);
  const mapping::ClassSet& classes = tree.classSet();
  std::map<int, visualization_msgs::Marker> by_class;  // class index (-1: none) -> cube list
  for (auto it = tree.begin_leafs(marker_depth), end = tree.end_leafs(); it != end; ++it) {
    if (!tree.isNodeOccupied(*it)) continue;
    const ClassIndex index = it->mostLikelyClass();
    geometry_msgs::Point p;
    p.x = it.getX();
    p.y = it.getY();
    p.z = it.getZ();
    by_class[index == mapping::kNoClass ? -1 : index].points.push_back(p);
  }
  visualization_msgs::MarkerArray array;
  visualization_msgs::Marker clear;
  clear.action = visualization_msgs::Marker::DELETEALL;
  array.markers.push_back(clear);
  for (auto& [key, marker] : by_class) {
    marker.header.frame_id = frame;
    marker.header.stamp = stamp;
    marker.ns = key < 0 ? "unlabeled" : classes.info(static_cast<ClassIndex>(key)).name;
    marker.id = key;
    marker.type = visualization_msgs::Marker::CUBE_LIST;
    marker.action = visualization_msgs::Marker::ADD;
    marker.pose.orientation.w = 1.0;
    marker.scale.x = marker.scale.y = marker.scale.z = size;
    marker.color.a = 1.0;
    if (key < 0) {
      marker.color.r = marker.color.g = marker.color.b = 0.5;
    } else {
      const auto& c = classes.info(static_cast<ClassIndex>(key)).rgb;
      marker.color.r = c[0] / 255.0;
      marker.color.g = c[1] / 255.0;
      marker.color.b = c[2] / 255.0;
    }
    array.markers.push_back(std::move(marker));
  }
  return array;
}

sensor_msgs::PointCloud2 labeledCloudMessage(const mapping::LabeledScan& scan,
                                             const mapping::ClassSet& classes,
                                             const std::string& frame, const ros::Time& stamp) {
  using mapping::SemanticMappingSession;
  sensor_msgs::PointCloud2 out;
  out.header.stamp = stamp;
  out.header.frame_id = frame;
  sensor_msgs::PointCloud2Modifier modifier(out);
  modifier.setPointCloud2Fields(
      5, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1, sensor_msgs::PointField::FLOAT32, "z", 1,
      sensor_msgs::PointField::FLOAT32, "rgb", 1, sensor_msgs::PointField::FLOAT32, "label", 1,
      sensor_msgs::PointField::UINT32);
  const std::size_t n = static_cast<std::size_t>(scan.points_map.cols());
  modifier.resize(n);
  sensor_msgs::PointCloud2Iterator<float> x(out, "x"), y(out, "y"), z(out, "z"), rgb(out, "rgb");
  sensor_msgs::PointCloud2Iterator<std::uint32_t> label(out, "label");
  for (std::size_t i = 0; i < n; ++i, ++x, ++y, ++z, ++rgb, ++label) {
    *x = scan.points_map(0, i);
    *y = scan.points_map(1, i);
    *z = scan.points_map(2, i);
    const std::uint32_t id =
        scan.label_ids.empty() ? SemanticMappingSession::kNoLabel : scan.label_ids[i];
    const ClassIndex index =
        id == SemanticMappingSession::kNoLabel ? mapping::kNoClass : classes.indexOf(id);
    std::uint32_t packed = 0x808080;  // grey: no label
    if (index != mapping::kNoClass) {
      const auto& c = classes.info(index).rgb;
      packed = (std::uint32_t{c[0]} << 16) | (std::uint32_t{c[1]} << 8) | c[2];
    }
    std::memcpy(&*rgb, &packed, sizeof(float));
    *label = id;
  }
  return out;
}

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
