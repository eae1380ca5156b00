#include "inekf_semantic_mapping/estimation/loop_closure.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>
#include <stdexcept>

#include "inekf_semantic_mapping/common/yaml_reader.h"
#include "inekf_semantic_mapping/estimation/smoothed_posterior_graph.h"
#include "inekf_semantic_mapping/lie/so3.h"

namespace inekf_semantic_mapping {
namespace estimation {
namespace {

constexpr double kDegToRad = M_PI / 180.0;

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

// The smoothed run's relative poses and positions with their uncertainty (the search and the gate).
class SmoothedRun {
 public:
  explicit SmoothedRun(const OxtsRunResult& run) : run_(run) {}

  // Covariance of the relative pose of frame b in frame a (residual order [dp in a's frame,
  // dphi]) from the smoothed marginals and cross-covariance. a > b is allowed (the relative pose
  // backwards in time); a == b gives 0.
  Matrix6d relativeCovariance(int a, int b) const {
    // Cov(xi_a, xi_b), its transpose for a > b.
    Matrix15d cross = smoothedCrossCovariance(run_, std::min(a, b), std::max(a, b));
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
    return clippedToPsd(m * error * m.transpose());
  }

  // Map-frame position covariance of frame k (left-invariant rho is body-frame).
  Eigen::Matrix3d positionCovariance(int k) const {
    const Eigen::Matrix3d& r = run_.states[k].rotation;
    return r * run_.smoothed_covariances[k].block<3, 3>(6, 6) * r.transpose();
  }

 private:
  const OxtsRunResult& run_;
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
  reader->read("loop_closure.max_iterations", &max_iterations);
  reader->read("loop_closure.max_outlier_rounds", &max_outlier_rounds);
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
  const SmoothedRun helper(run);
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

  // Loop candidates, registration and the gate.
  const auto registration_start = std::chrono::steady_clock::now();
  const Matrix6d loop_information = inverseSpd(loopCovariance(options));
  std::vector<RelativePoseFactor> loop_factors;  // the loops that passed the gate
  std::vector<int> loop_record;                  // record index per loop factor
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
    const Vector6d residual = relativePoseResidual(ti, tj, measured);
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
        loop_factors.push_back(factor);
        loop_record.push_back(static_cast<int>(result.loops.size()));
        record.accepted = true;  // provisionally: the residual check follows
      }
    }
    result.loops.push_back(record);
  }
  result.seconds_registration = seconds(registration_start);

  // Optimize; drop the worst loop whose residual stays above outlier_chi2 and solve again. The
  // graph is built only when a loop passed the gate: without one the posterior is the smoothed
  // run, kept bit for bit.
  const auto optimization_start = std::chrono::steady_clock::now();
  std::optional<SmoothedPosteriorGraph> graph;
  if (!loop_factors.empty()) {
    graph.emplace(run, result.keyframes);
    for (const RelativePoseFactor& factor : loop_factors) graph->addLoop(factor);
  }
  PoseGraphOptions graph_options;
  graph_options.max_iterations = options.max_iterations;
  for (int round = 0; graph; ++round) {
    // Each round starts from the smoothed trajectory (a dropped loop leaves no trace).
    graph->reset();
    result.summary = graph->optimize(graph_options);
    int worst = -1;
    double worst_chi2 = options.outlier_chi2;
    for (int l = 0; l < graph->numLoops(); ++l) {
      if (!graph->loop(l).active) continue;
      const double chi2 = graph->loopChi2(l);
      result.loops[loop_record[l]].chi2_final = chi2;
      if (chi2 > worst_chi2) {
        worst_chi2 = chi2;
        worst = l;
      }
    }
    if (worst < 0 || round >= options.max_outlier_rounds) break;
    graph->setLoopActive(worst, false);
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
  if (result.accepted == 0) return result;

  // Every frame's posterior: states (biases and velocities too) and pose covariances.
  const auto covariance_start = std::chrono::steady_clock::now();
  graph->posterior(&result.states, &result.pose_covariances);
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
