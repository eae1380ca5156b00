#include "inekf_semantic_mapping/kitti/poses.h"

#include <cstdio>
#include <fstream>
#include <sstream>

#include "inekf_semantic_mapping/kitti/errors.h"
#include "text_parsing.h"

namespace inekf_semantic_mapping {
namespace kitti {

std::vector<Eigen::Isometry3d> readKittiPoses(const std::string& path) {
  // A folder opens as an empty stream: refused by name (it read as "0 poses").
  std::ifstream in = detail::openOrThrow(path);
  std::vector<Eigen::Isometry3d> poses;
  std::string line;
  int line_number = 0;
  while (std::getline(in, line)) {
    ++line_number;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    const std::vector<std::string> tokens = detail::splitWhitespace(line);
    if (tokens.size() > 12) {
      throw KittiFormatError(
          path, line_number,
          "more than 12 numbers (3x4 row-major pose), extra '" + tokens[12] + "'");
    }
    if (tokens.size() < 12) {
      throw KittiFormatError(
          path, line_number,
          "expected 12 numbers (3x4 row-major pose), got " + std::to_string(tokens.size()));
    }
    Eigen::Matrix<double, 3, 4> pose;
    for (int i = 0; i < 12; ++i) {
      // Each token whole: "1.0abc" read as 1.0 and "nan" stopped the stream ("got 0").
      if (!detail::parseDouble(tokens[i], &pose(i / 4, i % 4))) {
        throw KittiFormatError(
            path, line_number,
            "value " + std::to_string(i + 1) + " '" + tokens[i] + "' is not a number");
      }
    }
    if (!pose.allFinite()) throw KittiFormatError(path, line_number, "non-finite pose");
    const Eigen::Matrix3d R = pose.leftCols<3>();
    if (!((R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() < 1e-3) ||
        !(R.determinant() > 0)) {
      throw KittiFormatError(path, line_number, "the 3x3 part is not a rotation");
    }
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.matrix().topRows<3>() = pose;
    poses.push_back(T);
  }
  return poses;
}

std::string kittiPoseLine(const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  char line[512];
  std::snprintf(line, sizeof(line),
                "%.12e %.12e %.12e %.12e %.12e %.12e %.12e %.12e %.12e %.12e %.12e %.12e\n",
                R(0, 0), R(0, 1), R(0, 2), t.x(), R(1, 0), R(1, 1), R(1, 2), t.y(), R(2, 0),
                R(2, 1), R(2, 2), t.z());
  return line;
}

}  // namespace kitti
}  // namespace inekf_semantic_mapping
