#include "fusionloc/eval/metrics.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <random>

#include "eval_fixtures.hpp"
#include "test_paths.hpp"

namespace fl::eval {
namespace {

using fl::test::MakeHelixTrajectory;
using fl::test::MakePlanarTrajectory;
using fl::test::MakeStraightTrajectory;
using fl::test::TransformTrajectory;

Eigen::Isometry3d MakeTransform(double roll, double pitch, double yaw, Eigen::Vector3d t) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = RotationFromRollPitchYaw(roll, pitch, yaw);
  T.translation() = t;
  return T;
}

std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const EvalError& e) {
    return e.what();
  }
  return "(no EvalError thrown)";
}

TEST(EvalErrorStats, ClosedForm) {
  const ErrorStats s = ComputeErrorStats({3.0, 0.0, 4.0, 1.0});
  EXPECT_EQ(s.count, 4u);
  EXPECT_DOUBLE_EQ(s.mean, 2.0);
  EXPECT_DOUBLE_EQ(s.median, 2.0);
  EXPECT_DOUBLE_EQ(s.rmse, std::sqrt(26.0 / 4.0));
  EXPECT_DOUBLE_EQ(s.std, std::sqrt((1.0 + 4.0 + 4.0 + 1.0) / 4.0));
  EXPECT_DOUBLE_EQ(s.max, 4.0);
  EXPECT_DOUBLE_EQ(ComputeErrorStats({5.0, 1.0, 2.0}).median, 2.0);
  EXPECT_EQ(ComputeErrorStats({}).count, 0u);
}

TEST(EvalAte, Se3RecoversKnownRigidTransform) {
  const Trajectory ref = MakeHelixTrajectory(100);
  const Eigen::Isometry3d T_ref_est = MakeTransform(0.2, -0.1, 1.3, {4.0, -2.0, 0.5});
  const Trajectory est = TransformTrajectory(ref, T_ref_est.inverse());
  const AteResult r = ComputeAte(est, ref, Alignment::kSE3, 1000);
  EXPECT_EQ(r.trans_m.count, 100u);
  EXPECT_LT(r.trans_m.rmse, 1e-9);
  EXPECT_LT(r.rot_deg.max, 1e-6);
  EXPECT_TRUE(r.T_ref_est.isApprox(T_ref_est, 1e-9));
  EXPECT_DOUBLE_EQ(r.scale, 1.0);
  EXPECT_TRUE(r.warning.empty()) << r.warning;
  // A straight line leaves the roll about it undetermined: warned.
  const Trajectory line = MakeStraightTrajectory(20, 1.0);
  EXPECT_NE(ComputeAte(line, line, Alignment::kSE3, 1000).warning.find("straight line"),
            std::string::npos);
  EXPECT_TRUE(ComputeAte(line, line, Alignment::kSE2, 1000).warning.empty());
  // Without alignment the same trajectory has a large error.
  EXPECT_GT(ComputeAte(est, ref, Alignment::kNone, 1000).trans_m.rmse, 1.0);
}

TEST(EvalAte, Sim3RecoversScale) {
  const Trajectory ref = MakeHelixTrajectory(80);
  const Eigen::Isometry3d T = MakeTransform(0.0, 0.3, -0.7, {1.0, 2.0, 3.0});
  // est = T^-1 applied to ref shrunk by 1/2.5: aligning needs scale 2.5.
  Trajectory est = TransformTrajectory(ref, Eigen::Isometry3d::Identity(), 1.0 / 2.5);
  est = TransformTrajectory(est, T.inverse());
  const AteResult sim3 = ComputeAte(est, ref, Alignment::kSim3, 1000);
  EXPECT_NEAR(sim3.scale, 2.5, 1e-9);
  EXPECT_LT(sim3.trans_m.rmse, 1e-9);
  EXPECT_LT(sim3.rot_deg.max, 1e-6);
  EXPECT_TRUE(sim3.T_ref_est.linear().isApprox(T.linear(), 1e-9));
  // SE3 cannot explain the scale.
  EXPECT_GT(ComputeAte(est, ref, Alignment::kSE3, 1000).trans_m.rmse, 0.5);
}

TEST(EvalAte, OffsetOnHalfThePointsGivesKnownStatistics) {
  const Trajectory ref = MakeHelixTrajectory(50);
  Trajectory est = ref;
  for (size_t i = 0; i < est.size(); i += 2) est[i].T_world_base.translation().x() += 0.1;
  const AteResult r = ComputeAte(est, ref, Alignment::kNone, 1000);
  EXPECT_EQ(r.trans_m.count, 50u);
  EXPECT_NEAR(r.trans_m.rmse, 0.1 / std::sqrt(2.0), 1e-12);
  EXPECT_NEAR(r.trans_m.mean, 0.05, 1e-12);
  EXPECT_NEAR(r.trans_m.median, 0.05, 1e-12);
  EXPECT_NEAR(r.trans_m.std, 0.05, 1e-12);
  EXPECT_NEAR(r.trans_m.max, 0.1, 1e-12);
  EXPECT_NEAR(r.err_x_m[0], 0.1, 1e-12);
  EXPECT_NEAR(r.err_x_m[1], 0.0, 1e-12);
  EXPECT_LT(r.rot_deg.max, 1e-9);
}

TEST(EvalRunSpread, PairwiseAteOfRunsWithKnownOffsets) {
  const Trajectory a = MakeHelixTrajectory(50);
  // b: a moved rigidly (aligned away: 0 from a); c: a with every other position 0.1 m off in x
  // (0.1/√2 from a and from b, as OffsetOnHalfThePointsGivesKnownStatistics without alignment;
  // with se3 the alignment absorbs part of it).
  const Trajectory b = TransformTrajectory(a, MakeTransform(0.1, -0.2, 0.7, {3, -1, 0.5}));
  Trajectory c = a;
  for (size_t i = 0; i < c.size(); i += 2) c[i].T_world_base.translation().x() += 0.1;
  const double ac = ComputeAte(c, a, Alignment::kSE3, 1000).trans_m.rmse;
  EXPECT_GT(ac, 0.03);
  EXPECT_LE(ac, 0.1 / std::sqrt(2.0) + 1e-12);
  const RunSpreadResult r = ComputeRunSpread({a, b, c}, Alignment::kSE3, 1000);
  EXPECT_EQ(r.pairs, 3u);
  EXPECT_NEAR(r.min_m, 0.0, 1e-9);  // a against b
  EXPECT_NEAR(r.max_m, ac, 1e-9);   // a or b against c
  EXPECT_NEAR(r.mean_m, 2.0 * ac / 3.0, 1e-9);
  // Identical runs have no spread; one run is an error, as is a run that shares no time.
  EXPECT_NEAR(ComputeRunSpread({a, a}, Alignment::kSE2, 1000).mean_m, 0.0, 1e-12);
  EXPECT_NE(ErrorOf([&] { ComputeRunSpread({a}, Alignment::kSE2, 1000); }).find("at least 2"),
            std::string::npos);
  const Trajectory late = MakeHelixTrajectory(50, 100000000);
  const std::string msg = ErrorOf([&] { ComputeRunSpread({a, late}, Alignment::kSE2, 1000); });
  EXPECT_NE(msg.find("run 1 against run 0"), std::string::npos) << msg;
}

TEST(EvalAverageRuns, SymmetricScatterAveragesOutAndASharedErrorStays) {
  const Trajectory truth = MakePlanarTrajectory(60, [](size_t i) {
    const double s = 0.1 * static_cast<double>(i);
    return Pose2(3.0 * std::sin(s), 2.0 * s, 0.3 * s);
  });
  // Every run shares a bend (0.2 m in y on the second half); runs 0 and 1 scatter about it in
  // opposite directions (±0.15 m in x on every third pose, ±3 degrees of heading), run 2 does
  // not, and each run is in its own frame.
  Trajectory shared = truth;
  for (size_t i = 30; i < shared.size(); ++i) shared[i].T_world_base.translation().y() += 0.2;
  std::vector<Trajectory> runs;
  for (const double sign : {1.0, -1.0, 0.0}) {
    Trajectory run = shared;
    for (size_t i = 0; i < run.size(); i += 3) {
      run[i].T_world_base.translation().x() += sign * 0.15;
      run[i].T_world_base.linear() =
          run[i].T_world_base.linear() *
          Eigen::AngleAxisd(sign * 3.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    }
    runs.push_back(TransformTrajectory(run, Pose2(sign * 2.0, 1.0 - sign, sign).ToIsometry3()));
  }
  const Trajectory average = AverageRuns(runs, Alignment::kSE2, 1000);
  ASSERT_EQ(average.size(), truth.size());
  // The scatter cancels: the average is the shared trajectory (up to the second-order
  // asymmetry of aligning +0.15 m and -0.15 m scatter onto run 0)...
  const AteResult to_shared = ComputeAte(average, shared, Alignment::kSE2, 1000);
  EXPECT_LT(to_shared.trans_m.rmse, 1e-4);
  EXPECT_LT(to_shared.rot_deg.max, 0.01);
  // ... so its error against the truth is the shared bend alone, below each scattered run's.
  const double shared_ate = ComputeAte(shared, truth, Alignment::kSE2, 1000).trans_m.rmse;
  EXPECT_GT(shared_ate, 0.05);
  EXPECT_NEAR(ComputeAte(average, truth, Alignment::kSE2, 1000).trans_m.rmse, shared_ate, 1e-4);
  EXPECT_GT(ComputeAte(runs[1], truth, Alignment::kSE2, 1000).trans_m.rmse, shared_ate + 0.01);
  // Only time stamps every run has are averaged; no runs is an error.
  runs[2].erase(runs[2].begin() + 10);
  EXPECT_EQ(AverageRuns(runs, Alignment::kSE2, 1000).size(), truth.size() - 1);
  EXPECT_NE(ErrorOf([] { AverageRuns({}, Alignment::kSE2, 1000); }).find("no runs"),
            std::string::npos);
}

TEST(EvalAte, Se2RecoversPlanarTransformAndHeadingError) {
  const Trajectory ref = MakePlanarTrajectory(60, [](size_t i) {
    const double s = 0.1 * static_cast<double>(i);
    return Pose2(3.0 * std::sin(s), 2.0 * s, 0.3 * s);
  });
  const Eigen::Isometry3d T_ref_est = Pose2(1.5, -0.5, 0.6).ToIsometry3();
  Trajectory est = TransformTrajectory(ref, T_ref_est.inverse());
  // A constant 2 degree heading error does not move positions.
  for (auto& p : est) {
    p.T_world_base.linear() =
        p.T_world_base.linear() *
        Eigen::AngleAxisd(2.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  }
  const AteResult r = ComputeAte(est, ref, Alignment::kSE2, 1000);
  EXPECT_LT(r.trans_m.rmse, 1e-9);
  EXPECT_TRUE(r.T_ref_est.isApprox(T_ref_est, 1e-9));
  EXPECT_NEAR(r.rot_deg.mean, 2.0, 1e-9);
  EXPECT_NEAR(r.err_yaw_deg.front(), 2.0, 1e-9);
  // SE2 does not touch z: a constant height offset stays as error.
  Trajectory lifted = est;
  for (auto& p : lifted) p.T_world_base.translation().z() += 0.3;
  EXPECT_NEAR(ComputeAte(lifted, ref, Alignment::kSE2, 1000).trans_m.rmse, 0.3, 1e-9);
}

TEST(EvalAte, Se2EqualsSe3OnNoisyPlanarData) {
  // For points in the z = 0 plane the optimal SE(3) rotation is about z, so the 2D closed form
  // and Umeyama must agree, also with noise (an independent check of the SE2 formula).
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 0.2);
  const Trajectory ref = MakePlanarTrajectory(80, [](size_t i) {
    const double s = 0.08 * static_cast<double>(i);
    return Pose2(8.0 * std::cos(s), 4.0 * std::sin(2 * s), s);
  });
  Trajectory est = TransformTrajectory(ref, Pose2(-3.0, 2.0, 2.5).ToIsometry3());
  for (auto& p : est) {
    p.T_world_base.translation().x() += noise(rng);
    p.T_world_base.translation().y() += noise(rng);
  }
  const AteResult se2 = ComputeAte(est, ref, Alignment::kSE2, 1000);
  const AteResult se3 = ComputeAte(est, ref, Alignment::kSE3, 1000);
  EXPECT_TRUE(se2.T_ref_est.isApprox(se3.T_ref_est, 1e-9));
  EXPECT_NEAR(se2.trans_m.rmse, se3.trans_m.rmse, 1e-9);
  EXPECT_GT(se2.trans_m.rmse, 0.15);  // the noise remains
  EXPECT_LT(se2.trans_m.rmse, 0.4);
}

TEST(EvalAte, BadInputsGiveClearErrors) {
  const Trajectory ref = MakeHelixTrajectory(10);
  EXPECT_NE(ErrorOf([&] { ComputeAte({}, ref, Alignment::kSE3, 1000); }).find("empty"),
            std::string::npos);
  Trajectory nan = ref;
  nan[3].T_world_base.translation().y() = std::nan("");
  EXPECT_NE(ErrorOf([&] { ComputeAte(nan, ref, Alignment::kSE3, 1000); }).find("NaN"),
            std::string::npos);
  const Trajectory late = MakeHelixTrajectory(10, 100000000);
  const std::string msg = ErrorOf([&] { ComputeAte(late, ref, Alignment::kSE3, 10000); });
  EXPECT_NE(msg.find("est covers t=[100.000, 100.900] s"), std::string::npos) << msg;
  EXPECT_NE(msg.find("ref covers [1.000, 1.900] s"), std::string::npos) << msg;
  EXPECT_NE(msg.find("no pair within 10 ms"), std::string::npos) << msg;
  const Trajectory two(ref.begin(), ref.begin() + 2);
  EXPECT_NE(ErrorOf([&] { ComputeAte(two, ref, Alignment::kSE3, 1000); }).find("at least 3"),
            std::string::npos);
  EXPECT_NO_THROW(ComputeAte(two, ref, Alignment::kSE2, 1000));
  EXPECT_NE(ErrorOf([] { ParseAlignment("affine"); }).find("se2"), std::string::npos);
}

TEST(EvalAssociate, ToleranceOneToOneAndMonotone) {
  const Trajectory ref = MakeStraightTrajectory(20, 1.0);                      // 10 Hz
  const Trajectory shifted = MakeStraightTrajectory(20, 1.0, 1000000 + 3000);  // +3 ms
  EXPECT_EQ(Associate(shifted, ref, 10000).size(), 20u);
  EXPECT_NE(ErrorOf([&] { Associate(shifted, ref, 2000); }).find("no pair within 2 ms"),
            std::string::npos);
  // est at 100 Hz, ref at 10 Hz: each ref pose is taken once, by the est pose at the same time.
  const Trajectory fast = MakeStraightTrajectory(191, 0.1, 1000000, 10000);
  const auto pairs = Associate(fast, ref, 50000);
  ASSERT_EQ(pairs.size(), 20u);
  for (size_t k = 0; k < pairs.size(); ++k) {
    EXPECT_EQ(pairs[k].second, k);
    EXPECT_EQ(fast[pairs[k].first].utime, ref[k].utime);
  }
  // Only the overlapping part is paired.
  const Trajectory partial = MakeStraightTrajectory(20, 1.0, 2000000);
  EXPECT_EQ(Associate(partial, ref, 1000).size(), 10u);
}

TEST(EvalRpe, KnownPerStepError) {
  const Trajectory ref = MakeStraightTrajectory(50, 1.0);
  const Trajectory est = MakeStraightTrajectory(50, 1.1);  // 0.1 m too long per step
  RpeResult r = ComputeRpe(est, ref, 1, DeltaUnit::kFrames, 1000);
  EXPECT_EQ(r.trans_m.count, 49u);
  EXPECT_NEAR(r.trans_m.rmse, 0.1, 1e-9);
  EXPECT_NEAR(r.trans_m.max, 0.1, 1e-9);
  r = ComputeRpe(est, ref, 2, DeltaUnit::kMeters, 1000);
  EXPECT_EQ(r.trans_m.count, 48u);
  EXPECT_NEAR(r.trans_m.mean, 0.2, 1e-9);
  r = ComputeRpe(est, ref, 0.5, DeltaUnit::kSeconds, 1000);  // 5 frames at 10 Hz
  EXPECT_EQ(r.trans_m.count, 45u);
  EXPECT_NEAR(r.trans_m.mean, 0.5, 1e-9);
  // A heading that turns 1 degree per step more than the reference.
  const Trajectory turning = MakePlanarTrajectory(
      30, [](size_t i) { return Pose2(1.0 * i, 0.0, static_cast<double>(i) * M_PI / 180.0); });
  r = ComputeRpe(turning, ref, 1, DeltaUnit::kFrames, 1000);
  EXPECT_NEAR(r.rot_deg.mean, 1.0, 1e-9);
  EXPECT_NEAR(r.rot_deg.std, 0.0, 1e-9);
  EXPECT_NE(ErrorOf([&] {
              ComputeRpe(est, ref, 100, DeltaUnit::kMeters, 1000);
            }).find("longer than the associated trajectory"),
            std::string::npos);
  EXPECT_NE(
      ErrorOf([&] { ComputeRpe(est, ref, 1.5, DeltaUnit::kFrames, 1000); }).find("whole number"),
      std::string::npos);
}

// The KITTI devkit (evaluate_odometry.cpp) written out literally, with 4x4 matrices, as an
// independent check of ComputeKittiDrift.
struct DevkitErrors {
  double t_err_mean = 0, r_err_mean = 0;  // [m/m], [rad/m]
  size_t n = 0;
};
DevkitErrors DevkitCalcSequenceErrors(const std::vector<Eigen::Matrix4d>& poses_gt,
                                      const std::vector<Eigen::Matrix4d>& poses_result,
                                      const std::vector<double>& lengths) {
  const int step_size = 10;
  std::vector<double> dist;
  dist.push_back(0);
  for (size_t i = 1; i < poses_gt.size(); i++) {
    const Eigen::Matrix4d& P1 = poses_gt[i - 1];
    const Eigen::Matrix4d& P2 = poses_gt[i];
    const double dx = P1(0, 3) - P2(0, 3), dy = P1(1, 3) - P2(1, 3), dz = P1(2, 3) - P2(2, 3);
    dist.push_back(dist[i - 1] + std::sqrt(dx * dx + dy * dy + dz * dz));
  }
  DevkitErrors out;
  double t_sum = 0, r_sum = 0;
  for (size_t first_frame = 0; first_frame < poses_gt.size(); first_frame += step_size) {
    for (double len : lengths) {
      int last_frame = -1;
      for (size_t i = first_frame; i < dist.size(); i++) {
        if (dist[i] > dist[first_frame] + len) {
          last_frame = static_cast<int>(i);
          break;
        }
      }
      if (last_frame == -1) continue;
      const Eigen::Matrix4d pose_delta_gt = poses_gt[first_frame].inverse() * poses_gt[last_frame];
      const Eigen::Matrix4d pose_delta_result =
          poses_result[first_frame].inverse() * poses_result[last_frame];
      const Eigen::Matrix4d pose_error = pose_delta_result.inverse() * pose_delta_gt;
      const double a = pose_error(0, 0), b = pose_error(1, 1), c = pose_error(2, 2);
      const double d = 0.5 * (a + b + c - 1.0);
      const double r_err = std::acos(std::max(std::min(d, 1.0), -1.0));
      const double t_err = pose_error.block<3, 1>(0, 3).norm();
      t_sum += t_err / len;
      r_sum += r_err / len;
      ++out.n;
    }
  }
  out.t_err_mean = t_sum / static_cast<double>(out.n);
  out.r_err_mean = r_sum / static_cast<double>(out.n);
  return out;
}

TEST(EvalKittiDrift, ScaledStraightPath) {
  // 200 m straight, 1 m apart; est 1 % too long. The devkit's last frame is the first one
  // *beyond* first + L, i.e. L + 1 m away: error = 0.01 * (L + 1) / L.
  const Trajectory ref = MakeStraightTrajectory(201, 1.0);
  const Trajectory est = MakeStraightTrajectory(201, 1.01);
  const DriftResult r = ComputeKittiDrift(est, ref, {100.0}, 1000);
  EXPECT_EQ(r.segments, 10u);  // first frames 0, 10, ..., 90 (last = first + 101 <= 200)
  EXPECT_NEAR(r.trans_pct, 1.01, 1e-9);
  EXPECT_NEAR(r.rot_deg_per_100m, 0.0, 1e-9);
  ASSERT_EQ(r.lengths_m.size(), 1u);
  EXPECT_NEAR(r.trans_pct_per_length[0], 1.01, 1e-9);
  // Finer sampling approaches exactly 1 %.
  const DriftResult fine = ComputeKittiDrift(MakeStraightTrajectory(2001, 0.101),
                                             MakeStraightTrajectory(2001, 0.1), {100.0}, 1000);
  EXPECT_NEAR(fine.trans_pct, 1.001, 1e-9);
}

TEST(EvalKittiDrift, ConstantYawRateError) {
  // Heading error grows 0.01 deg per metre travelled; positions exact.
  const double k_deg_per_m = 0.01;
  const Trajectory ref = MakeStraightTrajectory(301, 1.0);
  const Trajectory est = MakePlanarTrajectory(301, [&](size_t i) {
    return Pose2(1.0 * i, 0.0, k_deg_per_m * M_PI / 180.0 * static_cast<double>(i));
  });
  const DriftResult r = ComputeKittiDrift(est, ref, {100.0, 200.0}, 1000);
  // Segments of L have L + 1 m of heading drift: (L + 1) * k / L per metre.
  ASSERT_EQ(r.lengths_m.size(), 2u);
  EXPECT_NEAR(r.rot_deg_per_100m_per_length[0], 100.0 * k_deg_per_m * 101.0 / 100.0, 1e-9);
  EXPECT_NEAR(r.rot_deg_per_100m_per_length[1], 100.0 * k_deg_per_m * 201.0 / 200.0, 1e-9);
  EXPECT_EQ(r.segments_per_length[0], 20u);  // first <= 199
  EXPECT_EQ(r.segments_per_length[1], 10u);  // first <= 99
}

TEST(EvalKittiDrift, EqualsDevkitDefinitionOnRandomWalk) {
  std::mt19937 rng(42);
  std::normal_distribution<double> noise(0.0, 1.0);
  Trajectory ref, est;
  Eigen::Isometry3d T_ref = Eigen::Isometry3d::Identity(), T_est = T_ref;
  for (int i = 0; i < 400; ++i) {
    Eigen::Isometry3d step = Eigen::Isometry3d::Identity();
    step.translation() =
        Eigen::Vector3d(1.0 + 0.2 * noise(rng), 0.05 * noise(rng), 0.02 * noise(rng));
    step.linear() =
        RotationFromRollPitchYaw(0.003 * noise(rng), 0.003 * noise(rng), 0.03 * noise(rng));
    Eigen::Isometry3d step_err = Eigen::Isometry3d::Identity();
    step_err.translation() =
        Eigen::Vector3d(0.01 * noise(rng), 0.01 * noise(rng), 0.005 * noise(rng));
    step_err.linear() =
        RotationFromRollPitchYaw(0.001 * noise(rng), 0.001 * noise(rng), 0.002 * noise(rng));
    T_ref = T_ref * step;
    T_est = T_est * step * step_err;
    ref.push_back({i * 100000, T_ref});
    est.push_back({i * 100000, T_est});
  }
  std::vector<Eigen::Matrix4d> gt_m, res_m;
  for (size_t i = 0; i < ref.size(); ++i) {
    gt_m.push_back(ref[i].T_world_base.matrix());
    res_m.push_back(est[i].T_world_base.matrix());
  }
  const std::vector<double> lengths = {100, 200, 300};
  const DevkitErrors devkit = DevkitCalcSequenceErrors(gt_m, res_m, lengths);
  const DriftResult r = ComputeKittiDrift(est, ref, lengths, 1000, 10);
  ASSERT_GT(devkit.n, 10u);
  EXPECT_EQ(r.segments, devkit.n);
  EXPECT_NEAR(r.trans_pct, 100.0 * devkit.t_err_mean, 1e-9);
  // The devkit takes acos((trace - 1) / 2), which loses ~1e-8 rad near 0; we use the
  // quaternion angle, hence the looser tolerance.
  EXPECT_NEAR(r.rot_deg_per_100m, 100.0 * 180.0 / M_PI * devkit.r_err_mean, 1e-5);
  EXPECT_GT(r.rot_deg_per_100m, 0.01);
  EXPECT_GT(r.trans_pct, 0.1);  // the injected errors are visible
}

TEST(EvalKittiDrift, NoSegmentFitsIsAnError) {
  const Trajectory ref = MakeStraightTrajectory(51, 1.0);
  const std::string msg = ErrorOf([&] { ComputeKittiDrift(ref, ref, {100, 200}, 1000); });
  EXPECT_NE(msg.find("50.000 m long"), std::string::npos) << msg;
  EXPECT_NE(msg.find("--kitti-lengths"), std::string::npos) << msg;
}

TEST(EvalKittiDrift, DefaultLengths) {
  EXPECT_EQ(DefaultKittiLengths(1000.0),
            (std::vector<double>{100, 200, 300, 400, 500, 600, 700, 800}));
  EXPECT_EQ(DefaultKittiLengths(350.0), (std::vector<double>{100, 200, 300}));
  EXPECT_EQ(DefaultKittiLengths(107.0), (std::vector<double>{10, 20, 30, 40, 50, 60, 70, 80}));
  EXPECT_EQ(DefaultKittiLengths(20.0), (std::vector<double>{2, 4, 6, 8, 10, 12, 14, 16}));
  EXPECT_EQ(DefaultKittiLengths(60.0), (std::vector<double>{5, 10, 15, 20, 25, 30, 35, 40}));
  EXPECT_NE(ErrorOf([] { DefaultKittiLengths(0.0); }).find("did not move"), std::string::npos);
}

TEST(EvalRelations, KnownErrorAndFileRoundTrip) {
  const Trajectory ref = MakePlanarTrajectory(
      21, [](size_t i) { return Pose2(0.5 * static_cast<double>(i), 0.0, 0.0); });
  std::vector<Relation> relations;
  for (size_t i = 0; i + 1 < ref.size(); ++i) {
    relations.push_back(
        {ref[i].utime, ref[i + 1].utime, ref[i].T_world_base.inverse() * ref[i + 1].T_world_base});
  }
  const auto derived = RelationsFromTrajectory(ref, 1);
  ASSERT_EQ(derived.size(), relations.size());
  EXPECT_EQ(derived[5].utime2, relations[5].utime2);
  EXPECT_TRUE(derived[5].T_1_2.isApprox(relations[5].T_1_2));
  EXPECT_EQ(RelationsFromTrajectory(ref, 5).size(), 16u);
  EXPECT_THROW(RelationsFromTrajectory(ref, 21), EvalError);
  fl::test::TempDir dir;
  WriteRelations(relations, dir.file("rel.txt"));
  const auto read = ReadRelations(dir.file("rel.txt"));
  ASSERT_EQ(read.size(), relations.size());
  EXPECT_EQ(read[3].utime1, relations[3].utime1);
  EXPECT_TRUE(read[3].T_1_2.isApprox(relations[3].T_1_2, 1e-9));

  RelationResult r = ComputeRelationError(ref, dir.file("rel.txt"), 1000);
  EXPECT_EQ(r.used, 20u);
  EXPECT_LT(r.trans_m.max, 1e-9);
  // Move pose 10 by 0.1 m: relations 9->10 and 10->11 are 0.1 m off, the other 18 exact.
  Trajectory est = ref;
  est[10].T_world_base.translation().y() += 0.1;
  r = ComputeRelationError(est, relations, 1000);
  EXPECT_NEAR(r.trans_m.mean, 0.2 / 20.0, 1e-12);
  EXPECT_NEAR(r.trans_m.max, 0.1, 1e-12);
  EXPECT_NEAR(r.trans_sq_mean_m2, 2 * 0.01 / 20.0, 1e-12);
  // Relations outside est are counted as skipped, not silently dropped.
  const Trajectory first_half(ref.begin(), ref.begin() + 11);
  r = ComputeRelationError(first_half, relations, 1000);
  EXPECT_EQ(r.used, 10u);
  EXPECT_EQ(r.skipped, 10u);
  const Trajectory late = MakeStraightTrajectory(5, 1.0, 900000000);
  EXPECT_NE(ErrorOf([&] {
              ComputeRelationError(late, relations, 1000);
            }).find("none of the 20 relations"),
            std::string::npos);
}

TEST(EvalRelations, MalformedFile) {
  fl::test::TempDir dir;
  {
    std::ofstream f(dir.file("bad.txt"));
    f << "# comment\n1.0 2.0 0.1 0 0 0 0 0.1\n1.0 2.0 0.1 0 0 0 0\n";
  }
  const std::string msg = ErrorOf([&] { ReadRelations(dir.file("bad.txt")); });
  EXPECT_NE(msg.find("bad.txt:3"), std::string::npos) << msg;
  EXPECT_NE(msg.find("8 values"), std::string::npos) << msg;
}

}  // namespace
}  // namespace fl::eval
