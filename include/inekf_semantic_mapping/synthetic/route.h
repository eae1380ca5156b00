// The synthetic car's drive: a closed counter-clockwise loop around one town block (straights
// joined by 90-degree left turns with smooth curvature ramps), driven with a speed profile that
// starts at rest and has stops, over the world's hilly ground.
//
// Smoothness (so that the IMU is well defined): the curvature ramps and the speed changes use
// the quintic smootherstep, so heading, position and speed have continuous second derivatives.
// Position, velocity and acceleration are analytic; the body angular rate is the 4th-order
// central difference of the rotation (error ~1e-12 rad/s).
#pragma once

#include <Eigen/Core>
#include <vector>

#include "inekf_semantic_mapping/synthetic/world.h"

namespace inekf_semantic_mapping {
namespace synthetic {

constexpr double kGravity = 9.81;  // m/s^2; specific force at rest is +kGravity along body z

// Geometry of the loop in the horizontal plane. The route starts at the origin heading east
// in the middle of the bottom straight.
struct RouteLayout {
  double long_straight_m = 20.0;   // bottom and top straights (east-west)
  double short_straight_m = 10.0;  // left and right straights (north-south)
  double turn_radius_m = 15.0;
  double curvature_ramp_m = 6.0;  // curvature goes 0 -> 1/R over this length
  double lane_offset_m = 1.75;    // the street centre line is this far left of the route
  double imu_height_m = 0.93;     // OXTS unit above the ground (KITTI rig)
};

// The truth of the IMU (= OXTS = base_link) at one time, in the map frame.
struct VehicleState {
  double time_s = 0;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
  Eigen::Vector3d acceleration = Eigen::Vector3d::Zero();  // kinematic, map frame
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();  // R_map_imu = Rz(yaw)Ry(pitch)Rx(roll)
  double roll = 0, pitch = 0, yaw = 0;                     // KITTI conventions, yaw in (-pi, pi]
  Eigen::Vector3d angular_velocity_body = Eigen::Vector3d::Zero();  // rad/s, IMU frame

  // What a perfect IMU measures: R^T (a - g), g = (0, 0, -kGravity).
  Eigen::Vector3d specificForceBody() const;
};

// Speed keyframes: speed is held between keyframes and blended with smootherstep inside.
struct SpeedKeyframe {
  double time_s;
  double speed_mps;
};

class SyntheticRoute {
 public:
  SyntheticRoute(const RouteLayout& layout, const GroundSurface& ground);
  // The default layout on the given world's ground (what generateTown() laid its streets for).
  static SyntheticRoute forWorld(const SyntheticWorld& world);

  VehicleState stateAt(double time_s) const;
  // As stateAt() without the angular velocity (left zero): 5x cheaper, for sensor poses.
  VehicleState poseAt(double time_s) const;

  // Default speed profile: at rest 0.5 s, 8 m/s cruise, a stop of 1.5 s at ~10 s, and another
  // stop every 30 s after.
  static std::vector<SpeedKeyframe> defaultSpeedProfile();

  // The horizontal street centre lines the loop drives on (left, right, bottom, top).
  struct LoopStreets {
    double left_x, right_x, bottom_y, top_y;
  };
  static LoopStreets loopStreets(const RouteLayout& layout);

  double loopLength() const { return loop_length_; }
  double distanceAt(double time_s) const;  // arc length driven since t = 0
  const RouteLayout& layout() const { return layout_; }

 private:
  struct Piece {  // one piece of the curvature profile
    double s0, length;
    int kind;  // 0 straight, 1 ramp up, 2 arc, 3 ramp down
    double heading0;
    Eigen::Vector2d start;
  };
  // Horizontal geometry at arc length s: position, unit tangent, curvature.
  void planarAt(double s, Eigen::Vector2d* position, double* heading, double* curvature) const;
  void planarOnPiece(const Piece& piece, double sigma, Eigen::Vector2d* position, double* heading,
                     double* curvature) const;
  double speedAt(double time_s, double* accel) const;

  RouteLayout layout_;
  GroundSurface ground_;
  std::vector<Piece> pieces_;
  double loop_length_ = 0;
  std::vector<SpeedKeyframe> speed_profile_;
  std::vector<double> distance_at_keyframe_;
};

}  // namespace synthetic
}  // namespace inekf_semantic_mapping
