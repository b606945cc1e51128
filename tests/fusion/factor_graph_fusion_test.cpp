#include "fusionloc/fusion/factor_graph_fusion.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <memory>
#include <random>

#include "fusion_fixtures.hpp"
#include "test_paths.hpp"
#include "fusionloc/common/se2_between_cost.hpp"
#include "fusionloc/common/sqrt_information.hpp"

namespace fl::fusion {
namespace {

using fl::test::FusionSimData;
using fl::test::FusionSimOptions;
using fl::test::MakeRoundedSquareSim;

FusionOptions TestOptions() {
  FusionOptions o;
  o.full_solve_every_n_nodes = 0;   // the tests decide when to solve
  o.laser_chain_factors = "never";  // tested on its own (the fixtures' RBPF poses drift)
  o.use_wheel_odometry = false;     // likewise
  return o;
}

double PositionError(const Pose2& a, const Pose2& b) { return std::hypot(a.x - b.x, a.y - b.y); }

double MaxError(const std::vector<TrajectoryPoint>& est, const std::vector<TrajectoryPoint>& ref) {
  double worst = 0.0;
  for (size_t k = 0; k < std::min(est.size(), ref.size()); ++k) {
    worst = std::max(worst, PositionError(est[k].T_map_base, ref[k].T_map_base));
  }
  return worst;
}

double RmsError(const std::vector<TrajectoryPoint>& est, const std::vector<TrajectoryPoint>& ref) {
  double sum = 0.0;
  for (size_t k = 0; k < est.size(); ++k) {
    const double e = PositionError(est[k].T_map_base, ref[k].T_map_base);
    sum += e * e;
  }
  return std::sqrt(sum / static_cast<double>(est.size()));
}

// Feeds a whole simulation in time order, updating after every node.
std::vector<TrajectoryPoint> RunInOrder(const FusionSimData& d, FactorGraphFusion* fusion,
                                        bool with_vision = true) {
  size_t lf = 0, vf = 0;
  for (size_t k = 0; k < d.rbpf.size(); ++k) {
    EXPECT_TRUE(fusion->AddLaserPose(d.rbpf[k].utime, d.rbpf[k].T_map_base).ok());
    while (lf < d.laser_factors.size() && d.laser_factors[lf].utime_j <= d.rbpf[k].utime) {
      EXPECT_TRUE(fusion->AddFactor(d.laser_factors[lf++]).ok());
    }
    while (with_vision && vf < d.vision_factors.size() &&
           d.vision_factors[vf].utime_j <= d.rbpf[k].utime) {
      EXPECT_TRUE(fusion->AddFactor(d.vision_factors[vf++]).ok());
    }
    fusion->Update();
  }
  for (const auto& f : d.loop_factors) EXPECT_TRUE(fusion->AddFactor(f).ok());
  return fusion->Trajectory();
}

TEST(FusionFactorGraph, SquareWithLoopClosureConvergesToTruth) {
  // Exact measurements, strongly drifting RBPF initial values (0.04 rad/s heading bias).
  // Vision keyframes on the laser times here: off-node times are corrected with the RBPF's
  // relative motion, which this artificial bias makes inconsistent with the exact laser
  // factors (interpolation is tested on its own below).
  FusionSimOptions so;
  so.vision_offset_s = 0.0;
  const FusionSimData d = MakeRoundedSquareSim(so);
  FactorGraphFusion fusion(TestOptions());
  RunInOrder(d, &fusion);
  EXPECT_GT(MaxError(d.rbpf, d.truth), 1.0);   // the initial values are far off
  EXPECT_TRUE(fusion.full_solve_requested());  // the loop closure asks for it
  const SolveSummary s = fusion.FullSolve();
  EXPECT_TRUE(s.ran && s.full);
  EXPECT_EQ(s.termination, "CONVERGENCE") << s.ToString();
  EXPECT_FALSE(fusion.full_solve_requested());
  EXPECT_LT(MaxError(fusion.Trajectory(), d.truth), 1e-3);
}

TEST(FusionFactorGraph, NoisyFusionBeatsLaserAloneAndGaugeIsFixed) {
  FusionSimOptions so;
  so.laser_sigma_xy = 0.02;
  so.laser_sigma_theta = 0.01;
  so.vision_sigma_xy = 0.02;
  so.vision_sigma_theta = 0.003;
  so.loop_closure = false;
  so.seed = 3;
  const FusionSimData d = MakeRoundedSquareSim(so);
  FactorGraphFusion laser_only(TestOptions()), fused(TestOptions());
  RunInOrder(d, &laser_only, /*with_vision=*/false);
  RunInOrder(d, &fused);
  laser_only.FullSolve();
  fused.FullSolve();
  const double e_laser = RmsError(laser_only.Trajectory(), d.truth);
  const double e_fused = RmsError(fused.Trajectory(), d.truth);
  EXPECT_LT(e_fused, 0.7 * e_laser) << "laser " << e_laser << " fused " << e_fused;
  // Gauge: the first node stays at its prior (the first RBPF pose).
  const Pose2 first = fused.Trajectory().front().T_map_base;
  EXPECT_LT(PositionError(first, d.rbpf.front().T_map_base), 1e-4);
  EXPECT_LT(std::fabs(WrapAngle(first.theta - d.rbpf.front().T_map_base.theta)), 1e-4);
}

TEST(FusionFactorGraph, SameInputGivesIdenticalOutput) {
  FusionSimOptions so;
  so.laser_sigma_xy = 0.02;
  so.vision_sigma_xy = 0.02;
  const FusionSimData d = MakeRoundedSquareSim(so);
  FactorGraphFusion a(TestOptions()), b(TestOptions());
  RunInOrder(d, &a);
  RunInOrder(d, &b);
  a.FullSolve();
  b.FullSolve();
  const auto ta = a.Trajectory(), tb = b.Trajectory();
  ASSERT_EQ(ta.size(), tb.size());
  for (size_t k = 0; k < ta.size(); ++k) {
    EXPECT_EQ(ta[k].T_map_base.x, tb[k].T_map_base.x);
    EXPECT_EQ(ta[k].T_map_base.y, tb[k].T_map_base.y);
    EXPECT_EQ(ta[k].T_map_base.theta, tb[k].T_map_base.theta);
  }
}

// A vision factor between times that fall between laser nodes is moved onto the nearest
// nodes by interpolating the laser poses: with exact data the nodes must not move, while a
// naive "nearest node, same measurement" attachment would pull them by centimetres.
TEST(FusionFactorGraph, AsynchronousVisionFactorIsPlacedByInterpolation) {
  FusionSimOptions so;
  so.rbpf_heading_bias = 0.0;  // RBPF poses = truth
  so.loop_closure = false;
  const FusionSimData d = MakeRoundedSquareSim(so);
  FactorGraphFusion fusion(TestOptions());
  for (const auto& p : d.rbpf) ASSERT_TRUE(fusion.AddLaserPose(p.utime, p.T_map_base).ok());
  // Keyframes at 3.03 s and 5.53 s after start (nodes at 3.0 and 5.5): the robot is on the
  // first straight and then in the first corner, moving 1 m/s (3 cm per 30 ms).
  const Utime t0 = so.start_utime;
  const Utime ti = t0 + SecondsToUtime(3.03), tj = t0 + SecondsToUtime(5.53);
  const Pose2 truth_i = fl::test::RoundedSquarePose(so, 3.03),
              truth_j = fl::test::RoundedSquarePose(so, 5.53);
  RelativePoseFactor f;
  f.utime_i = ti;
  f.utime_j = tj;
  f.T_i_j = truth_i.between(truth_j).ToIsometry3();
  f.information = Eigen::Matrix<double, 6, 6>::Identity() * 1e4;
  f.source = FactorSource::kVision;
  ASSERT_TRUE(fusion.AddFactor(f).ok());
  // Hold node 30 with a strong laser-style link to node 0 so node 55 is only moved by the
  // vision factor.
  RelativePoseFactor anchor;
  anchor.utime_i = d.truth[0].utime;
  anchor.utime_j = d.truth[30].utime;
  anchor.T_i_j = d.truth[0].T_map_base.between(d.truth[30].T_map_base).ToIsometry3();
  anchor.information.diagonal() << 1e8, 1e8, 0, 0, 0, 1e8;
  ASSERT_TRUE(fusion.AddFactor(anchor).ok());
  fusion.FullSolve();
  const auto traj = fusion.Trajectory();
  EXPECT_LT(PositionError(traj[55].T_map_base, d.truth[55].T_map_base), 1e-4);
  EXPECT_LT(std::fabs(WrapAngle(traj[55].T_map_base.theta - d.truth[55].T_map_base.theta)), 1e-4);
  // The offset the interpolation corrects is large enough for this test to fail without it.
  EXPECT_GT(PositionError(truth_j, d.truth[55].T_map_base), 0.02);
}

// Laser scans lost around a keyframe time (nodes 55 and 56 missing: the nodes around 5.58 s,
// 54 and 57, are 0.3 s apart, neither within attach_tolerance_s): the factor is attached by
// interpolation across the gap and places the node as exactly as with every scan; a gap wider
// than attach_max_gap_s rejects it, naming both bounds.
TEST(FusionFactorGraph, FactorAcrossLostScansIsAttachedByInterpolation) {
  FusionSimOptions so;
  so.rbpf_heading_bias = 0.0;  // RBPF poses = truth
  so.loop_closure = false;
  const FusionSimData d = MakeRoundedSquareSim(so);
  for (const double max_gap : {0.35, 0.25}) {
    FusionOptions options = TestOptions();
    options.attach_max_gap_s = max_gap;
    FactorGraphFusion fusion(options);
    for (size_t k = 0; k < d.rbpf.size(); ++k) {
      if (k == 55 || k == 56) continue;  // lost
      ASSERT_TRUE(fusion.AddLaserPose(d.rbpf[k].utime, d.rbpf[k].T_map_base).ok());
    }
    const Utime t0 = so.start_utime;
    const Pose2 truth_i = fl::test::RoundedSquarePose(so, 3.0),
                truth_j = fl::test::RoundedSquarePose(so, 5.58);
    RelativePoseFactor f;
    f.utime_i = t0 + SecondsToUtime(3.0);
    f.utime_j = t0 + SecondsToUtime(5.58);
    f.T_i_j = truth_i.between(truth_j).ToIsometry3();
    f.information = Eigen::Matrix<double, 6, 6>::Identity() * 1e4;
    f.source = FactorSource::kVision;
    const Status st = fusion.AddFactor(f);
    if (max_gap < 0.3) {
      EXPECT_FALSE(st.ok());
      EXPECT_NE(st.message().find("nor two within 0.25 s"), std::string::npos) << st.message();
      continue;
    }
    ASSERT_TRUE(st.ok()) << st.message();
    RelativePoseFactor anchor;
    anchor.utime_i = d.truth[0].utime;
    anchor.utime_j = d.truth[30].utime;
    anchor.T_i_j = d.truth[0].T_map_base.between(d.truth[30].T_map_base).ToIsometry3();
    anchor.information.diagonal() << 1e8, 1e8, 0, 0, 0, 1e8;
    ASSERT_TRUE(fusion.AddFactor(anchor).ok());
    fusion.FullSolve();
    const auto traj = fusion.Trajectory();
    ASSERT_EQ(traj.size(), d.rbpf.size() - 2);
    // Node 57 (index 55 once 55 and 56 are gone) carries the factor's end.
    EXPECT_EQ(traj[55].utime, d.truth[57].utime);
    // 0.12 s from the node in a corner: the constant-velocity arc leaves millimetres, against
    // the 0.12 m the robot moves in that time.
    EXPECT_LT(PositionError(traj[55].T_map_base, d.truth[57].T_map_base), 5e-3);
    EXPECT_GT(PositionError(truth_j, d.truth[57].T_map_base), 0.1);
  }
}

TEST(FusionFactorGraph, OutOfOrderAndEarlyFactorsGiveTheSameResult) {
  FusionSimOptions so;
  so.laser_sigma_xy = 0.02;
  so.vision_sigma_xy = 0.02;
  const FusionSimData d = MakeRoundedSquareSim(so);
  FactorGraphFusion in_order(TestOptions()), shuffled(TestOptions());
  RunInOrder(d, &in_order);
  in_order.FullSolve();
  // All factors first (they wait for their nodes), in random order, then the laser poses.
  std::vector<RelativePoseFactor> all = d.laser_factors;
  all.insert(all.end(), d.vision_factors.begin(), d.vision_factors.end());
  all.insert(all.end(), d.loop_factors.begin(), d.loop_factors.end());
  std::mt19937 rng(5);
  std::shuffle(all.begin(), all.end(), rng);
  for (const auto& f : all) ASSERT_TRUE(shuffled.AddFactor(f).ok());
  EXPECT_EQ(shuffled.num_pending_factors(), static_cast<int>(all.size()));
  for (const auto& p : d.rbpf) ASSERT_TRUE(shuffled.AddLaserPose(p.utime, p.T_map_base).ok());
  EXPECT_EQ(shuffled.num_pending_factors(), 0);
  EXPECT_EQ(shuffled.num_factors(), in_order.num_factors());
  shuffled.FullSolve();
  // Same optimum; the solver's start (no window updates here) differs within its tolerance.
  EXPECT_LT(MaxError(shuffled.Trajectory(), in_order.Trajectory()), 1e-3);
}

TEST(FusionFactorGraph, LateFactorExtendsTheWindowOrRequestsAFullSolve) {
  FusionSimOptions so;
  so.loop_closure = false;
  const FusionSimData d = MakeRoundedSquareSim(so);
  FusionOptions o = TestOptions();
  o.window_size = 10;
  o.max_window_nodes = 40;
  FactorGraphFusion fusion(o);
  RunInOrder(d, &fusion, /*with_vision=*/false);
  EXPECT_FALSE(fusion.full_solve_requested());
  // A late vision factor 30 nodes back: the window grows to reach it.
  RelativePoseFactor late = d.vision_factors[d.vision_factors.size() - 6];
  ASSERT_TRUE(fusion.AddFactor(late).ok());
  SolveSummary s = fusion.Update();
  EXPECT_GT(s.num_nodes, 10);
  EXPECT_LE(s.num_nodes, 40);
  EXPECT_FALSE(fusion.full_solve_requested());
  // One far back: the full solve is requested.
  ASSERT_TRUE(fusion.AddFactor(d.vision_factors[1]).ok());
  s = fusion.Update();
  EXPECT_EQ(s.num_nodes, 10);
  EXPECT_TRUE(fusion.full_solve_requested());
}

TEST(FusionFactorGraph, AsyncFullSolveMergesNodesAddedMeanwhile) {
  FusionSimOptions so;
  so.laps = 2;
  const FusionSimData d = MakeRoundedSquareSim(so);
  FactorGraphFusion fusion(TestOptions());
  const size_t half = d.rbpf.size() / 2;
  for (size_t k = 0; k < half; ++k) {
    ASSERT_TRUE(fusion.AddLaserPose(d.rbpf[k].utime, d.rbpf[k].T_map_base).ok());
    if (k > 0) {
      ASSERT_TRUE(fusion.AddFactor(d.laser_factors[k - 1]).ok());
    }
    fusion.Update();
  }
  // Loop closure at the end of lap 1: node half-1 sees node 0.
  RelativePoseFactor loop;
  loop.utime_i = d.truth[half - 1].utime;
  loop.utime_j = d.truth[0].utime;
  loop.T_i_j = d.truth[half - 1].T_map_base.between(d.truth[0].T_map_base).ToIsometry3();
  loop.information.diagonal() << 1e4, 1e4, 0, 0, 0, 1e5;
  loop.is_loop_closure = true;
  ASSERT_TRUE(fusion.AddFactor(loop).ok());
  ASSERT_TRUE(fusion.full_solve_requested());
  auto job = fusion.PrepareFullSolve();
  // While the job would run on another thread, the graph keeps growing.
  for (size_t k = half; k < half + 20; ++k) {
    ASSERT_TRUE(fusion.AddLaserPose(d.rbpf[k].utime, d.rbpf[k].T_map_base).ok());
    ASSERT_TRUE(fusion.AddFactor(d.laser_factors[k - 1]).ok());
    fusion.Update();
  }
  job->Run();
  fusion.ApplyFullSolve(*job);
  EXPECT_EQ(fusion.counters().full_solves, 1);
  const auto traj = fusion.Trajectory();
  // Lap 1 is corrected to the truth, and so are the 20 nodes added during the solve.
  for (size_t k = 0; k < half + 20; ++k) {
    EXPECT_LT(PositionError(traj[k].T_map_base, d.truth[k].T_map_base), 1e-3) << k;
  }
}

TEST(FusionFactorGraph, WheelOdometryFactorsLinkNodes) {
  FusionSimOptions so;
  so.loop_closure = false;
  const FusionSimData d = MakeRoundedSquareSim(so);
  FusionOptions o = TestOptions();
  o.use_wheel_odometry = true;
  FactorGraphFusion fusion(o);
  // Odometry at 50 Hz = truth in its own frame (rotated and shifted); no other factors.
  const Pose2 T_odom_map(3.0, -2.0, 0.7);
  size_t node = 0;
  for (Utime t = so.start_utime; t <= d.truth.back().utime + 20000; t += 20000) {
    while (node < d.rbpf.size() && d.rbpf[node].utime <= t) {
      ASSERT_TRUE(fusion.AddLaserPose(d.rbpf[node].utime, d.rbpf[node].T_map_base).ok());
      ++node;
    }
    const Pose2 truth =
        fl::test::RoundedSquarePose(so, so.speed_mps * UtimeToSeconds(t - so.start_utime));
    ASSERT_TRUE(fusion.AddOdometry(t, T_odom_map * truth).ok());
  }
  EXPECT_EQ(fusion.counters().odometry_gaps, 0);
  EXPECT_EQ(fusion.num_factors(), static_cast<int>(d.rbpf.size()));  // prior + n-1 odometry
  fusion.FullSolve();
  // Odometry is interpolated linearly between 50 Hz samples: centimetre-level in corners.
  EXPECT_LT(MaxError(fusion.Trajectory(), d.truth), 0.02);
  // Out-of-order odometry is rejected.
  EXPECT_FALSE(fusion.AddOdometry(so.start_utime, Pose2()).ok());
  EXPECT_EQ(fusion.counters().rejected_odometry, 1);
}

// Odometry delayed by the network arrives after newer samples: inserted by its stamp, it is
// used by the node pair it falls in as if it had come in order; a repeated stamp, or one older
// than every kept sample, is rejected and counted.
TEST(FusionFactorGraph, LateOdometryIsInsertedByItsStamp) {
  FusionOptions o = TestOptions();
  o.use_wheel_odometry = true;
  const Utime t0 = 1000000;
  // Odometry samples around two laser nodes at t0 and t0 + 0.1 s; the one at t0 + 0.02 s is the
  // late one. It is not on a straight line with its neighbours: the node's interpolated
  // odometry depends on it.
  const std::vector<std::pair<Utime, Pose2>> samples = {{t0 - 10000, Pose2(-0.01, 0.0, 0.0)},
                                                        {t0 + 20000, Pose2(0.05, 0.01, 0.02)},
                                                        {t0 + 30000, Pose2(0.03, 0.0, 0.0)},
                                                        {t0 + 110000, Pose2(0.11, 0.0, 0.0)}};
  auto run = [&](const std::vector<int>& order, FusionCounters* counters) {
    FactorGraphFusion fusion(o);
    EXPECT_TRUE(fusion.AddLaserPose(t0, Pose2()).ok());
    for (int k : order) {
      if (k == 3) {
        EXPECT_TRUE(fusion.AddLaserPose(t0 + 100000, Pose2(0.1, 0.0, 0.0)).ok());
      }
      EXPECT_TRUE(fusion.AddOdometry(samples[k].first, samples[k].second).ok()) << k;
    }
    fusion.FullSolve();
    *counters = fusion.counters();
    return fusion.Trajectory();
  };
  FusionCounters in_order_c, late_c, missing_c;
  const auto in_order = run({0, 1, 2, 3}, &in_order_c);
  const auto late = run({0, 2, 1, 3}, &late_c);
  const auto missing = run({0, 2, 3}, &missing_c);
  EXPECT_EQ(in_order_c.late_odometry_placed, 0);
  EXPECT_EQ(late_c.late_odometry_placed, 1);
  EXPECT_EQ(late_c.rejected_odometry, 0);
  EXPECT_EQ(late_c.odometry_factors, 1);
  ASSERT_EQ(late.size(), 2u);
  EXPECT_EQ(late[1].T_map_base.x, in_order[1].T_map_base.x);
  EXPECT_EQ(late[1].T_map_base.y, in_order[1].T_map_base.y);
  EXPECT_EQ(late[1].T_map_base.theta, in_order[1].T_map_base.theta);
  EXPECT_GT(PositionError(missing[1].T_map_base, in_order[1].T_map_base), 1e-3);  // it counts

  FactorGraphFusion fusion(o);
  ASSERT_TRUE(fusion.AddLaserPose(t0, Pose2()).ok());
  for (int k : {0, 2}) ASSERT_TRUE(fusion.AddOdometry(samples[k].first, samples[k].second).ok());
  EXPECT_FALSE(fusion.AddOdometry(samples[2].first, samples[2].second).ok());  // a repeat
  EXPECT_FALSE(fusion.AddOdometry(t0 - 20000, Pose2()).ok());  // before every kept sample
  EXPECT_EQ(fusion.counters().rejected_odometry, 2);
  EXPECT_EQ(fusion.counters().late_odometry_placed, 0);
}

// A laser pose that arrives after newer ones adds no node (the nodes are a chain in time order)
// but gets its fused pose: the nearest node's, carried by the RBPF's own motion to its stamp.
TEST(FusionFactorGraph, LateLaserPosesArePlacedByTheirStampsWithoutANode) {
  FusionSimOptions so;
  so.vision_offset_s = 0.0;  // exact factors on the node times: the nodes converge to the truth
  const FusionSimData d = MakeRoundedSquareSim(so);
  FactorGraphFusion fusion(TestOptions());
  RunInOrder(d, &fusion);
  fusion.FullSolve();
  const int nodes = fusion.num_nodes(), factors = fusion.num_factors();
  int placed = 0;
  std::vector<double> heading_errors;
  for (size_t k = 3; k + 1 < d.rbpf.size(); k += 7) {
    // Between two nodes: the RBPF's pose there (its drift is far off the truth).
    const Utime t = (d.rbpf[k].utime + d.rbpf[k + 1].utime) / 2;
    const Pose2 rbpf = Interpolate(d.rbpf[k].T_map_base, d.rbpf[k + 1].T_map_base, 0.5);
    const Pose2 truth =
        fl::test::RoundedSquarePose(so, so.speed_mps * UtimeToSeconds(t - so.start_utime));
    TrajectoryPoint p;
    ASSERT_TRUE(fusion.PlaceLateLaserPose(t, rbpf, &p).ok()) << k;
    ++placed;
    EXPECT_EQ(p.utime, t);
    EXPECT_LT(PositionError(p.T_map_base, truth), 2e-3) << k;
    // The RBPF's heading bias over the half step from the node, 0.002 rad; up to 0.02 rad where
    // the half step enters or leaves a corner's arc (its interpolated motion is an arc).
    const double heading_error = std::fabs(WrapAngle(p.T_map_base.theta - truth.theta));
    EXPECT_LT(heading_error, 0.025) << k;
    heading_errors.push_back(heading_error);
    if (k > 40) {
      EXPECT_GT(PositionError(rbpf, truth), 0.1) << k;  // the RBPF's own is far off
    }
  }
  std::nth_element(heading_errors.begin(), heading_errors.begin() + heading_errors.size() / 2,
                   heading_errors.end());
  EXPECT_LT(heading_errors[heading_errors.size() / 2], 2.5e-3);
  EXPECT_EQ(fusion.counters().late_laser_poses_placed, placed);
  EXPECT_EQ(fusion.num_nodes(), nodes);  // no node, no factor
  EXPECT_EQ(fusion.num_factors(), factors);
  // A repeated stamp is not placed twice; a stamp far from every node is not placed at all.
  const int64_t rejected = fusion.counters().rejected_node_time;
  TrajectoryPoint p;
  EXPECT_FALSE(fusion.PlaceLateLaserPose(d.rbpf[10].utime, d.rbpf[10].T_map_base, &p).ok());
  EXPECT_FALSE(
      fusion.PlaceLateLaserPose(d.rbpf[0].utime - SecondsToUtime(5.0), d.rbpf[0].T_map_base, &p)
          .ok());
  EXPECT_FALSE(fusion.PlaceLateLaserPose(d.rbpf.back().utime + 1, d.rbpf.back().T_map_base, &p)
                   .ok());  // newer than the newest node: that is AddLaserPose's
  EXPECT_EQ(fusion.counters().rejected_node_time, rejected + 3);
  EXPECT_EQ(fusion.counters().late_laser_poses_placed, placed);
}

// A corridor: the laser is degenerate along the axis, the RBPF slides (its poses advance 20 %
// too little), the ICP keyframe factors carry (correctly) almost no information along x, and
// the wheel odometry is right. With the default chain mode the odometry decides the
// along-axis motion; chaining the RBPF poses as well would pull the result toward the slide.
TEST(FusionFactorGraph, WheelOdometryOutweighsASlidingRbpfAlongACorridor) {
  auto run = [](const std::string& chain_mode) {
    FusionOptions o;
    o.full_solve_every_n_nodes = 0;
    o.laser_chain_factors = chain_mode;
    FactorGraphFusion fusion(o);
    const Utime t0 = 1000000;
    for (int k = 0; k <= 200; ++k) {
      const Utime t = t0 + k * 100000;
      EXPECT_TRUE(fusion.AddOdometry(t, Pose2(0.05 * k, 0.0, 0.0)).ok());   // 0.5 m/s, exact
      EXPECT_TRUE(fusion.AddLaserPose(t, Pose2(0.04 * k, 0.0, 0.0)).ok());  // slides
      if (k > 0 && k % 10 == 0) {  // keyframe ICP factor: sure across, unsure along x
        RelativePoseFactor f;
        f.utime_i = t - 1000000;
        f.utime_j = t;
        f.T_i_j = Pose2(0.4, 0.0, 0.0).ToIsometry3();
        f.information.setZero();
        f.information(0, 0) = 1.0 / (2.0 * 2.0);  // sigma 2 m along the corridor
        f.information(1, 1) = 1.0 / (0.01 * 0.01);
        f.information(5, 5) = 1.0 / (0.002 * 0.002);
        f.source = FactorSource::kLaser;
        EXPECT_TRUE(fusion.AddFactor(f).ok());
      }
      fusion.Update();
    }
    fusion.FullSolve();
    TrajectoryPoint last;
    EXPECT_TRUE(fusion.Latest(&last));
    return std::make_pair(std::fabs(last.T_map_base.x - 10.0), fusion.counters());
  };
  const auto [gaps_err, gaps_counters] = run("odometry_gaps");
  EXPECT_EQ(gaps_counters.odometry_factors, 200);
  EXPECT_EQ(gaps_counters.chain_factors, 0);
  EXPECT_LT(gaps_err, 0.05);  // 10 m driven; the RBPF alone is 2 m short
  const auto [always_err, always_counters] = run("always");
  EXPECT_EQ(always_counters.chain_factors, 200);
  EXPECT_GT(always_err, 0.5);  // odometry counted against an equally confident sliding chain
}

// Odometry that stops (driver died) or never comes: after odom_max_latency_s the node pairs
// it does not cover get RBPF chain factors, so no node is left unconstrained.
TEST(FusionFactorGraph, ChainFactorsFillOdometryGaps) {
  FusionOptions o;
  o.full_solve_every_n_nodes = 0;
  o.odom_max_latency_s = 0.5;
  FactorGraphFusion fusion(o);
  const Utime t0 = 1000000;
  for (int k = 0; k <= 100; ++k) {
    const Utime t = t0 + k * 100000;
    if (k <= 40) {
      ASSERT_TRUE(fusion.AddOdometry(t, Pose2(0.05 * k, 0.0, 0.0)).ok());
    }
    ASSERT_TRUE(fusion.AddLaserPose(t, Pose2(0.05 * k, 0.0, 0.0)).ok());
  }
  const FusionCounters& c = fusion.counters();
  EXPECT_EQ(c.odometry_factors, 40);  // pairs (0,1) .. (39,40)
  // Pairs 41..100 lack odometry; those more than 0.5 s older than the newest node (41..94)
  // are gaps now, the last 6 still wait for late odometry.
  EXPECT_EQ(c.odometry_gaps, 54);
  EXPECT_EQ(c.chain_factors, 54);
  EXPECT_EQ(fusion.num_factors(), 1 + 40 + 54);
  // With the default options and no odometry channel at all, every pair gets there too.
  FactorGraphFusion no_odometry(o);
  for (int k = 0; k <= 100; ++k) {
    ASSERT_TRUE(no_odometry.AddLaserPose(t0 + k * 100000, Pose2(0.05 * k, 0.0, 0.0)).ok());
  }
  EXPECT_EQ(no_odometry.counters().chain_factors, 94);
  // Chain mode "never" leaves the gaps to interpolation; unknown modes are refused.
  o.laser_chain_factors = "sometimes";
  EXPECT_NE(o.Validate().message().find("laser_chain_factors"), std::string::npos);
}

// Every bad input is rejected with an error and a counter, and the graph is unchanged.
TEST(FusionFactorGraph, BadInputIsRejectedAndCountedWithoutCorruptingTheGraph) {
  FusionSimOptions so;
  so.loop_closure = false;
  const FusionSimData d = MakeRoundedSquareSim(so);
  FactorGraphFusion fusion(TestOptions());
  for (size_t k = 0; k < 40; ++k) {
    ASSERT_TRUE(fusion.AddLaserPose(d.rbpf[k].utime, d.rbpf[k].T_map_base).ok());
    if (k > 0) {
      ASSERT_TRUE(fusion.AddFactor(d.laser_factors[k - 1]).ok());
    }
  }
  fusion.Update();
  const int factors = fusion.num_factors();
  const auto before = fusion.Trajectory();
  const RelativePoseFactor good = d.laser_factors[5];
  const FusionCounters c0 = fusion.counters();

  RelativePoseFactor f = good;
  f.T_i_j.translation().x() = std::nan("");
  EXPECT_FALSE(fusion.AddFactor(f).ok());
  f = good;
  f.information(0, 0) = std::nan("");
  EXPECT_FALSE(fusion.AddFactor(f).ok());
  EXPECT_EQ(fusion.counters().rejected_non_finite, c0.rejected_non_finite + 2);

  f = good;
  f.information(0, 1) = 5.0;  // non-symmetric
  EXPECT_FALSE(fusion.AddFactor(f).ok());
  f = good;
  f.information(5, 5) = 0.0;  // singular
  EXPECT_FALSE(fusion.AddFactor(f).ok());
  f = good;
  f.information(1, 1) = -1.0;  // indefinite
  EXPECT_FALSE(fusion.AddFactor(f).ok());
  f = good;
  f.information = Eigen::Matrix<double, 6, 6>::Identity();
  f.information(3, 3) = 0.0;  // 6-DoF but singular in roll
  EXPECT_FALSE(fusion.AddFactor(f).ok());
  EXPECT_EQ(fusion.counters().rejected_information, c0.rejected_information + 4);

  f = good;
  f.utime_i = d.rbpf.front().utime - SecondsToUtime(5.0);  // before the first node
  const Status s = fusion.AddFactor(f);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("no laser node"), std::string::npos) << s.message();
  f = good;
  f.utime_j = f.utime_i + 20000;  // both on one node
  EXPECT_FALSE(fusion.AddFactor(f).ok());
  f = good;
  f.T_i_j.linear() *= 2.0;  // not a rotation
  EXPECT_FALSE(fusion.AddFactor(f).ok());
  EXPECT_EQ(fusion.counters().rejected_no_node, c0.rejected_no_node + 1);
  EXPECT_EQ(fusion.counters().rejected_same_node, c0.rejected_same_node + 1);

  // Laser poses: NaN and going back in time.
  EXPECT_FALSE(fusion.AddLaserPose(d.rbpf[40].utime, Pose2(std::nan(""), 0, 0)).ok());
  EXPECT_FALSE(fusion.AddLaserPose(d.rbpf[10].utime, d.rbpf[10].T_map_base).ok());
  EXPECT_EQ(fusion.counters().rejected_node_time, c0.rejected_node_time + 1);

  EXPECT_EQ(fusion.num_factors(), factors);
  EXPECT_EQ(fusion.num_nodes(), 40);
  EXPECT_EQ(fusion.num_pending_factors(), 0);
  const auto after = fusion.Trajectory();
  ASSERT_EQ(after.size(), before.size());
  for (size_t k = 0; k < after.size(); ++k) {
    EXPECT_EQ(after[k].T_map_base.x, before[k].T_map_base.x);
  }
  // A factor in a laser gap: nodes 40 and 41 are 2 s apart; a time in between matches none.
  ASSERT_TRUE(fusion.AddLaserPose(d.rbpf[60].utime, d.rbpf[60].T_map_base).ok());
  f = good;
  f.utime_i = d.rbpf[39].utime;
  f.utime_j = d.rbpf[50].utime;
  EXPECT_FALSE(fusion.AddFactor(f).ok());
  EXPECT_EQ(fusion.counters().rejected_no_node, c0.rejected_no_node + 2);
  // The graph still solves.
  EXPECT_TRUE(fusion.Update().ran);
}

TEST(FusionFactorGraph, VisionInformationIsMarginalisedToThePlane) {
  Eigen::Matrix<double, 6, 6> a = Eigen::Matrix<double, 6, 6>::Identity();
  a(0, 2) = 0.5;  // x correlated with z
  a(5, 3) = 0.4;  // yaw correlated with roll
  const Eigen::Matrix<double, 6, 6> cov = a * a.transpose() * 0.01;
  Eigen::Matrix3d planar;
  std::string reason;
  ASSERT_TRUE(ReduceInformationToPlanar(cov.inverse(), &planar, &reason)) << reason;
  const int idx[3] = {0, 1, 5};
  Eigen::Matrix3d cov3;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) cov3(r, c) = cov(idx[r], idx[c]);
  EXPECT_LT((planar - cov3.inverse()).norm(), 1e-6 * cov3.inverse().norm());
  // Cutting rows of the information would be over-confident in x.
  EXPECT_GT(cov.inverse()(0, 0), planar(0, 0) * 1.1);
  // Planar producers: the (x, y, yaw) block is used directly.
  Eigen::Matrix<double, 6, 6> p = Eigen::Matrix<double, 6, 6>::Zero();
  p(0, 0) = 4;
  p(1, 1) = 9;
  p(5, 5) = 16;
  p(0, 5) = p(5, 0) = 1;
  ASSERT_TRUE(ReduceInformationToPlanar(p, &planar, &reason)) << reason;
  EXPECT_EQ(planar(0, 0), 4);
  EXPECT_EQ(planar(2, 2), 16);
  EXPECT_EQ(planar(0, 2), 1);
}

TEST(FusionFactorGraph, LaserChainFactorsConstrainEveryNode) {
  FusionSimOptions so;
  so.rbpf_heading_bias = 0.0;  // RBPF poses = truth
  so.loop_closure = false;
  const FusionSimData d = MakeRoundedSquareSim(so);
  FusionOptions o = TestOptions();
  o.laser_chain_factors = "always";
  FactorGraphFusion fusion(o);
  for (const auto& p : d.rbpf) ASSERT_TRUE(fusion.AddLaserPose(p.utime, p.T_map_base).ok());
  EXPECT_EQ(fusion.num_factors(), static_cast<int>(d.rbpf.size()));  // prior + chain
  // A vision factor (sigma 0.1 m) that disagrees by 0.3 m over 5 s: the chain (about 0.1 m
  // plus heading freedom over those 50 steps) gives way smoothly: no node jumps.
  RelativePoseFactor f;
  f.utime_i = d.truth[10].utime;
  f.utime_j = d.truth[60].utime;
  Pose2 wrong = d.truth[10].T_map_base.between(d.truth[60].T_map_base);
  wrong.x += 0.3;
  f.T_i_j = wrong.ToIsometry3();
  f.information = Eigen::Matrix<double, 6, 6>::Identity() * 100;
  f.source = FactorSource::kVision;
  ASSERT_TRUE(fusion.AddFactor(f).ok());
  fusion.FullSolve();
  const auto traj = fusion.Trajectory();
  EXPECT_LT(MaxError(traj, d.truth), 0.29);  // less than the 0.3 m it claims
  EXPECT_GT(MaxError(traj, d.truth), 0.01);  // it did pull
  for (size_t k = 1; k < traj.size(); ++k) {
    const double step = PositionError(traj[k].T_map_base, traj[k - 1].T_map_base);
    const double true_step = PositionError(d.truth[k].T_map_base, d.truth[k - 1].T_map_base);
    EXPECT_LT(std::fabs(step - true_step), 0.02) << k;
  }
}

TEST(FusionFactorGraph, NewestNodeCovarianceAddsPriorAndChainNoise) {
  FusionOptions o = TestOptions();
  o.laser_chain_factors = "always";
  o.robust_loss = "none";
  FactorGraphFusion fusion(o);
  ASSERT_TRUE(fusion.AddLaserPose(1000000, Pose2(1.0, 2.0, 0.3)).ok());
  ASSERT_TRUE(fusion.AddLaserPose(1100000, Pose2(1.0, 2.0, 0.3)).ok());  // standing still
  fusion.Update();
  // Standing still (no lever arm): covariance = prior + one chain step, diagonal.
  const Eigen::Matrix3d c = fusion.latest_covariance();
  const double sxy = o.chain_sigma_xy_min, sth = o.chain_sigma_theta_min;
  EXPECT_NEAR(c(0, 0), o.prior_sigma_xy * o.prior_sigma_xy + sxy * sxy, 1e-9);
  EXPECT_NEAR(c(2, 2), o.prior_sigma_theta * o.prior_sigma_theta + sth * sth, 1e-9);
  EXPECT_NEAR(c(0, 1), 0.0, 1e-12);
}

// Feeds laser poses and factors (laser, vision) in time order; a full solve whenever one is
// requested. Returns the graph's size after each lap (nodes per lap: lap_nodes).
std::vector<int> RunWithFullSolves(const FusionSimData& d, FactorGraphFusion* fusion,
                                   size_t lap_nodes) {
  std::vector<int> sizes;
  size_t lf = 0, vf = 0;
  for (size_t k = 0; k < d.rbpf.size(); ++k) {
    EXPECT_TRUE(fusion->AddLaserPose(d.rbpf[k].utime, d.rbpf[k].T_map_base).ok());
    while (lf < d.laser_factors.size() && d.laser_factors[lf].utime_j <= d.rbpf[k].utime) {
      EXPECT_TRUE(fusion->AddFactor(d.laser_factors[lf++]).ok());
    }
    while (vf < d.vision_factors.size() && d.vision_factors[vf].utime_j <= d.rbpf[k].utime) {
      EXPECT_TRUE(fusion->AddFactor(d.vision_factors[vf++]).ok());
    }
    fusion->Update();
    if (fusion->full_solve_requested()) fusion->FullSolve();
    if ((k + 1) % lap_nodes == 0) sizes.push_back(fusion->num_nodes());
  }
  return sizes;
}

TEST(FusionFactorGraph, ReanchoredInformationKeepsTheCost) {
  // Z' = P Z Q between anchors a = i P^-1 and b = j Q has, with Omega' from
  // TransformBetweenInformation, the cost of Z between i and j (to first order).
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    const Pose2 T_i(u(rng) * 5, u(rng) * 5, u(rng) * 3);
    const Pose2 Z(u(rng) * 2, u(rng) * 2, u(rng));
    const Pose2 T_j = T_i * Z * Pose2(1e-3 * u(rng), 1e-3 * u(rng), 1e-3 * u(rng));
    const Pose2 P(u(rng), u(rng), u(rng) * 0.5), Q(u(rng), u(rng), u(rng) * 0.5);
    const Pose2 T_a = T_i * P.inverse(), T_b = T_j * Q;
    Eigen::Matrix3d a = Eigen::Matrix3d::Identity() + 0.3 * Eigen::Matrix3d::Random();
    const Eigen::Matrix3d info = a * a.transpose() * 1e4;
    const Eigen::Matrix3d info2 = TransformBetweenInformation(info, P, Z, Q);
    auto cost = [](const Pose2& meas, const Eigen::Matrix3d& omega, const Pose2& x_i,
                   const Pose2& x_j) {
      Eigen::Matrix3d s;
      EXPECT_TRUE(SqrtInformation<3>(omega, &s));
      std::unique_ptr<ceres::CostFunction> c(Se2BetweenCost::Create(meas, s));
      const double pi[3] = {x_i.x, x_i.y, x_i.theta}, pj[3] = {x_j.x, x_j.y, x_j.theta};
      const double* params[2] = {pi, pj};
      double r[3];
      c->Evaluate(params, r, nullptr);
      return r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
    };
    const double c1 = cost(Z, info, T_i, T_j);
    const double c2 = cost(P * Z * Q, info2, T_a, T_b);
    EXPECT_NEAR(c2, c1, 0.02 * c1 + 1e-6) << trial;
  }
}

TEST(FusionFactorGraph, BoundedGraphStopsGrowingOnceTheRouteIsMapped) {
  // 20 laps of the square, exact measurements: with a 30 s active window the graph holds the
  // window plus the map nodes of one lap, every pose is still in the trajectory, exact.
  FusionSimOptions so;
  so.laps = 20;
  so.loop_closure = false;
  so.vision_offset_s = 0.0;  // see SquareWithLoopClosureConvergesToTruth
  const FusionSimData d = MakeRoundedSquareSim(so);
  const size_t lap_nodes = d.rbpf.size() / 20;
  FusionOptions o = TestOptions();
  o.active_window_s = 30.0;
  o.max_window_nodes = 100;
  o.full_solve_every_n_nodes = 100;
  FactorGraphFusion fusion(o);
  const std::vector<int> sizes = RunWithFullSolves(d, &fusion, lap_nodes);
  ASSERT_EQ(sizes.size(), 20u);
  // Window: 300-400 nodes; map nodes: about one per metre of the 22.6 m lap.
  // (Retired in batches of 10 s: the size saw-tooths by ~100 nodes.)
  const int early = *std::max_element(sizes.begin() + 1, sizes.begin() + 5);
  const int late = *std::max_element(sizes.begin() + 10, sizes.end());
  EXPECT_LT(late, 500);
  EXPECT_LE(late, early + 5) << "largest in laps 2-5: " << early << ", in laps 11-20: " << late;
  EXPECT_GT(fusion.num_map_nodes(), 10);
  EXPECT_LT(fusion.num_map_nodes(), 60);
  EXPECT_GT(fusion.counters().merged_nodes, fusion.counters().retired_nodes / 2);
  EXPECT_GT(fusion.counters().reanchored_factors, 0);
  const auto traj = fusion.Trajectory();
  ASSERT_EQ(traj.size(), d.truth.size());
  EXPECT_LT(MaxError(traj, d.truth), 1e-3);
  Pose2 p;
  const size_t old = lap_nodes + 7;  // retired long ago
  ASSERT_TRUE(fusion.PoseAt(d.truth[old].utime + 30000, &p));
  EXPECT_LT(
      PositionError(p, Interpolate(d.truth[old].T_map_base, d.truth[old + 1].T_map_base, 0.3)),
      1e-3);

  // A late loop closure from the newest node to a retired time attaches (onto the map node
  // of that place) and keeps the graph exact; one between two retired times changes nothing.
  const int64_t rejected = fusion.counters().rejected_total();
  const int64_t added = fusion.counters().factors_added;
  RelativePoseFactor loop;
  loop.utime_i = d.truth.back().utime;
  loop.utime_j = d.truth[old].utime;
  loop.T_i_j = d.truth.back().T_map_base.between(d.truth[old].T_map_base).ToIsometry3();
  loop.information.diagonal() << 1e4, 1e4, 0, 0, 0, 1e5;
  loop.is_loop_closure = true;
  ASSERT_TRUE(fusion.AddFactor(loop).ok());
  EXPECT_EQ(fusion.counters().factors_added, added + 1);
  RelativePoseFactor past = loop;
  past.utime_i = d.truth[old + 50].utime;
  past.T_i_j = d.truth[old + 50].T_map_base.between(d.truth[old].T_map_base).ToIsometry3();
  const int64_t retired_factors = fusion.counters().retired_factors;
  ASSERT_TRUE(fusion.AddFactor(past).ok());
  EXPECT_EQ(fusion.counters().retired_factors, retired_factors + 1);
  EXPECT_EQ(fusion.counters().rejected_total(), rejected);
  fusion.FullSolve();
  EXPECT_LT(MaxError(fusion.Trajectory(), d.truth), 1e-3);
}

TEST(FusionFactorGraph, NodesRetireOnlyOnceASolveHasPlacedThem) {
  // A journal restore adds every node without solving, then runs one full solve: nothing may
  // be frozen at its unoptimised (drifting RBPF) pose before that.
  FusionSimOptions so;
  so.laps = 6;
  so.loop_closure = false;
  so.vision_offset_s = 0.0;
  const FusionSimData d = MakeRoundedSquareSim(so);
  FusionOptions o = TestOptions();
  o.active_window_s = 30.0;
  o.max_window_nodes = 100;
  FactorGraphFusion fusion(o);
  size_t lf = 0;
  for (size_t k = 0; k + 1 < d.rbpf.size(); ++k) {
    ASSERT_TRUE(fusion.AddLaserPose(d.rbpf[k].utime, d.rbpf[k].T_map_base).ok());
    while (lf < d.laser_factors.size() && d.laser_factors[lf].utime_j <= d.rbpf[k].utime) {
      ASSERT_TRUE(fusion.AddFactor(d.laser_factors[lf++]).ok());
    }
  }
  EXPECT_EQ(fusion.num_retired_nodes(), 0);
  EXPECT_EQ(fusion.num_nodes(), static_cast<int>(d.rbpf.size()) - 1);
  EXPECT_GT(MaxError(fusion.Trajectory(), d.truth), 0.5);  // the RBPF's drift
  fusion.FullSolve();
  // The next node retires everything older than the window, at its solved pose.
  ASSERT_TRUE(fusion.AddLaserPose(d.rbpf.back().utime, d.rbpf.back().T_map_base).ok());
  ASSERT_TRUE(fusion.AddFactor(d.laser_factors.back()).ok());
  EXPECT_GT(fusion.num_retired_nodes(), static_cast<int64_t>(d.rbpf.size()) / 2);
  EXPECT_LT(fusion.num_nodes(), 500);
  fusion.FullSolve();
  EXPECT_LT(MaxError(fusion.Trajectory(), d.truth), 1e-3);
}

TEST(FusionFactorGraph, BoundedGraphIsAsAccurateAsTheFullOneOnNoisyData) {
  // Noisy laser and vision factors, 8 laps, several seeds: the bounded graph (30 s window)
  // against keeping every node.
  for (unsigned seed = 1; seed <= 3; ++seed) {
    FusionSimOptions so;
    so.laps = 8;
    so.seed = seed;
    so.laser_sigma_xy = 0.01;
    so.laser_sigma_theta = 0.003;
    so.vision_sigma_xy = 0.02;
    so.vision_sigma_theta = 0.005;
    const FusionSimData d = MakeRoundedSquareSim(so);
    FusionOptions o = TestOptions();
    o.full_solve_every_n_nodes = 100;
    o.max_window_nodes = 100;
    o.active_window_s = 0.0;
    FactorGraphFusion full(o);
    RunWithFullSolves(d, &full, d.rbpf.size());
    o.active_window_s = 30.0;
    FactorGraphFusion bounded(o);
    RunWithFullSolves(d, &bounded, d.rbpf.size());
    EXPECT_LT(bounded.num_nodes(), full.num_nodes() / 3);
    const double e_full = RmsError(full.Trajectory(), d.truth);
    const double e_bounded = RmsError(bounded.Trajectory(), d.truth);
    EXPECT_LT(e_bounded, 1.5 * e_full + 0.02)
        << "seed " << seed << ": full " << e_full << " m, bounded " << e_bounded << " m";
  }
}

// Feeds steps [first, last) of `d` (laser poses, exact wheel odometry from the truth, laser
// and vision factors) with an Update after each node and the full solves it asks for.
void FeedSteps(const FusionSimData& d, size_t first, size_t last, FactorGraphFusion* fusion) {
  for (size_t k = first; k < last; ++k) {
    const Utime t = d.rbpf[k].utime;
    ASSERT_TRUE(fusion->AddOdometry(t, d.truth[k].T_map_base).ok());
    ASSERT_TRUE(fusion->AddLaserPose(t, d.rbpf[k].T_map_base).ok());
    for (const auto* factors : {&d.laser_factors, &d.vision_factors}) {
      for (const RelativePoseFactor& f : *factors) {
        const Utime prev = k == 0 ? 0 : d.rbpf[k - 1].utime;
        if (f.utime_j > prev && f.utime_j <= t) {
          ASSERT_TRUE(fusion->AddFactor(f).ok());
        }
      }
    }
    fusion->Update();
    if (fusion->full_solve_requested()) fusion->FullSolve();
  }
}

// `laps` of the square with noisy laser and vision factors.
FusionSimData NoisySquare(int laps) {
  FusionSimOptions so;
  so.laps = laps;
  so.laser_sigma_xy = 0.01;
  so.laser_sigma_theta = 0.003;
  so.vision_sigma_xy = 0.02;
  so.vision_sigma_theta = 0.005;
  return MakeRoundedSquareSim(so);
}

// Wheel odometry, periodic full solves and a 30 s active window (retired and map nodes).
FusionOptions BoundedOptions() {
  FusionOptions o = TestOptions();
  o.use_wheel_odometry = true;
  o.full_solve_every_n_nodes = 100;
  o.max_window_nodes = 100;
  o.active_window_s = 30.0;
  return o;
}

// The same stamps and bit-identical poses.
void ExpectBitIdentical(const std::vector<TrajectoryPoint>& a,
                        const std::vector<TrajectoryPoint>& b) {
  ASSERT_EQ(b.size(), a.size());
  for (size_t k = 0; k < a.size(); ++k) {
    ASSERT_EQ(a[k].utime, b[k].utime);
    ASSERT_EQ(a[k].T_map_base.x, b[k].T_map_base.x) << k;
    ASSERT_EQ(a[k].T_map_base.y, b[k].T_map_base.y) << k;
    ASSERT_EQ(a[k].T_map_base.theta, b[k].T_map_base.theta) << k;
  }
}

TEST(FusionFactorGraph, ASavedStateGoesOnExactlyAsTheOriginal) {
  // Noisy factors, wheel odometry, a 30 s active window (retired and map nodes), saved after
  // 2.5 of 4 laps and loaded into a new fusion: given the same inputs, both end bit-identical.
  const FusionSimData d = NoisySquare(4);
  const FusionOptions o = BoundedOptions();
  FactorGraphFusion original(o);
  const size_t half = d.rbpf.size() * 5 / 8;
  FeedSteps(d, 0, half, &original);
  ASSERT_GT(original.num_retired_nodes(), 100);
  ASSERT_GT(original.num_map_nodes(), 5);
  StateWriter w;
  original.SaveState(&w);
  const std::vector<uint8_t> bytes = w.Release();
  FactorGraphFusion loaded(o);
  StateReader r(bytes.data(), bytes.size());
  loaded.LoadState(&r);
  EXPECT_EQ(loaded.num_nodes(), original.num_nodes());
  EXPECT_EQ(loaded.num_factors(), original.num_factors());
  EXPECT_EQ(loaded.num_retired_nodes(), original.num_retired_nodes());

  FeedSteps(d, half, d.rbpf.size(), &original);
  FeedSteps(d, half, d.rbpf.size(), &loaded);
  for (const auto& f : d.loop_factors) {
    ASSERT_TRUE(original.AddFactor(f).ok());
    ASSERT_TRUE(loaded.AddFactor(f).ok());
  }
  original.FullSolve();
  loaded.FullSolve();
  const auto a = original.Trajectory();
  ASSERT_EQ(a.size(), d.truth.size());
  ExpectBitIdentical(a, loaded.Trajectory());
  EXPECT_EQ(loaded.latest_covariance(), original.latest_covariance());
  EXPECT_EQ(loaded.counters().factors_added, original.counters().factors_added);
  EXPECT_EQ(loaded.counters().odometry_factors, original.counters().odometry_factors);
  EXPECT_EQ(loaded.counters().merged_nodes, original.counters().merged_nodes);
  EXPECT_EQ(loaded.num_map_nodes(), original.num_map_nodes());
}

TEST(FusionFactorGraph, ASpilledRetiredTrajectoryChangesNoResult) {
  // The same inputs into a fusion that keeps its retired trajectory in memory and into one that
  // spills all but the newest 20 poses to a file: bit-identical trajectories, poses at retired
  // times, and late factors onto them; the spilling one saved halfway and restored from its
  // snapshot and (a copy of) its file goes on identically too, and its snapshot is smaller.
  const FusionSimData d = NoisySquare(6);
  const FusionOptions o = BoundedOptions();
  fl::test::TempDir dir;
  FactorGraphFusion in_memory(o), spilled(o);
  spilled.SpillRetiredTrajectory(std::make_shared<RetiredSpillFile>(dir.file("a.retired")), 20,
                                 /*batch=*/100);
  const size_t half = d.rbpf.size() * 3 / 4;
  FeedSteps(d, 0, half, &in_memory);
  FeedSteps(d, 0, half, &spilled);
  ASSERT_GE(spilled.retired_trajectory().spilled(), 500u);
  StateWriter w_memory, w_spilled;
  in_memory.SaveState(&w_memory);
  spilled.SaveState(&w_spilled);
  EXPECT_EQ(w_memory.bytes().size() - w_spilled.bytes().size(),
            spilled.retired_trajectory().spilled() * RetiredSpillFile::kRecordBytes);
  std::filesystem::copy_file(dir.file("a.retired"), dir.file("b.retired"));
  FactorGraphFusion restored(o);
  restored.SpillRetiredTrajectory(std::make_shared<RetiredSpillFile>(dir.file("b.retired")), 20,
                                  /*batch=*/100);
  StateReader r(w_spilled.bytes().data(), w_spilled.bytes().size());
  restored.LoadState(&r);

  std::vector<FactorGraphFusion*> all = {&in_memory, &spilled, &restored};
  for (FactorGraphFusion* f : all) FeedSteps(d, half, d.rbpf.size(), f);
  // A late loop closure from the newest node onto a pose retired (and spilled) long ago.
  const size_t old = 57;
  RelativePoseFactor loop;
  loop.utime_i = d.truth.back().utime;
  loop.utime_j = d.truth[old].utime + 20000;  // between two scans: interpolated
  loop.T_i_j = d.truth.back()
                   .T_map_base.between(Interpolate(d.truth[old].T_map_base,
                                                   d.truth[old + 1].T_map_base, 0.2))
                   .ToIsometry3();
  loop.information.diagonal() << 1e4, 1e4, 0, 0, 0, 1e5;
  loop.is_loop_closure = true;
  for (FactorGraphFusion* f : all) {
    ASSERT_TRUE(f->AddFactor(loop).ok());
    f->FullSolve();
  }
  EXPECT_EQ(spilled.counters().factors_added, in_memory.counters().factors_added);
  const auto a = in_memory.Trajectory();
  ASSERT_EQ(a.size(), d.truth.size());
  for (const FactorGraphFusion* f : {&spilled, &restored}) {
    ExpectBitIdentical(a, f->Trajectory());
    for (const Utime t : {d.truth[old].utime + 30000, d.truth[old * 5].utime, a.back().utime}) {
      Pose2 p, q;
      ASSERT_TRUE(in_memory.PoseAt(t, &p));
      ASSERT_TRUE(f->PoseAt(t, &q));
      EXPECT_EQ(p.x, q.x);
      EXPECT_EQ(p.y, q.y);
    }
    EXPECT_LT(f->retired_trajectory().in_memory(), 20u + 100u);
  }
  EXPECT_EQ(in_memory.retired_trajectory().spilled(), 0u);
}

// One lap with the laser silent (no RBPF poses, no laser factors) over steps [8 s, 16 s):
// wheel odometry at every step that drifts (a heading bias of 0.004 rad per step), vision
// factors throughout (exact, unless `with_vision` is false). Returns the largest position error
// over the outage's steps that have a pose (PoseAt), and how many of them had one.
struct OutageRun {
  double worst_outage_error_m = 0.0;
  int outage_steps_with_pose = 0;
  double final_rms_m = 0.0;
};
OutageRun RunLaserOutage(bool with_vision, FactorGraphFusion* fusion) {
  FusionSimOptions so;
  so.vision_offset_s = 0.0;
  const FusionSimData d = MakeRoundedSquareSim(so);
  const size_t first = 80, end = 160;  // the outage, in steps (10 Hz)
  auto silent = [&](Utime t) { return t >= d.truth[first].utime && t < d.truth[end].utime; };
  Pose2 odom = d.truth[0].T_map_base;
  size_t lf = 0, vf = 0;
  for (size_t k = 0; k < d.truth.size(); ++k) {
    const Utime t = d.truth[k].utime;
    if (k > 0) {
      const Pose2 motion = d.truth[k - 1].T_map_base.between(d.truth[k].T_map_base);
      odom = odom * Pose2(motion.x, motion.y, motion.theta + 0.004);
    }
    EXPECT_TRUE(fusion->AddOdometry(t, odom).ok());
    if (!silent(t)) {
      // As fl-fusion does: a laser pose older than the newest (odometry) node is placed late.
      if (t < fusion->newest_node_utime()) {
        TrajectoryPoint late;
        EXPECT_TRUE(fusion->PlaceLateLaserPose(t, d.rbpf[k].T_map_base, &late).ok());
      } else {
        EXPECT_TRUE(fusion->AddLaserPose(t, d.rbpf[k].T_map_base).ok());
      }
    }
    for (; lf < d.laser_factors.size() && d.laser_factors[lf].utime_j <= t; ++lf) {
      const RelativePoseFactor& f = d.laser_factors[lf];
      if (!silent(f.utime_i) && !silent(f.utime_j)) {
        EXPECT_TRUE(fusion->AddFactor(f).ok());
      }
    }
    for (; with_vision && vf < d.vision_factors.size() && d.vision_factors[vf].utime_j <= t;
         ++vf) {
      (void)fusion->AddFactor(d.vision_factors[vf]);  // in the outage: refused without nodes
    }
    fusion->Update();
    if (fusion->full_solve_requested()) fusion->FullSolve();
  }
  fusion->FullSolve();
  OutageRun run;
  for (size_t k = first; k < end; ++k) {
    Pose2 p;
    if (!fusion->PoseAt(d.truth[k].utime, &p)) continue;
    ++run.outage_steps_with_pose;
    run.worst_outage_error_m =
        std::max(run.worst_outage_error_m, PositionError(p, d.truth[k].T_map_base));
  }
  std::vector<TrajectoryPoint> laser_times;
  for (const TrajectoryPoint& tp : fusion->Trajectory()) {
    if (!silent(tp.utime)) laser_times.push_back(tp);
  }
  std::vector<TrajectoryPoint> truth;
  for (const TrajectoryPoint& tp : d.truth) {
    if (!silent(tp.utime)) truth.push_back(tp);
  }
  EXPECT_EQ(laser_times.size(), truth.size());
  run.final_rms_m = RmsError(laser_times, truth);
  return run;
}

TEST(FusionFactorGraph, ALaserOutageIsBridgedByOdometryNodesAndTheVisionFactors) {
  FusionOptions o = TestOptions();
  o.use_wheel_odometry = true;
  o.laser_chain_factors = "odometry_gaps";
  // Default: 1 s after the last laser pose, a node every 0.1 s from the odometry; the vision
  // factors of the outage attach to them and hold the drifting odometry.
  FactorGraphFusion fused(o);
  const OutageRun with_vision = RunLaserOutage(true, &fused);
  // Every 0.1 s of the 8 s outage (the first second filled in once it is noticed).
  EXPECT_GE(fused.counters().odometry_nodes, 79);
  EXPECT_LE(fused.counters().odometry_nodes, 81);
  EXPECT_EQ(with_vision.outage_steps_with_pose, 80);
  // A laser pose of the outage delivered late, at an odometry node's stamp (step 120): that
  // node takes it as its RBPF pose, once; no node is added.
  const Utime step_120 = 1000000 + 120 * 100000;
  const int64_t odometry_nodes = fused.counters().odometry_nodes;
  const int nodes = fused.num_nodes();
  EXPECT_TRUE(fused.TakeOverOdometryNode(step_120, Pose2(1, 2, 0.3)));
  EXPECT_FALSE(fused.TakeOverOdometryNode(step_120, Pose2(1, 2, 0.3)));  // a laser node now
  EXPECT_FALSE(fused.TakeOverOdometryNode(step_120 + 1, Pose2(1, 2, 0.3)));  // no node there
  EXPECT_EQ(fused.counters().odometry_nodes, odometry_nodes - 1);
  EXPECT_EQ(fused.num_nodes(), nodes);
  // Without vision the same nodes follow the odometry alone, and its drift.
  FactorGraphFusion odometry_only(o);
  const OutageRun no_vision = RunLaserOutage(false, &odometry_only);
  EXPECT_EQ(odometry_only.counters().odometry_nodes, odometry_nodes);
  EXPECT_GT(no_vision.worst_outage_error_m, 0.15);
  // (0.24 against 1.62 m when written.)
  EXPECT_LT(with_vision.worst_outage_error_m, 0.3 * no_vision.worst_outage_error_m)
      << "odometry only " << no_vision.worst_outage_error_m << " m";
  // Back on laser nodes after the outage, every laser time in the trajectory. The error the
  // outage ends with stays (the laser factors are relative; no loop closes here): 0.17 against
  // 1.31 m RMS over the laser times when written.
  EXPECT_LT(with_vision.final_rms_m, 0.3 * no_vision.final_rms_m)
      << "odometry only " << no_vision.final_rms_m << " m";
  // Off: no node in the outage; its vision factors are refused; the gap is interpolated.
  o.odometry_nodes_after_s = 0.0;
  FactorGraphFusion off(o);
  RunLaserOutage(true, &off);
  EXPECT_EQ(off.counters().odometry_nodes, 0);
  EXPECT_GT(off.counters().rejected_no_node, 10);
}

TEST(FusionFactorGraph, ADamagedSavedStateIsRefusedAndChangesNothing) {
  FusionSimOptions so;
  so.laps = 2;
  const FusionSimData d = MakeRoundedSquareSim(so);
  FusionOptions o = TestOptions();
  o.use_wheel_odometry = true;
  o.active_window_s = 10.0;
  FactorGraphFusion original(o);
  FeedSteps(d, 0, d.rbpf.size() / 2, &original);
  StateWriter w;
  original.SaveState(&w);
  const std::vector<uint8_t> bytes = w.Release();
  FactorGraphFusion other(o);
  FeedSteps(d, 0, 10, &other);
  const auto before = other.Trajectory();
  // Every truncation is an error, and the fusion it was loaded into is unchanged.
  for (size_t n = 0; n < bytes.size(); n += 1 + n / 16) {
    StateReader r(bytes.data(), n);
    EXPECT_THROW(other.LoadState(&r), StateError) << n << " of " << bytes.size() << " bytes";
  }
  // A node index out of range, a NaN, a count beyond the buffer: refused, named.
  std::vector<uint8_t> bad = bytes;
  const size_t nodes_at = 16;  // after the magic, byte-order mark and version
  const uint64_t huge = uint64_t{1} << 62;
  std::memcpy(bad.data() + nodes_at, &huge, sizeof(huge));
  StateReader r1(bad.data(), bad.size());
  try {
    other.LoadState(&r1);
    FAIL() << "a node count of 2^62 was read";
  } catch (const StateError& e) {
    EXPECT_NE(std::string(e.what()).find("nodes: a count of"), std::string::npos) << e.what();
  }
  bad = bytes;
  const double nan = std::nan("");
  std::memcpy(bad.data() + nodes_at + 8 + 8, &nan, sizeof(nan));  // node 0's T_map_base_rbpf.x
  StateReader r2(bad.data(), bad.size());
  EXPECT_THROW(other.LoadState(&r2), StateError);
  const auto after = other.Trajectory();
  ASSERT_EQ(after.size(), before.size());
  for (size_t k = 0; k < after.size(); ++k) EXPECT_EQ(after[k].T_map_base.x, before[k].T_map_base.x);
}

TEST(FusionFactorGraph, OptionsValidateWithClearErrors) {
  FusionOptions o;
  EXPECT_TRUE(o.Validate().ok());
  o.robust_loss = "tukey";
  EXPECT_NE(o.Validate().message().find("robust_loss"), std::string::npos);
  o = FusionOptions();
  o.window_size = 1;
  EXPECT_FALSE(o.Validate().ok());
  EXPECT_THROW(FactorGraphFusion bad(o), std::invalid_argument);
}

}  // namespace
}  // namespace fl::fusion
