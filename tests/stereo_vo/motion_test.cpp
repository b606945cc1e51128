// Tests of the motion solvers: SVD (Arun/Umeyama), RANSAC, the Ceres refinement and its
// covariance, the cost functors' Jacobians, and the covariance transport helpers.
#include "fusionloc/stereo_vo/motion.hpp"

#include <ceres/gradient_checker.h>
#include <gtest/gtest.h>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/stereo_vo/reprojection_cost.hpp"
#include "stereo_fixtures.hpp"

namespace fl::vo {
namespace {

using fl::test::stereo::MakeCorrespondences;
using fl::test::stereo::MakeMotion;

const std::vector<const ceres::Manifold*>* const kNoManifolds = nullptr;

StereoCamera Cam() { return {500.0, 500.0, 319.5, 239.5, 0.2}; }

double TransError(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return (a.translation() - b.translation()).norm();
}
double RotErrorDeg(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return fl::RotationAngle(a.linear().transpose() * b.linear()) * 180.0 / M_PI;
}

TEST(StereoVoMotion, SvdIsExactOnNoiseFreePoints) {
  const Eigen::Isometry3d T = MakeMotion(0.1, -0.3, 0.2, 1.5, -0.4, 2.0);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-5, 5);
  std::vector<Eigen::Vector3d> pa, pb;
  for (int i = 0; i < 20; ++i) {
    pb.emplace_back(u(rng), u(rng), u(rng));
    pa.push_back(T * pb.back());
  }
  Eigen::Isometry3d est;
  ASSERT_TRUE(SolveRigidSvd(pa, pb, {}, &est));
  EXPECT_LT(TransError(est, T), 1e-9);
  EXPECT_LT(RotErrorDeg(est, T), 1e-7);
  EXPECT_NEAR(est.linear().determinant(), 1.0, 1e-12);
  // Minimal sample of three points is exact too.
  ASSERT_TRUE(SolveRigidSvd(pa, pb, {2, 7, 11}, &est));
  EXPECT_LT(TransError(est, T), 1e-9);
}

TEST(StereoVoMotion, SvdRejectsDegenerateInput) {
  Eigen::Isometry3d est;
  std::vector<Eigen::Vector3d> line_a, line_b;
  for (int i = 0; i < 5; ++i) {
    line_b.emplace_back(i, 2.0 * i, 0.5 * i);
    line_a.push_back(line_b.back() + Eigen::Vector3d(1, 0, 0));
  }
  EXPECT_FALSE(SolveRigidSvd(line_a, line_b, {}, &est)) << "collinear points";
  EXPECT_FALSE(SolveRigidSvd({line_a[0], line_a[1]}, {line_b[0], line_b[1]}, {}, &est));
  EXPECT_FALSE(SolveRigidSvd(line_a, {line_b[0]}, {}, &est)) << "size mismatch";
}

TEST(StereoVoMotion, RansacFindsMotionWithHalfOutliers) {
  const Eigen::Isometry3d T = MakeMotion(0.01, 0.05, -0.01, 0.1, -0.02, 1.0);
  const auto corr = MakeCorrespondences(Cam(), T, 200, 100, 0.3, 11);
  RansacOptions opts;
  const RansacResult r = RansacMotion(Cam(), corr, opts);
  ASSERT_TRUE(r.ok);
  int wrong = 0;
  for (int i : r.inliers) wrong += i < 100 ? 1 : 0;
  EXPECT_LE(wrong, 3) << "outliers accepted as inliers";
  EXPECT_GE(static_cast<int>(r.inliers.size()), 40);
  // Minimal 3D-3D samples are noisy (far points' depth): RANSAC gets close, the refinement
  // on the reprojection error with re-selected inliers gets the motion (as StereoVo does).
  EXPECT_LT(TransError(r.T_a_b, T), 0.3);
  EXPECT_LT(RotErrorDeg(r.T_a_b, T), 1.0);
  RefineResult ref = RefineMotion(Cam(), corr, r.inliers, r.T_a_b, RefineOptions());
  ASSERT_TRUE(ref.ok);
  std::vector<int> inliers;
  for (int i = 0; i < static_cast<int>(corr.size()); ++i) {
    if (ForwardReprojectionError(Cam(), ref.T_a_b, corr[static_cast<size_t>(i)]) < 2.0) {
      inliers.push_back(i);
    }
  }
  wrong = 0;
  for (int i : inliers) wrong += i < 100 ? 1 : 0;
  EXPECT_LE(wrong, 3);
  EXPECT_GE(static_cast<int>(inliers.size()), 85);
  ref = RefineMotion(Cam(), corr, inliers, ref.T_a_b, RefineOptions());
  ASSERT_TRUE(ref.ok);
  EXPECT_LT(TransError(ref.T_a_b, T), 0.02);
  EXPECT_LT(RotErrorDeg(ref.T_a_b, T), 0.05);
  EXPECT_LT(ref.rms_px, 0.5);
}

TEST(StereoVoMotion, RansacFailsOnPureNoise) {
  const auto corr = MakeCorrespondences(Cam(), MakeMotion(0, 0, 0, 0, 0, 1), 60, 60, 0.0, 5);
  RansacOptions opts;
  opts.min_inliers = 12;
  const RansacResult r = RansacMotion(Cam(), corr, opts);
  EXPECT_FALSE(r.ok);
}

// The refinement's covariance should match the actual spread of its estimates (Monte Carlo):
// normalized estimation error squared averages about 6 for a consistent 6-DoF covariance.
TEST(StereoVoMotion, RefinementCovarianceIsConsistent) {
  const Eigen::Isometry3d T = MakeMotion(0.0, 0.03, 0.0, 0.05, 0.0, 0.8);
  for (bool joint : {true, false}) {
    RefineOptions opts;
    opts.optimize_points = joint;
    double nees = 0;
    const int runs = 40;
    for (int k = 0; k < runs; ++k) {
      const auto corr = MakeCorrespondences(Cam(), T, 150, 0, 0.5, 100 + k);
      std::vector<int> all(corr.size());
      for (size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int>(i);
      const RefineResult r = RefineMotion(Cam(), corr, all, T, opts);
      ASSERT_TRUE(r.ok);
      // delta with T_true = T_est Exp(delta)  ->  error in the estimate's tangent space.
      const Eigen::Isometry3d E = r.T_a_b.inverse() * T;
      Eigen::Matrix<double, 6, 1> d;
      d.head<3>() = E.translation();
      const Eigen::AngleAxisd aa(E.linear());
      d.tail<3>() = aa.angle() * aa.axis();
      nees += d.dot(r.covariance.ldlt().solve(d));
    }
    nees /= runs;
    // Two-view BA is consistent; fixed points ignore the points' noise (optimistic).
    if (joint) {
      EXPECT_GT(nees, 3.0) << "joint: covariance too large";
      EXPECT_LT(nees, 10.0) << "joint: covariance too small";
    } else {
      EXPECT_GT(nees, 3.0);
    }
  }
}

TEST(StereoVoMotion, CostFunctorsHaveCorrectJacobians) {
  const StereoCamera cam = Cam();
  const Eigen::Isometry3d T0 = MakeMotion(0.02, -0.1, 0.03, 0.3, 0.1, 1.2);
  const Eigen::Vector3d p(1.0, -0.5, 8.0), obs(350.0, 200.0, 338.0);
  double delta[6] = {0.01, -0.02, 0.03, 0.002, -0.004, 0.003};
  double point[3] = {1.0, -0.5, 8.0};
  ceres::NumericDiffOptions nd;
  for (auto dir : {StereoReprojectionCost::kForward, StereoReprojectionCost::kBackward}) {
    std::unique_ptr<ceres::CostFunction> cost(StereoReprojectionCost::Create(cam, T0, p, obs, dir));
    ceres::GradientChecker checker(cost.get(), kNoManifolds, nd);
    ceres::GradientChecker::ProbeResults results;
    std::vector<double*> params = {delta};
    EXPECT_TRUE(checker.Probe(params.data(), 1e-7, &results)) << results.error_log;
  }
  {
    std::unique_ptr<ceres::CostFunction> cost(StereoPointCostA::Create(cam, obs));
    ceres::GradientChecker checker(cost.get(), kNoManifolds, nd);
    ceres::GradientChecker::ProbeResults results;
    std::vector<double*> params = {point};
    EXPECT_TRUE(checker.Probe(params.data(), 1e-7, &results)) << results.error_log;
  }
  {
    std::unique_ptr<ceres::CostFunction> cost(StereoPointCostB::Create(cam, T0, obs));
    ceres::GradientChecker checker(cost.get(), kNoManifolds, nd);
    ceres::GradientChecker::ProbeResults results;
    std::vector<double*> params = {delta, point};
    EXPECT_TRUE(checker.Probe(params.data(), 1e-7, &results)) << results.error_log;
  }
}

TEST(StereoVoMotion, CostFunctorsMatchTheirDefinition) {
  // At delta = 0 the forward cost reprojects T0^-1 p; the backward one T0 p.
  const StereoCamera cam = Cam();
  const Eigen::Isometry3d T0 = MakeMotion(0.0, 0.1, 0.0, 0.2, 0.0, 1.0);
  const Eigen::Vector3d p(0.5, 0.2, 6.0);
  Eigen::Vector3d expect_fwd, expect_bwd;
  ASSERT_TRUE(cam.Project(T0.inverse() * p, &expect_fwd));
  ASSERT_TRUE(cam.Project(T0 * p, &expect_bwd));
  double zero[6] = {0, 0, 0, 0, 0, 0};
  const double* params[] = {zero};
  Eigen::Vector3d r;
  std::unique_ptr<ceres::CostFunction> fwd(StereoReprojectionCost::Create(
      cam, T0, p, Eigen::Vector3d::Zero(), StereoReprojectionCost::kForward));
  ASSERT_TRUE(fwd->Evaluate(params, r.data(), nullptr));
  EXPECT_LT((r - expect_fwd).norm(), 1e-9);
  std::unique_ptr<ceres::CostFunction> bwd(StereoReprojectionCost::Create(
      cam, T0, p, Eigen::Vector3d::Zero(), StereoReprojectionCost::kBackward));
  ASSERT_TRUE(bwd->Evaluate(params, r.data(), nullptr));
  EXPECT_LT((r - expect_bwd).norm(), 1e-9);
}

TEST(StereoVoMotion, AdjointTransportsPerturbations) {
  const Eigen::Isometry3d T = MakeMotion(0.3, -0.2, 0.5, 1.0, 2.0, -0.5);
  Eigen::Matrix<double, 6, 1> d;
  d << 1e-4, -2e-4, 3e-4, 2e-4, 1e-4, -3e-4;
  auto exp = [](const Eigen::Matrix<double, 6, 1>& v) {
    double a[6];
    for (int i = 0; i < 6; ++i) a[i] = v(i);
    return ApplyDelta(Eigen::Isometry3d::Identity(), a);
  };
  const Eigen::Isometry3d lhs = T * exp(d) * T.inverse();
  const Eigen::Isometry3d rhs = exp(Adjoint(T) * d);
  EXPECT_LT((lhs.matrix() - rhs.matrix()).norm(), 1e-7);
}

TEST(StereoVoMotion, ComposedCovarianceMatchesMonteCarlo) {
  const Eigen::Isometry3d T_ab = MakeMotion(0.0, 0.2, 0.0, 0.0, 0.0, 1.0);
  const Eigen::Isometry3d T_bc = MakeMotion(0.0, -0.1, 0.05, 0.1, 0.0, 1.0);
  Eigen::Matrix<double, 6, 6> ca = Eigen::Matrix<double, 6, 6>::Identity() * 1e-4;
  Eigen::Matrix<double, 6, 6> cb = Eigen::Matrix<double, 6, 6>::Identity() * 4e-4;
  const Eigen::Matrix<double, 6, 6> predicted = ComposeCovariance(ca, T_bc, cb);
  std::mt19937 rng(9);
  std::normal_distribution<double> n01;
  Eigen::Matrix<double, 6, 6> sample = Eigen::Matrix<double, 6, 6>::Zero();
  const int runs = 20000;
  const Eigen::Isometry3d T_ac = T_ab * T_bc;
  for (int k = 0; k < runs; ++k) {
    double da[6], db[6];
    for (int i = 0; i < 6; ++i) {
      da[i] = n01(rng) * 1e-2;
      db[i] = n01(rng) * 2e-2;
    }
    const Eigen::Isometry3d E = T_ac.inverse() * ApplyDelta(T_ab, da) * ApplyDelta(T_bc, db);
    Eigen::Matrix<double, 6, 1> d;
    d.head<3>() = E.translation();
    const Eigen::AngleAxisd aa(E.linear());
    d.tail<3>() = aa.angle() * aa.axis();
    sample += d * d.transpose();
  }
  sample /= runs;
  EXPECT_LT((sample - predicted).norm() / predicted.norm(), 0.05);
}

}  // namespace
}  // namespace fl::vo
