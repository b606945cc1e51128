#include "fusionloc/rbpf_slam/icp.hpp"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <iostream>
#include <random>
#include <string>

#include "fusionloc/rbpf_slam/scan_matcher.hpp"
#include "laser_fixtures.hpp"

namespace fl::rbpf {
namespace {

using test::ScanPoints;

TEST(Icp, RecoversAKnownTransformOnSyntheticScans) {
  const test::LaserWorld world = test::LaserWorld::RoomWithBoxes();
  const fl::Pose2 pose_i(-6.0, -4.5, 0.1);
  const fl::Pose2 T_i_j(0.45, 0.12, 0.15);
  const fl::Pose2 pose_j = pose_i * T_i_j;
  const auto ref = ComputeNormals(ScanPoints(world, pose_i, 0.005, 1));
  const auto query = ScanPoints(world, pose_j, 0.005, 2);
  IcpOptions o;
  // Start 10 cm / 3 degrees away from the truth.
  const IcpResult r = AlignPointToLine(ref, query, T_i_j * fl::Pose2(-0.08, 0.06, -0.05), o);
  ASSERT_TRUE(r.ok) << r.failure;
  EXPECT_NEAR(r.T_ref_query.x, T_i_j.x, 0.01);
  EXPECT_NEAR(r.T_ref_query.y, T_i_j.y, 0.01);
  EXPECT_NEAR(r.T_ref_query.theta, T_i_j.theta, 0.003);
  EXPECT_LT(r.rms, 0.01);
  EXPECT_GT(r.inlier_fraction, 0.8);
  // Information: symmetric positive definite, scaled by 1/σ².
  EXPECT_TRUE(r.information.isApprox(r.information.transpose()));
  EXPECT_GT(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(r.information).eigenvalues().minCoeff(),
            0.0);
}

TEST(Icp, InformationIsSmallAlongACorridor) {
  // Two parallel walls along x: x is unobservable, y and θ are.
  test::LaserWorld corridor;
  corridor.AddSegment({-50, -1.5}, {50, -1.5});
  corridor.AddSegment({-50, 1.5}, {50, 1.5});
  const auto ref = ComputeNormals(ScanPoints(corridor, fl::Pose2(), 0.0, 1));
  const auto query = ScanPoints(corridor, fl::Pose2(0.2, 0.0, 0.0), 0.0, 2);
  const IcpResult r = AlignPointToLine(ref, query, fl::Pose2(0.2, 0.05, 0.02), IcpOptions());
  EXPECT_NEAR(r.T_ref_query.y, 0.0, 0.005);
  EXPECT_NEAR(r.T_ref_query.theta, 0.0, 0.002);
  EXPECT_LT(r.information(0, 0), 1e-3 * r.information(1, 1));
}

// Monte-Carlo consistency of the reported covariance: chi2 = eᵀ Ω e of the ICP error against
// the truth over many noisy scan pairs. For a calibrated 3-DoF Gaussian its mean is 3.
struct Chi2Trials {
  std::vector<double> chi2;
  double mean = 0.0;
  double mean_sigma_x = 0.0;  // [m] mean reported std along world x
  double rms_err_x = 0.0;     // [m] actual RMS error along x
  int failures = 0;
};

Chi2Trials RunChi2Trials(const test::LaserWorld& world, const std::vector<fl::Pose2>& starts,
                         int beams, double fov, double max_range, double noise, int trials,
                         unsigned seed, const IcpOptions& options) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::normal_distribution<double> n01(0.0, 1.0);
  Chi2Trials out;
  auto points = [&](const fl::Pose2& pose) {
    return test::FanPoints(world, pose, beams, fov, max_range, noise, &rng);
  };
  for (int t = 0; t < trials; ++t) {
    const fl::Pose2 pose_i =
        starts[t % starts.size()] * fl::Pose2(0.3 * u(rng), 0.1 * u(rng), 0.1 * u(rng));
    const fl::Pose2 T_i_j(0.3 + 0.2 * u(rng), 0.1 * u(rng), 0.2 * u(rng));
    const auto ref = ComputeNormals(points(pose_i));
    const auto query = points(pose_i * T_i_j);
    // Initial guess as from the filter: a few cm and a degree off.
    const fl::Pose2 init = T_i_j * fl::Pose2(0.03 * n01(rng), 0.03 * n01(rng), 0.015 * n01(rng));
    const IcpResult r = AlignPointToLine(ref, query, init, options);
    if (!r.ok) {
      ++out.failures;
      continue;
    }
    const Eigen::Vector3d e(r.T_ref_query.x - T_i_j.x, r.T_ref_query.y - T_i_j.y,
                            fl::WrapAngle(r.T_ref_query.theta - T_i_j.theta));
    out.chi2.push_back(e.dot(r.information * e));
    // Along world x: rotate the (x, y) block into the world frame of keyframe i.
    const Eigen::Matrix2d R = pose_i.rotation();
    const Eigen::Matrix2d cov_w = R * r.covariance.topLeftCorner<2, 2>() * R.transpose();
    const Eigen::Vector2d e_w = R * e.head<2>();
    out.mean_sigma_x += std::sqrt(cov_w(0, 0));
    out.rms_err_x += e_w.x() * e_w.x();
  }
  const double n = static_cast<double>(out.chi2.size());
  for (double c : out.chi2) out.mean += c / n;
  out.mean_sigma_x /= n;
  out.rms_err_x = std::sqrt(out.rms_err_x / n);
  return out;
}

TEST(IcpCovariance, ModelIsCalibratedInARoom) {
  // SICK-like: 361 beams over 180°, 1 cm range noise, in the room with boxes. The covariance
  // floor models errors this exact synthetic world does not have (map, timing, distortion): set
  // it negligible to test the fitted part (sandwich, correlation) alone.
  const test::LaserWorld world = test::LaserWorld::RoomWithBoxes();
  const std::vector<fl::Pose2> starts = {
      {-6.0, -4.5, 0.1}, {5.0, -4.6, 0.0}, {7.8, -1.0, 1.6}, {0.0, 4.5, M_PI}, {-8.5, 1.0, -1.5}};
  IcpOptions o;
  o.floor_sigma_xy = 1e-6;
  o.floor_sigma_theta = 1e-7;
  // 400 pairs: the mean of χ²₃ has a standard error of 0.12 (this one's tail is heavier: 0.17).
  const Chi2Trials t = RunChi2Trials(world, starts, 361, M_PI, 25.0, 0.01, 400, 3, o);
  ASSERT_GE(t.chi2.size(), 390u) << t.failures << " failures";
  std::vector<double> sorted = t.chi2;
  std::sort(sorted.begin(), sorted.end());
  const double median = sorted[sorted.size() / 2];
  const double above_p95 =  // fraction above the 95% quantile of χ²₃
      static_cast<double>(sorted.end() - std::upper_bound(sorted.begin(), sorted.end(), 7.815)) /
      static_cast<double>(sorted.size());
  std::cout << "room (no floor): mean chi2 " << t.mean << ", median " << median << ", " << above_p95
            << " above 7.815 (calibrated: 3, 2.37, 0.05)\n";
  // The fit is a little over-confident here (mean 3.7, median 2.7, 10% above). The bounds fail
  // a covariance 1.5 times too large (mean 2.4) or too small (5.5), or without the correlation
  // inflation κ (mean 4.2, median 3.1, 14% above).
  EXPECT_GT(t.mean, 3.0);
  EXPECT_LT(t.mean, 4.0);
  EXPECT_GT(median, 2.0);
  EXPECT_LT(median, 3.0);
  EXPECT_LT(above_p95, 0.12);
  // With the default floor the covariance may only get more conservative.
  const Chi2Trials d = RunChi2Trials(world, starts, 361, M_PI, 25.0, 0.01, 400, 3, IcpOptions());
  EXPECT_LT(d.mean, t.mean);
}

TEST(IcpCovariance, IsLargeAlongACorridorAxis) {
  // A 100 m corridor, 2.5 m wide, with two door recesses; Hokuyo-like 682 beams over 240°, 10 m
  // range, 3 cm noise. Far from the recesses nothing fixes the axis: the reported std along it
  // must say so (and the solution must not slide on noise), while y and heading stay tight.
  test::LaserWorld world;
  world.AddSegment({-50, -1.25}, {50, -1.25});
  for (double x : {-6.0, 7.0}) world.AddBox(x - 0.5, 1.25, x + 0.5, 1.55);
  world.AddSegment({-50, 1.25}, {-6.5, 1.25});
  world.AddSegment({-5.5, 1.25}, {6.5, 1.25});
  world.AddSegment({7.5, 1.25}, {50, 1.25});
  const std::vector<fl::Pose2> far = {{-30.0, 0.0, 0.0}, {30.0, 0.2, M_PI}, {-20.0, 0.3, 0.02}};
  const Chi2Trials t =
      RunChi2Trials(world, far, 682, 240.0 * M_PI / 180.0, 10.0, 0.03, 90, 5, IcpOptions());
  ASSERT_GE(t.chi2.size(), 85u) << t.failures << " failures";
  std::vector<double> sorted = t.chi2;
  std::sort(sorted.begin(), sorted.end());
  std::cout << "corridor: mean chi2 " << t.mean << ", median " << sorted[sorted.size() / 2]
            << ", mean reported std along the axis " << t.mean_sigma_x << " m, RMS error "
            << t.rms_err_x << " m\n";
  EXPECT_GT(t.mean_sigma_x, 1.0);                 // "unknown", not centimetres
  EXPECT_LT(t.rms_err_x, 0.25 * t.mean_sigma_x);  // the error is well inside what is reported
  EXPECT_LT(t.mean, 6.0);                         // not over-confident (with the default floor)
  // Without the floor (the fitted part alone) y / heading are over-confident on this perfectly
  // straight synthetic corridor: mean 11.2 (median 6.5) where a calibrated covariance would give
  // about 2 (the axis adds almost nothing). Bound how much, tightly enough to fail a fitted
  // covariance 1.5 times smaller (mean 16.7) or larger (7.4); lower the bounds if the fitted
  // part gets more honest here.
  IcpOptions o;
  o.floor_sigma_xy = 1e-6;
  o.floor_sigma_theta = 1e-7;
  const Chi2Trials m = RunChi2Trials(world, far, 682, 240.0 * M_PI / 180.0, 10.0, 0.03, 90, 5, o);
  std::cout << "corridor (no floor): mean chi2 " << m.mean << "\n";
  EXPECT_GT(m.mean, 8.0);
  EXPECT_LT(m.mean, 13.0);
  EXPECT_GT(m.mean_sigma_x, 1.0);
}

// Points of a Hokuyo-like scan (682 beams over 240°, 10 m range) from `pose`, range noise
// `noise` drawn from rng.
std::vector<Eigen::Vector2d> UrgPoints(const test::LaserWorld& world, const fl::Pose2& pose,
                                       double noise, std::mt19937* rng) {
  return test::FanPoints(world, pose, 682, 240.0 * M_PI / 180.0, 10.0, noise, rng);
}

TEST(Icp, ScanRangeNoiseMeasuresTheSensorsNoise) {
  const test::LaserWorld room = test::LaserWorld::RoomWithBoxes();
  std::mt19937 rng(3);
  EXPECT_LT(ScanRangeNoise(UrgPoints(room, fl::Pose2(-6.0, -4.5, 0.1), 0.0, &rng)), 0.001);
  for (double noise : {0.01, 0.03, 0.1}) {
    const double est = ScanRangeNoise(UrgPoints(room, fl::Pose2(-6.0, -4.5, 0.1), noise, &rng));
    EXPECT_NEAR(est, noise, 0.15 * noise) << "noise " << noise;
  }
  EXPECT_EQ(ScanRangeNoise({{1.0, 0.0}, {1.0, 0.1}}), 0.0) << "too few points";
}

TEST(Icp, WideNormalsSeeThatNoisyCorridorWallsLeaveTheAxisFree) {
  // 10 cm range noise (the simulator's laser) in a featureless corridor: normals fitted within
  // 0.3 m follow the noise (tens of degrees off the wall) and make up information along the
  // axis: ICP then reports centimetres there while its error is a decimetre. The noise-wide
  // normals (icp.normal_radius_per_noise) say the axis is free, and that the narrow ones' claim
  // was the noise's.
  test::LaserWorld corridor;
  corridor.AddSegment({-50, -1.25}, {50, -1.25});
  corridor.AddSegment({-50, 1.25}, {50, 1.25});
  std::mt19937 rng(5);
  IcpOptions fixed;
  fixed.normal_radius_per_noise = 0.0;
  fixed.normal_gap_per_noise = 0.0;
  double wide_sigma_x = 0.0, fixed_sigma_x = 0.0, err2 = 0.0;
  int noise_made = 0, n = 0;
  for (int t = 0; t < 20; ++t) {
    const fl::Pose2 pose_i(-20.0 + 2.0 * t, 0.3 * std::sin(t), 0.03 * std::cos(t));
    const fl::Pose2 T_i_j(0.5, 0.02, 0.01);
    const auto ref_pts = UrgPoints(corridor, pose_i, 0.1, &rng);
    const auto query = UrgPoints(corridor, pose_i * T_i_j, 0.1, &rng);
    const IcpResult wide = AlignPointToLine(ComputeNormals(ref_pts, IcpOptions()), query,
                                            T_i_j * fl::Pose2(0.05, 0.0, 0.0), IcpOptions());
    const IcpResult narrow = AlignPointToLine(ComputeNormals(ref_pts, fixed), query,
                                              T_i_j * fl::Pose2(0.05, 0.0, 0.0), fixed);
    if (!wide.ok || !narrow.ok) continue;
    ++n;
    wide_sigma_x += std::sqrt(wide.covariance(0, 0));
    fixed_sigma_x += std::sqrt(narrow.covariance(0, 0));
    noise_made += wide.noise_made_dims;
    EXPECT_EQ(narrow.noise_made_dims, 0);
    err2 += std::pow(wide.T_ref_query.x - T_i_j.x, 2);
    EXPECT_NEAR(wide.T_ref_query.y, T_i_j.y, 0.05);
  }
  ASSERT_GE(n, 15);
  std::cout << "noisy corridor: reported std along the axis " << wide_sigma_x / n
            << " m (fixed normals: " << fixed_sigma_x / n << " m), RMS error "
            << std::sqrt(err2 / n) << " m, noise-made directions in " << noise_made << " of " << n
            << "\n";
  EXPECT_GT(wide_sigma_x / n, 1.0);
  EXPECT_LT(fixed_sigma_x / n, 0.05) << "the failure the wide normals are for";
  EXPECT_GE(noise_made, n - 1);
}

TEST(Icp, WideNormalsAreThePointsOwnOnACleanScan) {
  // 1 cm noise: the noise-wide fit is no wider than normal_radius, so nothing changes.
  const test::LaserWorld room = test::LaserWorld::RoomWithBoxes();
  std::mt19937 rng(7);
  const auto pts = UrgPoints(room, fl::Pose2(5.0, -4.6, 0.0), 0.01, &rng);
  const auto normals = ComputeNormals(pts, IcpOptions());
  ASSERT_GT(normals.size(), 300u);
  for (const PointNormal& pn : normals) ASSERT_EQ(pn.n_wide, pn.n);
  const auto plain = ComputeNormals(pts);
  ASSERT_EQ(plain.size(), normals.size());
  for (size_t i = 0; i < plain.size(); ++i) EXPECT_EQ(plain[i].n, normals[i].n);
}

// The Jacobian of one pair (PoseJacobian of the normal, used by the steps and the covariance)
// against central differences of e = nᵀ (R(θ) q + t − r) (icp.hpp), at headings all around the
// circle.
TEST(Icp, PointToLineJacobianMatchesNumericDifferentiation) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double h = 1e-6;
  for (int t = 0; t < 200; ++t) {
    const fl::Pose2 T(5 * u(rng), 5 * u(rng), M_PI * u(rng));
    const Eigen::Vector2d q(10 * u(rng), 10 * u(rng)), r(10 * u(rng), 10 * u(rng));
    const double a = M_PI * u(rng);
    const Eigen::Vector2d n(std::cos(a), std::sin(a));
    auto e = [&](const fl::Pose2& P) { return n.dot(P * q - r); };
    const Eigen::Vector3d J = PoseJacobian(n, q, std::cos(T.theta), std::sin(T.theta));
    const Eigen::Vector3d numeric(
        (e(fl::Pose2(T.x + h, T.y, T.theta)) - e(fl::Pose2(T.x - h, T.y, T.theta))) / (2 * h),
        (e(fl::Pose2(T.x, T.y + h, T.theta)) - e(fl::Pose2(T.x, T.y - h, T.theta))) / (2 * h),
        (e(fl::Pose2(T.x, T.y, T.theta + h)) - e(fl::Pose2(T.x, T.y, T.theta - h))) / (2 * h));
    EXPECT_LT((J - numeric).norm(), 1e-6 * (1 + q.norm()))
        << "J " << J.transpose() << ", numeric " << numeric.transpose();
  }
}

// Noisy scans (3 cm range noise) of a turn of ±0.6 rad at headings around the circle, ICP
// started 0.15 rad and 14 cm from the truth: Gauss-Newton with the right Jacobian converges
// (step below 1e-5) in 10-16 iterations (9 at the earliest: the pairing distance reaches its
// final value at iteration 9), within 1.7 cm and 3.3 mrad of the truth. With one sign wrong it
// stops elsewhere (decimetres off) or creeps on and runs out of iterations.
TEST(Icp, RecoversNoisyScansFromALargeRotation) {
  const test::LaserWorld world = test::LaserWorld::RoomWithBoxes();
  int iterations = 0;
  unsigned seed = 60;
  for (const fl::Pose2& pose_i : {fl::Pose2(-6.0, -4.5, 0.1), fl::Pose2(5.0, -4.6, 2.0),
                                  fl::Pose2(7.8, -1.0, -1.6), fl::Pose2(0.0, 4.5, M_PI)}) {
    for (const double turn : {0.6, -0.6}) {
      const fl::Pose2 T_i_j(0.3, 0.05, turn);
      const auto ref = ComputeNormals(ScanPoints(world, pose_i, 0.03, seed++));
      const auto query = ScanPoints(world, pose_i * T_i_j, 0.03, seed++);
      const fl::Pose2 init = T_i_j * fl::Pose2(0.1, -0.1, turn > 0 ? -0.15 : 0.15);
      const IcpResult r = AlignPointToLine(ref, query, init, IcpOptions());
      const fl::Pose2 e = T_i_j.between(r.T_ref_query);
      const std::string where =
          "turn " + std::to_string(turn) + " at heading " + std::to_string(pose_i.theta);
      EXPECT_TRUE(r.ok) << where << ": " << r.failure;
      EXPECT_TRUE(r.converged) << where << ": " << r.iterations << " iterations";
      EXPECT_LT(std::hypot(e.x, e.y), 0.025) << where;
      EXPECT_LT(std::abs(e.theta), 0.005) << where;
      iterations += r.iterations;
    }
  }
  EXPECT_LE(iterations, 8 * 14) << "8 alignments";
}

TEST(Icp, FailsClearlyWithTooFewPoints) {
  std::vector<PointNormal> ref(3);
  const IcpResult r = AlignPointToLine(ref, {{1, 0}, {2, 0}}, fl::Pose2(), IcpOptions());
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.failure.find("too few points"), std::string::npos);
}

}  // namespace
}  // namespace fl::rbpf
