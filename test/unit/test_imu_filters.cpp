// The three navigation filters: exact transition vs numerical linearization, error-coordinate
// maps, noise-free reproduction of a simulated drive, GPS update, gating, non-finite input,
// and consistency (NEES) over Monte-Carlo runs.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <vector>

#include "inekf_semantic_mapping/estimation/error_dynamics.h"
#include "inekf_semantic_mapping/estimation/imu_filters.h"
#include "inekf_semantic_mapping/estimation/smoother.h"
#include "inekf_semantic_mapping/lie/se23.h"
#include "inekf_semantic_mapping/lie/so3.h"
#include "simulated_drive.h"

namespace inekf_semantic_mapping {
namespace estimation {
namespace {

using Vector15d = Eigen::Matrix<double, 15, 1>;
using lie::ExtendedPose;

using test_drive::fixAt;
using test_drive::kGravity;
using test_drive::SimulatedDrive;
using test_drive::simulateDrive;
using test_drive::someState;
const FilterType kAllFilters[] = {FilterType::kLeftInvariant, FilterType::kRightInvariant,
                                  FilterType::kQuaternionEskf};

ExtendedPose poseOf(const NavState& s) {
  ExtendedPose x;
  x.rotation = s.rotation;
  x.velocity = s.velocity_map;
  x.position = s.position_map;
  return x;
}

// The left-invariant difference and its inverse are the smoother's (one definition).
NavState perturbLeft(const NavState& s, const Vector15d& xi) { return applyLeftInvariant(s, xi); }
Vector15d leftError(const NavState& estimate, const NavState& truth) {
  return leftInvariantDifference(estimate, truth);
}

// The transition by central differences of the (exact, constant-input) integration.
Matrix15d numericalTransition(const NavState& s, const Eigen::Vector3d& gyro,
                              const Eigen::Vector3d& accel, double dt) {
  const NavState next = integrateImu(s, gyro, accel, kGravity, dt);
  Matrix15d numeric;
  const double eps = 1e-6;
  for (int i = 0; i < 15; ++i) {
    const Vector15d d = eps * Vector15d::Unit(i);
    const NavState plus = integrateImu(perturbLeft(s, d), gyro, accel, kGravity, dt);
    const NavState minus = integrateImu(perturbLeft(s, -d), gyro, accel, kGravity, dt);
    numeric.col(i) = (leftError(next, plus) - leftError(next, minus)) / (2.0 * eps);
  }
  return numeric;
}

TEST(ErrorDynamics, TransitionMatchesNumericalLinearization) {
  const NavState s = someState();
  const Eigen::Vector3d gyro(0.3, -0.5, 1.2), accel(1.5, -0.7, 9.9);
  for (double dt : {0.01, 0.1, 0.5}) {
    const Matrix15d numeric = numericalTransition(s, gyro, accel, dt);
    const Matrix15d phi = leftErrorTransition(gyro - s.gyro_bias, accel - s.accel_bias, dt);
    EXPECT_LT((phi - numeric).norm(), 1e-6 * numeric.norm()) << "dt " << dt << "\n"
                                                             << phi - numeric;
  }
}

TEST(ErrorDynamics, TransitionComposesOverSubsteps) {
  // Phi(2 dt) = Phi(dt) Phi(dt) for a constant input: both sides one closed-form step (|w| 2 dt
  // below the 0.25 rad where a step is split), so the closed form itself is checked.
  const Eigen::Vector3d w(0.8, -0.4, 2.0), a(2.0, 1.0, 9.0);
  const double dt = 0.05;  // |w| 2 dt = 0.22 rad: beyond a 10 Hz car's turn per step
  const Matrix15d twice = leftErrorTransition(w, a, dt) * leftErrorTransition(w, a, dt);
  EXPECT_LT((leftErrorTransition(w, a, 2 * dt) - twice).norm(), 1e-7 * twice.norm());
}

// A bridged IMU gap of seconds while the car turns at 1 rad/s: the transition still matches the
// numerical linearization. One 4-point quadrature
// over the whole 10 s was 3.7 % off.
TEST(ErrorDynamics, TransitionIsAccurateOverALongTurningStep) {
  const NavState s = someState();
  const Eigen::Vector3d gyro(0.01, -0.02, 1.0), accel(0.5, 0.3, 9.8);
  for (double dt : {2.0, 5.0, 10.0}) {
    const Matrix15d numeric = numericalTransition(s, gyro, accel, dt);
    const Matrix15d phi = leftErrorTransition(gyro - s.gyro_bias, accel - s.accel_bias, dt);
    EXPECT_LT((phi - numeric).norm(), 1e-6 * numeric.norm()) << "dt " << dt;
  }
}

// The process noise of one long step equals the noise accumulated over many short ones (the
// input constant): Simpson's rule over the whole 10 s at 1 rad/s was 2.6 % off.
TEST(ErrorDynamics, ProcessNoiseOfALongStepEqualsManyShortSteps) {
  const Eigen::Vector3d w(0.01, -0.02, 1.0), a(0.5, 0.3, 9.8);
  const ImuNoise noise;
  for (double dt : {2.0, 10.0}) {
    const int steps = 1000;
    const double h = dt / steps;
    const Matrix15d phi_h = leftErrorTransition(w, a, h);
    const Matrix15d q_h = leftProcessNoise(w, a, noise, 1.0, 1.0, h);
    Matrix15d accumulated = Matrix15d::Zero();
    for (int i = 0; i < steps; ++i) accumulated = phi_h * accumulated * phi_h.transpose() + q_h;
    const Matrix15d q = leftProcessNoise(w, a, noise, 1.0, 1.0, dt);
    EXPECT_LT((q - accumulated).norm(), 1e-5 * accumulated.norm()) << "dt " << dt;
    EXPECT_LT(std::abs(q(6, 6) - accumulated(6, 6)), 1e-5 * accumulated(6, 6)) << "dt " << dt;
  }
}

TEST(ErrorCoordinates, MapsMatchNumericalDifferences) {
  const NavState s = someState();
  for (FilterType type : {FilterType::kRightInvariant, FilterType::kQuaternionEskf}) {
    auto filter = makeFilter(type, ImuNoise());
    const auto* base = dynamic_cast<const ImuFilterBase*>(filter.get());
    ASSERT_NE(base, nullptr);
    // Perturb by a left error, measure the filter's own error numerically.
    Matrix15d numeric;
    const double eps = 1e-6;
    for (int i = 0; i < 15; ++i) {
      const Vector15d d = eps * Vector15d::Unit(i);
      auto own_error = [&](const NavState& t) {
        Vector15d e;
        if (type == FilterType::kRightInvariant) {
          e.head<9>() = lie::logSE23(poseOf(t) * poseOf(s).inverse());
        } else {
          e.head<3>() = lie::logSO3(s.rotation.transpose() * t.rotation);
          e.segment<3>(3) = t.velocity_map - s.velocity_map;
          e.segment<3>(6) = t.position_map - s.position_map;
        }
        e.segment<3>(9) = t.gyro_bias - s.gyro_bias;
        e.segment<3>(12) = t.accel_bias - s.accel_bias;
        return e;
      };
      numeric.col(i) = (own_error(perturbLeft(s, d)) - own_error(perturbLeft(s, -d))) / (2 * eps);
    }
    EXPECT_LT((base->errorFromLeft(s) - numeric).norm(), 1e-6 * numeric.norm()) << toString(type);
    EXPECT_LT((base->leftFromError(s) * base->errorFromLeft(s) - Matrix15d::Identity()).norm(),
              1e-9);
  }
}

TEST(Filters, NoiseFreePropagationReproducesTheDrive) {
  const double dt = 0.1;
  const SimulatedDrive drive = simulateDrive(200, dt);  // 20 s, ~100 m, ~1 rad of turn
  for (FilterType type : kAllFilters) {
    auto filter = makeFilter(type, ImuNoise());
    filter->initialize(drive.truth[0], ErrorCovariance::Identity() * 1e-4);
    double worst_position = 0.0, worst_angle = 0.0, worst_velocity = 0.0;
    for (std::size_t k = 1; k < drive.imu.size(); ++k) {
      filter->propagate(drive.imu[k], dt);
      const NavState& est = filter->state();
      worst_position =
          std::max(worst_position, (est.position_map - drive.truth[k].position_map).norm());
      worst_velocity =
          std::max(worst_velocity, (est.velocity_map - drive.truth[k].velocity_map).norm());
      worst_angle = std::max(
          worst_angle, lie::logSO3(est.rotation.transpose() * drive.truth[k].rotation).norm());
    }
    EXPECT_LT(worst_position, 1e-6) << toString(type);
    EXPECT_LT(worst_velocity, 1e-7) << toString(type);
    EXPECT_LT(worst_angle, 1e-9) << toString(type);
    EXPECT_NEAR(filter->state().stamp_s, drive.truth.back().stamp_s, 1e-9);
    EXPECT_GT((drive.truth.back().position_map - drive.truth[0].position_map).norm(), 50.0);
  }
}

// Found by review: a non-finite covariance was taken, and every later propagation refused
// without a word (the stamp never advanced).
TEST(Filters, ANonFiniteStartIsRefused) {
  for (FilterType type : kAllFilters) {
    auto filter = makeFilter(type, ImuNoise());
    NavState state;
    ErrorCovariance covariance = ErrorCovariance::Identity();
    covariance(4, 4) = std::numeric_limits<double>::quiet_NaN();
    EXPECT_THROW(filter->initialize(state, covariance), std::invalid_argument) << toString(type);
    state.position_map.x() = std::numeric_limits<double>::infinity();
    EXPECT_THROW(filter->initialize(state, ErrorCovariance::Identity()), std::invalid_argument);
  }
}

TEST(Filters, PoseCovarianceAgreesAcrossFiltersWithoutUpdates) {
  // The three are linear maps of one linearization: with no update their Euclidean pose
  // covariances must coincide.
  const double dt = 0.1;
  const SimulatedDrive drive = simulateDrive(50, dt);
  Eigen::Matrix<double, 15, 1> sigma;
  sigma << 0.01, 0.02, 0.3, 0.2, 0.2, 0.1, 1.0, 1.5, 2.0, 1e-3, 1e-3, 1e-3, 0.05, 0.05, 0.05;
  const ErrorCovariance world = sigma.cwiseAbs2().asDiagonal();
  std::vector<PoseCovariance> results;
  for (FilterType type : kAllFilters) {
    auto filter = makeFilter(type, ImuNoise());
    filter->initialize(drive.truth[0], filter->fromWorldCovariance(drive.truth[0], world));
    for (std::size_t k = 1; k < drive.imu.size(); ++k) filter->propagate(drive.imu[k], dt);
    results.push_back(filter->poseCovariance());
  }
  EXPECT_LT((results[1] - results[0]).norm(), 1e-8 * results[0].norm());
  EXPECT_LT((results[2] - results[0]).norm(), 1e-8 * results[0].norm());
}

// The twist covariance (body velocity, bias-corrected rate) against samples of the errors it
// comes from, for each filter: v_b = R^T v and w = w_meas - b_g of states drawn around the
// estimate with a world-frame covariance. Before it, /inekf/odometry's twist covariance was all
// zero (to a consumer: perfectly known).
TEST(Filters, TwistCovarianceMatchesSampledErrors) {
  NavState estimate;
  estimate.rotation = lie::expSO3(Eigen::Vector3d(0.02, -0.03, 0.9));
  estimate.velocity_map = Eigen::Vector3d(6.0, 8.0, 0.2);
  estimate.gyro_bias = Eigen::Vector3d(1e-3, -2e-3, 5e-4);
  Eigen::Matrix<double, 15, 1> sigma;
  sigma << 0.01, 0.01, 0.05, 0.2, 0.3, 0.1, 1.0, 1.0, 2.0, 2e-3, 1e-3, 3e-3, 0.05, 0.05, 0.05;
  const ErrorCovariance world = sigma.cwiseAbs2().asDiagonal();
  const Eigen::Vector3d v_b = estimate.rotation.transpose() * estimate.velocity_map;
  std::mt19937 rng(7);
  std::normal_distribution<double> normal;
  constexpr int kSamples = 20000;
  Eigen::Matrix<double, 6, 6> sampled = Eigen::Matrix<double, 6, 6>::Zero();
  for (int i = 0; i < kSamples; ++i) {
    Eigen::Matrix<double, 15, 1> e;
    for (int k = 0; k < 15; ++k) e(k) = sigma(k) * normal(rng);
    const Eigen::Matrix3d rotation = lie::expSO3(e.segment<3>(0)) * estimate.rotation;
    const Eigen::Vector3d velocity = estimate.velocity_map + e.segment<3>(3);
    Eigen::Matrix<double, 6, 1> d;
    d << rotation.transpose() * velocity - v_b, -e.segment<3>(9);  // w = w_meas - (b + db)
    sampled += d * d.transpose() / kSamples;
  }
  for (FilterType type : kAllFilters) {
    auto filter = makeFilter(type, ImuNoise());
    filter->initialize(estimate, filter->fromWorldCovariance(estimate, world));
    const TwistCovariance twist = filter->twistCovariance();
    for (int r = 0; r < 6; ++r) {
      for (int c = 0; c < 6; ++c) {
        const double scale = std::sqrt(sampled(r, r) * sampled(c, c));
        EXPECT_NEAR(twist(r, c), sampled(r, c), 0.05 * scale) << "(" << r << ", " << c << ")";
      }
    }
    // One propagation adds the gyro sample's white noise to the rate's variance.
    ImuSample sample;
    sample.specific_force = estimate.rotation.transpose() * Eigen::Vector3d(0, 0, kGravity);
    filter->propagate(sample, 0.01);
    const double density = ImuNoise().gyro_noise_density;
    EXPECT_GT(filter->twistCovariance()(5, 5), density * density / 0.01);
  }
}

TEST(Filters, PositionUpdateMovesTowardTheFixAndShrinksTheCovariance) {
  for (FilterType type : kAllFilters) {
    auto filter = makeFilter(type, ImuNoise());
    const NavState s = someState();
    Eigen::Matrix<double, 15, 1> sigma;
    sigma << 0.05, 0.05, 0.1, 0.5, 0.5, 0.5, 2.0, 2.0, 2.0, 1e-3, 1e-3, 1e-3, 0.05, 0.05, 0.05;
    const ErrorCovariance world = sigma.cwiseAbs2().asDiagonal();
    filter->initialize(s, filter->fromWorldCovariance(s, world));
    const Eigen::Vector3d target = s.position_map + Eigen::Vector3d(2.0, -1.0, 0.5);
    const double before = (filter->state().position_map - target).norm();
    const double trace_before = filter->poseCovariance().topLeftCorner<3, 3>().trace();
    const CorrectionResult result = filter->correctPosition(fixAt(target, s.stamp_s, 1.0), 100.0);
    ASSERT_TRUE(result.accepted) << toString(type) << ": " << result.reason;
    EXPECT_GT(result.mahalanobis_squared, 0.0);
    const double after = (filter->state().position_map - target).norm();
    EXPECT_LT(after, 0.5 * before) << toString(type);
    const double trace_after = filter->poseCovariance().topLeftCorner<3, 3>().trace();
    EXPECT_LT(trace_after, 0.5 * trace_before) << toString(type);
    // The covariance stays symmetric positive definite.
    Eigen::LLT<ErrorCovariance> llt(filter->covariance());
    EXPECT_EQ(llt.info(), Eigen::Success);
    EXPECT_LT((filter->covariance() - filter->covariance().transpose()).norm(), 1e-12);
  }
}

// A fix of an antenna 1.5 m ahead, 0.4 m right and 1.2 m above the IMU (y = p + R l): a precise
// fix must move the estimate so that its own antenna lands on the fix, to first order, which
// needs the lever arm's attitude terms in each filter's Jacobian (with the rotation block wrong
// or missing, the attitude takes a share of the correction that does not move the antenna).
TEST(Filters, AFixOfAnAntennaOnALeverArmIsMetByTheUpdatedPose) {
  const Eigen::Vector3d lever(1.5, -0.4, 1.2);
  for (FilterType type : kAllFilters) {
    auto filter = makeFilter(type, ImuNoise());
    const NavState s = someState();
    Eigen::Matrix<double, 15, 1> sigma;
    sigma << 0.05, 0.05, 0.2, 0.5, 0.5, 0.5, 1.0, 1.0, 1.0, 1e-3, 1e-3, 1e-3, 0.05, 0.05, 0.05;
    filter->initialize(s, filter->fromWorldCovariance(s, sigma.cwiseAbs2().asDiagonal()));
    PositionFix fix = fixAt(
        s.position_map + s.rotation * lever + Eigen::Vector3d(0.03, -0.02, 0.01), s.stamp_s, 1e-3);
    fix.antenna_in_imu = lever;
    const double before = (s.position_map + s.rotation * lever - fix.position_map).norm();
    const CorrectionResult result = filter->correctPosition(fix, 1e12);
    ASSERT_TRUE(result.accepted) << toString(type) << ": " << result.reason;
    const NavState& after = filter->state();
    const double residual = (after.position_map + after.rotation * lever - fix.position_map).norm();
    EXPECT_LT(residual, 0.01 * before) << toString(type);
    // The attitude took part: the update is not a pure shift of the IMU's position.
    EXPECT_GT(lie::logSO3(s.rotation.transpose() * after.rotation).norm(), 1e-4) << toString(type);
  }
}

// The drive with the fixes of that antenna, every second: told the lever arm, each filter stays
// on the truth; taking the antenna for the IMU it is off by about the lever arm.
TEST(Filters, FixesOfAnAntennaOnALeverArmKeepTheFilterOnTheDrive) {
  const double dt = 0.1;
  const SimulatedDrive drive = simulateDrive(300, dt);
  const Eigen::Vector3d lever(1.5, -0.4, 1.2);
  for (FilterType type : kAllFilters) {
    for (const bool told : {true, false}) {
      auto filter = makeFilter(type, ImuNoise());
      Eigen::Matrix<double, 15, 1> sigma;
      sigma << 0.01, 0.01, 0.05, 0.2, 0.2, 0.2, 0.5, 0.5, 0.5, 1e-3, 1e-3, 1e-3, 0.05, 0.05, 0.05;
      filter->initialize(drive.truth[0], filter->fromWorldCovariance(
                                             drive.truth[0], sigma.cwiseAbs2().asDiagonal()));
      double worst_late_m = 0.0;
      for (std::size_t k = 1; k < drive.imu.size(); ++k) {
        filter->propagate(drive.imu[k], dt);
        const NavState& truth = drive.truth[k];
        if (k % 10 == 0) {
          PositionFix fix = fixAt(truth.position_map + truth.rotation * lever, truth.stamp_s, 0.3);
          if (told) fix.antenna_in_imu = lever;
          ASSERT_TRUE(filter->correctPosition(fix, 1e9).accepted);
        }
        if (k >= 200) {
          worst_late_m =
              std::max(worst_late_m, (filter->state().position_map - truth.position_map).norm());
        }
      }
      if (told) {
        EXPECT_LT(worst_late_m, 0.1) << toString(type);
      } else {
        EXPECT_GT(worst_late_m, 0.8) << toString(type);
      }
    }
  }
}

// A centimetre fix on a prior that knows the position only to 10,000 km, its errors correlated
// with the velocity's and the attitude's: the update's covariance must stay positive definite
// (the expanded form P - KHP... cancelled to negative variances at these scales).
TEST(Filters, PreciseFixOnAVaguePriorKeepsTheCovariancePositiveDefinite) {
  std::mt19937 rng(7);
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::Matrix<double, 15, 1> sigma;
  sigma << 1e-4, 1e-4, 1e-4, 1e3, 1e3, 1e3, 1e7, 1e7, 1e7, 1e-4, 1e-4, 1e-4, 1e-2, 1e-2, 1e-2;
  for (FilterType type : kAllFilters) {
    for (int trial = 0; trial < 20; ++trial) {
      Matrix15d root;
      for (int i = 0; i < 15; ++i) {
        for (int j = 0; j < 15; ++j) root(i, j) = normal(rng);
      }
      const Matrix15d correlated = root * root.transpose() / 15.0;
      const ErrorCovariance prior = sigma.asDiagonal() * correlated * sigma.asDiagonal();
      auto filter = makeFilter(type, ImuNoise());
      const NavState s = someState();
      filter->initialize(s, prior);
      const Eigen::Vector3d target = s.position_map + Eigen::Vector3d(3.0, -2.0, 1.0);
      const CorrectionResult result = filter->correctPosition(fixAt(target, s.stamp_s, 1e-3), 1e6);
      ASSERT_TRUE(result.accepted) << toString(type) << ": " << result.reason;
      const ErrorCovariance& updated = filter->covariance();
      EXPECT_GE(updated.diagonal().minCoeff(), 0.0) << toString(type) << " trial " << trial;
      EXPECT_EQ(Eigen::LLT<ErrorCovariance>(updated).info(), Eigen::Success)
          << toString(type) << " trial " << trial;
    }
  }
}

// The land-vehicle constraint on a car whose estimated heading is 3 deg off its velocity (known
// well): the heading turns to the velocity, the same in all three filters (one Jacobian, mapped
// into each filter's error coordinates), and the covariance stays symmetric positive definite.
TEST(Filters, NonholonomicUpdateTurnsTheHeadingToTheVelocity) {
  const double yaw = 0.8, offset = 3.0 * M_PI / 180.0;
  NavState estimate;
  estimate.stamp_s = 5.0;
  estimate.rotation = lie::expSO3(Eigen::Vector3d(0.0, 0.0, yaw + offset));
  estimate.velocity_map = 12.0 * Eigen::Vector3d(std::cos(yaw), std::sin(yaw), 0.0);
  Eigen::Matrix<double, 15, 1> sigma;
  sigma << 0.01, 0.01, 5.0 * M_PI / 180.0, 0.02, 0.02, 0.02, 1.0, 1.0, 1.0, 1e-4, 1e-4, 1e-4, 0.01,
      0.01, 0.01;
  NonholonomicModel tight;
  tight.lateral_sigma_mps = tight.vertical_sigma_mps = 0.05;
  std::vector<double> yaw_errors;
  for (FilterType type : kAllFilters) {
    auto filter = makeFilter(type, ImuNoise());
    filter->initialize(estimate,
                       filter->fromWorldCovariance(estimate, sigma.cwiseAbs2().asDiagonal()));
    const double heading_variance_before = filter->poseCovariance()(5, 5);
    const CorrectionResult result = filter->correctNonholonomic(tight, 100.0);
    ASSERT_TRUE(result.accepted) << toString(type) << ": " << result.reason;
    const Eigen::Vector3d body_velocity =
        filter->state().rotation.transpose() * filter->state().velocity_map;
    EXPECT_LT(std::abs(body_velocity.y()), 0.05 * body_velocity.x()) << toString(type);
    const double yaw_error =
        lie::logSO3(lie::expSO3(Eigen::Vector3d(0, 0, -yaw)) * filter->state().rotation).z();
    EXPECT_LT(std::abs(yaw_error), 0.1 * offset) << toString(type);
    yaw_errors.push_back(yaw_error);
    EXPECT_LT(filter->poseCovariance()(5, 5), 0.1 * heading_variance_before) << toString(type);
    Eigen::LLT<ErrorCovariance> llt(filter->covariance());
    EXPECT_EQ(llt.info(), Eigen::Success);
    EXPECT_LT((filter->covariance() - filter->covariance().transpose()).norm(), 1e-12);
    NonholonomicModel bad = tight;
    bad.lateral_sigma_mps = 0.0;
    EXPECT_FALSE(filter->correctNonholonomic(bad, 100.0).accepted);
    bad.lateral_sigma_mps = std::nan("");
    EXPECT_FALSE(filter->correctNonholonomic(bad, 100.0).accepted);
    bad = tight;
    bad.imu_from_vehicle(0, 0) = std::nan("");
    EXPECT_FALSE(filter->correctNonholonomic(bad, 100.0).accepted);
  }
  EXPECT_NEAR(yaw_errors[0], yaw_errors[1], 2e-4);
  EXPECT_NEAR(yaw_errors[0], yaw_errors[2], 2e-4);
}

TEST(Filters, NonholonomicUpdateMeasuresInTheVehicleFrame) {
  // x = (1, 0, 0) of the vehicle frame is the direction of travel in the IMU frame.
  const double pitch = 2.0 * M_PI / 180.0, yaw = -1.5 * M_PI / 180.0;
  const Eigen::Matrix3d imu_from_vehicle = vehicleFrameInImu(pitch, yaw);
  EXPECT_TRUE(imu_from_vehicle.col(0).isApprox(
      Eigen::Vector3d(std::cos(pitch) * std::cos(yaw), std::cos(pitch) * std::sin(yaw),
                      std::sin(pitch)),
      1e-12));
  EXPECT_NEAR(imu_from_vehicle.determinant(), 1.0, 1e-12);
  EXPECT_NEAR(imu_from_vehicle(2, 1), 0.0, 1e-12);  // no roll: the vehicle's y axis stays level

  // The IMU moves along the vehicle's x: nothing to correct in the vehicle frame; taken in the
  // IMU's own axes, the same velocity is 2 deg "vertical" and tilts the estimate.
  NavState estimate;
  estimate.stamp_s = 1.0;
  estimate.rotation = lie::expSO3(Eigen::Vector3d(0.01, -0.02, 0.7));
  estimate.velocity_map = estimate.rotation * imu_from_vehicle * Eigen::Vector3d(14.0, 0.0, 0.0);
  Eigen::Matrix<double, 15, 1> sigma;
  sigma << 0.02, 0.02, 0.05, 0.2, 0.2, 0.2, 1.0, 1.0, 1.0, 1e-4, 1e-4, 1e-4, 0.01, 0.01, 0.01;
  NonholonomicModel model;
  model.lateral_sigma_mps = model.vertical_sigma_mps = 0.05;
  model.imu_from_vehicle = imu_from_vehicle;
  NonholonomicModel imu_axes = model;
  imu_axes.imu_from_vehicle.setIdentity();
  for (FilterType type : kAllFilters) {
    auto filter = makeFilter(type, ImuNoise());
    const ErrorCovariance covariance =
        filter->fromWorldCovariance(estimate, sigma.cwiseAbs2().asDiagonal());
    filter->initialize(estimate, covariance);
    ASSERT_TRUE(filter->correctNonholonomic(model, 1e6).accepted) << toString(type);
    EXPECT_LT(lie::logSO3(estimate.rotation.transpose() * filter->state().rotation).norm(), 1e-9)
        << toString(type);
    EXPECT_LT((filter->state().velocity_map - estimate.velocity_map).norm(), 1e-9)
        << toString(type);

    filter->initialize(estimate, covariance);
    ASSERT_TRUE(filter->correctNonholonomic(imu_axes, 1e6).accepted) << toString(type);
    const Eigen::Vector3d body_velocity =
        filter->state().rotation.transpose() * filter->state().velocity_map;
    EXPECT_LT(std::abs(body_velocity.z()), 0.5 * 14.0 * std::sin(pitch)) << toString(type);
  }
}

// At rest the velocity is zero and the gyro reads its bias: the zero-velocity update takes a
// vague velocity to zero, the zero-rate one the bias to the measured mean rate, the same in all
// three filters; each is gated on its own.
TEST(Filters, StandstillUpdatesZeroTheVelocityAndTakeTheRateAsTheGyroBias) {
  NavState estimate;
  estimate.stamp_s = 2.0;
  estimate.rotation = lie::expSO3(Eigen::Vector3d(0.02, -0.01, 1.1));
  estimate.velocity_map = Eigen::Vector3d(0.15, -0.1, 0.02);
  Eigen::Matrix<double, 15, 1> sigma;
  sigma << 0.01, 0.01, 0.05, 0.3, 0.3, 0.3, 1.0, 1.0, 1.0, 0.01, 0.01, 0.01, 0.1, 0.1, 0.1;
  const Eigen::Vector3d mean_rate(0.004, -0.003, 0.005);
  const Eigen::Vector3d rate_variance = Eigen::Vector3d::Constant(1e-4 * 1e-4);
  std::vector<Eigen::Vector3d> biases;
  for (FilterType type : kAllFilters) {
    auto filter = makeFilter(type, ImuNoise());
    filter->initialize(estimate,
                       filter->fromWorldCovariance(estimate, sigma.cwiseAbs2().asDiagonal()));
    const double speed_variance_before = filter->twistCovariance()(0, 0);
    const CorrectionResult velocity = filter->correctZeroVelocity(0.01, 100.0);
    ASSERT_TRUE(velocity.accepted) << toString(type) << ": " << velocity.reason;
    EXPECT_LT(filter->state().velocity_map.norm(), 0.01) << toString(type);
    EXPECT_LT(filter->twistCovariance()(0, 0), 0.01 * speed_variance_before) << toString(type);
    const CorrectionResult rate = filter->correctZeroRate(mean_rate, rate_variance, 100.0);
    ASSERT_TRUE(rate.accepted) << toString(type) << ": " << rate.reason;
    EXPECT_LT((filter->state().gyro_bias - mean_rate).norm(), 2e-4) << toString(type);
    // The bias's variance is the measurement's now (it was 1e-4).
    EXPECT_LT(filter->covariance()(11, 11), 2e-8) << toString(type);
    Eigen::LLT<ErrorCovariance> llt(filter->covariance());
    EXPECT_EQ(llt.info(), Eigen::Success);
    biases.push_back(filter->state().gyro_bias);
    // A vehicle that is moving fails the velocity's gate, and the rate is still taken; bad
    // sigmas are refused.
    NavState moving = estimate;
    moving.velocity_map = Eigen::Vector3d(5.0, 0.0, 0.0);
    filter->initialize(moving, filter->fromWorldCovariance(moving, sigma.cwiseAbs2().asDiagonal()));
    EXPECT_FALSE(filter->correctZeroVelocity(0.01, 16.3).accepted) << toString(type);
    EXPECT_EQ(filter->state().velocity_map, moving.velocity_map);
    EXPECT_TRUE(filter->correctZeroRate(mean_rate, rate_variance, 16.3).accepted);
    // A rate far off the bias fails its own gate (a turn), the velocity is still taken.
    filter->initialize(estimate,
                       filter->fromWorldCovariance(estimate, sigma.cwiseAbs2().asDiagonal()));
    EXPECT_FALSE(
        filter->correctZeroRate(Eigen::Vector3d(0.0, 0.0, 0.2), rate_variance, 16.3).accepted);
    EXPECT_TRUE(filter->correctZeroVelocity(0.01, 16.3).accepted);
    EXPECT_FALSE(filter->correctZeroVelocity(0.0, 100.0).accepted);
    EXPECT_FALSE(filter->correctZeroVelocity(std::nan(""), 100.0).accepted);
    EXPECT_FALSE(
        filter->correctZeroRate(mean_rate, Eigen::Vector3d(0.0, 1e-8, 1e-8), 100.0).accepted);
    EXPECT_FALSE(
        filter->correctZeroRate(Eigen::Vector3d(0.0, std::nan(""), 0.0), rate_variance, 100.0)
            .accepted);
  }
  EXPECT_LT((biases[0] - biases[1]).norm(), 1e-6);
  EXPECT_LT((biases[0] - biases[2]).norm(), 1e-6);
}

// Wheel odometry's speed along the vehicle's direction of travel: taken by all three filters
// alike, the velocity's magnitude along the vehicle axis moves to it (the axis pitched against the
// IMU's, as on KITTI's rig), the lateral velocity is left alone; a wheel speed far off the estimate
// fails the gate, bad input is refused.
TEST(Filters, TheForwardSpeedCorrectsTheVelocityAlongTheVehicleAxis) {
  NavState estimate;
  estimate.stamp_s = 2.0;
  estimate.rotation = lie::expSO3(Eigen::Vector3d(0.02, -0.01, 1.1));
  NonholonomicModel model;
  model.imu_from_vehicle = vehicleFrameInImu(0.02, 0.0);  // travel 1.1 deg up in the IMU frame
  const Eigen::Vector3d travel_in_map = estimate.rotation * model.imu_from_vehicle.col(0);
  const Eigen::Vector3d side_in_map = estimate.rotation * model.imu_from_vehicle.col(1);
  estimate.velocity_map = 5.0 * travel_in_map + 0.2 * side_in_map;
  Eigen::Matrix<double, 15, 1> sigma;
  sigma << 0.01, 0.01, 0.05, 0.5, 0.5, 0.5, 1.0, 1.0, 1.0, 0.01, 0.01, 0.01, 0.1, 0.1, 0.1;
  std::vector<Eigen::Vector3d> velocities;
  for (FilterType type : kAllFilters) {
    auto filter = makeFilter(type, ImuNoise());
    filter->initialize(estimate,
                       filter->fromWorldCovariance(estimate, sigma.cwiseAbs2().asDiagonal()));
    const CorrectionResult result = filter->correctForwardSpeed(model, 5.6, 0.02, 0.02, 16.3);
    ASSERT_TRUE(result.accepted) << toString(type) << ": " << result.reason;
    EXPECT_NEAR(result.mahalanobis_squared, 0.36 / (0.25 + 0.0004), 0.05) << toString(type);
    const Eigen::Vector3d v = filter->state().velocity_map;
    EXPECT_NEAR(v.dot(travel_in_map), 5.6, 0.02) << toString(type);
    EXPECT_NEAR(v.dot(side_in_map), 0.2, 0.02) << toString(type);
    Eigen::LLT<ErrorCovariance> llt(filter->covariance());
    EXPECT_EQ(llt.info(), Eigen::Success);
    velocities.push_back(v);
    // Reversing: a negative speed is a speed like any other.
    NavState reversing = estimate;
    reversing.velocity_map = -3.2 * travel_in_map;
    filter->initialize(reversing,
                       filter->fromWorldCovariance(reversing, sigma.cwiseAbs2().asDiagonal()));
    ASSERT_TRUE(filter->correctForwardSpeed(model, -3.0, 0.02, 0.02, 16.3).accepted)
        << toString(type);
    EXPECT_NEAR(filter->state().velocity_map.dot(travel_in_map), -3.0, 0.02) << toString(type);
    // 5 m/s off at 0.5 m/s of velocity sigma: an outlier, the state kept.
    filter->initialize(estimate,
                       filter->fromWorldCovariance(estimate, sigma.cwiseAbs2().asDiagonal()));
    EXPECT_FALSE(filter->correctForwardSpeed(model, 10.0, 0.02, 0.02, 16.3).accepted)
        << toString(type);
    EXPECT_EQ(filter->state().velocity_map, estimate.velocity_map);
    EXPECT_FALSE(filter->correctForwardSpeed(model, std::nan(""), 0.02, 0.02, 16.3).accepted);
    EXPECT_FALSE(filter->correctForwardSpeed(model, 5.0, 0.0, 0.0, 16.3).accepted);
    EXPECT_FALSE(filter->correctForwardSpeed(model, 5.0, std::nan(""), 0.02, 16.3).accepted);
  }
  // A speed weighed as a share of a correlated stream (sigma 1 m/s) is still gated on its own
  // sigma: 1.5 m/s off at 0.5 m/s of velocity sigma and 0.1 m/s of its own is an outlier, though
  // at 1 m/s it would pass.
  for (FilterType type : kAllFilters) {
    auto filter = makeFilter(type, ImuNoise());
    filter->initialize(estimate,
                       filter->fromWorldCovariance(estimate, sigma.cwiseAbs2().asDiagonal()));
    const CorrectionResult slip = filter->correctForwardSpeed(model, 6.5, 1.0, 0.1, 6.63);
    EXPECT_FALSE(slip.accepted) << toString(type);
    EXPECT_NEAR(slip.mahalanobis_squared, 2.25 / (0.25 + 0.01), 0.1) << toString(type);
    EXPECT_TRUE(filter->correctForwardSpeed(model, 6.5, 1.0, 1.0, 6.63).accepted) << toString(type);
    EXPECT_FALSE(filter->correctForwardSpeed(model, 5.0, 0.1, 0.2, 6.63).accepted)
        << "a gate sigma above the update's";
  }
  EXPECT_LT((velocities[0] - velocities[1]).norm(), 1e-3);
  EXPECT_LT((velocities[0] - velocities[2]).norm(), 1e-3);
}

TEST(Filters, GateRejectsAnOutlierAndKeepsTheState) {
  for (FilterType type : kAllFilters) {
    auto filter = makeFilter(type, ImuNoise());
    const NavState s = someState();
    filter->initialize(s, filter->fromWorldCovariance(s, ErrorCovariance::Identity()));
    const ErrorCovariance covariance = filter->covariance();
    const CorrectionResult result = filter->correctPosition(
        fixAt(s.position_map + Eigen::Vector3d(80.0, 0.0, 0.0), s.stamp_s, 1.0), 16.0);
    EXPECT_FALSE(result.accepted) << toString(type);
    EXPECT_GT(result.mahalanobis_squared, 16.0);
    EXPECT_NE(result.reason.find("outlier"), std::string::npos) << result.reason;
    EXPECT_EQ(filter->state().position_map, s.position_map);
    EXPECT_EQ(filter->covariance(), covariance);
  }
}

TEST(Filters, NonFiniteInputIsRejected) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (FilterType type : kAllFilters) {
    auto filter = makeFilter(type, ImuNoise());
    filter->initialize(someState(), ErrorCovariance::Identity());
    const NavState s = filter->state();
    ImuSample bad;
    bad.angular_velocity = Eigen::Vector3d(nan, 0, 0);
    filter->propagate(bad, 0.1);
    EXPECT_EQ(filter->state().rotation, s.rotation);
    EXPECT_EQ(filter->state().stamp_s, s.stamp_s);
    ImuSample good;
    good.specific_force = Eigen::Vector3d(0, 0, kGravity);
    filter->propagate(good, nan);
    filter->propagate(good, -0.1);
    EXPECT_EQ(filter->state().stamp_s, s.stamp_s);
    PositionFix fix = fixAt(Eigen::Vector3d(nan, 0, 0), s.stamp_s, 1.0);
    EXPECT_FALSE(filter->correctPosition(fix, 100.0).accepted);
    fix = fixAt(s.position_map, s.stamp_s, 1.0);
    fix.covariance_map(0, 0) = nan;
    EXPECT_FALSE(filter->correctPosition(fix, 1e9).accepted);
    EXPECT_TRUE(filter->state().position_map.allFinite());
    EXPECT_TRUE(filter->covariance().allFinite());
  }
}

// Average pose NEES (6 dof) over Monte-Carlo runs of a noisy simulated drive with GPS.
double averagePoseNees(FilterType type, int runs, int steps) {
  const SimulatedDrive drive = simulateDrive(steps, 0.1);
  std::mt19937 rng(42);
  double nees_sum = 0.0;
  int count = 0;
  for (int run = 0; run < runs; ++run) {
    test_drive::simulateNoisyRun(
        type, drive, test_drive::RunNoise(), &rng, [&](const test_drive::RunStep& step) {
          if (step.k < 10) return;
          const NavState& estimate = step.filter->state();
          Eigen::Matrix<double, 6, 1> pose_error;
          pose_error.head<3>() = step.truth.position_map - estimate.position_map;
          pose_error.tail<3>() = lie::logSO3(estimate.rotation.transpose() * step.truth.rotation);
          nees_sum += pose_error.dot(step.filter->poseCovariance().ldlt().solve(pose_error));
          ++count;
        });
  }
  return nees_sum / count;
}

TEST(Filters, PoseNeesIsWithinTheChiSquareBand) {
  // 25 runs: the run-averaged NEES of 6 dof lies in [chi2_150(0.025), chi2_150(0.975)] / 25
  // = [4.68, 7.45] with 95 % probability at each time; the time average is tighter still.
  for (FilterType type : kAllFilters) {
    const double nees = averagePoseNees(type, 25, 200);
    EXPECT_GT(nees, 4.68) << toString(type);
    EXPECT_LT(nees, 7.45) << toString(type);
    std::printf("[ NEES     ] %s: average pose NEES %.2f (6 dof)\n", toString(type).c_str(), nees);
  }
}

TEST(Filters, ProcessNoiseOfAShortStepAtRestIsDensitySquaredTimesDt) {
  const ImuNoise noise;
  const double dt = 1e-3;
  const Matrix15d q =
      leftProcessNoise(Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), noise, 1.0, 1.0, dt);
  const double gyro = noise.gyro_noise_density * noise.gyro_noise_density * dt;
  const double accel = noise.accel_noise_density * noise.accel_noise_density * dt;
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(q(i, i), gyro, 1e-3 * gyro) << i;
    EXPECT_NEAR(q(3 + i, 3 + i), accel, 1e-3 * accel) << i;
  }
  const Matrix15d q2 =
      leftProcessNoise(Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), noise, 2.0, 3.0, dt);
  EXPECT_NEAR(q2(0, 0), 4.0 * gyro, 4e-3 * gyro);
  EXPECT_NEAR(q2(3, 3), 9.0 * accel, 9e-3 * accel);
}
}  // namespace
}  // namespace estimation
}  // namespace inekf_semantic_mapping
