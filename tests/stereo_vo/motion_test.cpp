// Tests of the motion solvers: SVD (Arun/Umeyama), RANSAC, the refinement (analytic and Ceres)
// and its covariance, the disparity offset estimation, the cost functors' Jacobians, and the
// covariance transport helpers.
#include "fusionloc/stereo_vo/motion.hpp"

#include <ceres/gradient_checker.h>
#include <gtest/gtest.h>

#include <cstdio>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/stereo_vo/reprojection_cost.hpp"
#include "stereo_fixtures.hpp"

namespace fl::vo {
namespace {

using fl::test::stereo::MakeCorrespondences;
using fl::test::stereo::MakeLaserMeasurements;
using fl::test::stereo::MakeMotion;

const std::vector<const ceres::Manifold*>* const kNoManifolds = nullptr;

StereoCamera Cam() { return {500.0, 500.0, 319.5, 239.5, 0.2}; }

using fl::test::stereo::RotErrorDeg;
using fl::test::stereo::TransError;

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
    opts.covariance_scale = 1.0;  // the two-view covariance itself (the default is for chains)
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

// The improved objective (laser-aided mode): with half the points measured in 3D (3 cm depth
// noise, as a laser gives them) beside the stereo reprojection error (0.5 px noise, so far
// points' stereo depth is poor), the motion is recovered better than from reprojection alone,
// and its covariance stays consistent.
TEST(StereoVoMotion, LaserPointErrorsRecoverTheMotionBetter) {
  const Eigen::Isometry3d T = MakeMotion(0.005, 0.03, -0.01, 0.05, -0.02, 1.0);
  RefineOptions opts;
  opts.covariance_scale = 1.0;  // the two-view covariance itself (the default is for chains)
  double err_plain = 0, err_laser = 0, rot_plain = 0, rot_laser = 0, nees = 0;
  const int runs = 30;
  for (int k = 0; k < runs; ++k) {
    std::vector<Eigen::Vector3d> truth;
    const auto corr = MakeCorrespondences(Cam(), T, 120, 0, 0.5, 500 + k, &truth);
    const PointMeasurements laser =
        MakeLaserMeasurements(Cam(), T, corr, truth, 0.5, 0.03, 0.5, 900 + k);
    std::vector<int> all(corr.size());
    for (size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int>(i);
    const RefineResult plain = RefineMotion(Cam(), corr, all, Eigen::Isometry3d::Identity(), opts);
    const RefineResult aided = RefineMotion(Cam(), corr, all, Eigen::Isometry3d::Identity(), opts,
                                            nullptr, nullptr, &laser);
    ASSERT_TRUE(plain.ok);
    ASSERT_TRUE(aided.ok);
    err_plain += (plain.T_a_b.translation() - T.translation()).norm();
    err_laser += (aided.T_a_b.translation() - T.translation()).norm();
    rot_plain += Eigen::AngleAxisd(plain.T_a_b.linear().transpose() * T.linear()).angle();
    rot_laser += Eigen::AngleAxisd(aided.T_a_b.linear().transpose() * T.linear()).angle();
    const Eigen::Isometry3d E = aided.T_a_b.inverse() * T;
    Eigen::Matrix<double, 6, 1> d;
    d.head<3>() = E.translation();
    const Eigen::AngleAxisd aa(E.linear());
    d.tail<3>() = aa.angle() * aa.axis();
    nees += d.dot(aided.covariance.ldlt().solve(d));
  }
  std::printf(
      "mean translation error: reprojection %.4f m, with laser %.4f m; rotation %.4f / "
      "%.4f deg; NEES %.2f\n",
      err_plain / runs, err_laser / runs, rot_plain / runs * 57.2958, rot_laser / runs * 57.2958,
      nees / runs);
  EXPECT_LT(err_laser, 0.75 * err_plain);  // measured 0.65
  EXPECT_LE(rot_laser, 1.05 * rot_plain);
  EXPECT_GT(nees / runs, 3.0);
  EXPECT_LT(nees / runs, 10.0);
}

// Noise-free pixels and exact 3D measurements: the 3D point errors are zero at the true motion
// and the solver lands on it from identity (their Jacobians are right).
TEST(StereoVoMotion, LaserPointErrorsAreExactOnNoiseFreeData) {
  const Eigen::Isometry3d T = MakeMotion(0.02, -0.05, 0.01, 0.2, 0.05, 0.8);
  std::vector<Eigen::Vector3d> truth;
  const auto corr = MakeCorrespondences(Cam(), T, 60, 0, 0.0, 7, &truth);
  PointMeasurements laser = MakeLaserMeasurements(Cam(), T, corr, truth, 1.0, 1e-9, 0.5, 1);
  for (auto& m : laser.per_correspondence) {  // unit weights: well conditioned
    m.W_a = Eigen::Matrix3d::Identity() * 10.0;
    m.W_b = Eigen::Matrix3d::Identity() * 10.0;
  }
  std::vector<int> all(corr.size());
  for (size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int>(i);
  RefineOptions opts;
  opts.max_iterations = 20;
  const RefineResult r =
      RefineMotion(Cam(), corr, all, Eigen::Isometry3d::Identity(), opts, nullptr, nullptr, &laser);
  ASSERT_TRUE(r.ok);
  EXPECT_LT((r.T_a_b.translation() - T.translation()).norm(), 1e-4);
  EXPECT_LT(Eigen::AngleAxisd(r.T_a_b.linear().transpose() * T.linear()).angle(), 1e-5);
  // Ceres does not model them: refused, not ignored.
  opts.use_ceres = true;
  EXPECT_FALSE(RefineMotion(Cam(), corr, all, T, opts, nullptr, nullptr, &laser).ok);
}

// The square-root information whitens the point's covariance: W Sigma W^T = I.
TEST(StereoVoMotion, PointSqrtInformationWhitens) {
  const Eigen::Vector3d ray(0.3, -0.2, 1.0);
  const double dep = 0.05, lat = 0.004;
  const Eigen::Matrix3d W = PointSqrtInformation(ray, dep, lat);
  const Eigen::Vector3d e = ray.normalized();
  const double dep_ray = dep * ray.norm();
  const Eigen::Matrix3d Sigma = lat * lat * (Eigen::Matrix3d::Identity() - e * e.transpose()) +
                                dep_ray * dep_ray * e * e.transpose();
  EXPECT_TRUE((W * Sigma * W.transpose()).isApprox(Eigen::Matrix3d::Identity(), 1e-9));
  // Depth noise along the ray is sigma_depth in z.
  const Eigen::Vector3d dz = ray * (dep / ray.z());
  EXPECT_NEAR((W * dz).norm(), 1.0, 1e-9);
}

// The analytic two-view bundle adjustment (default) and the Ceres reference give the same
// motion and covariance on the same problem.
TEST(StereoVoMotion, AnalyticBundleAdjustmentMatchesCeres) {
  const Eigen::Isometry3d T = MakeMotion(0.01, 0.04, -0.02, 0.15, -0.05, 0.9);
  const auto corr = MakeCorrespondences(Cam(), T, 120, 0, 0.4, 21);
  std::vector<int> all(corr.size());
  for (size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int>(i);
  const Eigen::Isometry3d T0 = T * MakeMotion(0.005, -0.004, 0.003, 0.03, 0.02, -0.04);
  RefineOptions analytic, ceres_opts;
  analytic.max_iterations = ceres_opts.max_iterations = 20;
  ceres_opts.use_ceres = true;
  std::vector<Eigen::Vector3d> pts_a, pts_c;
  const RefineResult a = RefineMotion(Cam(), corr, all, T0, analytic, &pts_a);
  const RefineResult c = RefineMotion(Cam(), corr, all, T0, ceres_opts, &pts_c);
  ASSERT_TRUE(a.ok);
  ASSERT_TRUE(c.ok);
  // Same minimum up to the solvers' stopping tolerances (a wrong Jacobian would be far off).
  EXPECT_LT(TransError(a.T_a_b, c.T_a_b), 2e-5);
  EXPECT_LT(RotErrorDeg(a.T_a_b, c.T_a_b), 2e-4);
  EXPECT_NEAR(a.final_cost, c.final_cost, 1e-5 * c.final_cost);
  EXPECT_LT((a.covariance - c.covariance).norm(), 1e-2 * c.covariance.norm());
  ASSERT_EQ(pts_a.size(), pts_c.size());
  for (size_t i = 0; i < pts_a.size(); ++i) {
    EXPECT_LT((pts_a[i] - pts_c[i]).norm(), 2e-4 * pts_c[i].z() * pts_c[i].z());  // ~ depth sd
  }
  EXPECT_FALSE(a.offset_estimated);
  // The offset is only modelled by the analytic solver: the Ceres path refuses it.
  OffsetPrior prior;
  EXPECT_FALSE(RefineMotion(Cam(), corr, all, T0, ceres_opts, nullptr, &prior).ok);
}

// Correspondences whose measured disparities carry the rectification yaw offset
// delta * OffsetBasis(u_right): far points appear farther (delta < 0), the motion too long.
std::vector<StereoCorrespondence> WithOffset(const StereoCamera& cam,
                                             std::vector<StereoCorrespondence> corr, double delta) {
  for (auto& c : corr) {
    // measured u_right = true u_right - delta g (so u_left - u_right = d_true + delta g).
    c.obs_a(2) -= delta * OffsetBasis(cam, c.obs_a(2));
    c.obs_b(2) -= delta * OffsetBasis(cam, c.obs_b(2));
    c.p_a = cam.Triangulate(c.obs_a(0), c.obs_a(1), c.obs_a(0) - c.obs_a(2));
    c.p_b = cam.Triangulate(c.obs_b(0), c.obs_b(1), c.obs_b(0) - c.obs_b(2));
  }
  return corr;
}

TEST(StereoVoMotion, BundleAdjustmentEstimatesTheDisparityOffset) {
  // KITTI-like rig and depths (4..40 m), forward motion of 1 m.
  const StereoCamera cam{720.0, 720.0, 620.0, 187.0, 0.54};
  const Eigen::Isometry3d T = MakeMotion(0.0, 0.01, 0.0, 0.02, 0.0, 1.0);
  const double delta = -0.3;  // [px]
  double scale_without = 0, scale_with = 0, offset_sum = 0, z_sum = 0;
  const int runs = 20;
  for (int k = 0; k < runs; ++k) {
    auto corr = MakeCorrespondences(cam, T, 200, 0, 0.2, 300 + k);
    // Widen to KITTI's field of view (the helper draws x in [-8, 8] m).
    corr = WithOffset(cam, std::move(corr), delta);
    std::vector<int> all(corr.size());
    for (size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int>(i);
    const RefineResult plain = RefineMotion(cam, corr, all, T, RefineOptions());
    OffsetPrior prior;
    prior.variance_px2 = 1.0;
    prior.sigma_px = 0.2;
    const RefineResult est = RefineMotion(cam, corr, all, T, RefineOptions(), nullptr, &prior);
    ASSERT_TRUE(plain.ok);
    ASSERT_TRUE(est.ok);
    ASSERT_TRUE(est.offset_estimated);
    EXPECT_GT(est.offset_data_information, 1.0 / (0.2 * 0.2)) << "offset observable here";
    scale_without += plain.T_a_b.translation().norm() / T.translation().norm() / runs;
    scale_with += est.T_a_b.translation().norm() / T.translation().norm() / runs;
    offset_sum += est.offset_px / runs;
    z_sum += (est.offset_px - delta) / std::sqrt(est.offset_variance_px2) / runs;
  }
  EXPECT_GT(scale_without, 1.005) << "the offset makes the motion too long";
  EXPECT_NEAR(scale_with, 1.0, 0.002);
  EXPECT_NEAR(offset_sum, delta, 0.03);
  EXPECT_LT(std::abs(z_sum), 1.0) << "mean normalised offset error";
}

TEST(StereoVoMotion, OffsetIsUnobservableWithoutTranslation) {
  // Pure rotation: every depth explains the observations, so the data say (almost) nothing
  // about the offset and the estimate stays at the prior (0); with 1 m of forward motion the
  // same scene determines it.
  const StereoCamera cam{720.0, 720.0, 620.0, 187.0, 0.54};
  OffsetPrior prior;
  prior.variance_px2 = 0.01;
  prior.sigma_px = 0.2;
  double information[2] = {0, 0};
  for (int moving = 0; moving < 2; ++moving) {
    const Eigen::Isometry3d T = MakeMotion(0.0, 0.03, 0.0, 0.0, 0.0, moving ? 1.0 : 0.0);
    const auto corr = WithOffset(cam, MakeCorrespondences(cam, T, 200, 0, 0.0, 5), -0.3);
    std::vector<int> all(corr.size());
    for (size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int>(i);
    const RefineResult est = RefineMotion(cam, corr, all, T, RefineOptions(), nullptr, &prior);
    ASSERT_TRUE(est.ok);
    information[moving] = est.offset_data_information;
    if (!moving) {
      EXPECT_LT(std::abs(est.offset_px), 0.02);
      EXPECT_LT(est.T_a_b.translation().norm(), 1e-3);
    }
  }
  EXPECT_LT(information[0], 0.01 * information[1]) << "[1/px^2]";
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
