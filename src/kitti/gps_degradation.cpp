#include "inekf_semantic_mapping/kitti/gps_degradation.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "inekf_semantic_mapping/kitti/mercator.h"

namespace inekf_semantic_mapping {
namespace kitti {
namespace {
constexpr double kPi = 3.14159265358979323846;
}

std::pair<double, double> GpsDegradationOptions::parseOutage(const std::string& text) {
  const auto colon = text.find(':');
  auto fail = [&]() {
    return std::invalid_argument("GPS outage '" + text +
                                 "': expected START:DURATION in seconds, both >= 0");
  };
  if (colon == std::string::npos) throw fail();
  try {
    std::size_t used_start = 0, used_duration = 0;
    const std::string start_text = text.substr(0, colon);
    const std::string duration_text = text.substr(colon + 1);
    const double start = std::stod(start_text, &used_start);
    const double duration = std::stod(duration_text, &used_duration);
    if (used_start != start_text.size() || used_duration != duration_text.size() ||
        !std::isfinite(start) || !std::isfinite(duration) || start < 0 || duration < 0) {
      throw fail();
    }
    return {start, duration};
  } catch (const std::logic_error&) {  // stod's invalid_argument / out_of_range
    throw fail();
  }
}

void GpsDegradationOptions::validate() const {
  if (!std::isfinite(sigma_horizontal_m) || sigma_horizontal_m < 0 ||
      !std::isfinite(sigma_vertical_m) || sigma_vertical_m < 0) {
    throw std::invalid_argument("GPS degradation: sigmas must be finite and >= 0");
  }
  if (every_n_frames < 1) {
    throw std::invalid_argument("GPS degradation: every_n_frames must be >= 1, got " +
                                std::to_string(every_n_frames));
  }
  for (const auto& [start, duration] : outages_s) {
    if (!(start >= 0) || !(duration >= 0)) {
      throw std::invalid_argument("GPS degradation: outage start and duration must be >= 0");
    }
  }
}

GpsDegrader::GpsDegrader(GpsDegradationOptions options)
    : options_(std::move(options)), random_engine_(options_.seed) {
  options_.validate();
}

bool GpsDegrader::inOutage(double t) const {
  return std::any_of(options_.outages_s.begin(), options_.outages_s.end(),
                     [t](const auto& o) { return t >= o.first && t < o.first + o.second; });
}

double GpsDegrader::standardNormal() {
  if (has_spare_normal_) {
    has_spare_normal_ = false;
    return spare_normal_;
  }
  // 53-bit uniforms in (0, 1]: log(0) is impossible.
  const double u1 = (static_cast<double>(random_engine_() >> 11) + 1.0) * 0x1.0p-53;
  const double u2 = static_cast<double>(random_engine_() >> 11) * 0x1.0p-53;
  const double radius = std::sqrt(-2.0 * std::log(u1));
  spare_normal_ = radius * std::sin(2.0 * kPi * u2);
  has_spare_normal_ = true;
  return radius * std::cos(2.0 * kPi * u2);
}

std::optional<GeodeticFix> GpsDegrader::degrade(std::size_t frame_index,
                                                double seconds_since_first_frame,
                                                const OxtsRecord& record) {
  if (record.posmode <= 0) return std::nullopt;  // no GPS solution: INS dead reckoning only
  if (!std::isfinite(record.lat) || !std::isfinite(record.lon) || !std::isfinite(record.alt)) {
    return std::nullopt;
  }
  if (frame_index % static_cast<std::size_t>(options_.every_n_frames) != 0) return std::nullopt;
  if (inOutage(seconds_since_first_frame)) return std::nullopt;

  GeodeticFix fix;
  const double east_m =
      options_.sigma_horizontal_m > 0 ? options_.sigma_horizontal_m * standardNormal() : 0.0;
  const double north_m =
      options_.sigma_horizontal_m > 0 ? options_.sigma_horizontal_m * standardNormal() : 0.0;
  const double up_m =
      options_.sigma_vertical_m > 0 ? options_.sigma_vertical_m * standardNormal() : 0.0;
  // Metres to degrees at this latitude on the devkit's sphere (the same radius as the map
  // projection, so the noise in the map frame has the requested sigma).
  const double metres_per_degree = kEarthRadiusM * kPi / 180.0;
  fix.lat_deg = record.lat + north_m / metres_per_degree;
  fix.lon_deg = record.lon + east_m / (metres_per_degree * std::cos(record.lat * kPi / 180.0));
  fix.alt_m = record.alt + up_m;
  const double reported = std::isfinite(record.pos_accuracy) ? record.pos_accuracy : 0.0;
  fix.sigma_horizontal_m = std::max(options_.sigma_horizontal_m, reported);
  fix.sigma_vertical_m = std::max(options_.sigma_vertical_m, reported);
  return fix;
}

}  // namespace kitti
}  // namespace inekf_semantic_mapping
