// Keyframe local bundle adjustment (local_ba.hpp): track collection, the cost blocks'
// Jacobians, the adjustment of a perturbed synthetic window, outliers, the covariance's
// consistency, and the refusals.
#include "fusionloc/stereo_vo/local_ba.hpp"

#include <ceres/ceres.h>
#include <ceres/gradient_checker.h>
#include <gtest/gtest.h>

#include <random>

#include "cost_fixtures.hpp"
#include "fusionloc/common/geometry.hpp"
#include "stereo_fixtures.hpp"

namespace fl::vo {
namespace {

using fl::test::stereo::MakeKeyframeWindow;
using fl::test::stereo::MakeMotion;

StereoCamera Cam() { return {500.0, 500.0, 319.5, 239.5, 0.5}; }

using fl::test::stereo::RotErrorDeg;
using fl::test::stereo::TransError;

// The window's poses but the first moved by a random error of about trans_m and rot_deg.
void Perturb(std::vector<BaKeyframe>* window, double trans_m, double rot_deg, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, 1.0);
  const double r = rot_deg * M_PI / 180.0;
  for (size_t k = 1; k < window->size(); ++k) {
    (*window)[k].T_world_camera = (*window)[k].T_world_camera *
                                  MakeMotion(r * n(rng), r * n(rng), r * n(rng), trans_m * n(rng),
                                             trans_m * n(rng), trans_m * n(rng));
  }
}

// Six keyframes 1 m apart seeing 300 points (pixel noise 0.3 px, `seed`), then perturbed by
// Perturb(trans_m, rot_deg, perturb_seed); the true poses in *truth.
std::vector<BaKeyframe> PerturbedWindow(const StereoCamera& cam, uint32_t seed, double trans_m,
                                        double rot_deg, uint32_t perturb_seed,
                                        std::vector<Eigen::Isometry3d>* truth) {
  std::vector<BaKeyframe> window = MakeKeyframeWindow(cam, 6, 300, 1.0, 0.04, 0.3, seed, truth);
  Perturb(&window, trans_m, rot_deg, perturb_seed);
  return window;
}

TEST(StereoVoLocalBa, CollectTracksKeepsSharedTracksTriangulatedWhereTheDisparityIsLargest) {
  const StereoCamera cam = Cam();
  std::vector<BaKeyframe> window(3);
  for (int k = 0; k < 3; ++k) {
    window[k].T_world_camera = MakeMotion(0, 0, 0, 0, 0, 1.0 * k);  // 1 m forward per keyframe
  }
  const Eigen::Vector3d p_world(1.0, 0.5, 12.0);
  for (int k = 0; k < 3; ++k) {
    Eigen::Vector3d uvu;
    ASSERT_TRUE(cam.Project(window[k].T_world_camera.inverse() * p_world, &uvu));
    window[k].observations.push_back({7, uvu, false, {}, {}});
  }
  window[0].observations.push_back({8, {300, 200, 290}, false, {}, {}});  // seen once: not shared
  window[1].observations.push_back(
      {9, {300, 200, 301}, false, {}, {}});  // negative disparity: skipped
  window[2].observations.push_back({9, {300, 200, 290}, false, {}, {}});
  const std::vector<BaTrack> tracks = CollectTracks(cam, window, 2);
  ASSERT_EQ(tracks.size(), 1u);
  EXPECT_EQ(tracks[0].track_id, 7);
  EXPECT_EQ(tracks[0].observations.size(), 3u);
  EXPECT_LT((tracks[0].p_o - p_world).norm(), 1e-9);  // frame o = keyframe 0 = world here
  EXPECT_EQ(CollectTracks(cam, window, 3).size(), 1u);
}

TEST(StereoVoLocalBa, ResidualBlocksPassTheGradientChecker) {
  const StereoCamera cam = Cam();
  std::vector<Eigen::Isometry3d> truth;
  std::vector<BaKeyframe> window = MakeKeyframeWindow(cam, 4, 40, 1.0, 0.05, 0.3, 3, &truth);
  Perturb(&window, 0.05, 0.5, 4);
  for (BaKeyframe& kf : window) {  // laser depth points on every third observation
    for (size_t i = 0; i < kf.observations.size(); i += 3) {
      BaObservation& o = kf.observations[i];
      o.has_point = true;
      o.m_camera = cam.Triangulate(o.uvu(0), o.uvu(1), o.uvu(0) - o.uvu(2)) * 1.01;
      o.W_camera << 30, 1, 0, 1, 30, 2, 0, 2, 10;
    }
  }
  for (size_t k = 1; k < window.size(); ++k) {  // motion priors (the chain, slightly off)
    window[k].has_motion = true;
    window[k].T_prev_camera =
        truth[k - 1].inverse() * truth[k] * MakeMotion(0.01, 0, 0, 0, 0.02, 0);
    window[k].motion_covariance.diagonal() << 1e-4, 2e-4, 1e-4, 1e-5, 1e-5, 2e-5;
  }
  const std::vector<BaTrack> tracks = CollectTracks(cam, window, 2);
  ASSERT_GE(tracks.size(), 20u);
  size_t observations = 0, with_points = 0;
  for (const BaTrack& t : tracks) {
    for (const auto& [k, o] : t.observations) {
      ++observations;
      with_points += o.has_point;
    }
  }
  BaState state = InitialState(window, tracks);
  // A non-zero perturbation to probe at.
  for (size_t k = 1; k < state.delta.size(); ++k) {
    state.delta[k] = {0.01, -0.02, 0.03, 0.002, -0.003, 0.001};
  }
  LocalBaOptions options;
  options.laser_points = true;
  ceres::Problem problem;
  BuildProblem(cam, window, tracks, options, 0.3, {}, &state, &problem);
  std::vector<ceres::ResidualBlockId> blocks;
  problem.GetResidualBlocks(&blocks);
  ASSERT_GT(with_points, 10u);
  // Reprojections, laser points, motion priors.
  EXPECT_EQ(blocks.size(), observations + with_points + window.size() - 1);
  int checked_a = 0, checked_b = 0, checked_motion = 0;
  for (ceres::ResidualBlockId id : blocks) {
    std::vector<double*> params;
    problem.GetParameterBlocksForResidualBlock(id, &params);
    const ceres::CostFunction* cost = problem.GetCostFunctionForResidualBlock(id);
    const std::vector<const ceres::Manifold*>* no_manifolds = nullptr;
    ceres::GradientChecker checker(cost, no_manifolds, fl::test::CheckerOptions());
    ceres::GradientChecker::ProbeResults results;
    EXPECT_TRUE(checker.Probe(params.data(), 1e-6, &results)) << results.error_log;
    ++(params.size() == 1 ? checked_a : params.size() == 4 ? checked_motion : checked_b);
  }
  EXPECT_GT(checked_a, 0);  // keyframe 0 (point only)
  EXPECT_GT(checked_b, 0);  // the others (rho, phi, point) and the laser points
  EXPECT_EQ(checked_motion, static_cast<int>(window.size()) - 1);  // (rho_i, phi_i, rho_j, phi_j)
}

TEST(StereoVoLocalBa, ReducesTheErrorOfAPerturbedWindow) {
  const StereoCamera cam = Cam();
  for (uint32_t seed : {1u, 2u, 3u}) {
    std::vector<Eigen::Isometry3d> truth;
    const std::vector<BaKeyframe> window = PerturbedWindow(cam, seed, 0.10, 1.0, seed + 100, &truth);
    double before_t = 0, before_r = 0;
    for (size_t k = 1; k < window.size(); ++k) {
      before_t = std::max(before_t, TransError(window[k].T_world_camera, truth[k]));
      before_r = std::max(before_r, RotErrorDeg(window[k].T_world_camera, truth[k]));
    }
    const LocalBaResult r = LocalBundleAdjustment(cam, window, LocalBaOptions(), 0.3);
    ASSERT_TRUE(r.ok) << r.message;
    EXPECT_LT(r.final_rms_px, 0.4);
    EXPECT_GT(r.initial_rms_px, 3.0);
    EXPECT_TRUE(r.covariance_ok);
    double after_t = 0, after_r = 0;
    for (size_t k = 1; k < window.size(); ++k) {
      after_t = std::max(after_t, TransError(r.T_world_camera[k], truth[k]));
      after_r = std::max(after_r, RotErrorDeg(r.T_world_camera[k], truth[k]));
    }
    EXPECT_EQ(r.T_world_camera[0].matrix(), window[0].T_world_camera.matrix());  // the gauge
    EXPECT_LT(after_t, 0.02) << "seed " << seed << ", before " << before_t << " m";
    EXPECT_LT(after_r, 0.05) << "seed " << seed << ", before " << before_r << " deg";
    EXPECT_LT(after_t, 0.2 * before_t);
  }
}

// function_tolerance ends the solves early (fewer steps than with none), and where they end is
// the converged window to far below its noise: poses within 1 mm and 0.005 deg.
TEST(StereoVoLocalBa, TheFunctionToleranceStopsAtTheConvergedWindow) {
  const StereoCamera cam = Cam();
  for (uint32_t seed : {1u, 2u, 3u}) {
    std::vector<Eigen::Isometry3d> truth;
    const std::vector<BaKeyframe> window = PerturbedWindow(cam, seed, 0.05, 0.5, seed + 200, &truth);
    LocalBaOptions converged;
    converged.function_tolerance = 0;
    converged.max_iterations = 30;
    const LocalBaResult full = LocalBundleAdjustment(cam, window, converged, 0.3);
    const LocalBaResult early = LocalBundleAdjustment(cam, window, LocalBaOptions(), 0.3);
    ASSERT_TRUE(full.ok && early.ok) << full.message << early.message;
    EXPECT_LT(early.iterations, full.iterations) << "seed " << seed;
    for (size_t k = 1; k < window.size(); ++k) {
      EXPECT_LT(TransError(early.T_world_camera[k], full.T_world_camera[k]), 1e-3)
          << "seed " << seed << ", keyframe " << k;
      EXPECT_LT(RotErrorDeg(early.T_world_camera[k], full.T_world_camera[k]), 5e-3);
    }
  }
}

TEST(StereoVoLocalBa, DropsOutlierObservations) {
  const StereoCamera cam = Cam();
  std::vector<Eigen::Isometry3d> truth;
  std::vector<BaKeyframe> window = MakeKeyframeWindow(cam, 5, 300, 1.0, 0.04, 0.3, 11, &truth);
  // Every tenth observation of the last keyframe moved by 15 px (a wrong track).
  int wrong = 0;
  for (size_t i = 0; i < window.back().observations.size(); i += 10, ++wrong) {
    window.back().observations[i].uvu += Eigen::Vector3d(15, -10, 15);
  }
  Perturb(&window, 0.05, 0.5, 12);
  const LocalBaResult r = LocalBundleAdjustment(cam, window, LocalBaOptions(), 0.3);
  ASSERT_TRUE(r.ok) << r.message;
  // A track seen twice cannot tell which of its two observations is wrong: both may go.
  EXPECT_GE(r.outliers, wrong * 9 / 10);
  EXPECT_LE(r.outliers, 2 * wrong + 5);
  EXPECT_LT(TransError(r.T_world_camera.back(), truth.back()), 0.02);
  EXPECT_LT(r.final_rms_px, 0.4);
}

TEST(StereoVoLocalBa, TheMotionPriorCarriesWhatTheChainMeasured) {
  // Few shared tracks (25 points, 1.5 px noise): the reprojections alone leave the poses a few
  // centimetres off; the chained motions (here the true ones, 1 mm / 0.03 deg) hold them.
  const StereoCamera cam = Cam();
  std::vector<Eigen::Isometry3d> truth;
  std::vector<BaKeyframe> window = MakeKeyframeWindow(cam, 5, 25, 1.0, 0.04, 1.5, 21, &truth);
  for (size_t k = 1; k < window.size(); ++k) {
    window[k].has_motion = true;
    window[k].T_prev_camera = truth[k - 1].inverse() * truth[k];
    window[k].motion_covariance.diagonal() << 1e-6, 1e-6, 1e-6, 3e-7, 3e-7, 3e-7;
  }
  Perturb(&window, 0.05, 0.5, 22);
  LocalBaOptions options;
  options.min_points = 10;
  options.motion_prior_covariance_scale = 1.0;
  double error[2] = {0, 0};
  for (int prior = 0; prior < 2; ++prior) {
    options.motion_prior = prior == 1;
    const LocalBaResult r = LocalBundleAdjustment(cam, window, options, 1.5);
    ASSERT_TRUE(r.ok) << r.message;
    for (size_t k = 1; k < window.size(); ++k) {
      error[prior] = std::max(error[prior], TransError(r.T_world_camera[k], truth[k]));
    }
  }
  EXPECT_LT(error[1], 0.005);
  EXPECT_LT(error[1], 0.5 * error[0]) << "without the prior " << error[0] << " m";
}

TEST(StereoVoLocalBa, LaserPointsHoldTheScaleAgainstADisparityBias) {
  // Every right image x off by +0.4 px (disparities too small: points too far, motion too
  // long). Laser depth points (3 cm) on a third of the observations pull the scale back.
  const StereoCamera cam = Cam();
  std::vector<Eigen::Isometry3d> truth;
  std::vector<BaKeyframe> window = MakeKeyframeWindow(cam, 5, 200, 1.0, 0.03, 0.3, 31, &truth);
  std::mt19937 rng(32);
  std::normal_distribution<double> depth_noise(0.0, 0.03);
  int measured = 0;
  for (size_t k = 0; k < window.size(); ++k) {
    for (size_t i = 0; i < window[k].observations.size(); ++i) {
      BaObservation& o = window[k].observations[i];
      if (i % 3 == 0) {
        // The true point along the observed pixel's ray, from the noise-free disparity.
        const Eigen::Vector3d ray((o.uvu(0) - cam.cx) / cam.fx, (o.uvu(1) - cam.cy) / cam.fy, 1.0);
        const double z_true = cam.Triangulate(o.uvu(0), o.uvu(1), o.uvu(0) - o.uvu(2)).z();
        o.has_point = true;
        o.m_camera = (z_true + depth_noise(rng)) * ray;
        o.W_camera = PointSqrtInformation(ray, 0.03, 2.5 * z_true / cam.fx);
        ++measured;
      }
      o.uvu(2) += 0.4;
    }
  }
  ASSERT_GT(measured, 100);
  LocalBaOptions options;
  double error[2] = {0, 0};
  int laser_points = 0;
  for (int laser = 0; laser < 2; ++laser) {
    options.laser_points = laser == 1;
    const LocalBaResult r = LocalBundleAdjustment(cam, window, options, 0.3);
    ASSERT_TRUE(r.ok) << r.message;
    error[laser] = TransError(r.T_world_camera.back(), truth.back());
    if (laser == 1) laser_points = r.laser_points;
  }
  EXPECT_GT(laser_points, 100);
  EXPECT_GT(error[0], 0.01) << "the bias must show without the laser";
  EXPECT_LT(error[1], 0.5 * error[0]) << "without the laser points " << error[0] << " m";
}

TEST(StereoVoLocalBa, TheRelativeCovarianceMatchesTheScatterOverNoiseDraws) {
  // chi^2 of the newest relative pose's error under the predicted covariance, averaged over
  // noise draws: 6 (its dimension) if the covariance is right.
  const StereoCamera cam = Cam();
  const double sigma_px = 0.5;
  double chi2_sum = 0;
  const int draws = 40;
  for (int d = 0; d < draws; ++d) {
    std::vector<Eigen::Isometry3d> truth;
    const std::vector<BaKeyframe> window =
        MakeKeyframeWindow(cam, 4, 150, 1.0, 0.04, sigma_px, 500 + d, &truth);
    LocalBaOptions options;
    options.huber_px = 100;  // Gaussian noise, no outliers: plain least squares
    const LocalBaResult r = LocalBundleAdjustment(cam, window, options, sigma_px);
    ASSERT_TRUE(r.ok && r.covariance_ok) << r.message;
    const size_t n = window.size();
    const Eigen::Isometry3d T_est = r.T_world_camera[n - 2].inverse() * r.T_world_camera[n - 1];
    const Eigen::Isometry3d T_true = truth[n - 2].inverse() * truth[n - 1];
    const Eigen::Isometry3d E = T_true.inverse() * T_est;  // T_est = T_true Exp(e)
    Eigen::Matrix<double, 6, 1> e;
    const Eigen::AngleAxisd aa(E.linear());
    e << E.translation(), aa.angle() * aa.axis();
    chi2_sum += e.dot(r.covariance_last.ldlt().solve(e));
  }
  const double chi2_mean = chi2_sum / draws;
  EXPECT_GT(chi2_mean, 6.0 * 0.6);
  EXPECT_LT(chi2_mean, 6.0 * 1.6);
}

TEST(StereoVoLocalBa, TheAnalyticSolverAgreesWithTheCeresReference) {
  // Every residual kind at once: reprojections with wrong tracks (outliers), the motion prior
  // (a chain 1 cm / 0.3 deg off the truth) and laser depth points; both solvers run to
  // convergence from the same perturbed window and must meet at the same minimum, with the
  // same observations dropped.
  const StereoCamera cam = Cam();
  for (uint32_t seed : {41u, 42u, 43u}) {
    std::vector<Eigen::Isometry3d> truth;
    std::vector<BaKeyframe> window =
        MakeKeyframeWindow(cam, 6, 150, 1.0, 0.04, 0.5, seed, &truth);
    std::mt19937 rng(seed + 1);
    std::normal_distribution<double> n(0.0, 1.0);
    for (size_t k = 0; k < window.size(); ++k) {
      for (size_t i = 0; i < window[k].observations.size(); ++i) {
        BaObservation& o = window[k].observations[i];
        if (k == window.size() - 1 && i % 15 == 0) o.uvu += Eigen::Vector3d(12, -8, 12);
        if (i % 4 == 0) {
          const Eigen::Vector3d ray((o.uvu(0) - cam.cx) / cam.fx, (o.uvu(1) - cam.cy) / cam.fy,
                                    1.0);
          const double z = cam.Triangulate(o.uvu(0), o.uvu(1), o.uvu(0) - o.uvu(2)).z();
          o.has_point = true;
          o.m_camera = (z + 0.03 * n(rng)) * ray;
          o.W_camera = PointSqrtInformation(ray, 0.03, 2.5 * z / cam.fx);
        }
      }
      if (k == 0) continue;
      window[k].has_motion = true;
      window[k].T_prev_camera = truth[k - 1].inverse() * truth[k] *
                                MakeMotion(0.005 * n(rng), 0.005 * n(rng), 0.005 * n(rng),
                                           0.01 * n(rng), 0.01 * n(rng), 0.01 * n(rng));
      window[k].motion_covariance.diagonal() << 1e-4, 1e-4, 1e-4, 3e-5, 3e-5, 3e-5;
    }
    Perturb(&window, 0.05, 0.5, seed + 2);
    LocalBaOptions options;
    options.laser_points = true;
    options.max_iterations = 30;
    options.function_tolerance = 1e-10;  // both solvers to convergence
    const LocalBaResult analytic = LocalBundleAdjustment(cam, window, options, 0.5);
    options.use_ceres = true;
    const LocalBaResult reference = LocalBundleAdjustment(cam, window, options, 0.5);
    ASSERT_TRUE(analytic.ok && reference.ok) << analytic.message << reference.message;
    ASSERT_TRUE(analytic.covariance_ok && reference.covariance_ok);
    EXPECT_GT(analytic.outliers, 5);
    EXPECT_GT(analytic.laser_points, 100);
    EXPECT_EQ(analytic.outliers, reference.outliers) << "seed " << seed;
    EXPECT_EQ(analytic.laser_points, reference.laser_points);
    EXPECT_NEAR(analytic.final_rms_px, reference.final_rms_px, 1e-6);
    for (size_t k = 1; k < window.size(); ++k) {
      EXPECT_LT(TransError(analytic.T_world_camera[k], reference.T_world_camera[k]), 1e-6)
          << "seed " << seed << ", keyframe " << k;
      EXPECT_LT(RotErrorDeg(analytic.T_world_camera[k], reference.T_world_camera[k]), 1e-5);
    }
    EXPECT_LT((analytic.covariance_last - reference.covariance_last).norm(),
              1e-4 * reference.covariance_last.norm());
  }
}

TEST(StereoVoLocalBa, RefusesWindowsItCannotAdjust) {
  const StereoCamera cam = Cam();
  std::vector<Eigen::Isometry3d> truth;
  std::vector<BaKeyframe> window = MakeKeyframeWindow(cam, 3, 10, 1.0, 0.0, 0.3, 5, &truth);
  LocalBaResult r = LocalBundleAdjustment(cam, window, LocalBaOptions(), 0.3);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.message.find("min_points"), std::string::npos) << r.message;
  ASSERT_EQ(r.T_world_camera.size(), window.size());  // the poses unchanged
  EXPECT_EQ(r.T_world_camera[2].matrix(), window[2].T_world_camera.matrix());
  r = LocalBundleAdjustment(cam, {window[0]}, LocalBaOptions(), 0.3);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.message.find("2 keyframes"), std::string::npos) << r.message;
}

TEST(StereoVoLocalBa, OptionsValidate) {
  EXPECT_TRUE(LocalBaOptions().Validate().ok());
  LocalBaOptions o;
  o.window_keyframes = 1;
  EXPECT_FALSE(o.Validate().ok());
  o = LocalBaOptions();
  o.min_track_keyframes = o.window_keyframes + 1;
  EXPECT_FALSE(o.Validate().ok());
  o = LocalBaOptions();
  o.huber_px = 0;
  EXPECT_FALSE(o.Validate().ok());
  o = LocalBaOptions();
  o.min_points = 2;
  EXPECT_FALSE(o.Validate().ok());
  o = LocalBaOptions();
  o.motion_prior_covariance_scale = 0;
  EXPECT_FALSE(o.Validate().ok());
  o = LocalBaOptions();
  o.function_tolerance = 1;
  EXPECT_FALSE(o.Validate().ok());
  o.function_tolerance = -1e-3;
  EXPECT_FALSE(o.Validate().ok());
}

}  // namespace
}  // namespace fl::vo
