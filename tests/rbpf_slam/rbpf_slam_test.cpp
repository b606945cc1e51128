#include "fusionloc/rbpf_slam/rbpf_slam.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <limits>
#include <map>
#include <tuple>
#include <numeric>

#include "fusionloc/common/yaml_options.hpp"
#include "laser_fixtures.hpp"

namespace fl::rbpf {
namespace {

LaserScan MakeScan(fl::Utime t, std::vector<float> ranges, double rad0 = -M_PI / 2,
                   double radstep = M_PI / 180) {
  LaserScan s;
  s.utime = t;
  s.ranges = std::move(ranges);
  s.rad0 = rad0;
  s.radstep = radstep;
  return s;
}

TEST(Resampling, EffectiveSampleSize) {
  EXPECT_NEAR(RbpfSlam::EffectiveSampleSize(std::vector<double>(30, 1.0 / 30)), 30.0, 1e-9);
  std::vector<double> peaked(30, 0.0);
  peaked[7] = 1.0;
  EXPECT_NEAR(RbpfSlam::EffectiveSampleSize(peaked), 1.0, 1e-12);
  EXPECT_NEAR(RbpfSlam::EffectiveSampleSize({0.5, 0.5, 0.0, 0.0}), 2.0, 1e-12);
}

TEST(Resampling, SystematicKeepsTheCountAndFollowsTheWeights) {
  const std::vector<double> w = {0.5, 0.25, 0.125, 0.125, 0.0};
  for (double u0 : {0.0, 0.3, 0.999}) {
    const std::vector<int> parents = RbpfSlam::SystematicResample(w, u0);
    ASSERT_EQ(parents.size(), w.size());
    std::vector<int> count(w.size(), 0);
    for (int p : parents) ++count[p];
    for (size_t i = 0; i < w.size(); ++i) {
      // Systematic resampling: each particle gets floor or ceil of n * w_i copies.
      EXPECT_GE(count[i], static_cast<int>(std::floor(w[i] * 5)));
      EXPECT_LE(count[i], static_cast<int>(std::ceil(w[i] * 5)));
    }
    EXPECT_EQ(count[4], 0);
  }
}

// Small fast configuration for the simulated runs.
RbpfSlamOptions TestOptions(int particles) {
  RbpfSlamOptions o;
  o.particles = particles;
  o.grid.max_range = 25.0;
  // The test laser's range noise is 1 cm (LoopRunOptions): a free-space margin of one cell is
  // 2 sigma (the default, 4 cells, is for the simulator's 10 cm).
  o.grid.free_space_margin = 1;
  return o;
}

// The loop corridor of RoomWithBoxes, a scan every 0.25 m, with the default odometry noise.
test::LoopRun RoomLoopRun(int laps) {
  test::LoopRunOptions lo;
  lo.step_m = 0.25;
  lo.laps = laps;
  return test::MakeLoopRun(test::LaserWorld::RoomWithBoxes(), lo);
}

// Feeds every scan of `run` to `slam` (each must be accepted); each(k, result) after scan k.
template <class Each>
void Drive(RbpfSlam* slam, const test::LoopRun& run, Each each) {
  for (size_t k = 0; k < run.utimes.size(); ++k) {
    ScanResult r;
    EXPECT_TRUE(slam->AddScan(MakeScan(run.utimes[k], run.ranges[k]), run.odom[k], &r).ok());
    each(k, r);
  }
}

// Runs a whole simulated drive through a filter with options `o`; returns the largest error of
// its final trajectory against the truth and (optionally) its stats.
double MaxTrajectoryError(const RbpfSlamOptions& o, const test::LoopRun& run,
                          RbpfSlamStats* stats = nullptr) {
  RbpfSlam slam(o);
  for (size_t k = 0; k < run.utimes.size(); ++k) {
    ScanResult r;
    EXPECT_TRUE(slam.AddScan(MakeScan(run.utimes[k], run.ranges[k]), run.odom[k], &r).ok());
  }
  slam.Finish();
  if (stats) *stats = slam.stats();
  const auto traj = slam.Trajectory();
  double err = 0.0;
  for (size_t k = 0; k < traj.size(); ++k) {
    err = std::max(err, (traj[k].T_world_base.translation() - run.truth[k].translation()).norm());
  }
  return err;
}

// The room loop in 0.25 m steps with nearly exact odometry.
test::LoopRun NearExactOdometryLoop() {
  test::LoopRunOptions lo;
  lo.step_m = 0.25;
  lo.odom_trans_noise = 0.002;
  lo.odom_rot_noise = 0.001;
  lo.odom_rot_bias = 0.0;
  return test::MakeLoopRun(test::LaserWorld::RoomWithBoxes(), lo);
}

// A crippled one-particle filter for NearExactOdometryLoop(): its motion model samples heading
// errors of `heading_sigma_per_m` [rad/m] and its matcher may correct only 0.01 rad, so it
// drifts away from the truth unless a keyframe check catches it. No loop search; every scan
// goes to the filter (the turn gate is tested on its own).
RbpfSlamOptions CrippledFilterOptions(int seed, double heading_sigma_per_m) {
  RbpfSlamOptions o = TestOptions(1);
  o.seed = seed;
  o.motion.stt = 0.0;
  o.motion.str = heading_sigma_per_m;
  o.matcher.max_correction_rad = 0.01;
  o.graph.loop_search.enabled = false;
  o.max_turn_rate = 0.0;
  return o;
}

TEST(RbpfSlam, ResamplesOnlyWhenNeffDropsBelowTheThreshold) {
  const test::LoopRun run = RoomLoopRun(1);
  for (double threshold : {0.0, 0.5, 1.0}) {
    RbpfSlamOptions o = TestOptions(10);
    o.neff_threshold = threshold;
    o.graph.enabled = false;
    RbpfSlam slam(o);
    int processed = 0, resampled = 0;
    for (size_t k = 0; k < 60; ++k) {
      ScanResult r;
      ASSERT_TRUE(slam.AddScan(MakeScan(run.utimes[k], run.ranges[k]), run.odom[k], &r).ok());
      if (k == 0 || !r.processed) continue;
      ++processed;
      EXPECT_EQ(slam.num_particles(), 10);
      // Resampling happens exactly when N_eff < N_th.
      EXPECT_EQ(r.resampled, r.neff < threshold * 10) << "scan " << k << " neff " << r.neff;
      resampled += r.resampled ? 1 : 0;
      if (r.resampled) {
        const auto w = slam.NormalizedWeights();
        EXPECT_NEAR(RbpfSlam::EffectiveSampleSize(w), 10.0, 1e-9);  // uniform after resampling
      }
    }
    ASSERT_GT(processed, 20);
    if (threshold == 0.0) {
      EXPECT_EQ(resampled, 0);
    }
    if (threshold == 1.0) {
      EXPECT_EQ(resampled, processed);
    }
  }
}

TEST(RbpfSlam, SimulatedLoopIsClosed) {
  const test::LoopRun run = RoomLoopRun(1);
  RbpfSlamOptions o = TestOptions(10);
  RbpfSlam slam(o);
  int factors = 0, loops = 0;
  for (size_t k = 0; k < run.utimes.size(); ++k) {
    ScanResult r;
    ASSERT_TRUE(slam.AddScan(MakeScan(run.utimes[k], run.ranges[k]), run.odom[k], &r).ok());
    for (const KeyframeFactor& f : r.factors) {
      ++factors;
      loops += f.is_loop_closure ? 1 : 0;
      EXPECT_LT(f.utime_i, f.utime_j);
      EXPECT_GT(f.information.determinant(), 0.0);
    }
  }
  slam.Finish();
  EXPECT_GT(factors, 20);
  EXPECT_GE(loops, 1);
  EXPECT_GE(slam.stats().loop_closures, 1);
  // The trajectory ends where it started (the run is a closed loop) and stays near the truth.
  const auto traj = slam.Trajectory();
  ASSERT_EQ(traj.size(), run.utimes.size());
  double max_err = 0.0, odom_end_err = 0.0;
  for (size_t k = 0; k < traj.size(); ++k) {
    max_err =
        std::max(max_err, (traj[k].T_world_base.translation() - run.truth[k].translation()).norm());
  }
  odom_end_err = (run.odom.back().translation() - run.truth.back().translation()).norm();
  const double end_err =
      (traj.back().T_world_base.translation() - run.truth.back().translation()).norm();
  EXPECT_GT(odom_end_err, 0.5) << "the simulated odometry should drift";
  EXPECT_LT(end_err, 0.1);
  EXPECT_LT(max_err, 0.25);
}

// The two-stage AddScan (pose first, keyframe stage after, as the LCM node runs it) leaves
// the filter exactly where the one-stage call does: the same factors, the same final
// trajectory; only the pose of a scan whose keyframe stage corrected the filter is the
// filter's own (the correction shows at the next scan).
TEST(RbpfSlam, DeferredKeyframeStageGivesTheSameFactorsAndTrajectory) {
  const test::LoopRun run = RoomLoopRun(1);
  const RbpfSlamOptions o = TestOptions(10);
  RbpfSlam once(o), twice(o);
  int factors = 0, pending = 0, corrected = 0;
  for (size_t k = 0; k < run.utimes.size(); ++k) {
    const LaserScan scan = MakeScan(run.utimes[k], run.ranges[k]);
    ScanResult a, b;
    ASSERT_TRUE(once.AddScan(scan, run.odom[k], &a).ok());
    ASSERT_TRUE(twice.AddScan(scan, run.odom[k], &b, /*defer_keyframe=*/true).ok());
    EXPECT_TRUE(b.factors.empty());
    const Pose2 filter_pose = b.T_world_base;
    if (b.keyframe_pending) ++pending;
    twice.FinishScan(&b);
    EXPECT_FALSE(b.keyframe_pending);
    ASSERT_EQ(a.factors.size(), b.factors.size()) << k;
    for (size_t f = 0; f < a.factors.size(); ++f) {
      EXPECT_EQ(a.factors[f].utime_i, b.factors[f].utime_i);
      EXPECT_EQ(a.factors[f].T_i_j.x, b.factors[f].T_i_j.x);
      EXPECT_EQ(a.factors[f].T_i_j.theta, b.factors[f].T_i_j.theta);
    }
    factors += static_cast<int>(a.factors.size());
    EXPECT_EQ(a.T_world_base.x, b.T_world_base.x) << k;
    EXPECT_EQ(a.T_world_base.theta, b.T_world_base.theta) << k;
    if ((filter_pose.translation() - a.T_world_base.translation()).norm() > 1e-9) ++corrected;
  }
  once.Finish();
  twice.Finish();
  EXPECT_GT(factors, 20);
  EXPECT_GT(pending, 20);
  EXPECT_GE(corrected, 1) << "some keyframe stage should have corrected the filter's pose";
  const auto ta = once.Trajectory(), tb = twice.Trajectory();
  ASSERT_EQ(ta.size(), tb.size());
  for (size_t k = 0; k < ta.size(); ++k) {
    EXPECT_EQ(ta[k].T_world_base.x, tb[k].T_world_base.x) << k;
    EXPECT_EQ(ta[k].T_world_base.y, tb[k].T_world_base.y) << k;
  }
}

// The final trajectory gives every scan a pose; a scan the filter did not run on (here three
// scans in four: the filter runs every metre) is blended between the filtered scans around it,
// so the odometry's drift between two filter runs is corrected on it too. (Without the blend
// the final steps' heading error is the online one's, 0.0169 vs 0.0171 rad; with it 0.0063.)
// Mean absolute heading error of each scan's motion from the previous scan, against the truth.
double MeanStepHeadingError(const test::LoopRun& run, const std::vector<Pose2>& poses) {
  double sum = 0.0;
  for (size_t k = 1; k < poses.size(); ++k) {
    const Pose2 e = run.truth[k - 1].between(run.truth[k]).between(poses[k - 1].between(poses[k]));
    sum += std::abs(e.theta);
  }
  return sum / static_cast<double>(poses.size() - 1);
}

// A loop run with strong heading drift (0.05 rad/m) and sparse filter updates (0.9 m, 1 rad),
// so most scans fall between filter runs.
test::LoopRun SparseUpdateRun() {
  test::LoopRunOptions lo;
  lo.step_m = 0.25;
  lo.odom_rot_bias = 0.05;  // [rad/m]
  return test::MakeLoopRun(test::LaserWorld::RoomWithBoxes(), lo);
}

struct SparseUpdateResult {
  std::vector<Pose2> online;       // T_world_base per scan, as AddScan returned it
  std::vector<Pose2> final_poses;  // T_world_base per scan after Finish()
  RbpfSlamStats stats;
};

// refine: refine_scans_with_icp (off by default here: the two tests below are about the
// filter's own placement of the scans between its runs).
SparseUpdateResult RunSparseUpdates(const test::LoopRun& run, bool match_between_updates,
                                    bool refine = false) {
  RbpfSlamOptions o = TestOptions(10);
  o.linear_update = 0.9;
  o.angular_update = 1.0;
  o.max_turn_rate = 0.0;
  o.match_between_updates = match_between_updates;
  o.refine_scans_with_icp = refine;
  RbpfSlam slam(o);
  SparseUpdateResult out;
  Drive(&slam, run, [&](size_t, const ScanResult& r) { out.online.push_back(r.T_world_base); });
  out.stats = slam.stats();
  slam.Finish();
  for (const auto& p : slam.Trajectory()) out.final_poses.push_back(p.T_world_base);
  return out;
}

TEST(RbpfSlam, ScansBetweenFilterRunsAreBlendedIntoTheFinalTrajectory) {
  // Without matching between updates the odometry carries the online pose of the skipped
  // scans; the final trajectory ties them to their keyframes and removes most of that drift.
  const test::LoopRun run = SparseUpdateRun();
  const SparseUpdateResult r = RunSparseUpdates(run, /*match_between_updates=*/false);
  ASSERT_EQ(r.final_poses.size(), run.utimes.size());
  const double online_err = MeanStepHeadingError(run, r.online);
  const double final_err = MeanStepHeadingError(run, r.final_poses);
  EXPECT_LT(final_err, 0.5 * online_err) << "online " << online_err << " final " << final_err;
}

TEST(RbpfSlam, ScansBetweenFilterRunsAreMatchedAloneWhenAsked) {
  // With match_between_updates every scan the filter skips is matched against the best map, so
  // the online pose of those scans follows the truth and not the odometry; the particles
  // themselves are untouched (same keyframe count).
  const test::LoopRun run = SparseUpdateRun();
  const SparseUpdateResult on = RunSparseUpdates(run, true), off = RunSparseUpdates(run, false);
  EXPECT_EQ(off.stats.matched_between_updates, 0);
  EXPECT_GT(on.stats.matched_between_updates, static_cast<int64_t>(run.utimes.size()) / 2);
  EXPECT_EQ(on.stats.processed, off.stats.processed);
  EXPECT_EQ(on.stats.keyframes, off.stats.keyframes);
  const double err_on = MeanStepHeadingError(run, on.online);
  const double err_off = MeanStepHeadingError(run, off.online);
  EXPECT_LT(err_on, 0.5 * err_off) << "matched " << err_on << " odometry " << err_off;
}

// Mean translational error [m] of consecutive scans' relative poses against the truth.
double MeanStepTranslationError(const test::LoopRun& run, const std::vector<Pose2>& poses) {
  double sum = 0.0;
  for (size_t k = 1; k < poses.size(); ++k) {
    const Pose2 e = run.truth[k - 1].between(run.truth[k]).between(poses[k - 1].between(poses[k]));
    sum += std::hypot(e.x, e.y);
  }
  return sum / static_cast<double>(poses.size() - 1);
}

TEST(RbpfSlam, ScanPosesRefinedByIcpAgainstTheirKeyframeAreCloserToTheTruth) {
  // The grid matcher places a scan to about its 5 cm cell; ICP against the keyframe's scan to
  // millimetres. Scan to scan, online and final, both errors fall.
  const test::LoopRun run = SparseUpdateRun();
  const SparseUpdateResult on = RunSparseUpdates(run, true, true);
  const SparseUpdateResult off = RunSparseUpdates(run, true, false);
  EXPECT_EQ(off.stats.scans_refined, 0);
  EXPECT_GT(on.stats.scans_refined, static_cast<int64_t>(run.utimes.size()) / 2);
  EXPECT_EQ(on.stats.processed, off.stats.processed);  // the filter itself is untouched
  for (const auto& [name, a, b] : {std::make_tuple("online", &on.online, &off.online),
                                   std::make_tuple("final", &on.final_poses, &off.final_poses)}) {
    const double t_on = MeanStepTranslationError(run, *a), t_off = MeanStepTranslationError(run, *b);
    const double h_on = MeanStepHeadingError(run, *a), h_off = MeanStepHeadingError(run, *b);
    std::cout << name << ": step error " << t_on << " m, " << h_on << " rad refined; " << t_off
              << " m, " << h_off << " rad not\n";
    EXPECT_LT(t_on, 0.7 * t_off) << name;
    EXPECT_LT(h_on, 0.7 * h_off) << name;
  }
}

// Each scan's index in `run` by its time.
std::map<fl::Utime, size_t> ScanIndex(const test::LoopRun& run) {
  std::map<fl::Utime, size_t> index;
  for (size_t k = 0; k < run.utimes.size(); ++k) index[run.utimes[k]] = k;
  return index;
}

// The room loop scanned with the simulator's 10 cm range noise (or `range_noise`), 10 particles
// with the default free-space margin (for that noise); the sequential factors each scan
// published (loop closures left out), the final trajectory and the stats.
struct FactorRun {
  std::vector<KeyframeFactor> factors;
  std::vector<StampedPose2> trajectory;
  RbpfSlamStats stats;
};
FactorRun RunForFactors(const test::LoopRun& run, double noisy_factor_rms_per_noise) {
  RbpfSlamOptions o;
  o.particles = 10;
  o.graph.noisy_factor_rms_per_noise = noisy_factor_rms_per_noise;
  RbpfSlam slam(o);
  FactorRun out;
  Drive(&slam, run, [&](size_t, const ScanResult& r) {
    for (const KeyframeFactor& f : r.factors) {
      if (!f.is_loop_closure) out.factors.push_back(f);
    }
  });
  slam.Finish();
  out.trajectory = slam.Trajectory();
  out.stats = slam.stats();
  return out;
}

TEST(RbpfSlam, NoisyScansStillGiveTheFusionItsFactors) {
  // At 10 cm range noise a right ICP fit has an RMS of 5-7 cm: most keyframe ICPs fail the
  // 5 cm gate. Those that failed only it, within 0.8x the scan's noise, are published anyway
  // (graph.noisy_factor_rms_per_noise) with their calibrated information; the internal graph,
  // and so the trajectory, are exactly as without them.
  test::LoopRunOptions lo;
  lo.step_m = 0.25;
  lo.range_noise = 0.1;
  const test::LoopRun run = test::MakeLoopRun(test::LaserWorld::RoomWithBoxes(), lo);
  const FactorRun on = RunForFactors(run, RbpfSlamOptions().graph.noisy_factor_rms_per_noise);
  const FactorRun off = RunForFactors(run, 0.0);
  EXPECT_EQ(off.stats.noisy_factors, 0);
  EXPECT_GT(on.stats.noisy_factors, 5);
  EXPECT_EQ(on.factors.size(), off.factors.size() + static_cast<size_t>(on.stats.noisy_factors));
  ASSERT_EQ(on.trajectory.size(), off.trajectory.size());
  for (size_t k = 0; k < on.trajectory.size(); ++k) {
    EXPECT_EQ(on.trajectory[k].T_world_base.x, off.trajectory[k].T_world_base.x) << k;
    EXPECT_EQ(on.trajectory[k].T_world_base.theta, off.trajectory[k].T_world_base.theta) << k;
  }
  // The published factors against the truth: e^T Omega e, median near the calibrated ~2.4.
  const std::map<fl::Utime, size_t> scan_of = ScanIndex(run);
  std::vector<double> chi2;
  for (const KeyframeFactor& f : on.factors) {
    const Pose2 truth = run.truth[scan_of.at(f.utime_i)].between(run.truth[scan_of.at(f.utime_j)]);
    const Pose2 d = truth.between(f.T_i_j);
    const Eigen::Vector3d e(d.x, d.y, d.theta);
    chi2.push_back(e.dot(f.information * e));
  }
  std::nth_element(chi2.begin(), chi2.begin() + static_cast<std::ptrdiff_t>(chi2.size() / 2),
                   chi2.end());
  const double median = chi2[chi2.size() / 2];
  std::cout << "factors " << on.factors.size() << " (noisy " << on.stats.noisy_factors
            << "), chi2 median " << median << "\n";
  EXPECT_GT(median, 0.5);
  EXPECT_LT(median, 8.0);
  // Clean scans (1 cm) never reach it.
  EXPECT_EQ(RunForFactors(RoomLoopRun(1), 0.8).stats.noisy_factors, 0);
}

// A scan delivered after newer ones (delayed by the network beyond the node's merge window) is
// placed by its stamp: from the scan before it by the odometry, refined by ICP against that
// scan's keyframe. Relative to the scan before it, it is placed as accurately as the scans that
// came on time; it enters the final trajectory in time order; the filter is exactly as if it
// had never come.
TEST(RbpfSlam, LateScansArePlacedByTheirStampsWithoutTouchingTheFilter) {
  const test::LoopRun run = RoomLoopRun(1);
  const RbpfSlamOptions o = TestOptions(10);
  RbpfSlam with_late(o), without(o);
  std::vector<size_t> late;  // every 7th scan arrives 3 scans (0.3 s) late
  std::vector<Pose2> online(run.utimes.size());
  for (size_t k = 0; k < run.utimes.size(); ++k) {
    if (k > 5 && k % 7 == 0) {
      late.push_back(k);
    } else {
      ScanResult a, b;
      ASSERT_TRUE(with_late.AddScan(MakeScan(run.utimes[k], run.ranges[k]), run.odom[k], &a).ok());
      ASSERT_TRUE(without.AddScan(MakeScan(run.utimes[k], run.ranges[k]), run.odom[k], &b).ok());
      EXPECT_EQ(a.T_world_base.x, b.T_world_base.x) << k;
      EXPECT_EQ(a.T_world_base.theta, b.T_world_base.theta) << k;
      online[k] = a.T_world_base;
    }
    if (k >= 3 && !late.empty() && late.back() == k - 3) {
      const size_t j = k - 3;
      ASSERT_TRUE(
          with_late.PlaceLateScan(MakeScan(run.utimes[j], run.ranges[j]), run.odom[j], &online[j])
              .ok())
          << j;
    }
  }
  EXPECT_EQ(with_late.stats().late_scans_placed, static_cast<int64_t>(late.size()));
  // The step from the scan before, against the truth's: late scans and the others.
  auto step_error = [&](const std::vector<Pose2>& poses, size_t k) {
    const Pose2 est = poses[k - 1].between(poses[k]), truth = run.truth[k - 1].between(run.truth[k]);
    return std::hypot(est.x - truth.x, est.y - truth.y);
  };
  auto mean_step_errors = [&](const std::vector<Pose2>& poses, double* on_late, double* on_time) {
    double sum_late = 0.0, sum_time = 0.0;
    for (size_t k = 1; k < poses.size(); ++k) {
      const bool is_late = std::find(late.begin(), late.end(), k) != late.end();
      (is_late ? sum_late : sum_time) += step_error(poses, k);
    }
    *on_late = sum_late / static_cast<double>(late.size());
    *on_time = sum_time / static_cast<double>(poses.size() - 1 - late.size());
  };
  double online_late, online_time;
  mean_step_errors(online, &online_late, &online_time);
  // Refused and counted: a stamp already taken, one older than late_scan_max_age_s, one that is
  // not late. Nothing changes.
  Pose2 T;
  const size_t n = run.utimes.size() - 1;
  EXPECT_FALSE(with_late
                   .PlaceLateScan(MakeScan(run.utimes[n - 1], run.ranges[n - 1]), run.odom[n - 1],
                                  &T)
                   .ok());
  EXPECT_FALSE(
      with_late.PlaceLateScan(MakeScan(run.utimes[1], run.ranges[1]), run.odom[1], &T).ok());
  EXPECT_FALSE(
      with_late
          .PlaceLateScan(MakeScan(run.utimes[n] + 100000, run.ranges[n]), run.odom[n], &T)
          .ok());
  EXPECT_EQ(with_late.stats().dropped_time_backwards, 3);
  EXPECT_EQ(with_late.stats().late_scans_placed, static_cast<int64_t>(late.size()));
  with_late.Finish();
  without.Finish();
  EXPECT_EQ(with_late.stats().keyframes, without.stats().keyframes);
  EXPECT_EQ(with_late.stats().processed, without.stats().processed);
  EXPECT_EQ(with_late.CurrentPose().x, without.CurrentPose().x);
  const auto traj = with_late.Trajectory();
  ASSERT_EQ(traj.size(), run.utimes.size());
  ASSERT_EQ(without.Trajectory().size(), run.utimes.size() - late.size());
  std::vector<Pose2> final_poses;
  for (size_t k = 0; k < traj.size(); ++k) {
    EXPECT_EQ(traj[k].utime, run.utimes[k]);  // in time order, the late ones in their place
    final_poses.push_back(traj[k].T_world_base);
  }
  double final_late, final_time;
  mean_step_errors(final_poses, &final_late, &final_time);
  std::cout << "step error online: late scans " << online_late << " m, on time " << online_time
            << " m; final: " << final_late << " m, " << final_time << " m\n";
  // Online, a late pose is in the map as the graph has corrected it since the scan before it
  // was published (0.3 s earlier), hence the looser bound; final, both in the same map.
  EXPECT_LT(online_late, std::max(0.01, 2.0 * online_time));
  EXPECT_LT(final_late, std::max(0.01, 1.5 * final_time));
}

TEST(RbpfSlam, LoopClosureSpacingSkipsTheSearchAfterAClosure) {
  // Two laps: on the second, nearly every keyframe could close a loop. With spacing 4 the
  // closures' keyframes are at least 4 apart; with the default (1) some are closer.
  const test::LoopRun run = RoomLoopRun(2);
  auto closure_keyframes = [&](int spacing, RbpfSlamStats* stats) {
    RbpfSlamOptions o = TestOptions(10);
    o.graph.loop_closure_spacing = spacing;
    o.graph.reuse_distance = 0.0;  // every keyframe of the second lap is new and may close
    RbpfSlam slam(o);
    std::vector<int> kf;
    for (size_t k = 0; k < run.utimes.size(); ++k) {
      ScanResult r;
      EXPECT_TRUE(slam.AddScan(MakeScan(run.utimes[k], run.ranges[k]), run.odom[k], &r).ok());
      for (const KeyframeFactor& f : r.factors) {
        if (f.is_loop_closure && (kf.empty() || kf.back() != f.keyframe_j)) {
          kf.push_back(f.keyframe_j);
        }
      }
    }
    *stats = slam.stats();
    return kf;
  };
  RbpfSlamStats every, spaced;
  const std::vector<int> kf_every = closure_keyframes(1, &every);
  const std::vector<int> kf_spaced = closure_keyframes(4, &spaced);
  int min_gap_every = 1 << 30, min_gap_spaced = 1 << 30;
  for (size_t i = 1; i < kf_every.size(); ++i) {
    min_gap_every = std::min(min_gap_every, kf_every[i] - kf_every[i - 1]);
  }
  for (size_t i = 1; i < kf_spaced.size(); ++i) {
    min_gap_spaced = std::min(min_gap_spaced, kf_spaced[i] - kf_spaced[i - 1]);
  }
  ASSERT_GE(kf_every.size(), 6u);
  ASSERT_GE(kf_spaced.size(), 3u) << "spaced search should still close the loop";
  EXPECT_LT(min_gap_every, 4);
  EXPECT_GE(min_gap_spaced, 4);
  EXPECT_LT(spaced.loop_candidates, every.loop_candidates);
}

// Laps of a mapped loop: with keyframe reuse (the default) the keyframes stop growing after
// the first lap, once the first return has closed the loop (reuse waits for it); without it
// every lap adds a lap of keyframes. The reuse factors measure
// the scan against the old keyframe (checked against the truth) and the final trajectory is as
// good as without reuse.
TEST(RbpfSlam, RevisitsReuseKeyframesAndTheGraphStopsGrowing) {
  const int laps = 4;
  const test::LoopRun run = RoomLoopRun(laps);
  const size_t per_lap = run.utimes.size() / laps;
  const std::map<fl::Utime, size_t> index = ScanIndex(run);
  struct Outcome {
    std::vector<int64_t> keyframes_after_lap;
    RbpfSlamStats stats;
    double max_err = 0.0;
    int reuse_factors = 0;
    double worst_reuse_factor_err_m = 0.0;
  };
  auto drive = [&](double reuse_distance) {
    RbpfSlamOptions o = TestOptions(10);
    o.graph.reuse_distance = reuse_distance;
    RbpfSlam slam(o);
    Outcome out;
    Drive(&slam, run, [&](size_t k, const ScanResult& r) {
      for (const KeyframeFactor& f : r.factors) {
        EXPECT_LT(f.utime_i, f.utime_j);
        EXPECT_GT(f.information.determinant(), 0.0);
        if (f.keyframe_j >= 0) continue;
        ++out.reuse_factors;
        EXPECT_TRUE(f.is_loop_closure);
        EXPECT_EQ(f.utime_j, run.utimes[k]) << "a reuse factor ends at its scan";
        const fl::Pose2 truth =
            run.truth[index.at(f.utime_i)].between(run.truth[index.at(f.utime_j)]);
        out.worst_reuse_factor_err_m = std::max(
            out.worst_reuse_factor_err_m, (truth.translation() - f.T_i_j.translation()).norm());
      }
      if ((k + 1) % per_lap == 0) out.keyframes_after_lap.push_back(slam.stats().keyframes);
    });
    slam.Finish();
    out.stats = slam.stats();
    const auto traj = slam.Trajectory();
    EXPECT_EQ(traj.size(), run.utimes.size());
    for (size_t k = 0; k < traj.size(); ++k) {
      out.max_err = std::max(
          out.max_err, (traj[k].T_world_base.translation() - run.truth[k].translation()).norm());
    }
    return out;
  };
  const Outcome reuse = drive(RbpfSlamOptions().graph.reuse_distance);
  const Outcome all = drive(0.0);
  ASSERT_EQ(reuse.keyframes_after_lap.size(), static_cast<size_t>(laps));
  const int64_t first_lap = reuse.keyframes_after_lap[0];
  // Without reuse each lap adds about a lap of keyframes.
  EXPECT_GT(all.keyframes_after_lap.back(), 3 * first_lap);
  EXPECT_EQ(all.stats.keyframe_reuses, 0);
  EXPECT_EQ(all.reuse_factors, 0);
  // With it (84, 85, 85, 85 here), laps 2-4 together add under a tenth of the first lap's ...
  EXPECT_LT(reuse.keyframes_after_lap.back() - first_lap, first_lap / 10)
      << "keyframes per lap: " << reuse.keyframes_after_lap[0] << " "
      << reuse.keyframes_after_lap[1] << " " << reuse.keyframes_after_lap[2] << " "
      << reuse.keyframes_after_lap[3];
  // ... and the last lap almost none.
  EXPECT_LE(reuse.keyframes_after_lap[3] - reuse.keyframes_after_lap[2], 2);
  EXPECT_GT(reuse.stats.keyframe_reuses, 2 * first_lap);
  EXPECT_EQ(reuse.reuse_factors, reuse.stats.keyframe_reuses);
  EXPECT_LT(reuse.worst_reuse_factor_err_m, 0.1);
  // The first return still closed the loop.
  EXPECT_GE(reuse.stats.loop_closures, 1);
  EXPECT_LT(reuse.max_err, 0.25);
  EXPECT_LT(reuse.max_err, all.max_err + 0.05);
}

// Laps of a mapped loop where no reuse verifies (here forced: a reuse may correct the filter by
// 0.1 mm at most; in the simulator, 10 cm range noise puts the ICP RMS over the loop limit):
// without the density bound every lap adds a lap of keyframes; with it
// (graph.max_keyframes_per_place) a place holds at most about that many keyframes of earlier
// passes, so the keyframes stop growing once every place of the loop is full, and the filter
// anchored to the existing keyframes stays as accurate.
TEST(RbpfSlam, FullPlacesGetNoMoreKeyframesWhenReuseFails) {
  const int laps = 6;
  const test::LoopRun run = RoomLoopRun(laps);
  const size_t per_lap = run.utimes.size() / laps;
  struct Outcome {
    std::vector<int64_t> keyframes_after_lap;
    RbpfSlamStats stats;
    double max_err = 0.0;
    int factors_to_scans = 0;  // factors whose end is a scan, not a keyframe (reuses)
  };
  auto drive = [&](int max_per_place) {
    RbpfSlamOptions o = TestOptions(10);
    o.graph.reuse_max_correction_m = 1e-4;
    o.graph.reuse_max_correction_rad = 1e-4;
    o.graph.max_keyframes_per_place = max_per_place;
    RbpfSlam slam(o);
    Outcome out;
    Drive(&slam, run, [&](size_t k, const ScanResult& r) {
      for (const KeyframeFactor& f : r.factors) {
        EXPECT_LT(f.utime_i, f.utime_j);
        if (f.keyframe_j < 0) ++out.factors_to_scans;
      }
      if ((k + 1) % per_lap == 0) out.keyframes_after_lap.push_back(slam.stats().keyframes);
    });
    slam.Finish();
    out.stats = slam.stats();
    const auto traj = slam.Trajectory();
    EXPECT_EQ(traj.size(), run.utimes.size()) << "every scan keeps a final pose";
    for (size_t k = 0; k < traj.size(); ++k) {
      out.max_err = std::max(
          out.max_err, (traj[k].T_world_base.translation() - run.truth[k].translation()).norm());
    }
    return out;
  };
  const Outcome unbounded = drive(0);
  const Outcome bounded = drive(4);
  ASSERT_EQ(bounded.keyframes_after_lap.size(), static_cast<size_t>(laps));
  const int64_t first_lap = unbounded.keyframes_after_lap[0];
  // Nothing verifies: without the bound every lap adds about a lap of keyframes.
  EXPECT_EQ(unbounded.stats.keyframe_reuses, 0);
  EXPECT_EQ(unbounded.stats.keyframes_bounded, 0);
  EXPECT_GT(unbounded.keyframes_after_lap.back(), (laps - 1) * first_lap);
  // With it, the places fill in the first passes (84, 174, 228, 250, 256, 258 here: each lap
  // adds fewer, as fewer places have room) and the last lap adds almost nothing.
  const auto& b = bounded.keyframes_after_lap;
  const std::string per_lap_text = std::to_string(b[0]) + " " + std::to_string(b[1]) + " " +
                                   std::to_string(b[2]) + " " + std::to_string(b[3]) + " " +
                                   std::to_string(b[4]) + " " + std::to_string(b[5]);
  EXPECT_LE(b[laps - 1] - b[laps - 2], first_lap / 20) << "keyframes after each lap: " << per_lap_text;
  EXPECT_LT(b.back(), 3.5 * first_lap) << per_lap_text;
  EXPECT_GT(bounded.stats.keyframes_bounded, 2 * first_lap);
  EXPECT_EQ(bounded.stats.keyframe_reuses, 0);
  EXPECT_EQ(bounded.factors_to_scans, 0) << "an unverified anchor publishes no factor";
  // Anchoring to the existing keyframes keeps the trajectory as good.
  EXPECT_LT(bounded.max_err, 0.25);
  EXPECT_LT(bounded.max_err, unbounded.max_err + 0.05)
      << "bounded " << bounded.max_err << " m, unbounded " << unbounded.max_err << " m";
}

TEST(RbpfSlam, FilterEdgeHoldsEachKeyframeWhereTheFilterPutIt) {
  // The first 10 m of the loop (no loop closure yet, so no optimisation moves a keyframe): next
  // to each successful sequential ICP edge there is a filter edge with the filter's relative
  // pose at the time and the documented std for the odometry's motion (d, dθ) between the two
  // keyframes: k (srr d + srt |dθ|) in x and y, k (stt |dθ| + str d) in heading, at least the
  // minimum.
  const test::LoopRun run = RoomLoopRun(1);
  for (bool filter_edges : {true, false}) {
    RbpfSlamOptions o = TestOptions(5);
    o.graph.filter_edges = filter_edges;
    RbpfSlam slam(o);
    std::vector<fl::Pose2> created;  // each keyframe's pose when it was created
    std::vector<fl::Pose2> odom;     // ... and the odometry then
    for (size_t k = 0; k < 40; ++k) {
      ScanResult r;
      ASSERT_TRUE(slam.AddScan(MakeScan(run.utimes[k], run.ranges[k]), run.odom[k], &r).ok());
      if (r.new_keyframe) {
        created.push_back(slam.KeyframePoses().back().T_world_base);
        odom.push_back(run.odom[k]);
      }
    }
    ASSERT_EQ(slam.stats().loop_closures, 0);
    ASSERT_GE(created.size(), 10u);
    const PoseGraph2D& g = slam.graph();
    ASSERT_EQ(g.num_nodes(), static_cast<int>(created.size()));
    int filter = 0, pairs = 0;  // filter edges, consecutive keyframe pairs
    for (int j = 1; j < g.num_nodes(); ++j) {
      std::vector<const PoseGraphEdge*> between;
      for (const PoseGraphEdge& e : g.edges()) {
        if (e.i == j - 1 && e.j == j) between.push_back(&e);
      }
      ASSERT_GE(between.size(), 1u);
      ASSERT_LE(between.size(), filter_edges ? 2u : 1u);
      ++pairs;
      if (between.size() < 2) continue;
      const PoseGraphEdge& fe = *between[1];
      const fl::Pose2 rel = created[j - 1].between(created[j]);
      EXPECT_NEAR(fe.T_i_j.x, rel.x, 1e-9);
      EXPECT_NEAR(fe.T_i_j.y, rel.y, 1e-9);
      EXPECT_NEAR(fe.T_i_j.theta, rel.theta, 1e-9);
      const fl::Pose2 moved = odom[j - 1].between(odom[j]);
      const double d = std::hypot(moved.x, moved.y), a = std::abs(moved.theta);
      const double k = o.graph.filter_edge_sigma_scale;
      const double s_xy =
          std::max(k * (o.motion.srr * d + o.motion.srt * a), o.graph.filter_edge_min_sigma_m);
      const double s_th =
          std::max(k * (o.motion.stt * a + o.motion.str * d), o.graph.filter_edge_min_sigma_rad);
      EXPECT_NEAR(fe.information(0, 0), 1.0 / (s_xy * s_xy), 1e-6);
      EXPECT_NEAR(fe.information(1, 1), 1.0 / (s_xy * s_xy), 1e-6);
      EXPECT_NEAR(fe.information(2, 2), 1.0 / (s_th * s_th), 1e-6);
      EXPECT_DOUBLE_EQ(fe.huber_scale, o.graph.filter_edge_huber);
      EXPECT_FALSE(fe.loop_closure);
      ++filter;
    }
    if (filter_edges) {
      EXPECT_GE(filter, pairs - 2) << "every keyframe pair whose ICP succeeded";
      EXPECT_GE(filter, 8);
    } else {
      EXPECT_EQ(filter, 0);
    }
  }
}

TEST(RbpfSlam, DivergedFilterIsCaughtByIcpFromOdometry) {
  // Nearly exact odometry, but a one-particle filter whose motion model samples heading errors
  // of ~0.1 rad per step and whose matcher may correct only 0.01 rad: the filter drifts away
  // from the truth (metres). ICP started from the odometry's relative pose fits the keyframes
  // better than ICP from the filter's, so the check overrules the filter. The scenario is
  // chaotic (one bad keyframe spoils the rest), so the test looks at the median of five seeds:
  // with the check most seeds stay within decimetres (2026-11-30: 0.13-0.15 m on three of five,
  // 2.3 and 3.6 m on the others), without it none does (6-23 m). The lost-track search, a second
  // safety net for the same failure, is off in both runs.
  const test::LoopRun run = NearExactOdometryLoop();
  auto max_error = [&](bool check, int seed, RbpfSlamStats* stats) {
    RbpfSlamOptions o = CrippledFilterOptions(seed, 0.4);  // ~0.1 rad per 0.25 m step
    o.graph.divergence_check = check;
    o.graph.recovery_search.enabled = false;  // the other safety net (tested on its own)
    return MaxTrajectoryError(o, run, stats);
  };
  std::vector<double> with, without;
  for (int seed : {1, 2, 3, 4, 42}) {
    RbpfSlamStats with_check, without_check;
    with.push_back(max_error(true, seed, &with_check));
    without.push_back(max_error(false, seed, &without_check));
    EXPECT_EQ(without_check.divergences, 0);
    EXPECT_GE(with_check.divergences, 10);
  }
  std::sort(with.begin(), with.end());
  std::sort(without.begin(), without.end());
  EXPECT_GT(without[2], 5.0) << "the crippled filter should drift";
  EXPECT_LT(with[2], 0.5) << "median of five seeds";
  EXPECT_GT(without[0], 1.0) << "no seed should stay on track without the check";
}

// A drive of `length` m along the axis of a smooth-walled corridor (LaserWorld::Corridor,
// 60 m x 2.5 m) at 0.07 m per scan, with the simulator's laser (341 beams over 240°, 10 m
// range, 10 cm range noise) and its odometry noise (5 cm per sqrt(m)).
constexpr double kCorridorRad0 = -120.0 * M_PI / 180;
constexpr double kCorridorRadStep = 240.0 * M_PI / 180 / 340;
test::LoopRun FeaturelessCorridorRun(double length, unsigned seed) {
  std::vector<fl::Pose2> path;
  for (double x = 2.0; x <= 2.0 + length; x += 0.07) path.emplace_back(x, 0.0, 0.0);
  test::LoopRunOptions lo;
  lo.beams = 341;
  lo.rad0 = kCorridorRad0;
  lo.radstep = kCorridorRadStep;
  lo.max_range = 10.0;
  lo.range_noise = 0.1;
  lo.odom_trans_noise = 0.05;
  lo.odom_rot_noise = 0.005;
  lo.odom_rot_bias = 0.0;
  lo.seed = seed;
  return test::MakePathRun(test::LaserWorld::Corridor(60.0, 2.5), path, lo);
}

// The final trajectory's distance along the corridor over the odometry's, for the options o
// (10 particles, filter seed `seed`) on `run`.
double CorridorDistanceKept(const test::LoopRun& run, unsigned seed, RbpfSlamOptions o,
                            RbpfSlamStats* stats) {
  o.particles = 10;
  o.seed = static_cast<int>(seed);
  RbpfSlam slam(o);
  for (size_t k = 0; k < run.utimes.size(); ++k) {
    ScanResult r;
    EXPECT_TRUE(
        slam.AddScan(MakeScan(run.utimes[k], run.ranges[k], kCorridorRad0, kCorridorRadStep),
                     run.odom[k], &r)
            .ok());
  }
  slam.Finish();
  *stats = slam.stats();
  const auto traj = slam.Trajectory();
  const double odom = run.odom.front().between(run.odom.back()).x;
  return (traj.back().T_world_base.x - traj.front().T_world_base.x) / odom;
}

TEST(RbpfSlam, FilterKeepsTheOdometrysMotionAlongAFeaturelessCorridor) {
  // Along the corridor's axis the scans say nothing; the likelihood field pulls the filter
  // toward the edge of its map, so that without the odometry check the filter covers about
  // half the distance the odometry (and the truth) cover (2026-12-06, seeds 1-3: 46-59 %).
  // With it, each keyframe whose motion is unlikely under the motion model while ICP from the
  // odometry fits about as well keeps the odometry's motion (81-85 %; the rest is ICP's own
  // slide on the noisy walls, where both ICPs fail their start check and nothing is decided).
  double with_sum = 0.0, without_sum = 0.0;
  for (unsigned seed : {1u, 2u, 3u}) {
    const test::LoopRun run = FeaturelessCorridorRun(40.0, seed);
    ASSERT_NEAR(run.odom.front().between(run.odom.back()).x, 40.0, 1.0);
    auto travelled = [&](double chi2, RbpfSlamStats* stats) {
      RbpfSlamOptions o;
      o.graph.divergence_odometry_chi2 = chi2;
      o.graph.degenerate_from_odometry = false;  // the check alone (next test: with it)
      return CorridorDistanceKept(run, seed, o, stats);
    };
    RbpfSlamStats with_check, without_check;
    const double with = travelled(RbpfSlamOptions().graph.divergence_odometry_chi2, &with_check);
    const double without = travelled(0.0, &without_check);
    EXPECT_GT(with, without + 0.15) << "seed " << seed;
    EXPECT_GT(with_check.divergences, without_check.divergences + 10) << "seed " << seed;
    with_sum += with;
    without_sum += without;
  }
  EXPECT_GT(with_sum / 3, 0.75) << "fraction of the odometry's distance, mean of 3 seeds";
  EXPECT_LT(without_sum / 3, 0.65) << "the slide this check is for";
}

TEST(RbpfSlam, KeyframesKeepTheOdometrysMotionAlongACorridorsUnseenAxis) {
  // With the noise-wide normals (icp.normal_radius_per_noise) ICP sees that the corridor's axis
  // is unconstrained (its own normals, fitted within 0.3 m of 10 cm noise, said otherwise), and
  // each keyframe takes the odometry's motion along it (graph.degenerate_from_odometry): the
  // filter covers 93-96 % of the odometry's distance instead of 81-85 % (2026-12-06, seeds 1-3;
  // the rest: keyframes whose ICP fails the RMS gate, 6-9 of 44, keep the filter's motion).
  double with_sum = 0.0, without_sum = 0.0;
  for (unsigned seed : {1u, 2u, 3u}) {
    const test::LoopRun run = FeaturelessCorridorRun(40.0, seed);
    auto travelled = [&](bool keep, RbpfSlamStats* stats) {
      RbpfSlamOptions o;
      o.graph.degenerate_from_odometry = keep;
      return CorridorDistanceKept(run, seed, o, stats);
    };
    RbpfSlamStats with_stats, without_stats;
    const double with = travelled(true, &with_stats);
    const double without = travelled(false, &without_stats);
    std::cout << "seed " << seed << ": " << with << " of the odometry's distance kept, "
              << without << " without (" << with_stats.degenerate_kept << " of "
              << with_stats.keyframes << " keyframes moved, ICP failed at "
              << with_stats.icp_failures << ")\n";
    EXPECT_GT(with_stats.degenerate_kept, with_stats.keyframes / 2) << "seed " << seed;
    EXPECT_EQ(without_stats.degenerate_kept, 0);
    EXPECT_GT(with, without + 0.05) << "seed " << seed;
    with_sum += with;
    without_sum += without;
  }
  EXPECT_GT(with_sum / 3, 0.91) << "fraction of the odometry's distance, mean of 3 seeds";
  EXPECT_LT(with_sum / 3, 1.03) << "no overshoot either";
  EXPECT_LT(without_sum / 3, 0.88);
}

TEST(RbpfSlam, LostTrackAfterAnOdometrySlipIsFoundOnTheMap) {
  // Good odometry except one step whose heading is 0.45 rad off (a wheel slip), more than the
  // matcher may correct (0.35 rad): the filter follows the odometry and is lost, and the
  // divergence check sees nothing (filter and odometry agree). ICP against the previous
  // keyframe fails; the correlative search finds where the scan fits, the map confirms it, and
  // the filter is moved there. Without the search the rest of the loop is rotated by the slip.
  const test::LaserWorld world = test::LaserWorld::RoomWithBoxes();
  test::LoopRunOptions lo;
  lo.odom_trans_noise = 0.005;
  lo.odom_rot_noise = 0.002;
  lo.odom_rot_bias = 0.0;
  test::LoopRun run = test::MakeLoopRun(world, lo);
  const size_t slip_at = 40;  // mid-way along the first corridor
  const fl::Pose2 before_slip = run.odom[slip_at - 1];
  for (size_t k = slip_at; k < run.odom.size(); ++k) {
    run.odom[k] = before_slip * fl::Pose2(0.0, 0.0, 0.45) * before_slip.between(run.odom[k]);
  }
  auto max_error = [&](bool search, RbpfSlamStats* stats) {
    RbpfSlamOptions o = TestOptions(5);
    o.graph.recovery_search.enabled = search;
    // The slip's scan goes to the filter (the turn gate would hold it back: 4.5 rad/s).
    o.max_turn_rate = 0.0;
    return MaxTrajectoryError(o, run, stats);
  };
  RbpfSlamStats with_stats, without_stats;
  const double with_search = max_error(true, &with_stats);
  const double without_search = max_error(false, &without_stats);
  EXPECT_GT(without_search, 1.0) << "the slip should leave the filter lost";
  EXPECT_EQ(without_stats.recoveries, 0);
  EXPECT_GE(with_stats.recoveries, 1);
  EXPECT_LT(with_search, 0.3);
}

TEST(RbpfSlam, LostTrackSearchAlsoLooksAroundTheOdometry) {
  // Nearly exact odometry, but a one-particle filter whose motion model samples heading errors
  // of ~0.25 rad per step and whose matcher may correct only 0.01 rad: the filter's relative
  // pose between keyframes is often more than the search's ±0.5 rad from the truth, and ICP
  // from it fails. The search around the filter's relative pose then misses the truth; the one
  // around the odometry's finds it. (On csail-corrected, the keyframe after the log's 0.36 rad
  // heading error is such a case.) The divergence check, the other safety net, is off. The
  // scenario is chaotic (one keyframe placed wrong spoils the rest), so the test looks at the
  // median of five seeds (2026-12-01: with the odometry's search 0.13, 0.24, 0.86, 1.5, 5.2 m;
  // without it 11-36 m).
  const test::LoopRun run = NearExactOdometryLoop();
  auto max_error = [&](bool from_odometry, int seed, RbpfSlamStats* stats) {
    RbpfSlamOptions o = CrippledFilterOptions(seed, 1.0);  // ~0.25 rad per 0.25 m step
    o.graph.divergence_check = false;
    o.graph.recovery_search_from_odometry = from_odometry;
    return MaxTrajectoryError(o, run, stats);
  };
  std::vector<double> with, without;
  for (int seed : {1, 2, 3, 4, 5}) {
    RbpfSlamStats with_stats, without_stats;
    with.push_back(max_error(true, seed, &with_stats));
    without.push_back(max_error(false, seed, &without_stats));
    EXPECT_GT(with_stats.recoveries, without_stats.recoveries) << "seed " << seed;
    EXPECT_LT(with.back(), without.back()) << "seed " << seed;
  }
  std::sort(with.begin(), with.end());
  std::sort(without.begin(), without.end());
  EXPECT_LT(with[2], 2.0) << "median of five seeds";
  EXPECT_GT(without[2], 5.0) << "the crippled filter should drift";
}

TEST(RbpfSlam, ScansTakenInFastTurnsWaitForTheNextScan) {
  // The loop's corners are turns in place at 1.5 rad/s (0.15 rad per scan at 10 Hz). With
  // max_turn_rate 1 rad/s the filter uses none of those scans: the turn's odometry accumulates
  // and the first scan after it is matched with the whole turn as its motion. The loop must
  // still close.
  const test::LoopRun run = RoomLoopRun(1);
  RbpfSlamOptions o = TestOptions(10);
  ASSERT_EQ(o.max_turn_rate, 1.0);  // the default
  RbpfSlam slam(o);
  int fast = 0;
  for (size_t k = 0; k < run.utimes.size(); ++k) {
    ScanResult r;
    ASSERT_TRUE(slam.AddScan(MakeScan(run.utimes[k], run.ranges[k]), run.odom[k], &r).ok());
    if (k > 0 && std::abs(run.odom[k - 1].between(run.odom[k]).theta) > 0.1) {  // > 1 rad/s
      ++fast;
      EXPECT_FALSE(r.processed) << "scan " << k << " was taken in a fast turn";
    }
  }
  slam.Finish();
  EXPECT_GT(fast, 20);
  EXPECT_GT(slam.stats().skipped_fast_turn, 20);
  EXPECT_LE(slam.stats().skipped_fast_turn, fast);
  EXPECT_GE(slam.stats().loop_closures, 1);
  const auto traj = slam.Trajectory();
  double max_err = 0.0;
  for (size_t k = 0; k < traj.size(); ++k) {
    max_err =
        std::max(max_err, (traj[k].T_world_base.translation() - run.truth[k].translation()).norm());
  }
  EXPECT_LT(max_err, 0.3);
}

TEST(RbpfSlam, ScansInAndAfterFastTurnsArePlacedByASearchWhenTheOdometrysHeadingIsOff) {
  // The odometry's heading leads the laser by two scans (0.3 rad in the corners' turns in
  // place): in and after each turn the filter's pose is off by more than the refinement may
  // correct. The turn search finds those scans on their keyframe's scan (11 of them in the
  // four corners).
  test::LoopRun run = RoomLoopRun(1);
  test::LeadOdometryHeading(&run, 2);
  struct Out {
    std::vector<Pose2> online, final_poses;
    RbpfSlamStats stats;
  };
  auto run_with = [&](bool search) {
    RbpfSlamOptions o = TestOptions(10);
    o.turn_search.enabled = search;
    RbpfSlam slam(o);
    Out out;
    Drive(&slam, run, [&](size_t, const ScanResult& r) { out.online.push_back(r.T_world_base); });
    slam.Finish();
    out.stats = slam.stats();
    for (const auto& p : slam.Trajectory()) out.final_poses.push_back(p.T_world_base);
    return out;
  };
  const Out on = run_with(true), off = run_with(false);
  EXPECT_EQ(off.stats.turn_searches, 0);
  EXPECT_GE(on.stats.turn_scans_placed, 4);
  EXPECT_LE(on.stats.turn_scans_placed, on.stats.turn_searches);
  EXPECT_EQ(on.stats.processed, off.stats.processed);  // the filter itself is untouched
  for (const auto& [name, a, b] : {std::make_tuple("online", &on.online, &off.online),
                                   std::make_tuple("final", &on.final_poses, &off.final_poses)}) {
    const double h_on = MeanStepHeadingError(run, *a), h_off = MeanStepHeadingError(run, *b);
    std::cout << name << ": step heading error " << h_on << " rad searched, " << h_off
              << " rad not\n";
    EXPECT_LT(h_on, 0.5 * h_off) << name;
  }
}

TEST(RbpfSlam, TurnGateHoldsBackOnlyScansOfADenseStream) {
  // A 0.9 rad turn between two scans is 4.5 rad/s if they are 0.2 s apart (held back) and
  // 1.5 rad/s if they are 0.6 s apart: still over max_turn_rate, but beyond turn_skip_max_gap
  // (0.3 s) the next scan is too far away to wait for, so the filter uses it.
  const test::LaserWorld world = test::LaserWorld::RoomWithBoxes();
  const fl::Pose2 before(-8.5, -4.5, 0.0), after(-8.5, -4.5, 0.9);
  std::mt19937 rng(3);
  const auto scan_before = world.Scan(before, 181, -M_PI / 2, M_PI / 180, 25.0, 0.01, &rng);
  const auto scan_after = world.Scan(after, 181, -M_PI / 2, M_PI / 180, 25.0, 0.01, &rng);
  for (const fl::Utime gap : {fl::Utime{200000}, fl::Utime{600000}}) {
    RbpfSlam slam(TestOptions(2));
    ScanResult r;
    ASSERT_TRUE(slam.AddScan(MakeScan(1000000, scan_before), before, &r).ok());
    ASSERT_TRUE(slam.AddScan(MakeScan(1000000 + gap, scan_after), after, &r).ok());
    EXPECT_EQ(r.processed, gap > 300000) << "gap " << gap << " us";
    EXPECT_EQ(slam.stats().skipped_fast_turn, gap > 300000 ? 0 : 1);
  }
}

TEST(RbpfSlam, NoLoopSearchWhereIcpFailedOnlyOnOverlap) {
  // Two laps of the room: some candidates overlap the new keyframe too little, and ICP from the
  // graph's pose converges near it but fails on the inlier fraction. By default no correlative
  // search follows those; with loop_search_after_partial_overlap they are searched, and every
  // one of those searches fails too (same closures, same searches otherwise).
  const test::LoopRun run = RoomLoopRun(2);
  auto stats = [&](bool search_after_partial_overlap) {
    RbpfSlamOptions o = TestOptions(10);
    o.graph.loop_search_after_partial_overlap = search_after_partial_overlap;
    o.graph.reuse_distance = 0.0;  // every keyframe of the second lap searches for closures
    RbpfSlam slam(o);
    for (size_t k = 0; k < run.utimes.size(); ++k) {
      ScanResult r;
      EXPECT_TRUE(slam.AddScan(MakeScan(run.utimes[k], run.ranges[k]), run.odom[k], &r).ok());
    }
    return slam.stats();
  };
  const RbpfSlamStats skip = stats(false), search = stats(true);
  EXPECT_GE(skip.loop_searches_skipped, 2);
  EXPECT_EQ(search.loop_searches_skipped, 0);
  EXPECT_EQ(search.loop_searches, skip.loop_searches + skip.loop_searches_skipped);
  EXPECT_EQ(search.loop_closures, skip.loop_closures);
  EXPECT_GE(skip.loop_closures, 6);
}

TEST(RbpfSlamBadInput, InvalidBeamsAreIgnored) {
  RbpfSlam slam(TestOptions(2));
  std::vector<float> r(181, 3.0f);
  r[0] = std::numeric_limits<float>::quiet_NaN();
  r[1] = std::numeric_limits<float>::infinity();
  r[2] = 0.0f;
  r[3] = -1.0f;
  r[4] = 80.0f;  // over max_range
  ScanResult res;
  ASSERT_TRUE(slam.AddScan(MakeScan(1000, r), fl::Pose2(), &res).ok());
  EXPECT_EQ(res.valid_beams, 176);
  EXPECT_EQ(slam.stats().invalid_beams, 5);
  // A scan with no valid beam at all is accepted (nothing to match) and does not crash.
  ASSERT_TRUE(
      slam.AddScan(MakeScan(2000, std::vector<float>(181, NAN)), fl::Pose2(0.5, 0, 0), &res).ok());
  EXPECT_EQ(res.valid_beams, 0);
  EXPECT_TRUE(std::isfinite(res.T_world_base.x));
}

TEST(RbpfSlamBadInput, BeamCountChangeIsAnError) {
  RbpfSlam slam(TestOptions(2));
  ASSERT_TRUE(
      slam.AddScan(MakeScan(1000, std::vector<float>(181, 3.0f)), fl::Pose2(), nullptr).ok());
  const Status s =
      slam.AddScan(MakeScan(2000, std::vector<float>(180, 3.0f)), fl::Pose2(), nullptr);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("180 beams"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("181"), std::string::npos);
  EXPECT_EQ(slam.stats().rejected_bad_scan, 1);
  EXPECT_TRUE(
      slam.AddScan(MakeScan(3000, std::vector<float>(181, 3.0f)), fl::Pose2(), nullptr).ok());
}

TEST(RbpfSlamBadInput, TimeGoingBackwardsIsDropped) {
  RbpfSlam slam(TestOptions(2));
  ASSERT_TRUE(
      slam.AddScan(MakeScan(5000, std::vector<float>(181, 3.0f)), fl::Pose2(), nullptr).ok());
  const Status s =
      slam.AddScan(MakeScan(4000, std::vector<float>(181, 3.0f)), fl::Pose2(), nullptr);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("does not come after"), std::string::npos);
  EXPECT_FALSE(
      slam.AddScan(MakeScan(5000, std::vector<float>(181, 3.0f)), fl::Pose2(), nullptr).ok());
  EXPECT_EQ(slam.stats().dropped_time_backwards, 2);
  EXPECT_EQ(slam.stats().scans, 1);
  EXPECT_FALSE(
      slam.AddScan(MakeScan(6000, std::vector<float>(181, 3.0f)), fl::Pose2(NAN, 0, 0), nullptr)
          .ok());
}

TEST(RbpfSlamBadInput, OdometryJumpIsFlaggedAndNotTrusted) {
  const test::LaserWorld world = test::LaserWorld::RoomWithBoxes();
  test::LoopRunOptions lo;
  lo.step_m = 0.2;
  lo.odom_rot_bias = 0.0;
  const test::LoopRun run = test::MakeLoopRun(world, lo);
  RbpfSlam slam(TestOptions(10));
  const fl::Pose2 jump(25.0, -7.0, 1.0);  // the odometry teleports at scan 30
  int flagged = 0;
  for (size_t k = 0; k < 50; ++k) {
    const fl::Pose2 odom = k >= 30 ? jump * run.odom[k] : run.odom[k];
    ScanResult r;
    ASSERT_TRUE(slam.AddScan(MakeScan(run.utimes[k], run.ranges[k]), odom, &r).ok());
    flagged += r.odometry_jump ? 1 : 0;
  }
  EXPECT_EQ(flagged, 1);
  EXPECT_EQ(slam.stats().odometry_jumps, 1);
  // The estimate followed the scans, not the jump.
  const fl::Pose2 est = slam.CurrentPose();
  const fl::Pose2 truth = run.truth[49];
  EXPECT_LT(std::hypot(est.x - truth.x, est.y - truth.y), 0.3);
}

// A laser that stops for 5 s while the robot drives on (1 m/s, round a corner of the loop):
// the odometry's 5 m over the gap is motion, not a jump, and the filter carries on from it.
// (With the jump limits alone, 3 m and 2 rad, the step was replaced by "no motion" plus 0.3 m
// of noise and the scans after the gap matched a wrong place: the fault bench's clock jumps.)
TEST(RbpfSlamBadInput, AGapInTheScansIsNotAnOdometryJump) {
  test::LoopRunOptions lo;
  lo.step_m = 0.1;  // 1 m/s at 10 scans per second
  const test::LoopRun run = test::MakeLoopRun(test::LaserWorld::RoomWithBoxes(), lo);
  ASSERT_GT(run.utimes.size(), 240u);
  const size_t gap_begin = 140, gap_end = 190;  // scans 140..189 never arrive
  double turned = 0.0;
  for (size_t k = gap_begin; k <= gap_end; ++k) {
    turned += std::abs(run.truth[k - 1].between(run.truth[k]).theta);
  }
  ASSERT_GT(turned, 1.0) << "the gap should span a corner";
  RbpfSlam slam(TestOptions(10));
  double worst_after_gap = 0.0, worst_heading_after_gap = 0.0;
  for (size_t k = 0; k < 240; ++k) {
    if (k >= gap_begin && k < gap_end) continue;
    ScanResult r;
    ASSERT_TRUE(slam.AddScan(MakeScan(run.utimes[k], run.ranges[k]), run.odom[k], &r).ok());
    EXPECT_FALSE(r.odometry_jump) << "scan " << k;
    if (k >= gap_end) {
      const fl::Pose2 d = run.truth[k].between(r.T_world_base);
      worst_after_gap = std::max(worst_after_gap, std::hypot(d.x, d.y));
      worst_heading_after_gap = std::max(worst_heading_after_gap, std::abs(d.theta));
    }
  }
  EXPECT_EQ(slam.stats().odometry_jumps, 0);
  // Measured: 0.40 m and 0.07 rad (the odometry's heading error over the gap, in a part of the
  // loop not mapped before); taken for a jump: 4-6 m and 1.56 rad.
  EXPECT_LT(worst_after_gap, 0.5);
  EXPECT_LT(worst_heading_after_gap, 0.1);
}

TEST(RbpfSlamOptions, ValidateNamesTheProblem) {
  RbpfSlamOptions o;
  EXPECT_TRUE(o.Validate().ok());
  o.particles = 0;
  EXPECT_NE(o.Validate().message().find("particles"), std::string::npos);
  o = RbpfSlamOptions();
  o.grid.field_max_distance = 2.0;
  EXPECT_NE(o.Validate().message().find("field_max_distance"), std::string::npos);
  EXPECT_THROW(RbpfSlam bad(o), std::invalid_argument);
  o = RbpfSlamOptions();
  o.icp.degeneracy_ratio = 1.5;
  EXPECT_NE(o.Validate().message().find("icp.degeneracy_ratio"), std::string::npos);
  o = RbpfSlamOptions();
  o.icp.max_sigma_xy = 0.001;
  EXPECT_NE(o.Validate().message().find("icp.max_sigma_xy"), std::string::npos);
  o = RbpfSlamOptions();
  o.matcher.degeneracy_ratio = -0.1;
  EXPECT_NE(o.Validate().message().find("matcher.degeneracy_ratio"), std::string::npos);
  for (double bad : {-1e-4, 1.0}) {
    o = RbpfSlamOptions();
    o.matcher.function_tolerance = bad;
    EXPECT_NE(o.Validate().message().find("matcher.function_tolerance"), std::string::npos) << bad;
    o = RbpfSlamOptions();
    o.graph.function_tolerance = bad;
    EXPECT_NE(o.Validate().message().find("graph.function_tolerance"), std::string::npos) << bad;
  }
  o = RbpfSlamOptions();
  o.graph.edge_sigma = -1.0;
  EXPECT_NE(o.Validate().message().find("graph.edge_sigma"), std::string::npos);
  o = RbpfSlamOptions();
  o.graph.loop_max_candidates = 0;
  EXPECT_NE(o.Validate().message().find("graph.loop_max_candidates"), std::string::npos);
  o = RbpfSlamOptions();
  o.graph.loop_closure_spacing = 0;
  EXPECT_NE(o.Validate().message().find("graph.loop_closure_spacing"), std::string::npos);
  o = RbpfSlamOptions();
  o.graph.loop_search.sigma = 0.0;
  EXPECT_NE(o.Validate().message().find("graph.loop_search.sigma"), std::string::npos);
  o = RbpfSlamOptions();
  o.turn_search.linear_window = -0.1;
  EXPECT_NE(o.Validate().message().find("turn_search.linear_window"), std::string::npos);
  o = RbpfSlamOptions();
  o.turn_search_after_s = -1.0;
  EXPECT_NE(o.Validate().message().find("turn_search_after_s"), std::string::npos);
  o = RbpfSlamOptions();
  o.graph.divergence_min_gain = 1.5;
  EXPECT_NE(o.Validate().message().find("graph.divergence_min_gain"), std::string::npos);
  o = RbpfSlamOptions();
  o.graph.divergence_odometry_chi2 = -1.0;
  EXPECT_NE(o.Validate().message().find("graph.divergence_odometry_chi2"), std::string::npos);
  o = RbpfSlamOptions();
  o.graph.divergence_odometry_rms_ratio = 0.0;
  EXPECT_NE(o.Validate().message().find("graph.divergence_odometry_rms_ratio"), std::string::npos);
  // The two correlative searches are named apart.
  o = RbpfSlamOptions();
  o.graph.recovery_search.linear_window = 0.0;
  EXPECT_NE(o.Validate().message().find("graph.recovery_search.linear_window"), std::string::npos);
  o = RbpfSlamOptions();
  o.graph.filter_edge_min_sigma_m = 0.0;
  EXPECT_NE(o.Validate().message().find("graph.filter_edge_min_sigma_m"), std::string::npos);
  o = RbpfSlamOptions();
  o.graph.filter_edge_sigma_scale = -2.0;
  EXPECT_NE(o.Validate().message().find("graph.filter_edge_sigma_scale"), std::string::npos);
  o = RbpfSlamOptions();
  o.graph.recovery_min_gain = -1.0;
  EXPECT_NE(o.Validate().message().find("graph.recovery_min_gain"), std::string::npos);
  // Nested keys load from YAML; unknown nested keys are rejected.
  const RbpfSlamOptions y = fl::LoadYamlString<RbpfSlamOptions>(
      "graph:\n  loop_search:\n    linear_window: 1.5\n  divergence_check: false\n");
  EXPECT_DOUBLE_EQ(y.graph.loop_search.linear_window, 1.5);
  EXPECT_DOUBLE_EQ(y.graph.recovery_search.linear_window, 0.5);  // its own defaults
  EXPECT_FALSE(y.graph.divergence_check);
  EXPECT_THROW(fl::LoadYamlString<RbpfSlamOptions>("graph:\n  loop_search:\n    window: 1\n"),
               fl::ConfigError);
}

TEST(RbpfSlamOptions, ConfigFileLoadsAndMatchesDefaults) {
  const std::string path = std::string(FL_SOURCE_DIR) + "/config/rbpf_slam.yaml";
  const RbpfSlamOptions o = fl::LoadYamlFile<RbpfSlamOptions>(path);
  EXPECT_EQ(fl::SaveYamlString(o), fl::SaveYamlString(RbpfSlamOptions()));
  EXPECT_THROW(fl::LoadYamlString<RbpfSlamOptions>("particle: 30\n"), fl::ConfigError);
}

}  // namespace
}  // namespace fl::rbpf
