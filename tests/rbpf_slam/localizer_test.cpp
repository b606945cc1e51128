// Monte Carlo localization on a saved map (localizer.hpp): a simulated world is mapped by the
// SLAM, the map goes through the files fl-map-export writes and --localize reads, and another
// run of the same world (another noise seed) is localized on it.
#include "fusionloc/rbpf_slam/localizer.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>

#include "bot_core/planar_lidar_t.hpp"
#include "bot_core/pose_t.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/yaml_options.hpp"
#include "fusionloc/eval/metrics.hpp"
#include "fusionloc/maps/map_export.hpp"
#include "fusionloc/maps/map_load.hpp"
#include "fusionloc/rbpf_slam/localizer_lcm.hpp"
#include "fusionloc/rbpf_slam/rbpf_slam.hpp"
#include "fusionloc/rbpf_slam/rbpf_slam_lcm.hpp"
#include "fusionloc/rbpf_slam/scan_matcher.hpp"
#include "fusionloc/relative_pose_factor_t.hpp"
#include "fusionloc/status_t.hpp"
#include "fusionloc/wheel_odometry_t.hpp"
#include "laser_fixtures.hpp"
#include "test_paths.hpp"

namespace fl::rbpf {
namespace {

LaserScan MakeScan(fl::Utime t, const std::vector<float>& ranges, const test::LoopRunOptions& o) {
  LaserScan s;
  s.utime = t;
  s.ranges = ranges;
  s.rad0 = o.rad0;
  s.radstep = o.radstep;
  return s;
}

double Ate(const std::vector<fl::Utime>& t, const std::vector<fl::Pose2>& est,
           const std::vector<fl::Pose2>& ref) {
  eval::Trajectory e, r;
  for (size_t k = 0; k < t.size(); ++k) {
    e.push_back({t[k], est[k].ToIsometry3()});
    r.push_back({t[k], ref[k].ToIsometry3()});
  }
  return eval::ComputeAte(e, r, eval::Alignment::kSE2, 1000).trans_m.rmse;
}

// The room (RoomWithBoxes) mapped by the SLAM on one lap (noise seed 7, 10 scans per second at
// 1 m/s), exported to PGM + YAML with SaveOccupancyGrid and loaded back with LoadOccupancyGrid:
// the map a user gets from `fl-map-export` and gives to `fl-rbpf-slam --localize`.
// `slam_ate` (optional): the SLAM's own error on that run (ATE of its final trajectory), how far
// its map is off the truth here and there.
OccupancyMap MappedRoom(double* slam_ate = nullptr) {
  test::LoopRunOptions lo;
  lo.step_m = 0.1;
  lo.seed = 7;
  const test::LoopRun run = test::MakeLoopRun(test::LaserWorld::RoomWithBoxes(), lo);
  RbpfSlamOptions so;
  so.grid.max_range = 25.0;
  RbpfSlam slam(so);
  for (size_t k = 0; k < run.utimes.size(); ++k) {
    ScanResult r;
    EXPECT_TRUE(slam.AddScan(MakeScan(run.utimes[k], run.ranges[k], lo), run.odom[k], &r).ok());
  }
  slam.Finish();
  if (slam_ate) {
    std::vector<fl::Utime> t;
    std::vector<fl::Pose2> est, ref;
    for (const StampedPose2& p : slam.Trajectory()) {
      t.push_back(p.utime);
      est.push_back(p.T_world_base);
      ref.push_back(run.truth[t.size() - 1]);
    }
    *slam_ate = Ate(t, est, ref);
  }
  test::TempDir dir;
  maps::SaveOccupancyGrid(GridToLcm(0, slam.BestMap()), dir.file("room"));
  return OccupancyMapFromLcm(maps::LoadOccupancyGrid(dir.file("room.yaml")));
}

// The room drawn exactly (every wall segment's cells occupied, the inside free): no map error,
// so what is left is the localizer's own.
OccupancyMap ExactRoom() {
  OccupancyMap m;
  m.resolution = 0.05;
  m.origin_x = -11.0;
  m.origin_y = -7.0;
  m.width = 440;
  m.height = 280;
  m.cells.assign(static_cast<size_t>(m.width) * m.height, -1);
  for (int j = 0; j < m.height; ++j) {
    for (int i = 0; i < m.width; ++i) {
      const double x = m.origin_x + (i + 0.5) * m.resolution;
      const double y = m.origin_y + (j + 0.5) * m.resolution;
      if (std::abs(x) < 10.0 && std::abs(y) < 6.0) m.cells[j * m.width + i] = 0;
    }
  }
  const test::LaserWorld world = test::LaserWorld::RoomWithBoxes();
  for (const test::Segment& s : world.segments()) {
    const double len = (s.b - s.a).norm();
    for (double t = 0.0; t <= len; t += 0.01) {
      const Eigen::Vector2d p = s.a + (s.b - s.a) * (t / len);
      const int i = static_cast<int>(std::floor((p.x() - m.origin_x) / m.resolution));
      const int j = static_cast<int>(std::floor((p.y() - m.origin_y) / m.resolution));
      if (i >= 0 && j >= 0 && i < m.width && j < m.height) m.cells[j * m.width + i] = 100;
    }
  }
  return m;
}

// The fixture's laser has 1 cm of range noise: on the right pose a scan fits at -0.01 .. -0.09
// per beam (OnAnExactMapTheErrorIsTheLocalizersOwn), while the pose 3 m ahead in the same
// corridor (AWrongInitialPoseIsRejectedNotFollowed) fits at -0.60 .. -0.92 until it is
// rejected, its walls lining up with the corridor's: the tests use -0.3, midway, rather than
// the default -0.5, which the wrong pose approaches as the filter slides.
LocalizerOptions TestOptions() {
  LocalizerOptions o;
  o.max_range = 25.0;
  o.lost_log_likelihood = -0.3;
  return o;
}

// A localization run: the scans of `run` from index `from` on, with the odometry of `odom`.
struct Output {
  std::vector<fl::Utime> utimes;
  std::vector<fl::Pose2> poses;  // T_map_base at every scan
  std::vector<fl::Pose2> truth;
  std::vector<LocalizationResult> results;
};

Output Localize(MonteCarloLocalizer* loc, const test::LoopRun& run, const test::LoopRunOptions& lo,
                const std::vector<fl::Pose2>& odom,
                const std::function<void(size_t)>& before_scan = {}) {
  Output out;
  for (size_t k = 0; k < run.utimes.size(); ++k) {
    if (before_scan) before_scan(k);
    LocalizationResult r;
    EXPECT_TRUE(loc->AddScan(MakeScan(run.utimes[k], run.ranges[k], lo), odom[k], &r).ok());
    out.utimes.push_back(run.utimes[k]);
    out.poses.push_back(r.T_map_base);
    out.truth.push_back(run.truth[k]);
    out.results.push_back(std::move(r));
  }
  return out;
}

double Distance(const fl::Pose2& a, const fl::Pose2& b) { return std::hypot(a.x - b.x, a.y - b.y); }

// The range of the fits (mean log-likelihood per beam) of the filter updates in [from, to).
std::pair<double, double> FitRange(const Output& out, size_t from, size_t to) {
  double lo = 0.0, hi = -1e9;
  for (size_t k = from; k < to && k < out.results.size(); ++k) {
    if (!out.results[k].processed) continue;
    lo = std::min(lo, out.results[k].fit);
    hi = std::max(hi, out.results[k].fit);
  }
  return {lo, hi};
}

TEST(Localizer, KldBoundGrowsWithTheOccupiedBins) {
  EXPECT_EQ(MonteCarloLocalizer::KldParticleCount(1, 0.05, 2.33), 1);
  // Fox 2003, eq. 13 with k - 1 = 1: 1 / 0.1 * (1 - 2/9 + sqrt(2/9) * 2.33)^3 = 66.03.
  EXPECT_EQ(MonteCarloLocalizer::KldParticleCount(2, 0.05, 2.33), 67);
  int previous = 1;
  for (int bins : {3, 10, 100, 1000}) {
    const int n = MonteCarloLocalizer::KldParticleCount(bins, 0.05, 2.33);
    EXPECT_GT(n, previous);
    previous = n;
  }
  // k - 1 = 999: 9990 * (1 - 2/8991 + sqrt(2/8991) * 2.33)^3 = 11060.9, close to linear in k.
  EXPECT_EQ(MonteCarloLocalizer::KldParticleCount(1000, 0.05, 2.33), 11061);
}

// The resampling stage draws as many particles as the occupied bins need: a spread cloud gets
// many, a tight one the minimum.
TEST(Localizer, KldResamplingAdaptsTheParticleCountToTheCloudsSpread) {
  LocalizerOptions o = TestOptions();
  o.initial_sigma_xy = 2.0;
  o.initial_sigma_theta = 1.0;
  MonteCarloLocalizer spread(o, ExactRoom());
  spread.InitializeAround(fl::Pose2(0.0, -4.5, 0.0));
  EXPECT_EQ(spread.num_particles(), o.min_particles);
  const int n_spread = spread.ResampleKld();
  o.initial_sigma_xy = 0.01;
  o.initial_sigma_theta = 0.01;
  MonteCarloLocalizer tight(o, ExactRoom());
  tight.InitializeAround(fl::Pose2(0.1, -4.4, 0.0));  // inside one 0.25 m, 0.17 rad bin
  const int n_tight = tight.ResampleKld();
  std::printf("KLD resampling: 30 particles spread over 2 m / 1 rad -> %d, within 1 cm -> %d\n",
              n_spread, n_tight);
  EXPECT_GT(n_spread, 300);  // up to 30 bins: the bound for 30 is 496
  EXPECT_LE(n_spread, o.max_particles);
  EXPECT_EQ(n_tight, o.min_particles);
}

TEST(Localizer, OptionsValidateAndTheConfigFileLoads) {
  EXPECT_TRUE(LocalizerOptions().Validate().ok());
  LocalizerOptions o;
  o.max_particles = 10;
  o.min_particles = 20;
  EXPECT_NE(o.Validate().message().find("max_particles"), std::string::npos);
  o = LocalizerOptions();
  o.lost_log_likelihood = 0.5;
  EXPECT_NE(o.Validate().message().find("lost_log_likelihood"), std::string::npos);
  o = LocalizerOptions();
  o.global_hypotheses = 5000;
  EXPECT_NE(o.Validate().message().find("global_hypotheses"), std::string::npos);
  // The shipped file holds the defaults, and every key is known.
  const auto file = LoadYamlFile<LocalizerOptions>(test::SourceDir() + "/config/localizer.yaml");
  EXPECT_EQ(SaveYamlString(file), SaveYamlString(LocalizerOptions()));
  EXPECT_THROW(LoadYamlString<LocalizerOptions>("min_particle: 3\n"), ConfigError);
}

TEST(Localizer, AMapWithoutObstaclesOrMalformedIsRefused) {
  OccupancyMap m;
  m.width = 10;
  m.height = 10;
  m.cells.assign(100, 0);
  EXPECT_THROW(MonteCarloLocalizer(LocalizerOptions(), m), std::invalid_argument);
  m.cells.resize(99);
  EXPECT_THROW(MonteCarloLocalizer(LocalizerOptions(), m), std::invalid_argument);
}

// The first case: map a simulated world, then localize in another run of it (another
// noise seed), from an initial pose: ATE <= 0.05 m.
TEST(Localizer, LocalizesAnotherRunOfAMappedWorldWithin5cm) {
  double slam_ate = 0.0;
  const OccupancyMap map = MappedRoom(&slam_ate);
  test::LoopRunOptions lo;
  lo.step_m = 0.1;  // 1 m/s at 10 scans per second
  lo.seed = 11;
  const test::LoopRun run = test::MakeLoopRun(test::LaserWorld::RoomWithBoxes(), lo);
  MonteCarloLocalizer loc(TestOptions(), map);
  // The operator's initial pose: 0.2 m and 0.1 rad off.
  const fl::Pose2 start = run.truth[0];
  ASSERT_TRUE(loc.SetInitialPose(fl::Pose2(start.x + 0.2, start.y - 0.1, start.theta + 0.1)).ok());
  const Output out = Localize(&loc, run, lo, run.odom);
  const double ate = Ate(out.utimes, out.poses, out.truth);
  double worst = 0.0;
  for (size_t k = 10; k < out.poses.size(); ++k) {
    worst = std::max(worst, Distance(out.poses[k], out.truth[k]));
  }
  const auto& s = loc.stats();
  std::printf("the SLAM's ATE on the mapping run (the map's error): %.4f m\n", slam_ate);
  std::printf(
      "localization: %zu scans, %lld updates, ATE %.4f m (SE(2)-aligned), worst %.3f m "
      "(unaligned, after the first second), particles at the end %d (max %d), factors "
      "%lld, odometry ATE %.3f m\n",
      out.poses.size(), static_cast<long long>(s.processed), ate, worst, loc.num_particles(),
      s.max_particles_used, static_cast<long long>(s.factors),
      Ate(out.utimes, run.odom, out.truth));
  EXPECT_LE(ate, 0.05);
  EXPECT_LT(worst, 0.25);
  EXPECT_EQ(loc.state(), LocalizerState::kLocalized);
  EXPECT_EQ(s.initial_pose_rejections, 0);
  EXPECT_EQ(s.lost_detections, 0);
  EXPECT_EQ(s.global_initializations, 0);
  // Tracking needs few particles (KLD): the minimum most of the time.
  EXPECT_LT(s.max_particles_used, 200);
  // Factors: one per keyframe (0.5 m / 0.35 rad), consecutive, their relative poses close to
  // the truth's, their information positive definite.
  EXPECT_GT(s.factors, 60);
  int checked = 0;
  std::vector<double> chi2;
  for (size_t k = 0; k < out.results.size(); ++k) {
    for (const KeyframeFactor& f : out.results[k].factors) {
      EXPECT_EQ(f.keyframe_j, f.keyframe_i + 1);
      EXPECT_EQ(f.utime_j, out.utimes[k]);
      const size_t i = static_cast<size_t>(
          std::find(out.utimes.begin(), out.utimes.end(), f.utime_i) - out.utimes.begin());
      ASSERT_LT(i, k);
      const fl::Pose2 truth = out.truth[i].between(out.truth[k]);
      EXPECT_LT(Distance(truth, f.T_i_j), 0.1);
      const Eigen::Vector3d e(f.T_i_j.x - truth.x, f.T_i_j.y - truth.y,
                              WrapAngle(f.T_i_j.theta - truth.theta));
      chi2.push_back(e.dot(f.information * e));
      EXPECT_GT(f.information.determinant(), 0.0);
      EXPECT_GT(f.information(0, 0), 0.0);
      EXPECT_GT(f.information(2, 2), 0.0);
      ++checked;
    }
  }
  EXPECT_EQ(checked, s.factors);
  std::sort(chi2.begin(), chi2.end());
  std::printf(
      "factors: chi2 against the truth median %.2f, p95 %.2f (2.37 and 7.8 if "
      "calibrated)\n",
      chi2[chi2.size() / 2], chi2[chi2.size() * 95 / 100]);
  // Conservative, not overconfident: the floors (2 cm, 0.01 rad a pose) are for lasers noisier
  // than this one.
  EXPECT_LT(chi2[chi2.size() / 2], 2.37);
}

// The localizer's own error: the same run on an exact map of the world.
TEST(Localizer, OnAnExactMapTheErrorIsTheLocalizersOwn) {
  test::LoopRunOptions lo;
  lo.step_m = 0.1;
  lo.seed = 11;
  const test::LoopRun run = test::MakeLoopRun(test::LaserWorld::RoomWithBoxes(), lo);
  MonteCarloLocalizer loc(TestOptions(), ExactRoom());
  ASSERT_TRUE(loc.SetInitialPose(run.truth[0]).ok());
  const Output out = Localize(&loc, run, lo, run.odom);
  std::vector<fl::Utime> t;
  std::vector<fl::Pose2> updated, truth;
  for (size_t k = 0; k < out.poses.size(); ++k) {
    if (!out.results[k].processed) continue;
    t.push_back(out.utimes[k]);
    updated.push_back(out.poses[k]);
    truth.push_back(out.truth[k]);
  }
  const double ate = Ate(out.utimes, out.poses, out.truth);
  const double ate_updates = Ate(t, updated, truth);
  const auto fits = FitRange(out, 0, out.results.size());
  std::printf(
      "exact map: ATE %.4f m over every scan, %.4f m at the filter updates; fit on the "
      "right pose %.2f .. %.2f\n",
      ate, ate_updates, fits.first, fits.second);
  EXPECT_LE(ate, 0.02);
  EXPECT_LE(ate_updates, 0.01);
}

// A map whose origin is not a multiple of its resolution (maps saved by ROS often are not):
// the poses come out in the map's frame all the same.
TEST(Localizer, AMapOriginOffTheCellLatticeKeepsTheMapFrame) {
  test::LoopRunOptions lo;
  lo.step_m = 0.1;
  lo.seed = 11;
  test::LoopRun run = test::MakeLoopRun(test::LaserWorld::RoomWithBoxes(), lo);
  run.utimes.resize(150);
  OccupancyMap shifted = ExactRoom();
  const Eigen::Vector2d shift(0.013, -0.021);  // under half a 5 cm cell
  shifted.origin_x += shift.x();
  shifted.origin_y += shift.y();
  MonteCarloLocalizer a(TestOptions(), ExactRoom()), b(TestOptions(), shifted);
  EXPECT_NEAR((b.map_offset() - a.map_offset() - shift).norm(), 0.0, 1e-12);
  ASSERT_TRUE(a.SetInitialPose(run.truth[0]).ok());
  const fl::Pose2 s0(run.truth[0].x + shift.x(), run.truth[0].y + shift.y(), run.truth[0].theta);
  ASSERT_TRUE(b.SetInitialPose(s0).ok());
  const Output oa = Localize(&a, run, lo, run.odom), ob = Localize(&b, run, lo, run.odom);
  for (size_t k = 0; k < oa.poses.size(); ++k) {
    ASSERT_NEAR(ob.poses[k].x - oa.poses[k].x, shift.x(), 1e-9) << k;
    ASSERT_NEAR(ob.poses[k].y - oa.poses[k].y, shift.y(), 1e-9) << k;
  }
}

// Without an initial pose the filter initialises over the free space and finds the robot.
// (This and the next two tests run on the exact map, so that the truth is the map's frame.)
TEST(Localizer, GlobalInitialisationFindsTheRobotWithoutAnInitialPose) {
  const OccupancyMap map = ExactRoom();
  test::LoopRunOptions lo;
  lo.step_m = 0.1;
  lo.seed = 12;
  const test::LoopRun run = test::MakeLoopRun(test::LaserWorld::RoomWithBoxes(), lo);
  MonteCarloLocalizer loc(TestOptions(), map);
  EXPECT_GT(loc.GlobalCandidates().size(), 1000u);
  const Output out = Localize(&loc, run, lo, run.odom);
  ASSERT_TRUE(out.results[0].global_initialization);
  EXPECT_EQ(out.results[0].particles, TestOptions().global_hypotheses);
  // The first time after which every pose is within 0.1 m of the truth (between filter updates
  // the fixture's odometry, 3 cm/m and biased, moves the pose up to 5 cm off).
  size_t settled = out.poses.size();
  for (size_t k = out.poses.size(); k-- > 0;) {
    if (Distance(out.poses[k], out.truth[k]) > 0.1) break;
    settled = k;
  }
  ASSERT_LT(settled, out.poses.size());
  const double seconds = 1e-6 * static_cast<double>(out.utimes[settled] - out.utimes[0]);
  std::printf(
      "global initialisation: %d hypotheses -> within 0.1 m for good after %.1f s of "
      "data; particles at the end %d\n",
      out.results[0].particles, seconds, loc.num_particles());
  EXPECT_LE(seconds, 2.0);
  EXPECT_EQ(loc.state(), LocalizerState::kLocalized);
  EXPECT_EQ(loc.stats().global_initializations, 1);
  EXPECT_EQ(loc.num_particles(), TestOptions().min_particles);
}

// A run whose robot is carried 5 m away (and turned) at `kidnap_index` while its odometry goes
// on smoothly: the scans from there on are those of the drive from `resume_index`.
struct KidnapRun {
  test::LoopRun run;       // utimes, ranges and truth as seen by the robot
  size_t first_after = 0;  // index of the first scan after the kidnapping
  double jump_m = 0.0;
};

KidnapRun MakeKidnapRun(unsigned seed) {
  test::LoopRunOptions lo;
  lo.step_m = 0.1;
  lo.seed = seed;
  const test::LoopRun full = test::MakeLoopRun(test::LaserWorld::RoomWithBoxes(), lo);
  // Kidnapped on the first straight at x = 3.5 (after 12 s); put down where the route is 5 m
  // away, on the next straight (heading +y).
  size_t k0 = 0;
  while (full.truth[k0].x < 3.5) ++k0;
  size_t k1 = k0 + 30;
  while (k1 < full.truth.size() && Distance(full.truth[k1], full.truth[k0]) < 5.0) ++k1;
  KidnapRun out;
  out.first_after = k0 + 1;
  out.jump_m = Distance(full.truth[k1], full.truth[k0]);
  test::LoopRun& r = out.run;
  for (size_t k = 0; k <= k0; ++k) {
    r.utimes.push_back(full.utimes[k]);
    r.ranges.push_back(full.ranges[k]);
    r.truth.push_back(full.truth[k]);
    r.odom.push_back(full.odom[k]);
  }
  for (size_t k = k1; k < full.truth.size(); ++k) {
    r.utimes.push_back(r.utimes.back() + 100000);
    r.ranges.push_back(full.ranges[k]);
    r.truth.push_back(full.truth[k]);
    // The odometry does not see the kidnapping: it goes on with the motion from k1 on.
    r.odom.push_back(full.odom[k0] * full.odom[k1 - 1].between(full.odom[k]));
  }
  return out;
}

// The second case: a kidnapped robot (a pose jump of 5 m) is recovered within 10 s of
// data.
TEST(Localizer, AKidnappedRobotIsFoundAgainWithin10SecondsOfData) {
  const OccupancyMap map = ExactRoom();
  const KidnapRun kr = MakeKidnapRun(13);
  test::LoopRunOptions lo;
  MonteCarloLocalizer loc(TestOptions(), map);
  ASSERT_TRUE(loc.SetInitialPose(kr.run.truth[0]).ok());
  const Output out = Localize(&loc, kr.run, lo, kr.run.odom);
  const size_t j = kr.first_after;
  // Tracked before, within 0.1 m of the truth.
  for (size_t k = 0; k < j; ++k) ASSERT_LT(Distance(out.poses[k], out.truth[k]), 0.1) << k;
  size_t lost_at = out.poses.size(), settled = out.poses.size();
  for (size_t k = j; k < out.poses.size(); ++k) {
    if (out.results[k].lost && lost_at == out.poses.size()) lost_at = k;
  }
  for (size_t k = out.poses.size(); k-- > j;) {
    if (Distance(out.poses[k], out.truth[k]) > 0.1) break;
    settled = k;
  }
  ASSERT_LT(lost_at, out.poses.size()) << "the kidnapping was not detected";
  ASSERT_LT(settled, out.poses.size()) << "not recovered";
  const double detect_s = 1e-6 * static_cast<double>(out.utimes[lost_at] - out.utimes[j]);
  const double recover_s = 1e-6 * static_cast<double>(out.utimes[settled] - out.utimes[j]);
  std::printf(
      "kidnapped %.2f m: detected after %.1f s, within 0.1 m for good after %.1f s of "
      "data (%zu s of data after it); lost %lld, global initialisations %lld, particles "
      "at most %d\n",
      kr.jump_m, detect_s, recover_s,
      static_cast<size_t>(1e-6 * static_cast<double>(out.utimes.back() - out.utimes[j])),
      static_cast<long long>(loc.stats().lost_detections),
      static_cast<long long>(loc.stats().global_initializations), loc.stats().max_particles_used);
  EXPECT_GE(kr.jump_m, 5.0);
  EXPECT_LT(kr.jump_m, 5.2);
  EXPECT_LE(recover_s, 10.0);
  EXPECT_EQ(loc.stats().lost_detections, 1);
  EXPECT_EQ(loc.stats().initial_pose_rejections, 0);
  EXPECT_EQ(loc.state(), LocalizerState::kLocalized);
  // No factor spans the kidnapping: the chain restarts after the relocalization.
  for (size_t k = j; k < out.poses.size(); ++k) {
    for (const KeyframeFactor& f : out.results[k].factors)
      EXPECT_GE(f.utime_i, out.utimes[lost_at]);
  }
}

// The third case: a wrong initial pose is rejected with a status, not followed.
TEST(Localizer, AWrongInitialPoseIsRejectedNotFollowed) {
  const OccupancyMap map = ExactRoom();
  test::LoopRunOptions lo;
  lo.step_m = 0.1;
  lo.seed = 14;
  const test::LoopRun run = test::MakeLoopRun(test::LaserWorld::RoomWithBoxes(), lo);
  for (const bool relocalize : {true, false}) {
    SCOPED_TRACE(relocalize ? "relocalize" : "report only");
    LocalizerOptions o = TestOptions();
    o.relocalize = relocalize;
    MonteCarloLocalizer loc(o, map);
    // 3 m ahead of the robot, in the same corridor, same heading.
    const fl::Pose2 wrong(run.truth[0].x + 3.0, run.truth[0].y, run.truth[0].theta);
    ASSERT_TRUE(loc.SetInitialPose(wrong).ok());
    const Output out = Localize(&loc, run, lo, run.odom);
    size_t rejected = out.poses.size();
    for (size_t k = 0; k < out.poses.size(); ++k) {
      if (out.results[k].initial_pose_rejected) {
        rejected = k;
        break;
      }
      // Until then: never reported as localized, no factor published.
      EXPECT_NE(out.results[k].state, LocalizerState::kLocalized) << k;
      EXPECT_TRUE(out.results[k].factors.empty()) << k;
    }
    ASSERT_LT(rejected, out.poses.size()) << "the wrong initial pose was never rejected";
    const double seconds = 1e-6 * static_cast<double>(out.utimes[rejected] - out.utimes[0]);
    EXPECT_EQ(loc.stats().initial_pose_rejections, 1);
    EXPECT_LE(seconds, 3.0);
    if (relocalize) {
      // Then found globally: localized at the end, within 0.1 m of the truth for the last
      // half of the run.
      for (size_t k = out.poses.size() / 2; k < out.poses.size(); ++k) {
        ASSERT_LT(Distance(out.poses[k], out.truth[k]), 0.1) << k;
      }
      EXPECT_EQ(loc.state(), LocalizerState::kLocalized);
      const auto fits = FitRange(out, 0, rejected + 1);
      std::printf(
          "wrong initial pose (3 m off): fit %.2f .. %.2f, rejected after %.1f s of "
          "data, then found globally\n",
          fits.first, fits.second, seconds);
    } else {
      EXPECT_EQ(out.results[rejected].state, LocalizerState::kLost);
      // Reported as localized again only where the scans fit the map.
      size_t last_wrong = 0, localized_wrong = 0;
      for (size_t k = rejected; k < out.poses.size(); ++k) {
        const bool wrong = Distance(out.poses[k], out.truth[k]) > 0.1;
        if (wrong) last_wrong = k;
        if (wrong && out.results[k].state == LocalizerState::kLocalized) ++localized_wrong;
      }
      std::printf(
          "wrong initial pose (3 m off), relocalize off: rejected after %.1f s, state "
          "%s at the end, %.3f m off; last scan more than 0.1 m off: %zu of %zu; "
          "scans more than 0.1 m off reported as localized: %zu\n",
          seconds, LocalizerStateName(loc.state()), Distance(out.poses.back(), out.truth.back()),
          last_wrong, out.poses.size(), localized_wrong);
      EXPECT_EQ(localized_wrong, 0u);
    }
  }
}

// People around the robot (obstacles the map does not have) spoil the fit for a while: the
// search of the whole map finds no place that fits better, and the filter stays where it is
// (no jump to a look-alike place, not reported lost).
TEST(Localizer, PoorFitsWithNoBetterPlaceOnTheMapKeepTheFilterWhereItIs) {
  test::LaserWorld crowded = test::LaserWorld::RoomWithBoxes();
  for (double x = 0.0; x <= 3.0; x += 1.0) {  // people along 3 m of the first corridor
    crowded.AddBox(x, -5.4, x + 0.4, -5.0);
    crowded.AddBox(x + 0.5, -4.0, x + 0.9, -3.6);
  }
  test::LoopRunOptions lo;
  lo.step_m = 0.1;
  lo.seed = 17;
  const test::LoopRun run = test::MakeLoopRun(crowded, lo);
  MonteCarloLocalizer loc(TestOptions(), ExactRoom());
  ASSERT_TRUE(loc.SetInitialPose(run.truth[0]).ok());
  const Output out = Localize(&loc, run, lo, run.odom);
  double worst = 0.0;
  for (size_t k = 0; k < out.poses.size(); ++k) {
    worst = std::max(worst, Distance(out.poses[k], out.truth[k]));
  }
  const auto& st = loc.stats();
  const auto fits = FitRange(out, 0, out.results.size());
  std::printf(
      "crowd: fits %.2f .. %.2f, bad updates %lld, searches that found no better place "
      "%lld, lost %lld, worst error %.3f m\n",
      fits.first, fits.second, static_cast<long long>(st.bad_updates),
      static_cast<long long>(st.relocalizations_refused),
      static_cast<long long>(st.lost_detections), worst);
  EXPECT_GE(st.relocalizations_refused, 1);
  EXPECT_EQ(st.lost_detections, 0);
  EXPECT_EQ(st.global_initializations, 0);
  EXPECT_LT(worst, 0.1);
}

// The node drops a bad INITIAL_POSE (outside the map) with the reason, and applies a good one
// at the next scan; one that is not finite is dropped and counted before, by the LCM layer.
TEST(LocalizerNode, BadInitialPosesAreDroppedAndCountedAGoodOneIsApplied) {
  auto lcm = MakeLcm("memq://");
  RbpfSlamNodeOptions node_options;
  node_options.mounting_wait_s = 0.0;
  LocalizerNode node(TestOptions(), node_options, ExactRoom(), "room.yaml", lcm.get(),
                     ChannelMap());
  test::LoopRunOptions lo;
  lo.step_m = 0.1;
  const test::LoopRun run = test::MakeLoopRun(test::LaserWorld::RoomWithBoxes(), lo);
  bot_core::pose_t bad = PoseToLcm(run.utimes[0], fl::Pose2(std::nan(""), 0.0, 0.0));
  lcm->Publish("INITIAL_POSE", bad, 0);
  bad = PoseToLcm(run.utimes[0], fl::Pose2(500.0, 0.0, 0.0));
  lcm->Publish("INITIAL_POSE", bad, 0);
  const bot_core::pose_t good = PoseToLcm(run.utimes[0], run.truth[0]);
  lcm->Publish("INITIAL_POSE", good, 0);
  int poses = 0;
  lcm->Subscribe<bot_core::pose_t>("RBPF_POSE",
                                   [&](const bot_core::pose_t&, const std::string&) { ++poses; });
  for (size_t k = 0; k < 20; ++k) {
    fusionloc::wheel_odometry_t o{};
    o.utime = run.utimes[k];
    o.x = run.odom[k].x;
    o.y = run.odom[k].y;
    o.theta = run.odom[k].theta;
    lcm->Publish("ODOMETRY", o, o.utime);
    bot_core::planar_lidar_t sc{};
    sc.utime = run.utimes[k];
    sc.ranges = run.ranges[k];
    sc.nranges = static_cast<int32_t>(sc.ranges.size());
    sc.rad0 = static_cast<float>(lo.rad0);
    sc.radstep = static_cast<float>(lo.radstep);
    lcm->Publish("LASER", sc, sc.utime);
    while (lcm->HandleSubscriptions(0) > 0) {
    }
    node.Poll();
  }
  node.Finish();
  while (lcm->HandleSubscriptions(0) > 0) {
  }
  EXPECT_EQ(node.status().dropped(), 1);  // outside the map
  EXPECT_EQ(lcm->invalid_values(), 1);     // not finite
  EXPECT_EQ(node.localizer().stats().initial_poses, 1);
  EXPECT_EQ(node.localizer().stats().global_initializations, 0);
  EXPECT_EQ(node.localizer().state(), LocalizerState::kLocalized);
  EXPECT_EQ(poses, 20);
}

// ---- the process: fl-rbpf-slam --localize MAP.yaml over a log ----

struct ProcessRun {
  test::CommandResult result;
  std::vector<bot_core::pose_t> poses;
  int factors = 0, maps = 0;
  std::vector<fusionloc::status_t> statuses;
};

// Writes the exact room as map files and a log of 25 s of the drive (LASER, ODOMETRY and, before
// the first scan, INITIAL_POSE `initial`), and runs fl-rbpf-slam --localize on it.
ProcessRun RunLocalizeProcess(const test::TempDir& dir, const fl::Pose2& initial,
                              test::LoopRun* run_out) {
  ProcessRun out;
  maps::SaveOccupancyGrid(OccupancyMapToLcm(0, ExactRoom()), dir.file("room"));
  test::LoopRunOptions lo;
  lo.step_m = 0.1;
  lo.seed = 15;
  test::LoopRun run = test::MakeLoopRun(test::LaserWorld::RoomWithBoxes(), lo);
  run.utimes.resize(250);
  {
    LcmLogWriter w(dir.file("in.lcmlog"));
    bot_core::pose_t p = PoseToLcm(run.utimes[0] - 1000, initial);
    w.Write("INITIAL_POSE", p, p.utime);
    for (size_t k = 0; k < run.utimes.size(); ++k) {
      fusionloc::wheel_odometry_t o{};
      o.utime = run.utimes[k];
      o.x = run.odom[k].x;
      o.y = run.odom[k].y;
      o.theta = run.odom[k].theta;
      w.Write("ODOMETRY", o, o.utime);
      bot_core::planar_lidar_t s{};
      s.utime = run.utimes[k];
      s.ranges = run.ranges[k];
      s.nranges = static_cast<int32_t>(s.ranges.size());
      s.rad0 = static_cast<float>(lo.rad0);
      s.radstep = static_cast<float>(lo.radstep);
      w.Write("LASER", s, s.utime);
    }
    w.Close();
  }
  out.result = test::RunCommand(test::BinDir() +
                                    "/fl-rbpf-slam --localize room.yaml "
                                    "--mounting-wait-s 0 --lcm-url log:in.lcmlog,out.lcmlog",
                                dir);
  if (out.result.status != 0) return out;
  LcmLogReader r(dir.file("out.lcmlog"));
  LcmLogEvent ev;
  while (r.Next(&ev)) {
    const int n = static_cast<int>(ev.data.size());
    if (ev.channel == "RBPF_POSE") {
      bot_core::pose_t m{};
      EXPECT_EQ(m.decode(ev.data.data(), 0, n), n);
      out.poses.push_back(m);
    } else if (ev.channel == "RBPF_FACTORS") {
      fusionloc::relative_pose_factor_t f{};
      EXPECT_EQ(f.decode(ev.data.data(), 0, n), n);
      const int8_t laser = fusionloc::relative_pose_factor_t::SOURCE_LASER;
      EXPECT_EQ(f.source, laser);
      EXPECT_LT(f.utime_i, f.utime_j);
      EXPECT_GT(f.information[0], 0.0);   // x
      EXPECT_GT(f.information[35], 0.0);  // yaw
      ++out.factors;
    } else if (ev.channel == "RBPF_MAP") {
      ++out.maps;
    } else if (ev.channel == "STATUS_FL_RBPF_SLAM") {
      fusionloc::status_t m{};
      EXPECT_EQ(m.decode(ev.data.data(), 0, n), n);
      out.statuses.push_back(m);
    }
  }
  *run_out = run;
  return out;
}

double StatusValue(const fusionloc::status_t& m, const std::string& key) {
  for (int i = 0; i < m.num_keys; ++i) {
    if (m.keys[i] == key) return m.values[i];
  }
  return std::nan("");
}

TEST(LocalizerProcess, LocalizesFromInitialPoseAndPublishesWhatTheSlamPublishes) {
  const std::string bin = test::BinDir() + "/fl-rbpf-slam";
  if (!std::filesystem::exists(bin)) GTEST_SKIP() << "build fl-rbpf-slam first: " << bin;
  test::TempDir dir;
  test::LoopRunOptions lo;
  lo.seed = 15;
  const fl::Pose2 start = test::MakeLoopRun(test::LaserWorld::RoomWithBoxes(), lo).truth[0];
  test::LoopRun run;
  const ProcessRun out = RunLocalizeProcess(dir, start, &run);
  ASSERT_EQ(out.result.status, 0) << out.result.err;
  ASSERT_EQ(out.poses.size(), run.utimes.size());
  double worst = 0.0;
  for (size_t k = 0; k < out.poses.size(); ++k) {
    EXPECT_EQ(out.poses[k].utime, run.utimes[k]);
    worst = std::max(worst, std::hypot(out.poses[k].pos[0] - run.truth[k].x,
                                       out.poses[k].pos[1] - run.truth[k].y));
  }
  EXPECT_LT(worst, 0.1);
  EXPECT_GT(out.factors, 20);
  EXPECT_GE(out.maps, 2);  // at the first scan and at the end
  ASSERT_FALSE(out.statuses.empty());
  const fusionloc::status_t& last = out.statuses.back();
  const int8_t ok = fusionloc::status_t::LEVEL_OK;
  EXPECT_EQ(last.level, ok) << last.message;
  EXPECT_NE(last.message.find("localized on room.yaml"), std::string::npos) << last.message;
  EXPECT_EQ(StatusValue(last, "state"), static_cast<double>(LocalizerState::kLocalized));
  EXPECT_EQ(StatusValue(last, "initial_poses"), 1.0);
  EXPECT_EQ(StatusValue(last, "initial_pose_rejections"), 0.0);
  EXPECT_NE(out.result.err.find("INITIAL_POSE"), std::string::npos) << out.result.err;
}

// The STATUS says that the initial pose was rejected and why (not a silent divergence).
TEST(LocalizerProcess, AWrongInitialPoseIsReportedInTheStatus) {
  const std::string bin = test::BinDir() + "/fl-rbpf-slam";
  if (!std::filesystem::exists(bin)) GTEST_SKIP() << "build fl-rbpf-slam first: " << bin;
  test::TempDir dir;
  test::LoopRunOptions lo;
  lo.seed = 15;
  const fl::Pose2 start = test::MakeLoopRun(test::LaserWorld::RoomWithBoxes(), lo).truth[0];
  test::LoopRun run;
  const ProcessRun out =
      RunLocalizeProcess(dir, fl::Pose2(start.x + 3.0, start.y, start.theta), &run);
  ASSERT_EQ(out.result.status, 0) << out.result.err;
  bool reported = false;
  for (const fusionloc::status_t& m : out.statuses) {
    if (m.message.find("initial pose (-5.5, -4.5, 0.0 rad) rejected") == std::string::npos) {
      continue;
    }
    reported = true;
    EXPECT_NE(m.message.find("did not fit the map"), std::string::npos) << m.message;
    EXPECT_EQ(StatusValue(m, "initial_pose_rejections"), 1.0);
    const int8_t ok = fusionloc::status_t::LEVEL_OK, warn = fusionloc::status_t::LEVEL_WARN;
    if (m.level != ok) {
      EXPECT_EQ(m.level, warn) << m.message;
    }
  }
  EXPECT_TRUE(reported) << out.result.err;
  EXPECT_NE(out.result.err.find("rejected"), std::string::npos) << out.result.err;
}

TEST(LocalizerProcess, BadMapFilesAndFlagsExitWithTheReason) {
  const std::string bin = test::BinDir() + "/fl-rbpf-slam";
  if (!std::filesystem::exists(bin)) GTEST_SKIP() << "build fl-rbpf-slam first: " << bin;
  test::TempDir dir;
  test::CommandResult r = test::RunCommand(bin + " --help", dir);
  EXPECT_EQ(r.status, 0);
  EXPECT_NE(r.out.find("--localize"), std::string::npos) << r.out;
  r = test::RunCommand(bin + " --localize missing.yaml --lcm-url memq://", dir);
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("map file 'missing.yaml' not found"), std::string::npos) << r.err;
  std::ofstream(dir.file("bad.yaml")) << "image: x.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n";
  r = test::RunCommand(bin + " --localize bad.yaml --lcm-url memq://", dir);
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("x.pgm"), std::string::npos) << r.err;
  r = test::RunCommand(bin + " --localize=", dir);
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find("--localize MAP.yaml"), std::string::npos) << r.err;
  r = test::RunCommand(bin + " --localize m.yaml --no-odometry", dir);
  EXPECT_EQ(r.status, 2);
  // A map without any obstacle: nothing to localize against.
  OccupancyMap empty;
  empty.width = empty.height = 4;
  empty.cells.assign(16, 0);
  maps::SaveOccupancyGrid(OccupancyMapToLcm(0, empty), dir.file("empty"));
  r = test::RunCommand(bin + " --localize empty.yaml --lcm-url memq://", dir);
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("no occupied cell"), std::string::npos) << r.err;
}

// A noisy laser (10 cm of range noise, the simulator's URG-04LX): with the likelihood field's
// std at the noise (matcher.sigma 0.1 instead of 0.05), the right pose fits above the default
// lost_log_likelihood (-0.5) all along, and a wrong initial pose below it. (With 0.05 the right
// pose fits at -0.59 .. -1.13 and the wrong one at -1.01 .. -1.35: they overlap.)
TEST(Localizer, ANoisyLaserWithTheFieldAtItsNoiseTracksAndRejectsAWrongInitialPose) {
  test::LoopRunOptions lo;
  lo.step_m = 0.1;
  lo.seed = 16;
  lo.range_noise = 0.1;
  const test::LoopRun run = test::MakeLoopRun(test::LaserWorld::RoomWithBoxes(), lo);
  LocalizerOptions o;  // the defaults ...
  o.max_range = 25.0;
  o.matcher.sigma = 0.1;  // ... with the field at the laser's noise
  {
    MonteCarloLocalizer loc(o, ExactRoom());
    ASSERT_TRUE(loc.SetInitialPose(run.truth[0]).ok());
    const Output out = Localize(&loc, run, lo, run.odom);
    const auto fits = FitRange(out, 0, out.results.size());
    const double worst_fit = fits.first;
    const double ate = Ate(out.utimes, out.poses, out.truth);
    std::printf("10 cm laser, sigma 0.1: ATE %.4f m, fit on the right pose %.2f .. %.2f\n", ate,
                fits.first, fits.second);
    EXPECT_LE(ate, 0.05);
    EXPECT_GT(worst_fit, o.lost_log_likelihood);
    EXPECT_EQ(loc.stats().bad_updates, 0);
  }
  {
    MonteCarloLocalizer loc(o, ExactRoom());
    ASSERT_TRUE(
        loc.SetInitialPose(fl::Pose2(run.truth[0].x + 3.0, run.truth[0].y, run.truth[0].theta))
            .ok());
    const Output out = Localize(&loc, run, lo, run.odom);
    // Reported at the first search (poor fit; with the default relocalize_min_gain, 0.5, the
    // true place did not fit better by that much yet), rejected at a later one.
    size_t rejected = out.poses.size(), reported = out.poses.size();
    for (size_t k = 0; k < out.poses.size() && rejected == out.poses.size(); ++k) {
      if (out.results[k].initial_pose_rejected) rejected = k;
      if ((out.results[k].initial_pose_rejected || out.results[k].relocalization_refused) &&
          reported == out.poses.size()) {
        reported = k;
      }
      EXPECT_TRUE(out.results[k].factors.empty()) << k;
      EXPECT_NE(out.results[k].state, LocalizerState::kLocalized) << k;
    }
    ASSERT_LT(rejected, out.poses.size());
    const double seconds = 1e-6 * static_cast<double>(out.utimes[rejected] - out.utimes[0]);
    const double reported_s = 1e-6 * static_cast<double>(out.utimes[reported] - out.utimes[0]);
    const auto fits = FitRange(out, 0, rejected + 1);
    std::printf(
        "10 cm laser, sigma 0.1, wrong initial pose: fit %.2f .. %.2f, poor fit reported after "
        "%.1f s, rejected after %.1f s of data\n",
        fits.first, fits.second, reported_s, seconds);
    EXPECT_LE(reported_s, 3.0);
    EXPECT_LE(seconds, 10.0);
    for (size_t k = out.poses.size() / 2; k < out.poses.size(); ++k) {
      ASSERT_LT(Distance(out.poses[k], out.truth[k]), 0.15) << k;
    }
  }
  // With the field at the default 0.05 m the two overlap: the right pose over the whole run,
  // the wrong one over its first 12 updates (before the filter slides off it).
  o.matcher.sigma = 0.05;
  o.relocalize = false;
  o.lost_log_likelihood = -100.0;
  std::pair<double, double> right, wrong;
  for (const bool at_truth : {true, false}) {
    MonteCarloLocalizer loc(o, ExactRoom());
    const fl::Pose2 t0 = run.truth[0];
    ASSERT_TRUE(loc.SetInitialPose(fl::Pose2(t0.x + (at_truth ? 0.0 : 3.0), t0.y, t0.theta)).ok());
    const Output out = Localize(&loc, run, lo, run.odom);
    size_t twelfth = 0;
    for (int n = 0; twelfth < out.results.size() && n < 12; ++twelfth) {
      if (out.results[twelfth].processed) ++n;
    }
    (at_truth ? right : wrong) = FitRange(out, 0, at_truth ? out.results.size() : twelfth);
  }
  std::printf(
      "10 cm laser, sigma 0.05: right pose %.2f .. %.2f, 3 m ahead (first 12 updates) "
      "%.2f .. %.2f\n",
      right.first, right.second, wrong.first, wrong.second);
  EXPECT_LT(right.first, wrong.second);  // they overlap
}

}  // namespace
}  // namespace fl::rbpf
