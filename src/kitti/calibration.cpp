#include "inekf_semantic_mapping/kitti/calibration.h"

#include <cstdio>
#include <filesystem>
#include <map>
#include <stdexcept>
#include <vector>

#include "inekf_semantic_mapping/kitti/errors.h"
#include "text_parsing.h"

namespace inekf_semantic_mapping {
namespace kitti {
namespace {

struct KeyValues {
  std::string path;
  std::map<std::string, std::vector<double>> values;
  std::map<std::string, int> line_of;

  bool has(const std::string& key) const { return values.count(key) > 0; }

  const std::vector<double>& get(const std::string& key, std::size_t expected_count) const {
    const auto it = values.find(key);
    if (it == values.end()) throw KittiFormatError(path, "missing key '" + key + "'");
    if (it->second.size() != expected_count) {
      throw KittiFormatError(path, line_of.at(key),
                             "'" + key + "' has " + std::to_string(it->second.size()) +
                                 " values, expected " + std::to_string(expected_count));
    }
    return it->second;
  }

  Eigen::Matrix3d matrix3(const std::string& key) const {
    const auto& v = get(key, 9);
    Eigen::Matrix3d m;
    m << v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8];
    return m;
  }
  Eigen::Matrix<double, 3, 4> matrix34(const std::string& key) const {
    const auto& v = get(key, 12);
    Eigen::Matrix<double, 3, 4> m;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) m(r, c) = v[4 * r + c];
    return m;
  }
  // A rotation, refused (naming the key and its line) unless it is one within the files'
  // printing precision: a wrong R_rect turned every camera's tf and projection without a word.
  Eigen::Matrix3d rotation3(const std::string& key) const {
    const Eigen::Matrix3d r = matrix3(key);
    const double error = (r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
    if (!(error < 1e-3) || !(r.determinant() > 0)) {
      throw KittiFormatError(
          path, line_of.at(key),
          "'" + key + "' is not a rotation (|R^T R - I| = " + std::to_string(error) + ")");
    }
    return r;
  }
  // A rectified pinhole projection K [I | t]: refused unless its focal lengths and P(2,2) are
  // positive (a zero focal length made the camera's tf NaN and put every point at the principal
  // point).
  Eigen::Matrix<double, 3, 4> projection34(const std::string& key) const {
    const Eigen::Matrix<double, 3, 4> p = matrix34(key);
    if (!(p(0, 0) > 0 && p(1, 1) > 0 && p(2, 2) > 0)) {
      throw KittiFormatError(path, line_of.at(key),
                             "'" + key + "' is not a camera projection (focal lengths " +
                                 std::to_string(p(0, 0)) + ", " + std::to_string(p(1, 1)) +
                                 " and P(2,2) " + std::to_string(p(2, 2)) + " must be > 0)");
    }
    return p;
  }
  Eigen::Isometry3d isometry34(const std::string& key) const {
    Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
    const Eigen::Matrix<double, 3, 4> m = matrix34(key);
    t.linear() = m.leftCols<3>();
    t.translation() = m.col(3);
    return t;
  }
  Eigen::Isometry3d isometryRT(const std::string& r_key, const std::string& t_key) const {
    Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
    t.linear() = matrix3(r_key);
    const auto& v = get(t_key, 3);
    t.translation() = Eigen::Vector3d(v[0], v[1], v[2]);
    return t;
  }
};

// "key: v v v" lines (the object benchmark also uses "key v v v" for nothing, so ':' is
// required). Values of known non-numeric keys (calib_time) are skipped.
KeyValues readKeyValues(const std::string& path) {
  std::ifstream stream = detail::openOrThrow(path);
  KeyValues kv;
  kv.path = path;
  std::string line;
  int line_number = 0;
  while (std::getline(stream, line)) {
    ++line_number;
    if (detail::trim(line).empty()) continue;
    const auto colon = line.find(':');
    if (colon == std::string::npos) {
      throw KittiFormatError(path, line_number, "expected 'key: values', got '" + line + "'");
    }
    const std::string key = detail::trim(line.substr(0, colon));
    if (key == "calib_time") continue;
    std::vector<double> values;
    for (const std::string& token : detail::splitWhitespace(line.substr(colon + 1))) {
      double v;
      if (!detail::parseDouble(token, &v)) {
        throw KittiFormatError(path, line_number,
                               "'" + key + "': value '" + token + "' is not a number");
      }
      if (!std::isfinite(v)) {
        throw KittiFormatError(path, line_number,
                               "'" + key + "': value '" + token + "' is not finite");
      }
      values.push_back(v);
    }
    kv.values[key] = std::move(values);
    kv.line_of[key] = line_number;
  }
  return kv;
}

// The rotations in KITTI files are printed with 7 digits: re-orthonormalize so that
// Isometry3d inverse() (which assumes an orthonormal linear part) stays exact.
void orthonormalize(Eigen::Isometry3d* t) {
  const Eigen::Quaterniond q(t->linear());
  t->linear() = q.normalized().toRotationMatrix();
}

// The same for a rotation read from `path`: a matrix that is no rotation within the files'
// printing precision is an error naming the key, never silently made into one.
void orthonormalizeRead(Eigen::Isometry3d* t, const std::string& path, const std::string& key) {
  const Eigen::Matrix3d R = t->linear();
  const double error = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (!(error < 1e-3) || !(R.determinant() > 0)) {
    throw KittiFormatError(path, "'" + key +
                                     "' is not a rotation (|R^T R - I| = " + std::to_string(error) +
                                     ", det = " + std::to_string(R.determinant()) + ")");
  }
  orthonormalize(t);
}

}  // namespace

Eigen::Isometry3d CameraProjection::T_rectified_camera_velo() const {
  const Eigen::Matrix3d K = rectifiedIntrinsics();
  const Eigen::Vector3d baseline = K.inverse() * P_rect.col(3);
  Eigen::Isometry3d T_rect0_cam0 = Eigen::Isometry3d::Identity();
  T_rect0_cam0.linear() = R_rect;
  Eigen::Isometry3d result = Eigen::Translation3d(baseline) * T_rect0_cam0 * T_cam0_velo;
  orthonormalize(&result);
  return result;
}

void CameraProjection::checkRectifiedImageSize(const std::string& image_path, int image_width,
                                               int image_height) const {
  if (width <= 0 || height <= 0) return;
  if (image_width == width && image_height == height) return;
  throw KittiFormatError(
      image_path, std::to_string(image_width) + "x" + std::to_string(image_height) +
                      ", the calibration's rectified size (S_rect) says " + std::to_string(width) +
                      "x" + std::to_string(height) +
                      ": not the rectified image the projection needs (an _extract "
                      "drive's images are not rectified: use its _sync drive)");
}

CameraProjection RawCalibration::projection(int camera_index) const {
  if (camera_index < 0 || camera_index >= 4 || !cameras[camera_index].present) {
    throw std::out_of_range(
        (cam_to_cam_path.empty() ? std::string("calib_cam_to_cam.txt") : cam_to_cam_path) +
        ": camera " + std::to_string(camera_index) + " is not there (no P_rect_0" +
        std::to_string(camera_index) + " line)");
  }
  const CameraCalibration& camera = cameras[camera_index];
  CameraProjection projection;
  projection.P_rect = camera.P_rect;
  projection.R_rect = cameras[0].present ? cameras[0].R_rect : camera.R_rect;
  projection.T_cam0_velo = T_cam0_velo;
  projection.width = static_cast<int>(camera.S_rect.x());
  projection.height = static_cast<int>(camera.S_rect.y());
  return projection;
}

std::vector<std::string> missingRawCalibrationFiles(const std::string& dir) {
  std::vector<std::string> missing;
  for (const char* name :
       {"calib_cam_to_cam.txt", "calib_imu_to_velo.txt", "calib_velo_to_cam.txt"}) {
    if (!std::filesystem::is_regular_file(dir + "/" + name)) missing.emplace_back(name);
  }
  return missing;
}

bool hasRawCalibration(const std::string& dir) { return missingRawCalibrationFiles(dir).empty(); }

RawCalibration readRawCalibration(const std::string& date_dir) {
  RawCalibration calib;
  const KeyValues imu_to_velo = readKeyValues(date_dir + "/calib_imu_to_velo.txt");
  calib.T_velo_imu = imu_to_velo.isometryRT("R", "T");
  orthonormalizeRead(&calib.T_velo_imu, imu_to_velo.path, "R");
  const KeyValues velo_to_cam = readKeyValues(date_dir + "/calib_velo_to_cam.txt");
  calib.T_cam0_velo = velo_to_cam.isometryRT("R", "T");
  orthonormalizeRead(&calib.T_cam0_velo, velo_to_cam.path, "R");

  const KeyValues cam_to_cam = readKeyValues(date_dir + "/calib_cam_to_cam.txt");
  calib.cam_to_cam_path = cam_to_cam.path;
  bool any_camera = false;
  for (int i = 0; i < 4; ++i) {
    char suffix[8];
    std::snprintf(suffix, sizeof(suffix), "_%02d", i);
    CameraCalibration& camera = calib.cameras[i];
    if (!cam_to_cam.has(std::string("P_rect") + suffix)) continue;
    camera.present = any_camera = true;
    const auto& s = cam_to_cam.get(std::string("S") + suffix, 2);
    camera.S = Eigen::Vector2d(s[0], s[1]);
    camera.K = cam_to_cam.matrix3(std::string("K") + suffix);
    const auto& d = cam_to_cam.get(std::string("D") + suffix, 5);
    for (int k = 0; k < 5; ++k) camera.D[k] = d[k];
    camera.R = cam_to_cam.matrix3(std::string("R") + suffix);
    const auto& t = cam_to_cam.get(std::string("T") + suffix, 3);
    camera.T = Eigen::Vector3d(t[0], t[1], t[2]);
    const auto& s_rect = cam_to_cam.get(std::string("S_rect") + suffix, 2);
    camera.S_rect = Eigen::Vector2d(s_rect[0], s_rect[1]);
    if (!(s_rect[0] >= 1 && s_rect[0] <= 100000 && s_rect[1] >= 1 && s_rect[1] <= 100000)) {
      throw KittiFormatError(
          cam_to_cam.path, cam_to_cam.line_of.at(std::string("S_rect") + suffix),
          std::string("'S_rect") + suffix + "' must be an image size in [1, 100000]");
    }
    camera.R_rect = cam_to_cam.rotation3(std::string("R_rect") + suffix);
    camera.P_rect = cam_to_cam.projection34(std::string("P_rect") + suffix);
  }
  if (!any_camera) throw KittiFormatError(cam_to_cam.path, "no P_rect_0N camera entries");
  return calib;
}

CameraProjection ObjectCalibration::projection(int camera_index, int width, int height) const {
  if (camera_index < 0 || camera_index >= 4) {
    throw std::out_of_range("ObjectCalibration::projection: camera index " +
                            std::to_string(camera_index));
  }
  CameraProjection projection;
  projection.P_rect = P[camera_index];
  projection.R_rect = R0_rect;
  projection.T_cam0_velo = Tr_velo_to_cam;
  projection.width = width;
  projection.height = height;
  return projection;
}

ObjectCalibration readObjectCalibration(const std::string& calib_txt) {
  const KeyValues kv = readKeyValues(calib_txt);
  ObjectCalibration calib;
  for (int i = 0; i < 4; ++i) calib.P[i] = kv.projection34("P" + std::to_string(i));
  if (kv.has("R0_rect")) {
    calib.R0_rect = kv.rotation3("R0_rect");
  } else if (kv.has("Tr_velo_to_cam")) {
    // The object format always has it (the odometry format, with "Tr", has none: identity). A
    // file without it is cut short; identity projected every point a little off, silently.
    throw KittiFormatError(calib_txt,
                           "missing key 'R0_rect' (the object format's "
                           "'Tr_velo_to_cam' goes with it)");
  }
  if (kv.has("Tr_velo_to_cam")) {
    calib.Tr_velo_to_cam = kv.isometry34("Tr_velo_to_cam");
  } else if (kv.has("Tr")) {  // odometry / SemanticKITTI calib.txt
    calib.Tr_velo_to_cam = kv.isometry34("Tr");
  } else {
    throw KittiFormatError(calib_txt, "missing key 'Tr_velo_to_cam' (or odometry 'Tr')");
  }
  orthonormalizeRead(&calib.Tr_velo_to_cam, calib_txt,
                     kv.has("Tr_velo_to_cam") ? "Tr_velo_to_cam" : "Tr");
  calib.has_imu_to_velo = kv.has("Tr_imu_to_velo");
  if (calib.has_imu_to_velo) {
    calib.Tr_imu_to_velo = kv.isometry34("Tr_imu_to_velo");
    orthonormalizeRead(&calib.Tr_imu_to_velo, calib_txt, "Tr_imu_to_velo");
  }
  return calib;
}

}  // namespace kitti
}  // namespace inekf_semantic_mapping
