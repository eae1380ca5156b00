#include "inekf_semantic_mapping/synthetic/route.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace inekf_semantic_mapping {
namespace synthetic {
namespace {

enum PieceKind { kStraight = 0, kRampUp = 1, kArc = 2, kRampDown = 3 };

// Quintic smootherstep and its integral / derivative: zero 1st and 2nd derivatives at both ends,
// which is what keeps heading and speed C2 across pieces.
double smootherstep(double u) { return u * u * u * (u * (6 * u - 15) + 10); }
double smootherstepIntegral(double u) { return u * u * u * u * (u * (u - 3) + 2.5); }
double smootherstepDerivative(double u) { return 30 * u * u * (u - 1) * (u - 1); }

// 5-point Gauss-Legendre nodes/weights on [-1, 1].
constexpr double kGaussNodes[5] = {-0.9061798459386640, -0.5384693101056831, 0.0,
                                   0.5384693101056831, 0.9061798459386640};
constexpr double kGaussWeights[5] = {0.2369268850561891, 0.4786286704993665, 0.5688888888888889,
                                     0.4786286704993665, 0.2369268850561891};

double wrapAngle(double a) {
  a = std::fmod(a + M_PI, 2 * M_PI);
  if (a <= 0) a += 2 * M_PI;
  return a - M_PI;
}

Eigen::Matrix3d rotationRollPitchYaw(double roll, double pitch, double yaw) {
  return (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

}  // namespace

Eigen::Vector3d VehicleState::specificForceBody() const {
  return rotation.transpose() * (acceleration + Eigen::Vector3d(0, 0, kGravity));
}

SyntheticRoute::SyntheticRoute(const RouteLayout& layout, const GroundSurface& ground)
    : layout_(layout), ground_(ground), speed_profile_(defaultSpeedProfile()) {
  const double arc_length = M_PI / 2 * layout.turn_radius_m - layout.curvature_ramp_m;
  if (layout.turn_radius_m <= 0 || layout.curvature_ramp_m <= 0 || arc_length < 0 ||
      layout.long_straight_m <= 0 || layout.short_straight_m <= 0) {
    throw std::invalid_argument(
        "RouteLayout: need turn_radius_m > 0, 0 < curvature_ramp_m <= pi/2 * turn_radius_m and "
        "positive straights");
  }
  std::vector<std::pair<int, double>> kinds;
  auto add_turn = [&]() {
    kinds.push_back({kRampUp, layout.curvature_ramp_m});
    if (arc_length > 0) kinds.push_back({kArc, arc_length});
    kinds.push_back({kRampDown, layout.curvature_ramp_m});
  };
  kinds.push_back({kStraight, layout.long_straight_m / 2});
  add_turn();
  kinds.push_back({kStraight, layout.short_straight_m});
  add_turn();
  kinds.push_back({kStraight, layout.long_straight_m});
  add_turn();
  kinds.push_back({kStraight, layout.short_straight_m});
  add_turn();
  kinds.push_back({kStraight, layout.long_straight_m / 2});

  double s = 0, heading = 0;
  Eigen::Vector2d start = Eigen::Vector2d::Zero();
  for (const auto& [kind, length] : kinds) {
    if (length <= 0) continue;
    pieces_.push_back(Piece{s, length, kind, heading, start});
    double end_heading, end_curvature;
    Eigen::Vector2d end_position;
    planarOnPiece(pieces_.back(), length, &end_position, &end_heading, &end_curvature);
    s += length;
    heading = end_heading;
    start = end_position;
  }
  loop_length_ = s;

  distance_at_keyframe_.resize(speed_profile_.size(), 0.0);
  for (std::size_t i = 1; i < speed_profile_.size(); ++i) {
    const SpeedKeyframe& a = speed_profile_[i - 1];
    const SpeedKeyframe& b = speed_profile_[i];
    const double dt = b.time_s - a.time_s;
    distance_at_keyframe_[i] = distance_at_keyframe_[i - 1] + a.speed_mps * dt +
                               (b.speed_mps - a.speed_mps) * dt * smootherstepIntegral(1.0);
  }
}

SyntheticRoute SyntheticRoute::forWorld(const SyntheticWorld& world) {
  return SyntheticRoute(RouteLayout(), world.ground());
}

std::vector<SpeedKeyframe> SyntheticRoute::defaultSpeedProfile() {
  constexpr double kCruise = 8.0;
  std::vector<SpeedKeyframe> keys = {{0.0, 0.0},  {0.5, 0.0},  {3.5, kCruise}, {10.0, kCruise},
                                     {12.5, 0.0}, {14.0, 0.0}, {17.0, kCruise}};
  // A stop every 30 s after the first: enough for hour-long drives.
  for (double stop = 40.0; stop < 4000.0; stop += 30.0) {
    keys.push_back({stop, kCruise});
    keys.push_back({stop + 2.5, 0.0});
    keys.push_back({stop + 4.0, 0.0});
    keys.push_back({stop + 7.0, kCruise});
  }
  return keys;
}

SyntheticRoute::LoopStreets SyntheticRoute::loopStreets(const RouteLayout& layout) {
  const SyntheticRoute route(layout, GroundSurface());
  std::vector<const Piece*> straights;
  for (const Piece& piece : route.pieces_) {
    if (piece.kind == kStraight) straights.push_back(&piece);
  }
  // Straights in driving order: bottom (first half), right, top, left, bottom (second half).
  LoopStreets streets{};
  streets.bottom_y = straights[0]->start.y() + layout.lane_offset_m;
  streets.right_x = straights[1]->start.x() - layout.lane_offset_m;
  streets.top_y = straights[2]->start.y() - layout.lane_offset_m;
  streets.left_x = straights[3]->start.x() + layout.lane_offset_m;
  return streets;
}

void SyntheticRoute::planarAt(double s, Eigen::Vector2d* position, double* heading,
                              double* curvature) const {
  // Whole loops add nothing to the position and 2 pi to the heading.
  const double loops = std::floor(s / loop_length_);
  s = std::clamp(s - loops * loop_length_, 0.0, loop_length_);
  auto it = std::upper_bound(pieces_.begin(), pieces_.end(), s,
                             [](double value, const Piece& p) { return value < p.s0; });
  const Piece& piece = *(it == pieces_.begin() ? it : std::prev(it));
  planarOnPiece(piece, s - piece.s0, position, heading, curvature);
  *heading += 2 * M_PI * loops;
}

void SyntheticRoute::planarOnPiece(const Piece& piece, double sigma, Eigen::Vector2d* position,
                                   double* heading, double* curvature) const {
  const double kappa = 1.0 / layout_.turn_radius_m;
  const double ramp = layout_.curvature_ramp_m;
  sigma = std::clamp(sigma, 0.0, piece.length);

  auto heading_at = [&](double local) {
    switch (piece.kind) {
      case kRampUp:
        return piece.heading0 + kappa * ramp * smootherstepIntegral(local / ramp);
      case kArc:
        return piece.heading0 + kappa * local;
      case kRampDown:
        return piece.heading0 + kappa * ramp * (local / ramp - smootherstepIntegral(local / ramp));
      default:
        return piece.heading0;
    }
  };
  switch (piece.kind) {
    case kRampUp:
      *curvature = kappa * smootherstep(sigma / ramp);
      break;
    case kArc:
      *curvature = kappa;
      break;
    case kRampDown:
      *curvature = kappa * (1 - smootherstep(sigma / ramp));
      break;
    default:
      *curvature = 0;
  }
  const double theta = heading_at(sigma);
  *heading = theta;

  Eigen::Vector2d p = piece.start;
  if (piece.kind == kStraight) {
    p += sigma * Eigen::Vector2d(std::cos(theta), std::sin(theta));
  } else if (piece.kind == kArc) {
    p += Eigen::Vector2d(std::sin(theta) - std::sin(piece.heading0),
                         std::cos(piece.heading0) - std::cos(theta)) /
         kappa;
  } else {
    // Gauss-Legendre on sub-intervals of <= 0.5 m: the integrand is analytic, the error is
    // far below a micrometre.
    const int intervals = std::max(1, static_cast<int>(std::ceil(sigma / 0.5)));
    const double h = sigma / intervals;
    for (int k = 0; k < intervals; ++k) {
      const double mid = (k + 0.5) * h;
      for (int g = 0; g < 5; ++g) {
        const double th = heading_at(mid + 0.5 * h * kGaussNodes[g]);
        p += 0.5 * h * kGaussWeights[g] * Eigen::Vector2d(std::cos(th), std::sin(th));
      }
    }
  }
  *position = p;
}

double SyntheticRoute::speedAt(double time_s, double* accel) const {
  *accel = 0;
  if (time_s <= speed_profile_.front().time_s) return speed_profile_.front().speed_mps;
  if (time_s >= speed_profile_.back().time_s) return speed_profile_.back().speed_mps;
  auto it = std::upper_bound(speed_profile_.begin(), speed_profile_.end(), time_s,
                             [](double value, const SpeedKeyframe& k) { return value < k.time_s; });
  const SpeedKeyframe& b = *it;
  const SpeedKeyframe& a = *std::prev(it);
  const double dt = b.time_s - a.time_s;
  const double u = (time_s - a.time_s) / dt;
  *accel = (b.speed_mps - a.speed_mps) * smootherstepDerivative(u) / dt;
  return a.speed_mps + (b.speed_mps - a.speed_mps) * smootherstep(u);
}

double SyntheticRoute::distanceAt(double time_s) const {
  const SpeedKeyframe& first = speed_profile_.front();
  if (time_s <= first.time_s) return first.speed_mps * (time_s - first.time_s);
  const SpeedKeyframe& last = speed_profile_.back();
  if (time_s >= last.time_s) {
    return distance_at_keyframe_.back() + last.speed_mps * (time_s - last.time_s);
  }
  auto it = std::upper_bound(speed_profile_.begin(), speed_profile_.end(), time_s,
                             [](double value, const SpeedKeyframe& k) { return value < k.time_s; });
  const std::size_t i = static_cast<std::size_t>(std::prev(it) - speed_profile_.begin());
  const SpeedKeyframe& a = speed_profile_[i];
  const SpeedKeyframe& b = *it;
  const double dt = b.time_s - a.time_s;
  const double u = (time_s - a.time_s) / dt;
  return distance_at_keyframe_[i] + a.speed_mps * u * dt +
         (b.speed_mps - a.speed_mps) * dt * smootherstepIntegral(u);
}

VehicleState SyntheticRoute::poseAt(double time_s) const {
  VehicleState state;
  state.time_s = time_s;
  double tangential_accel;
  const double speed = speedAt(time_s, &tangential_accel);
  Eigen::Vector2d p_xy;
  double heading, curvature;
  planarAt(distanceAt(time_s), &p_xy, &heading, &curvature);
  const Eigen::Vector2d tangent(std::cos(heading), std::sin(heading));
  const Eigen::Vector2d normal(-tangent.y(), tangent.x());
  const Eigen::Vector2d v_xy = speed * tangent;
  const Eigen::Vector2d a_xy = tangential_accel * tangent + speed * speed * curvature * normal;

  const Eigen::Vector2d grad = ground_.gradient(p_xy.x(), p_xy.y());
  const Eigen::Matrix2d hess = ground_.hessian(p_xy.x(), p_xy.y());
  state.position << p_xy, ground_.height(p_xy.x(), p_xy.y()) + layout_.imu_height_m;
  state.velocity << v_xy, grad.dot(v_xy);
  state.acceleration << a_xy, v_xy.dot(hess * v_xy) + grad.dot(a_xy);

  // Body x along the ground's slope in the driving direction, body z along the ground normal.
  state.pitch = -std::atan(grad.dot(tangent));
  state.roll = std::atan(std::cos(state.pitch) * grad.dot(normal));
  state.yaw = wrapAngle(heading);
  state.rotation = rotationRollPitchYaw(state.roll, state.pitch, heading);
  return state;
}

VehicleState SyntheticRoute::stateAt(double time_s) const {
  VehicleState state = poseAt(time_s);
  constexpr double h = 1e-3;
  const Eigen::Matrix3d r_dot =
      (-poseAt(time_s + 2 * h).rotation + 8 * poseAt(time_s + h).rotation -
       8 * poseAt(time_s - h).rotation + poseAt(time_s - 2 * h).rotation) /
      (12 * h);
  const Eigen::Matrix3d omega_hat = state.rotation.transpose() * r_dot;
  state.angular_velocity_body =
      0.5 * Eigen::Vector3d(omega_hat(2, 1) - omega_hat(1, 2), omega_hat(0, 2) - omega_hat(2, 0),
                            omega_hat(1, 0) - omega_hat(0, 1));
  return state;
}

}  // namespace synthetic
}  // namespace inekf_semantic_mapping
