#include "inekf_semantic_mapping/registration/icp_registration.h"

#include <pcl/filters/voxel_grid.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/registration/gicp.h>
#include <pcl/registration/icp.h>

#include <Eigen/SVD>
#include <map>
#include <mutex>
#include <stdexcept>
#include <utility>

#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/common/yaml_reader.h"
#include "inekf_semantic_mapping/kitti/velodyne.h"

namespace inekf_semantic_mapping {
namespace registration {

using Cloud = pcl::PointCloud<pcl::PointXYZ>;

void IcpOptions::read(common::YamlReader* reader) {
  reader->read("registration.coarse_voxel_m", &coarse_voxel_m);
  reader->read("registration.coarse_max_correspondence_m", &coarse_max_correspondence_m);
  reader->read("registration.coarse_iterations", &coarse_iterations);
  reader->read("registration.generalized", &generalized);
  reader->read("registration.voxel_m", &voxel_m);
  reader->read("registration.min_range_m", &min_range_m);
  reader->read("registration.max_range_m", &max_range_m);
  reader->read("registration.max_correspondence_m", &max_correspondence_m);
  reader->read("registration.max_iterations", &max_iterations);
  reader->read("registration.fitness_max_distance_m", &fitness_max_distance_m);
  try {
    validate();
  } catch (const std::invalid_argument& error) {
    reader->fail("registration", error.what());
  }
}

void IcpOptions::validate() const {
  if (!(coarse_voxel_m > 0.0))
    throw std::invalid_argument("coarse_voxel_m must be a positive number");
  if (!(coarse_max_correspondence_m > 0.0)) {
    throw std::invalid_argument("coarse_max_correspondence_m must be a positive number");
  }
  if (coarse_iterations < 0) throw std::invalid_argument("coarse_iterations must be >= 0");
  if (!(voxel_m > 0.0)) throw std::invalid_argument("voxel_m must be a positive number");
  if (!(min_range_m >= 0.0)) throw std::invalid_argument("min_range_m must be >= 0");
  if (!(max_range_m > min_range_m)) {
    throw std::invalid_argument("max_range_m must be larger than min_range_m");
  }
  if (!(max_correspondence_m > 0.0)) {
    throw std::invalid_argument("max_correspondence_m must be a positive number");
  }
  if (max_iterations < 1) throw std::invalid_argument("max_iterations must be >= 1");
  if (!(fitness_max_distance_m > 0.0)) {
    throw std::invalid_argument("fitness_max_distance_m must be a positive number");
  }
}

struct IcpScanMatcher::Impl {
  std::function<std::string(int)> scan_path;
  IcpOptions options;
  std::mutex mutex;
  std::map<int, std::pair<Cloud::Ptr, Cloud::Ptr>> clouds;  // fine, coarse

  static Cloud::Ptr downsample(const Cloud::Ptr& raw, double leaf_m) {
    Cloud::Ptr filtered(new Cloud);
    pcl::VoxelGrid<pcl::PointXYZ> grid;
    grid.setInputCloud(raw);
    const float leaf = static_cast<float>(leaf_m);
    grid.setLeafSize(leaf, leaf, leaf);
    grid.filter(*filtered);
    return filtered;
  }

  std::pair<Cloud::Ptr, Cloud::Ptr> cloud(int frame) {
    std::lock_guard<std::mutex> lock(mutex);
    const auto found = clouds.find(frame);
    if (found != clouds.end()) return found->second;
    ScopedTimer timer("registration.read_scan");
    const kitti::VelodyneScan scan = kitti::readVelodyneScan(scan_path(frame));
    Cloud::Ptr raw(new Cloud);
    raw->reserve(scan.size());
    const double min2 = options.min_range_m * options.min_range_m;
    const double max2 = options.max_range_m * options.max_range_m;
    for (std::size_t i = 0; i < scan.size(); ++i) {
      const float* p = scan.point(i);
      const double r2 = double(p[0]) * p[0] + double(p[1]) * p[1] + double(p[2]) * p[2];
      if (!(r2 >= min2 && r2 <= max2)) continue;  // also drops NaN
      raw->push_back(pcl::PointXYZ(p[0], p[1], p[2]));
    }
    const std::pair<Cloud::Ptr, Cloud::Ptr> both(downsample(raw, options.voxel_m),
                                                 downsample(raw, options.coarse_voxel_m));
    clouds.emplace(frame, both);
    return both;
  }
};

IcpScanMatcher::IcpScanMatcher(std::function<std::string(int)> scan_path, IcpOptions options)
    : impl_(std::make_shared<Impl>()) {
  options.validate();
  impl_->scan_path = std::move(scan_path);
  impl_->options = options;
}

int IcpScanMatcher::scansRead() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return static_cast<int>(impl_->clouds.size());
}

estimation::ScanRegistrationResult IcpScanMatcher::operator()(
    int target_frame, int source_frame, const Eigen::Isometry3d& guess) const {
  const auto [target, coarse_target] = impl_->cloud(target_frame);
  const auto [source, coarse_source] = impl_->cloud(source_frame);
  estimation::ScanRegistrationResult result;
  if (target->size() < 20 || source->size() < 20) return result;  // nothing to register
  const IcpOptions& options = impl_->options;
  Eigen::Matrix4f start = guess.matrix().cast<float>();
  if (options.coarse_iterations > 0) {
    ScopedTimer timer("registration.coarse");
    pcl::IterativeClosestPoint<pcl::PointXYZ, pcl::PointXYZ> coarse;
    coarse.setInputTarget(coarse_target);
    coarse.setInputSource(coarse_source);
    coarse.setMaximumIterations(options.coarse_iterations);
    coarse.setTransformationEpsilon(1e-6);
    Cloud aligned;
    for (const double distance :
         {options.coarse_max_correspondence_m, options.coarse_max_correspondence_m / 3.0}) {
      coarse.setMaxCorrespondenceDistance(distance);
      coarse.align(aligned, start);
      if (coarse.hasConverged()) start = coarse.getFinalTransformation();
    }
  }
  std::unique_ptr<pcl::IterativeClosestPoint<pcl::PointXYZ, pcl::PointXYZ>> icp;
  if (options.generalized) {
    icp = std::make_unique<pcl::GeneralizedIterativeClosestPoint<pcl::PointXYZ, pcl::PointXYZ>>();
  } else {
    icp = std::make_unique<pcl::IterativeClosestPoint<pcl::PointXYZ, pcl::PointXYZ>>();
  }
  icp->setInputTarget(target);
  icp->setInputSource(source);
  icp->setMaxCorrespondenceDistance(options.max_correspondence_m);
  icp->setMaximumIterations(options.max_iterations);
  icp->setTransformationEpsilon(1e-8);
  icp->setEuclideanFitnessEpsilon(1e-8);
  Cloud aligned;
  ScopedTimer timer("registration.fine");
  icp->align(aligned, start);
  result.converged = icp->hasConverged();
  const double max_distance = options.fitness_max_distance_m;
  result.fitness_m2 = icp->getFitnessScore(max_distance * max_distance);  // squared distances
  Eigen::Matrix4d t = icp->getFinalTransformation().cast<double>();
  result.target_from_source.matrix() = t;
  // Re-orthonormalize the float rotation.
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(t.topLeftCorner<3, 3>(),
                                              Eigen::ComputeFullU | Eigen::ComputeFullV);
  result.target_from_source.linear() = svd.matrixU() * svd.matrixV().transpose();
  return result;
}

}  // namespace registration
}  // namespace inekf_semantic_mapping
