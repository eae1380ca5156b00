#include "inekf_semantic_mapping/kitti/velodyne.h"

#include <cmath>
#include <filesystem>
#include <fstream>

#include "inekf_semantic_mapping/kitti/errors.h"
#include "text_parsing.h"

namespace inekf_semantic_mapping {
namespace kitti {
namespace {

std::vector<char> readBinaryFile(const std::string& path, std::size_t record_bytes,
                                 const char* what) {
  if (std::filesystem::is_directory(path)) throw KittiFormatError(path, "is a folder, not a file");
  std::ifstream stream(path, std::ios::binary | std::ios::ate);
  if (!stream) throw KittiFormatError(path, "cannot open file (missing or unreadable)");
  const std::streamsize size = stream.tellg();
  if (size < 0 || static_cast<std::size_t>(size) % record_bytes != 0) {
    throw KittiFormatError(path, "size " + std::to_string(size) + " bytes is not a multiple of " +
                                     std::to_string(record_bytes) + " (" + what + ")");
  }
  std::vector<char> bytes(static_cast<std::size_t>(size));
  stream.seekg(0);
  if (size > 0 && !stream.read(bytes.data(), size)) {
    throw KittiFormatError(path, "read error");
  }
  return bytes;
}

}  // namespace

VelodyneScan readVelodyneBin(const std::string& path) {
  static_assert(sizeof(float) == 4, "KITTI .bin stores float32");
  const std::vector<char> bytes = readBinaryFile(path, 16, "float32 x y z reflectance per point");
  VelodyneScan scan;
  scan.xyzi.resize(bytes.size() / sizeof(float));
  std::copy(bytes.begin(), bytes.end(), reinterpret_cast<char*>(scan.xyzi.data()));
  return scan;
}

VelodyneScan readVelodyneText(const std::string& path) {
  std::ifstream stream = detail::openOrThrow(path);
  VelodyneScan scan;
  std::string line;
  int line_number = 0;
  while (std::getline(stream, line)) {
    ++line_number;
    const auto tokens = detail::splitWhitespace(line);
    if (tokens.empty()) continue;
    if (tokens.size() != 4) {
      throw KittiFormatError(path, line_number,
                             "expected 4 values (x y z r), found " + std::to_string(tokens.size()));
    }
    for (const auto& token : tokens) {
      double v;
      if (!detail::parseDouble(token, &v)) {
        throw KittiFormatError(path, line_number, "value '" + token + "' is not a number");
      }
      scan.xyzi.push_back(static_cast<float>(v));
    }
  }
  return scan;
}

VelodyneScan readVelodyneScan(const std::string& path) {
  const std::string extension = std::filesystem::path(path).extension().string();
  if (extension == ".bin") return readVelodyneBin(path);
  if (extension == ".txt") return readVelodyneText(path);
  throw KittiFormatError(
      path, "unknown velodyne scan extension '" + extension + "' (expected .bin or .txt)");
}

std::vector<std::uint32_t> readLabelFile(const std::string& path) {
  const std::vector<char> bytes = readBinaryFile(path, 4, "uint32 per point");
  std::vector<std::uint32_t> labels(bytes.size() / 4);
  std::copy(bytes.begin(), bytes.end(), reinterpret_cast<char*>(labels.data()));
  return labels;
}

std::vector<std::uint16_t> computeRings(const VelodyneScan& scan, int num_beams) {
  constexpr double kHalfPi = 1.57079632679489661923;
  const std::size_t n = scan.size();
  std::vector<std::uint16_t> rings(n, 0);
  if (n == 0 || num_beams <= 0) return rings;
  const auto max_ring = static_cast<std::uint16_t>(num_beams - 1);
  std::uint16_t ring = 0;
  // A laser sweeps counter-clockwise from the front (azimuth 0) round to the front again; the
  // next laser starts where the azimuth crosses from negative to non-negative. Requiring that
  // the current ring has visited the right rear quadrant first ignores jitter around 0.
  bool visited_rear_right = false;
  double previous_azimuth = std::atan2(scan.point(0)[1], scan.point(0)[0]);
  for (std::size_t i = 0; i < n; ++i) {
    const float* p = scan.point(i);
    const double azimuth = std::atan2(p[1], p[0]);
    if (i > 0 && visited_rear_right && previous_azimuth < 0 && azimuth >= 0 &&
        previous_azimuth > -kHalfPi && azimuth < kHalfPi) {
      if (ring < max_ring) ++ring;
      visited_rear_right = false;
    }
    if (azimuth < -kHalfPi) visited_rear_right = true;
    rings[i] = ring;
    previous_azimuth = azimuth;
  }
  return rings;
}

}  // namespace kitti
}  // namespace inekf_semantic_mapping
