// Runs the Localizer over a KITTI raw OXTS sequence under the evaluation protocol: the one
// implementation behind inekf_offline, the real-drive tests and the benchmark.
//
// Each frame becomes the events inekf_node gets from kitti2bag / kitti_player, in stamp order,
// fed to the same LocalizationSession: the IMU sample (ax..az, wx..wz, with the OXTS
// orientation roll/pitch/yaw, plus an optional injected yaw error), the GPS velocity (ve, vn,
// vu, map frame) and the (degraded) lat/lon/alt fix. The session starts the filter at the first
// fix with that frame's orientation and velocity, as the node does; after the start only the
// IMU samples and the fixes are used. A frame that carries no attitude (kitti::carriesAttitude:
// its attitude and velocity columns all exactly zero, or imu_gps_only) gives an IMU sample
// without an orientation and no GPS velocity: the filter starts levelled from gravity with an
// unknown yaw, as inekf_node does for an Imu message without orientation. The map origin is frame
// 0's OXTS position (the truth's). Frames with posmode < 0 (KITTI filled them by interpolation) are
// fed as `interpolated` samples, so their IMU noise is inflated.
#pragma once

#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/estimation/error_dynamics.h"
#include "inekf_semantic_mapping/estimation/localization_session.h"
#include "inekf_semantic_mapping/kitti/gps_degradation.h"
#include "inekf_semantic_mapping/kitti/oxts.h"

namespace inekf_semantic_mapping {
namespace estimation {

struct OxtsRunOptions {
  LocalizationSessionConfig config;  // its origin is replaced by frame 0's
  kitti::GpsDegradationOptions gps;
  double init_yaw_error_deg = 0.0;  // added to frame 0's yaw (tests convergence)
  // The OXTS solution's attitude and velocity columns are dropped (zeroed) before the session
  // sees them: only the IMU and the GPS position are left (inekf_offline --imu-gps-only).
  bool imu_gps_only = false;
  // > 0: simulated wheel odometry, each frame's OXTS forward velocity vf plus N(0, this) as a
  // wheel speed after its IMU sample (seeded by gps.seed; kept with imu_gps_only: the wheels do
  // not come from the INS solution). 0: none, as on KITTI.
  double wheel_speed_sigma_mps = 0.0;
  // After the causal run, a Rauch-Tung-Striebel pass over it (estimation/smoother.h): states and
  // pose covariances become the smoothed ones. Needs the left-invariant filter.
  bool smooth = false;
  // With smooth, when the run started without a usable heading (no attitude in the start frame,
  // or a reference heading the monitor had to re-initialise): once the forward run's heading has
  // settled (yaw sigma <= settled_yaw_sigma_deg for 30 s or to the end, no heading event), its
  // orientation there is carried back to the start frame through the gyro (the bias estimated
  // there) and the run is repeated from that start (yaw sigma: the settled sigma plus the bias's
  // drift). The smoothed frames before the alignment then have the heading as well: an offline
  // smoother knows the future. inekf_offline --single-pass turns it off.
  bool second_pass = true;
  double settled_yaw_sigma_deg = 2.0;
};

struct OxtsRunResult {
  std::vector<NavState> states;                  // one per OXTS frame
  std::vector<PoseCovariance> pose_covariances;  // one per OXTS frame (see NavigationFilter)
  std::vector<Eigen::Isometry3d> truth;          // T_map_imu from the OXTS solution
  LocalizationSession::Statistics statistics;
  int fixes_offered = 0;  // fixes the degrader produced
  // The frame the filter started at (its first fix); earlier frames repeat the start's state
  // and are left out of compareWithTruth. states.size() when it never started.
  int first_estimated_frame = 0;
  // Frames after the start without an estimate at their own stamp, ascending: the filter had
  // been reset (an IMU gap, a non-finite state) and not yet restarted, or the session dropped
  // the frame's IMU sample (the first of a jump forward). They repeat the last estimate and are
  // left out of compareWithTruth.
  std::vector<int> held_frames;
  // Frames whose stamps alone were off (kitti::isolatedMisstampedFrames: one bad line of
  // timestamps.txt or a few in a row): not fed to the filter,
  // held (above) once it runs.
  std::vector<int> misstamped_frames;
  bool smoothed = false;    // the states are the smoother's
  int smoother_breaks = 0;  // IMU steps the smoother could not reproduce (segments restarted)
  // With smoothing, one per OXTS frame (frames before the start repeat it, with a zero gain):
  // the smoothed 15x15 left-invariant covariance and the RTS gain G_k to the next frame, from
  // which the loop closure takes relative-pose covariances (estimation/smoother.h).
  std::vector<Matrix15d> smoothed_covariances;
  std::vector<Matrix15d> smoother_gains;
  // The fixes the filter was given after its start, in the map frame (the GPS factors of a pose
  // graph), with the OXTS frame each belongs to.
  struct Fix {
    int frame = 0;
    PositionFix fix;
  };
  std::vector<Fix> fixes;
  // The session's notes of its heading alignments, recoveries and re-opens and of its resets,
  // once each, in order (inekf_offline prints them; inekf_node logs them).
  std::vector<std::string> heading_notes;
  // The second pass (OxtsRunOptions::second_pass): whether it ran, the frame whose heading it
  // carried back and the start's yaw sigma it used; the notes above are then the second pass's,
  // after one line saying so (or why there was none).
  bool second_pass = false;
  int second_pass_reference_frame = -1;
  double second_pass_yaw_sigma_deg = 0.0;
};

// The evaluation protocol's GPS (scripts/run_inekf_protocol.sh): the OXTS fix plus N(0, 1.5 m)
// horizontal and N(0, 3 m) vertical noise, once a second (every 10th frame), seed 1.
kitti::GpsDegradationOptions protocolGps();

// The fix event a receiver reporting `fix` at `stamp_s` gives the session (diagonal ENU
// covariance from its horizontal and vertical sigmas): what kitti_player/kitti2bag publish.
GeodeticFixEvent fixEventFromDegraded(const kitti::GeodeticFix& fix, double stamp_s);

// Throws std::invalid_argument on an empty sequence, or smoothing with another filter than left.
OxtsRunResult runLocalizerOnOxts(const std::vector<kitti::OxtsFrame>& frames,
                                 const OxtsRunOptions& options);

// Quick accuracy figures against the truth (unaligned): RMS position error, RMS of the rotation
// error angle, RMS yaw error; over frames [first, last) (last < 0: to the end) from the
// first estimated frame on.
struct TrajectoryErrors {
  double ate_m = 0.0;
  double rotation_rmse_deg = 0.0;
  double yaw_rmse_deg = 0.0;
};
TrajectoryErrors compareWithTruth(const OxtsRunResult& run, int first = 0, int last = -1);

// The mean error of the fixes the filter was given (fix minus the OXTS truth at its frame, map
// frame, m) and how many. A position averaged over all of them is off by this much: it is the
// ATE of an estimator that knew the car's relative motion exactly and took its absolute position
// from these fixes alone, the floor no smoother of this run can beat on average.
struct FixErrorMean {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  int fixes = 0;
};
FixErrorMean meanFixError(const OxtsRunResult& run);

// Signed yaw error (deg, in (-180, 180]) of frame k: heading of the estimate minus the truth's.
double yawErrorDeg(const OxtsRunResult& run, int frame);

// The direction of travel in the IMU frame, as the estimated velocity shows it: medians of the
// body velocity's elevation (towards +z) and azimuth (towards +y) over the states moving forward
// at min_speed_mps or more (slower, sensor noise and standstill dominate). From a smoothed
// GPS-aided run it calibrates the land-vehicle constraint's vehicle frame
// (LocalizerConfig::nonholonomic_vehicle_pitch_deg / _yaw_deg) without any ground truth.
struct TravelDirection {
  int samples = 0;  // states used; 0: none fast enough (the angles are then 0)
  double pitch_deg = 0.0, yaw_deg = 0.0;
};
TravelDirection travelDirectionInImu(const std::vector<NavState>& states,
                                     double min_speed_mps = 3.0);

}  // namespace estimation
}  // namespace inekf_semantic_mapping
