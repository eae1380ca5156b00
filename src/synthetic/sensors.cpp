#include "inekf_semantic_mapping/synthetic/sensors.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <string>
#include <thread>

#include "inekf_semantic_mapping/common/atomic_file.h"
#include "inekf_semantic_mapping/perception/cityscapes.h"

namespace inekf_semantic_mapping {
namespace synthetic {
namespace cs = cityscapes;

namespace {

Eigen::Matrix3d rowMajor3(std::initializer_list<double> v) {
  Eigen::Matrix3d m;
  auto it = v.begin();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) m(r, c) = *it++;
  return m;
}

Eigen::Matrix<double, 3, 4> rowMajor34(std::initializer_list<double> v) {
  Eigen::Matrix<double, 3, 4> m;
  auto it = v.begin();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) m(r, c) = *it++;
  return m;
}

template <typename Matrix>
std::string formatRowMajor(const Matrix& m) {
  std::string out;
  char buffer[32];
  for (int r = 0; r < m.rows(); ++r) {
    for (int c = 0; c < m.cols(); ++c) {
      std::snprintf(buffer, sizeof(buffer), "%s%e", out.empty() ? "" : " ", m(r, c));
      out += buffer;
    }
  }
  return out;
}

// Deterministic per-pixel hash -> [0, 1).
inline double pixelHash(std::uint64_t seed, std::uint64_t index) {
  std::uint64_t h = seed * 0x9E3779B97F4A7C15ull + index * 0xD1B54A32D192ED03ull;
  h ^= h >> 31;
  h *= 0xBF58476D1CE4E5B9ull;
  h ^= h >> 29;
  h *= 0x94D049BB133111EBull;
  h ^= h >> 32;
  return static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0);
}

double baseReflectance(std::uint8_t label) {
  switch (label) {
    case cs::kRoad:
      return 0.22;
    case cs::kSidewalk:
      return 0.3;
    case cs::kBuilding:
      return 0.35;
    case cs::kVegetation:
      return 0.45;
    case cs::kTerrain:
      return 0.4;
    case cs::kCar:
      return 0.55;
    case cs::kTrafficSign:
      return 0.9;  // retro-reflective
    default:
      return 0.3;
  }
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Rig
// ---------------------------------------------------------------------------------------------
KittiRig KittiRig::kitti2011_09_26() {
  KittiRig rig;
  rig.R_velo_imu =
      rowMajor3({9.999976e-01, 7.553071e-04, -2.035826e-03, -7.854027e-04, 9.998898e-01,
                 -1.482298e-02, 2.024406e-03, 1.482454e-02, 9.998881e-01});
  rig.t_velo_imu = {-8.086759e-01, 3.195559e-01, -7.997231e-01};
  rig.R_cam0_velo =
      rowMajor3({7.533745e-03, -9.999714e-01, -6.166020e-04, 1.480249e-02, 7.280733e-04,
                 -9.998902e-01, 9.998621e-01, 7.523790e-03, 1.480755e-02});
  rig.t_cam0_velo = {-4.069766e-03, -7.631618e-02, -2.717806e-01};

  Camera& c0 = rig.cameras[0];
  c0.K = rowMajor3({9.842439e+02, 0, 6.900000e+02, 0, 9.808141e+02, 2.331966e+02, 0, 0, 1});
  c0.D << -3.728755e-01, 2.037299e-01, 2.219027e-03, 1.383707e-03, -7.233722e-02;
  c0.R = Eigen::Matrix3d::Identity();
  c0.T = {2.573699e-16, -1.059758e-16, 1.614870e-16};
  c0.R_rect = rowMajor3({9.999239e-01, 9.837760e-03, -7.445048e-03, -9.869795e-03, 9.999421e-01,
                         -4.278459e-03, 7.402527e-03, 4.351614e-03, 9.999631e-01});
  c0.P_rect =
      rowMajor34({7.215377e+02, 0, 6.095593e+02, 0, 0, 7.215377e+02, 1.728540e+02, 0, 0, 0, 1, 0});

  Camera& c1 = rig.cameras[1];
  c1.K = rowMajor3({9.895267e+02, 0, 7.020000e+02, 0, 9.878386e+02, 2.455590e+02, 0, 0, 1});
  c1.D << -3.644661e-01, 1.790019e-01, 1.148107e-03, -6.298563e-04, -5.314062e-02;
  c1.R = rowMajor3({9.993513e-01, 1.860866e-02, -3.083487e-02, -1.887662e-02, 9.997863e-01,
                    -8.421873e-03, 3.067156e-02, 8.998467e-03, 9.994890e-01});
  c1.T = {-5.370000e-01, 4.822061e-03, -1.252488e-02};
  c1.R_rect = rowMajor3({9.996878e-01, -8.976826e-03, 2.331651e-02, 8.876121e-03, 9.999508e-01,
                         4.418952e-03, -2.335503e-02, -4.210612e-03, 9.997184e-01});
  c1.P_rect = rowMajor34(
      {7.215377e+02, 0, 6.095593e+02, -3.875744e+02, 0, 7.215377e+02, 1.728540e+02, 0, 0, 0, 1, 0});

  Camera& c2 = rig.cameras[2];
  c2.K = rowMajor3({9.597910e+02, 0, 6.960217e+02, 0, 9.569251e+02, 2.241806e+02, 0, 0, 1});
  c2.D << -3.691481e-01, 1.968681e-01, 1.353473e-03, 5.677587e-04, -6.770705e-02;
  c2.R = rowMajor3({9.999758e-01, -5.267463e-03, -4.552439e-03, 5.251945e-03, 9.999804e-01,
                    -3.413835e-03, 4.570332e-03, 3.389843e-03, 9.999838e-01});
  c2.T = {5.956621e-02, 2.900141e-04, 2.577209e-03};
  c2.R_rect = rowMajor3({9.998817e-01, 1.511453e-02, -2.841595e-03, -1.511724e-02, 9.998853e-01,
                         -9.338510e-04, 2.827154e-03, 9.766976e-04, 9.999955e-01});
  c2.P_rect = rowMajor34({7.215377e+02, 0, 6.095593e+02, 4.485728e+01, 0, 7.215377e+02,
                          1.728540e+02, 2.163791e-01, 0, 0, 1, 2.745884e-03});

  Camera& c3 = rig.cameras[3];
  c3.K = rowMajor3({9.037596e+02, 0, 6.957519e+02, 0, 9.019653e+02, 2.242509e+02, 0, 0, 1});
  c3.D << -3.639558e-01, 1.788651e-01, 6.029694e-04, -3.922424e-04, -5.382460e-02;
  c3.R = rowMajor3({9.995599e-01, 1.699522e-02, -2.431313e-02, -1.704422e-02, 9.998531e-01,
                    -1.809756e-03, 2.427880e-02, 2.223358e-03, 9.997028e-01});
  c3.T = {-4.731050e-01, 5.551470e-03, -5.250882e-03};
  c3.R_rect = rowMajor3({9.998321e-01, -7.193136e-03, 1.685599e-02, 7.232804e-03, 9.999712e-01,
                         -2.293585e-03, -1.683901e-02, 2.415116e-03, 9.998553e-01});
  c3.P_rect = rowMajor34({7.215377e+02, 0, 6.095593e+02, -3.395242e+02, 0, 7.215377e+02,
                          1.728540e+02, 2.199936e+00, 0, 0, 1, 2.729905e-03});
  return rig;
}

Eigen::Matrix<double, 3, 4> KittiRig::scaledProjection(int camera_index, int width,
                                                       int height) const {
  Eigen::Matrix<double, 3, 4> P = cameras.at(camera_index).P_rect;
  P.row(0) *= static_cast<double>(width) / kNominalWidth;
  P.row(1) *= static_cast<double>(height) / kNominalHeight;
  return P;
}

void KittiRig::writeRawCalibration(const std::string& date_dir, int width, int height) const {
  std::string cam = "calib_time: 09-Jan-2012 13:57:47\ncorner_dist: 9.950000e-02\n";
  for (int i = 0; i < 4; ++i) {
    const Camera& c = cameras[i];
    char suffix[8];
    std::snprintf(suffix, sizeof(suffix), "_%02d: ", i);
    const Eigen::Vector2d size(1392, 512), size_rect(width, height);
    cam += "S" + std::string(suffix) + formatRowMajor(size.transpose()) + "\n";
    cam += "K" + std::string(suffix) + formatRowMajor(c.K) + "\n";
    cam += "D" + std::string(suffix) + formatRowMajor(c.D.transpose()) + "\n";
    cam += "R" + std::string(suffix) + formatRowMajor(c.R) + "\n";
    cam += "T" + std::string(suffix) + formatRowMajor(c.T.transpose()) + "\n";
    cam += "S_rect" + std::string(suffix) + formatRowMajor(size_rect.transpose()) + "\n";
    cam += "R_rect" + std::string(suffix) + formatRowMajor(c.R_rect) + "\n";
    cam +=
        "P_rect" + std::string(suffix) + formatRowMajor(scaledProjection(i, width, height)) + "\n";
  }
  common::writeTextAtomically(date_dir + "/calib_cam_to_cam.txt", cam);
  common::writeTextAtomically(date_dir + "/calib_imu_to_velo.txt",
                              "calib_time: 25-May-2012 16:47:16\nR: " + formatRowMajor(R_velo_imu) +
                                  "\nT: " + formatRowMajor(t_velo_imu.transpose()) + "\n");
  common::writeTextAtomically(
      date_dir + "/calib_velo_to_cam.txt",
      "calib_time: 15-Mar-2012 11:37:16\nR: " + formatRowMajor(R_cam0_velo) +
          "\nT: " + formatRowMajor(t_cam0_velo.transpose()) +
          "\ndelta_f: 0.000000e+00 0.000000e+00\n"
          "delta_c: 0.000000e+00 0.000000e+00\n");
}

// ---------------------------------------------------------------------------------------------
// Lidar
// ---------------------------------------------------------------------------------------------
std::vector<double> LidarModel::elevationsRad() const {
  std::vector<double> elevations;
  constexpr double kDeg = M_PI / 180.0;
  if (beams == 64) {
    for (int i = 0; i < 32; ++i) elevations.push_back((2.0 - i / 3.0) * kDeg);
    for (int i = 0; i < 32; ++i) elevations.push_back((-8.83 - i * (24.8 - 8.83) / 31.0) * kDeg);
  } else {
    for (int i = 0; i < beams; ++i) {
      const double f = beams > 1 ? static_cast<double>(i) / (beams - 1) : 0.0;
      elevations.push_back((2.0 - f * 26.8) * kDeg);
    }
  }
  return elevations;
}

int LidarModel::columns() const {
  return std::max(1, static_cast<int>(std::lround(360.0 / azimuth_step_deg)));
}

LidarScan simulateLidarScan(const SyntheticWorld& world, const Eigen::Isometry3d& T_map_velo,
                            const LidarModel& model, std::uint64_t noise_seed) {
  const std::vector<double> elevations = model.elevationsRad();
  const int columns = model.columns();
  std::vector<double> cos_az(columns), sin_az(columns);
  for (int c = 0; c < columns; ++c) {
    const double azimuth = M_PI - (c + 0.5) * 2 * M_PI / columns;  // clockwise from the rear
    cos_az[c] = std::cos(azimuth);
    sin_az[c] = std::sin(azimuth);
  }
  std::mt19937_64 rng(noise_seed);
  std::normal_distribution<double> range_noise(0.0, 1.0);
  std::normal_distribution<double> reflectance_noise(0.0, 0.03);

  const Eigen::Matrix3d R = T_map_velo.linear();
  const Eigen::Vector3d origin = T_map_velo.translation();
  LidarScan scan;
  scan.xyzi.reserve(elevations.size() * columns * 4);
  scan.labels.reserve(elevations.size() * columns);
  RayHit hit;
  for (double elevation : elevations) {
    const double ce = std::cos(elevation), se = std::sin(elevation);
    for (int c = 0; c < columns; ++c) {
      const Eigen::Vector3d d_velo(ce * cos_az[c], ce * sin_az[c], se);
      const Eigen::Vector3d d_map = R * d_velo;
      if (!world.raycast(origin, d_map, model.max_range_m, &hit)) continue;
      if (hit.distance < model.min_range_m) continue;
      const double range = hit.distance + model.range_noise_std_m *
                                              (model.range_noise_std_m > 0 ? range_noise(rng) : 0);
      const Eigen::Vector3d p = range * d_velo;
      const double incidence = std::abs(hit.normal.dot(d_map));
      double reflectance = baseReflectance(hit.label_id) * (0.55 + 0.45 * incidence);
      if (hit.primitive_index < 0 && world.streets().isLaneMarking(hit.point.x(), hit.point.y())) {
        reflectance = 0.75;
      }
      reflectance = std::clamp(reflectance + reflectance_noise(rng), 0.0, 1.0);
      scan.xyzi.insert(scan.xyzi.end(),
                       {static_cast<float>(p.x()), static_cast<float>(p.y()),
                        static_cast<float>(p.z()), static_cast<float>(reflectance)});
      scan.labels.push_back(hit.label_id);
    }
  }
  return scan;
}

// ---------------------------------------------------------------------------------------------
// Camera
// ---------------------------------------------------------------------------------------------
RenderedImage renderCamera(const SyntheticWorld& world, const Eigen::Isometry3d& T_map_camera,
                           const Eigen::Matrix3d& K, int width, int height,
                           const RenderOptions& options, int threads) {
  RenderedImage image;
  image.width = width;
  image.height = height;
  const std::size_t pixels = static_cast<std::size_t>(width) * height;
  image.bgr.resize(3 * pixels);
  image.labels.resize(pixels);
  image.range_m.resize(pixels);
  const Eigen::Matrix3d K_inv = K.inverse();
  const Eigen::Matrix3d R = T_map_camera.linear();
  const Eigen::Vector3d origin = T_map_camera.translation();
  const Eigen::Vector3d sun = options.sun_direction.normalized();
  const double noise_scale = options.pixel_noise_std * std::sqrt(12.0);

  auto render_rows = [&](int first_row, int row_step) {
    RayHit hit;
    for (int v = first_row; v < height; v += row_step) {
      for (int u = 0; u < width; ++u) {
        const std::size_t index = static_cast<std::size_t>(v) * width + u;
        const Eigen::Vector3d d = (R * (K_inv * Eigen::Vector3d(u, v, 1.0))).normalized();
        Eigen::Vector3d rgb;
        if (world.raycast(origin, d, options.max_range_m, &hit)) {
          const Eigen::Vector3f albedo = world.surfaceColor(hit);
          const double diffuse = std::max(0.0, hit.normal.dot(sun));
          rgb = albedo.cast<double>() * (options.ambient + (1.0 - options.ambient) * diffuse);
          image.labels[index] = hit.label_id;
          image.range_m[index] = static_cast<float>(hit.distance);
        } else {
          const double up = std::clamp(d.z(), 0.0, 1.0);
          rgb =
              (1 - up) * Eigen::Vector3d(0.80, 0.86, 0.93) + up * Eigen::Vector3d(0.30, 0.50, 0.85);
          image.labels[index] = cs::kSky;
          image.range_m[index] = std::numeric_limits<float>::infinity();
        }
        const double noise = noise_scale * (pixelHash(options.noise_seed, index) - 0.5);
        for (int ch = 0; ch < 3; ++ch) {
          image.bgr[3 * index + (2 - ch)] =
              static_cast<std::uint8_t>(std::clamp(255.0 * rgb[ch] + noise, 0.0, 255.0));
        }
      }
    }
  };
  threads = std::max(1, threads);
  if (threads == 1) {
    render_rows(0, 1);
  } else {
    std::vector<std::thread> workers;
    for (int t = 0; t < threads; ++t) workers.emplace_back(render_rows, t, threads);
    for (std::thread& worker : workers) worker.join();
  }
  return image;
}

}  // namespace synthetic
}  // namespace inekf_semantic_mapping
