#include "inekf_semantic_mapping/estimation/loop_closure.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>

#include "inekf_semantic_mapping/common/yaml_reader.h"
#include "inekf_semantic_mapping/lie/so3.h"

namespace inekf_semantic_mapping {
namespace estimation {
namespace {

constexpr double kDegToRad = M_PI / 180.0;

Pose3 poseOf(const NavState& state) {
  Pose3 pose;
  pose.rotation = state.rotation;
  pose.position = state.position_map;
  return pose;
}

Pose3 poseOf(const Eigen::Isometry3d& t) {
  Pose3 pose;
  pose.rotation = t.linear();
  pose.position = t.translation();
  return pose;
}

Eigen::Isometry3d isometryOf(const Pose3& pose) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = pose.rotation;
  t.translation() = pose.position;
  return t;
}

// The [rotation; position] block of a 15x15 left-invariant covariance (SE(3) error [phi; rho]).
Matrix6d poseBlock(const Matrix15d& m) {
  static const int idx[6] = {0, 1, 2, 6, 7, 8};
  Matrix6d out;
  for (int r = 0; r < 6; ++r) {
    for (int c = 0; c < 6; ++c) out(r, c) = m(idx[r], idx[c]);
  }
  return out;
}

// Adjoint of an SE(3) pose for errors ordered [phi; rho]: T exp(xi) T^-1 = exp(Ad xi).
Matrix6d adjoint(const Pose3& t) {
  Matrix6d ad = Matrix6d::Zero();
  ad.topLeftCorner<3, 3>() = t.rotation;
  ad.bottomRightCorner<3, 3>() = t.rotation;
  ad.bottomLeftCorner<3, 3>() = lie::hat(t.position) * t.rotation;
  return ad;
}

double seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

Matrix6d symmetricPart(const Matrix6d& m) { return 0.5 * (m + m.transpose()); }

// The nearest positive semi-definite matrix to the symmetric part of m (negative eigenvalues,
// rounding or a difference of informations, clipped to 0).
Matrix6d clippedToPsd(const Matrix6d& m) {
  const Eigen::SelfAdjointEigenSolver<Matrix6d> eig(symmetricPart(m));
  return eig.eigenvectors() * eig.eigenvalues().cwiseMax(0.0).asDiagonal() *
         eig.eigenvectors().transpose();
}

class Graph {
 public:
  Graph(const OxtsRunResult& run, const LoopClosureOptions& options)
      : run_(run), options_(options) {}

  // Covariance of the relative pose of frame b in frame a (residual order [dp in a's frame,
  // dphi]) from the smoothed marginals and cross-covariance, with the odometry floors added
  // (floored) or not. a > b is allowed (the relative pose backwards in time); a == b gives 0.
  Matrix6d relativeCovariance(int a, int b, bool floored = true) const {
    // Cov(xi_a, xi_b) = G_a..G_b-1 P_b for a <= b, its transpose the other way round.
    Matrix15d cross = run_.smoothed_covariances[std::max(a, b)];
    for (int k = std::max(a, b) - 1; k >= std::min(a, b); --k) {
      cross = run_.smoother_gains[k] * cross;
    }
    if (a > b) cross.transposeInPlace();
    const Pose3 ta = poseOf(run_.states[a]), tb = poseOf(run_.states[b]);
    const Pose3 relative = ta.inverse() * tb;
    const Matrix6d ad = adjoint(relative.inverse());
    const Matrix6d pa = poseBlock(run_.smoothed_covariances[a]);
    const Matrix6d pb = poseBlock(run_.smoothed_covariances[b]);
    const Matrix6d cab = poseBlock(cross);
    Matrix6d error = pb + ad * pa * ad.transpose() - cab.transpose() * ad.transpose() - ad * cab;
    // To the residual's coordinates: dt = R_ab rho, dphi = phi.
    Matrix6d m = Matrix6d::Zero();
    m.block<3, 3>(0, 3) = relative.rotation;
    m.block<3, 3>(3, 0) = Eigen::Matrix3d::Identity();
    Matrix6d cov = clippedToPsd(m * error * m.transpose());
    if (!floored) return cov;
    const double fm = options_.odometry_floor_sigma_m;
    const double fr = options_.odometry_floor_sigma_deg * kDegToRad;
    cov.diagonal() +=
        (Vector6d() << fm * fm, fm * fm, fm * fm, fr * fr, fr * fr, fr * fr).finished();
    return cov;
  }

  // Map-frame position covariance of frame k (left-invariant rho is body-frame).
  Eigen::Matrix3d positionCovariance(int k) const {
    const Eigen::Matrix3d& r = run_.states[k].rotation;
    return r * run_.smoothed_covariances[k].block<3, 3>(6, 6) * r.transpose();
  }

 private:
  const OxtsRunResult& run_;
  const LoopClosureOptions& options_;
};

Matrix6d loopCovariance(const LoopClosureOptions& options) {
  const double m = options.loop_sigma_m * options.loop_sigma_m;
  const double r = std::pow(options.loop_sigma_deg * kDegToRad, 2);
  return (Vector6d() << m, m, m, r, r, r).finished().asDiagonal();
}

Matrix6d inverseSpd(const Matrix6d& m) { return m.llt().solve(Matrix6d::Identity()); }

}  // namespace

void LoopClosureOptions::read(common::YamlReader* reader) {
  const auto number = [reader](const std::string& key, double* out) {
    reader->read("loop_closure." + key, out);
  };
  number("keyframe_spacing_m", &keyframe_spacing_m);
  number("keyframe_max_interval_s", &keyframe_max_interval_s);
  number("min_time_gap_s", &min_time_gap_s);
  number("min_travel_gap_m", &min_travel_gap_m);
  number("search_radius_m", &search_radius_m);
  number("search_sigmas", &search_sigmas);
  number("max_search_radius_m", &max_search_radius_m);
  number("query_spacing_m", &query_spacing_m);
  number("max_fitness_m2", &max_fitness_m2);
  number("loop_sigma_m", &loop_sigma_m);
  number("loop_sigma_deg", &loop_sigma_deg);
  number("gate_chi2", &gate_chi2);
  number("outlier_chi2", &outlier_chi2);
  std::string kernel_name = toString(kernel);
  reader->read("loop_closure.robust_kernel", &kernel_name);
  try {
    kernel = robustKernelFromString(kernel_name);
  } catch (const std::invalid_argument& error) {
    reader->fail("loop_closure.robust_kernel", error.what());
  }
  number("kernel_scale", &kernel_scale);
  number("odometry_floor_sigma_m", &odometry_floor_sigma_m);
  number("odometry_floor_sigma_deg", &odometry_floor_sigma_deg);
  reader->read("loop_closure.max_iterations", &max_iterations);
  reader->read("loop_closure.max_outlier_rounds", &max_outlier_rounds);
  reader->read("loop_closure.tilt_priors", &tilt_priors);
  try {
    validate();
  } catch (const std::invalid_argument& error) {
    reader->fail("loop_closure", error.what());
  }
}

void LoopClosureOptions::validate() const {
  const auto positive = [](double value, const char* name) {
    if (!(value > 0.0)) {
      throw std::invalid_argument(std::string(name) + " must be a positive number");
    }
  };
  const auto non_negative = [](double value, const char* name) {
    if (!(value >= 0.0)) throw std::invalid_argument(std::string(name) + " must be >= 0");
  };
  positive(keyframe_spacing_m, "keyframe_spacing_m");
  positive(keyframe_max_interval_s, "keyframe_max_interval_s");
  non_negative(min_time_gap_s, "min_time_gap_s");
  non_negative(min_travel_gap_m, "min_travel_gap_m");
  positive(search_radius_m, "search_radius_m");
  non_negative(search_sigmas, "search_sigmas");
  positive(max_search_radius_m, "max_search_radius_m");
  non_negative(query_spacing_m, "query_spacing_m");
  positive(max_fitness_m2, "max_fitness_m2");
  positive(loop_sigma_m, "loop_sigma_m");
  positive(loop_sigma_deg, "loop_sigma_deg");
  positive(gate_chi2, "gate_chi2");
  positive(outlier_chi2, "outlier_chi2");
  positive(kernel_scale, "kernel_scale");
  non_negative(odometry_floor_sigma_m, "odometry_floor_sigma_m");
  non_negative(odometry_floor_sigma_deg, "odometry_floor_sigma_deg");
  if (max_iterations < 1) throw std::invalid_argument("max_iterations must be >= 1");
  if (max_outlier_rounds < 0) throw std::invalid_argument("max_outlier_rounds must be >= 0");
}

LoopClosureResult closeLoops(const OxtsRunResult& run, const std::vector<bool>& frame_has_scan,
                             const Eigen::Isometry3d& T_imu_sensor,
                             const ScanRegistration& registration,
                             const LoopClosureOptions& options) {
  options.validate();
  const int frames = static_cast<int>(run.states.size());
  if (!run.smoothed || static_cast<int>(run.smoothed_covariances.size()) != frames ||
      static_cast<int>(run.smoother_gains.size()) != frames) {
    throw std::invalid_argument("loop closure needs a smoothed run (--smooth)");
  }
  if (!frame_has_scan.empty() && static_cast<int>(frame_has_scan.size()) != frames) {
    throw std::invalid_argument("loop closure: frame_has_scan has " +
                                std::to_string(frame_has_scan.size()) + " entries for " +
                                std::to_string(frames) + " frames");
  }
  LoopClosureResult result;
  result.states = run.states;
  result.pose_covariances = run.pose_covariances;
  const Graph helper(run, options);
  const auto has_scan = [&](int k) { return frame_has_scan.empty() || frame_has_scan[k]; };

  // Keyframes along the estimated path.
  std::vector<double> travel(frames, 0.0);  // estimated path length driven to each frame
  for (int k = 1; k < frames; ++k) {
    travel[k] =
        travel[k - 1] + (run.states[k].position_map - run.states[k - 1].position_map).norm();
  }
  for (int k = run.first_estimated_frame; k < frames; ++k) {
    if (!has_scan(k)) continue;
    if (result.keyframes.empty() ||
        travel[k] - travel[result.keyframes.back()] >= options.keyframe_spacing_m ||
        run.states[k].stamp_s - run.states[result.keyframes.back()].stamp_s >=
            options.keyframe_max_interval_s) {
      result.keyframes.push_back(k);
    }
  }
  const int nodes = static_cast<int>(result.keyframes.size());
  if (nodes < 2) return result;

  PoseGraph graph;
  for (int frame : result.keyframes) graph.addNode(poseOf(run.states[frame]));
  // Odometry between consecutive keyframes: the smoothed relative pose and its covariance.
  for (int n = 0; n + 1 < nodes; ++n) {
    const int a = result.keyframes[n], b = result.keyframes[n + 1];
    RelativePoseFactor factor;
    factor.from = n;
    factor.to = n + 1;
    factor.measurement = poseOf(run.states[a]).inverse() * poseOf(run.states[b]);
    factor.information = inverseSpd(helper.relativeCovariance(a, b));
    graph.addRelative(factor);
  }
  // A weak prior on the first keyframe (its smoothed covariance x 1e4): only an anchor for a
  // graph without fixes.
  {
    PosePriorFactor prior;
    prior.node = 0;
    prior.pose = poseOf(run.states[result.keyframes[0]]);
    Matrix6d cov = Matrix6d::Zero();
    const Matrix6d p = poseBlock(run.smoothed_covariances[result.keyframes[0]]);
    const Eigen::Matrix3d& r = run.states[result.keyframes[0]].rotation;
    cov.topLeftCorner<3, 3>() = r * p.bottomRightCorner<3, 3>() * r.transpose();
    cov.bottomRightCorner<3, 3>() = p.topLeftCorner<3, 3>();
    cov = 1e4 * cov + 1e-6 * Matrix6d::Identity();
    prior.information = inverseSpd(cov);
    graph.addPrior(prior);
  }
  // Roll and pitch priors at every keyframe from the smoothed marginals: gravity makes the tilt
  // observable to the filter, which relative factors and GPS positions alone would not tell the
  // graph (loops would tilt the trajectory within the chain's relative uncertainty).
  if (options.tilt_priors) {
    for (int n = 0; n < nodes; ++n) {
      const int frame = result.keyframes[n];
      const Eigen::Matrix3d& r = run.states[frame].rotation;
      // Map-frame small angle of the left-invariant (body) error: R phi.
      const Eigen::Matrix3d map_cov =
          r * run.smoothed_covariances[frame].topLeftCorner<3, 3>() * r.transpose();
      const Eigen::Matrix2d tilt_cov = map_cov.topLeftCorner<2, 2>();
      const Eigen::LLT<Eigen::Matrix2d> llt(tilt_cov);
      if (llt.info() != Eigen::Success) continue;
      Eigen::Matrix3d map_information = Eigen::Matrix3d::Zero();
      map_information.topLeftCorner<2, 2>() = llt.solve(Eigen::Matrix2d::Identity());
      PosePriorFactor prior;
      prior.node = n;
      prior.pose = poseOf(run.states[frame]);
      prior.information.setZero();
      // The prior's residual is the body-frame angle Log(R0^T R); map-frame = R0 of it.
      prior.information.bottomRightCorner<3, 3>() = r.transpose() * map_information * r;
      graph.addPrior(prior);
    }
  }
  // GPS factors at the keyframe nearest in time, moved along the smoothed trajectory.
  for (const OxtsRunResult::Fix& fix : run.fixes) {
    if (fix.frame < 0 || fix.frame >= frames) continue;
    const auto after =
        std::lower_bound(result.keyframes.begin(), result.keyframes.end(), fix.frame);
    int node = static_cast<int>(after - result.keyframes.begin());
    if (node == nodes ||
        (node > 0 &&
         run.states[fix.frame].stamp_s - run.states[result.keyframes[node - 1]].stamp_s <
             run.states[result.keyframes[node]].stamp_s - run.states[fix.frame].stamp_s)) {
      --node;
    }
    const int frame = result.keyframes[node];
    if (std::abs(run.states[frame].stamp_s - run.states[fix.frame].stamp_s) >
        options.keyframe_max_interval_s) {
      continue;
    }
    PositionFactor factor;
    factor.node = node;
    factor.position = fix.fix.position_map +
                      (run.states[frame].position_map - run.states[fix.frame].position_map);
    factor.information = fix.fix.covariance_map.inverse();
    graph.addPosition(factor);
    ++result.gps_factors;
  }

  // Loop candidates, registration and the gate.
  const auto registration_start = std::chrono::steady_clock::now();
  const Matrix6d loop_information = inverseSpd(loopCovariance(options));
  std::vector<int> loop_factor;  // graph index of the relative factor per accepted loop record
  std::vector<int> loop_record;  // record index per loop factor
  double last_query_travel = -std::numeric_limits<double>::infinity();
  for (int j = 1; j < nodes; ++j) {
    const int fj = result.keyframes[j];
    if (travel[fj] - last_query_travel < options.query_spacing_m) continue;
    int best = -1;
    double best_distance = 0.0, best_sigma = 0.0;
    const Eigen::Matrix3d cov_j = helper.positionCovariance(fj);
    for (int i = 0; i < j; ++i) {
      const int fi = result.keyframes[i];
      if (run.states[fj].stamp_s - run.states[fi].stamp_s < options.min_time_gap_s) break;
      if (travel[fj] - travel[fi] < options.min_travel_gap_m) break;
      const Eigen::Vector3d d = run.states[fj].position_map - run.states[fi].position_map;
      const double distance = d.norm();
      if (distance > options.max_search_radius_m) continue;
      const Eigen::Vector3d u =
          distance > 1e-9 ? Eigen::Vector3d(d / distance) : Eigen::Vector3d::UnitX();
      const double sigma =
          std::sqrt(std::max(0.0, u.dot((cov_j + helper.positionCovariance(fi)) * u)));
      const double radius = std::min(options.max_search_radius_m,
                                     options.search_radius_m + options.search_sigmas * sigma);
      if (distance <= radius && (best < 0 || distance < best_distance)) {
        best = i;
        best_distance = distance;
        best_sigma = sigma;
      }
    }
    if (best < 0) continue;
    last_query_travel = travel[fj];
    const int fi = result.keyframes[best];
    LoopRecord record;
    record.query_frame = fj;
    record.match_frame = fi;
    record.time_gap_s = run.states[fj].stamp_s - run.states[fi].stamp_s;
    record.distance_m = best_distance;
    record.distance_sigma_m = best_sigma;
    const Pose3 ti = poseOf(run.states[fi]), tj = poseOf(run.states[fj]);
    const Eigen::Isometry3d guess =
        (isometryOf(ti) * T_imu_sensor).inverse() * (isometryOf(tj) * T_imu_sensor);
    const ScanRegistrationResult registered = registration(fi, fj, guess);
    record.registered = registered.converged;
    record.fitness_m2 = registered.fitness_m2;
    const Pose3 measured =
        poseOf(T_imu_sensor * registered.target_from_source * T_imu_sensor.inverse());
    const Vector6d residual = PoseGraph::relativeResidual(ti, tj, measured);
    record.correction_m = residual.head<3>().norm();
    record.correction_deg = residual.tail<3>().norm() / kDegToRad;
    if (!registered.converged || !measured.rotation.allFinite() || !measured.position.allFinite()) {
      record.reason = "registration did not converge";
    } else if (!(registered.fitness_m2 <= options.max_fitness_m2)) {
      char text[96];
      std::snprintf(text, sizeof(text), "fitness %.3f m^2 > %.3f", registered.fitness_m2,
                    options.max_fitness_m2);
      record.reason = text;
    } else {
      const Matrix6d cov = helper.relativeCovariance(fi, fj) + loopCovariance(options);
      record.chi2_estimate = residual.dot(cov.llt().solve(residual));
      if (!(record.chi2_estimate <= options.gate_chi2)) {
        char text[128];
        std::snprintf(text, sizeof(text),
                      "inconsistent with the estimate: chi2 %.1f > %.1f (%.2f m, %.2f deg)",
                      record.chi2_estimate, options.gate_chi2, record.correction_m,
                      record.correction_deg);
        record.reason = text;
      } else {
        RelativePoseFactor factor;
        factor.from = best;
        factor.to = j;
        factor.measurement = measured;
        factor.information = loop_information;
        factor.kernel = options.kernel;
        factor.kernel_scale = options.kernel_scale;
        loop_factor.push_back(graph.addRelative(factor));
        loop_record.push_back(static_cast<int>(result.loops.size()));
        record.accepted = true;  // provisionally: the residual check follows
      }
    }
    result.loops.push_back(record);
  }
  result.seconds_registration = seconds(registration_start);

  // Optimize; drop the worst loop whose residual stays above outlier_chi2 and solve again.
  const auto optimization_start = std::chrono::steady_clock::now();
  PoseGraphOptions graph_options;
  graph_options.max_iterations = options.max_iterations;
  for (int round = 0;; ++round) {
    // Each round starts from the smoothed trajectory (a dropped loop leaves no trace).
    PoseGraph fresh = graph;
    result.summary = fresh.optimize(graph_options);
    int worst = -1;
    double worst_chi2 = options.outlier_chi2;
    for (std::size_t l = 0; l < loop_factor.size(); ++l) {
      if (!fresh.relative(loop_factor[l]).active) continue;
      const double chi2 = fresh.relativeChi2(loop_factor[l]);
      result.loops[loop_record[l]].chi2_final = chi2;
      if (chi2 > worst_chi2) {
        worst_chi2 = chi2;
        worst = static_cast<int>(l);
      }
    }
    if (worst < 0 || round >= options.max_outlier_rounds) {
      graph = fresh;
      break;
    }
    graph.setRelativeActive(loop_factor[worst], false);
    LoopRecord& record = result.loops[loop_record[worst]];
    record.accepted = false;
    char text[128];
    std::snprintf(text, sizeof(text), "residual after the optimization: chi2 %.1f > %.1f",
                  worst_chi2, options.outlier_chi2);
    record.reason = text;
  }
  result.seconds_optimization = seconds(optimization_start);
  for (LoopRecord& record : result.loops) {
    if (record.accepted) {
      record.reason = "accepted";
      ++result.accepted;
    } else {
      ++result.rejected;
    }
  }

  // Without a loop the graph would only re-fit the fixes the smoother already used (counted twice:
  // measured on drive 0013, 50 frames, ATE 1.37 -> 1.93 m): the smoothed run stands.
  if (result.accepted == 0) return result;

  // The keyframe corrections (body-frame rotation, map-frame translation), interpolated in time
  // onto every frame; frames outside the keyframes take the nearest one's.
  std::vector<Eigen::Vector3d> rotation_correction(nodes), translation_correction(nodes);
  for (int n = 0; n < nodes; ++n) {
    const NavState& s = run.states[result.keyframes[n]];
    rotation_correction[n] = lie::logSO3(s.rotation.transpose() * graph.node(n).rotation);
    translation_correction[n] = graph.node(n).position - s.position_map;
  }
  int next = 0;
  for (int k = 0; k < frames; ++k) {
    while (next < nodes && result.keyframes[next] < k) ++next;
    Eigen::Vector3d dphi, dp;
    if (next == 0) {
      dphi = rotation_correction[0];
      dp = translation_correction[0];
    } else if (next == nodes) {
      dphi = rotation_correction[nodes - 1];
      dp = translation_correction[nodes - 1];
    } else {
      const double t0 = run.states[result.keyframes[next - 1]].stamp_s;
      const double t1 = run.states[result.keyframes[next]].stamp_s;
      const double alpha =
          t1 > t0 ? std::clamp((run.states[k].stamp_s - t0) / (t1 - t0), 0.0, 1.0) : 1.0;
      dphi = (1.0 - alpha) * rotation_correction[next - 1] + alpha * rotation_correction[next];
      dp = (1.0 - alpha) * translation_correction[next - 1] + alpha * translation_correction[next];
    }
    NavState& out = result.states[k];
    const Eigen::Matrix3d rotation = lie::normalizeRotation(out.rotation * lie::expSO3(dphi));
    out.velocity_map = rotation * (out.rotation.transpose() * out.velocity_map);
    out.rotation = rotation;
    out.position_map += dp;
  }

  // The loop-closed pose covariances (see LoopClosureResult::pose_covariances).
  const auto covariance_start = std::chrono::steady_clock::now();
  // At the keyframes: the smoother's information plus the information the accepted loops add to
  // the graph, (P_s^-1 + Sigma_loops^-1 - Sigma_no_loops^-1)^-1, with the graph's marginals with
  // and without the loop factors at the same (loop-closed) solution. Not the graph's marginal
  // itself: the graph counts the fixes twice (in the GPS factors and in the smoother's relative
  // covariances), and without loops its marginals are about half the smoother's sigma where the
  // estimate is no better (drive 0018 with oracle loops: position NEES 12 against the OXTS truth;
  // this way 6, and the smoothed covariance unchanged far from every loop). The loop information
  // is positive semi-definite (adding factors at the same point can only lower the marginals);
  // rounding below zero is clipped.
  const std::vector<Matrix6d> with_loops = graph.marginalCovariances();
  PoseGraph without_loops = graph;
  for (int index : loop_factor) without_loops.setRelativeActive(index, false);
  const std::vector<Matrix6d> no_loops = without_loops.marginalCovariances();
  std::vector<Matrix6d> marginals(nodes);
  for (int n = 0; n < nodes; ++n) {
    const Matrix6d smoothed = run.pose_covariances[result.keyframes[n]];
    const Matrix6d gained = clippedToPsd(inverseSpd(with_loops[n]) - inverseSpd(no_loops[n]));
    marginals[n] = symmetricPart(inverseSpd(inverseSpd(smoothed) + gained));
  }
  // The marginal of keyframe node n carried to frame k: T_k = T_n T_nk, with T_n perturbed as a
  // graph node (p + dp, R Exp(dphi)) and the relative pose T_nk = (R_nk, t_nk) as a relative
  // factor's measurement (t_nk + dt in n's frame, R_nk Exp(dphi')) with the smoother's
  // covariance of [dt, dphi'], the two independent. To first order:
  // dp_k = dp - R_n [t_nk]x dphi + R_n dt, dphi_k = R_nk^T dphi + dphi'.
  const auto carried = [&](int n, int k) -> Matrix6d {
    const int keyframe = result.keyframes[n];
    if (k == keyframe) return marginals[n];
    const Pose3 from = graph.node(n);
    const Pose3 relative = from.inverse() * poseOf(result.states[k]);
    Matrix6d j_node = Matrix6d::Identity();
    j_node.block<3, 3>(0, 3) = -from.rotation * lie::hat(relative.position);
    j_node.block<3, 3>(3, 3) = relative.rotation.transpose();
    Matrix6d j_relative = Matrix6d::Identity();
    j_relative.block<3, 3>(0, 0) = from.rotation;
    return j_node * marginals[n] * j_node.transpose() +
           j_relative * helper.relativeCovariance(keyframe, k, false) * j_relative.transpose();
  };
  next = 0;
  for (int k = run.first_estimated_frame; k < frames; ++k) {
    while (next < nodes && result.keyframes[next] < k) ++next;
    Matrix6d cov;
    if (next == 0) {
      cov = carried(0, k);
    } else if (next == nodes) {
      cov = carried(nodes - 1, k);
    } else {
      const double t0 = run.states[result.keyframes[next - 1]].stamp_s;
      const double t1 = run.states[result.keyframes[next]].stamp_s;
      const double alpha =
          t1 > t0 ? std::clamp((run.states[k].stamp_s - t0) / (t1 - t0), 0.0, 1.0) : 1.0;
      cov = alpha >= 1.0 ? carried(next, k)
                         : (1.0 - alpha) * carried(next - 1, k) + alpha * carried(next, k);
    }
    cov = symmetricPart(cov);
    if (!cov.allFinite()) {
      throw std::runtime_error("loop closure: the pose covariance of frame " + std::to_string(k) +
                               " is not finite");
    }
    result.pose_covariances[k] = cov;
  }
  // Frames before the filter's start repeat its first estimate (OxtsRunResult), covariance too.
  for (int k = 0; k < std::min(run.first_estimated_frame, frames); ++k) {
    result.pose_covariances[k] = result.pose_covariances[run.first_estimated_frame];
  }
  result.seconds_covariance = seconds(covariance_start);
  return result;
}

std::string loopCsvHeader() {
  return "query_frame,match_frame,time_gap_s,distance_m,distance_sigma_m,registered,fitness_m2,"
         "correction_m,correction_deg,chi2_estimate,chi2_final,accepted,reason";
}

std::string loopCsvLine(const LoopRecord& loop) {
  char text[512];
  std::snprintf(text, sizeof(text), "%d,%d,%.3f,%.3f,%.3f,%d,%.5f,%.3f,%.3f,%.2f,%.2f,%d,\"%s\"",
                loop.query_frame, loop.match_frame, loop.time_gap_s, loop.distance_m,
                loop.distance_sigma_m, loop.registered ? 1 : 0, loop.fitness_m2, loop.correction_m,
                loop.correction_deg, loop.chi2_estimate, loop.chi2_final, loop.accepted ? 1 : 0,
                loop.reason.c_str());
  return text;
}

}  // namespace estimation
}  // namespace inekf_semantic_mapping
