#include "fusionloc/importers/carmen.hpp"

#include <gtest/gtest.h>
#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <sstream>

#include "bot_core/planar_lidar_t.hpp"
#include "bot_core/pose_t.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/yaml_options.hpp"
#include "fusionloc/wheel_odometry_t.hpp"
#include "importer_fixtures.hpp"
#include "test_paths.hpp"

namespace fl::importers {
namespace {

namespace fs = std::filesystem;
using fl::test::TempDir;

std::string Laser(const std::string& name) { return fl::test::SharedDataDir() + "/laser/" + name; }

// Converts and expects failure; returns the message. Checks nothing is left at `out`.
std::string ExpectConvertError(const CarmenOptions& opts, const std::string& in,
                               const std::string& out) {
  std::string message;
  try {
    ConvertCarmen(opts, in, out);
    ADD_FAILURE() << "conversion of " << in << " should have failed";
  } catch (const std::exception& e) {
    message = e.what();
  }
  EXPECT_FALSE(fs::exists(out)) << "half-written output left at " << out;
  EXPECT_FALSE(fs::exists(out + ".partial")) << "partial output left at " << out;
  return message;
}

TEST(CarmenTest, BeamStepFollowsCarmenConvention) {
  const double deg = M_PI / 180.0;
  EXPECT_NEAR(CarmenBeamStep(361, M_PI), 0.5 * deg, 1e-12);
  EXPECT_NEAR(CarmenBeamStep(360, M_PI), 0.5 * deg, 1e-12);
  EXPECT_NEAR(CarmenBeamStep(181, M_PI), 1.0 * deg, 1e-12);
  EXPECT_NEAR(CarmenBeamStep(180, M_PI), 1.0 * deg, 1e-12);
  EXPECT_NEAR(CarmenBeamStep(401, M_PI), 0.25 * deg, 1e-12);
  EXPECT_NEAR(CarmenBeamStep(100, M_PI), M_PI / 99, 1e-12);
  EXPECT_NEAR(CarmenBeamStep(100, 0.5 * M_PI), 0.5 * M_PI / 99, 1e-12);
}

TEST(CarmenTest, ConvertsRawMitCsailWithItsOwnOdometry) {
  const std::string in = Laser("mit-csail.clf");
  FL_REQUIRE_SHARED_FILE(in);
  TempDir dir;
  const std::string out = dir.file("csail.lcmlog");
  const ConvertSummary s = ConvertCarmen(CarmenOptions{}, in, out);
  EXPECT_EQ(s.messages.at(channels::kLaser), 1988);
  EXPECT_EQ(s.messages.at(channels::kOdometry), 1988);
  EXPECT_EQ(s.messages.count(channels::kGroundTruth), 0u);  // raw log: no reference here
  const auto log = fl::test::ReadLog(out);
  ASSERT_EQ(log.count(channels::kLaser), 1988u);
  const auto scan = log.Decode<bot_core::planar_lidar_t>(channels::kLaser, 0);
  EXPECT_EQ(scan.nranges, 361);
  EXPECT_EQ(scan.nintensities, 0);
  EXPECT_FLOAT_EQ(scan.rad0, static_cast<float>(-M_PI / 2));
  EXPECT_FLOAT_EQ(scan.radstep, static_cast<float>(M_PI / 360));
  EXPECT_FLOAT_EQ(scan.ranges[0], 1.40f);
  EXPECT_EQ(scan.utime, 1134864629895182);  // ipc_timestamp of the first FLASER line
  EXPECT_EQ(log.utimes.at(channels::kLaser)[0], scan.utime);
  const auto odo = log.Decode<fusionloc::wheel_odometry_t>(channels::kOdometry, 0);
  EXPECT_DOUBLE_EQ(odo.x, 576.536523);
  EXPECT_DOUBLE_EQ(odo.y, 0.106594);
  EXPECT_DOUBLE_EQ(odo.theta, -2.255213);
  // Odometry precedes its scan; times never go backwards in this log.
  EXPECT_EQ(log.channel_order[0], channels::kOdometry);
  EXPECT_EQ(log.channel_order[1], channels::kLaser);
  EXPECT_TRUE(s.warnings.empty());
}

TEST(CarmenTest, ConvertsEveryCorrectedLogWithGroundTruth) {
  const std::vector<std::pair<std::string, int>> logs = {{"intel-corrected.log.gz", 910},
                                                         {"aces-corrected.log.gz", 440},
                                                         {"csail-corrected.log.gz", 406}};
  for (const auto& [name, scans] : logs) {
    SCOPED_TRACE(name);
    const std::string in = Laser(name);
    FL_REQUIRE_SHARED_FILE(in);
    TempDir dir;
    const std::string out = dir.file("out.lcmlog");
    const ConvertSummary s = ConvertCarmen(CarmenOptions{}, in, out);
    EXPECT_EQ(s.messages.at(channels::kLaser), scans);
    EXPECT_EQ(s.messages.at(channels::kOdometry), scans);
    EXPECT_EQ(s.messages.at(channels::kGroundTruth), scans);
    // The reference is the line's corrected pose; the odometry differs from it (noise).
    const CarmenLog parsed = ReadCarmenLog(in);
    const auto log = fl::test::ReadLog(out);
    const size_t last = static_cast<size_t>(scans - 1);
    const auto gt = log.Decode<bot_core::pose_t>(channels::kGroundTruth, last);
    EXPECT_DOUBLE_EQ(gt.pos[0], parsed.scans[last].pose.x);
    EXPECT_DOUBLE_EQ(gt.pos[1], parsed.scans[last].pose.y);
    EXPECT_NEAR(2.0 * std::atan2(gt.orientation[3], gt.orientation[0]),
                parsed.scans[last].pose.theta, 1e-9);
    const auto odo = log.Decode<fusionloc::wheel_odometry_t>(channels::kOdometry, last);
    EXPECT_GT(std::hypot(odo.x - gt.pos[0], odo.y - gt.pos[1]), 0.01);
    const auto first = log.Decode<bot_core::planar_lidar_t>(channels::kLaser, 0);
    EXPECT_FLOAT_EQ(first.rad0, static_cast<float>(-M_PI / 2));
    EXPECT_FLOAT_EQ(first.radstep,
                    static_cast<float>(first.nranges >= 360 ? M_PI / 360 : M_PI / 180));
  }
}

TEST(CarmenTest, RecoversCsailCorrectedTimestampsFromTheRawLog) {
  const std::string in = Laser("csail-corrected.log.gz");
  const std::string raw = Laser("mit-csail.clf");
  FL_REQUIRE_SHARED_FILE(in);
  FL_REQUIRE_SHARED_FILE(raw);
  TempDir dir;
  // Without help: the log prints its stamps with 6 digits, so nearly all collide (warned).
  const ConvertSummary plain = ConvertCarmen(CarmenOptions{}, in, dir.file("a.lcmlog"));
  bool warned = false;
  for (const auto& w : plain.warnings) warned |= w.find("--timestamps-from") != std::string::npos;
  EXPECT_TRUE(warned);

  CarmenOptions opts;
  opts.timestamps_from = raw;
  const ConvertSummary s = ConvertCarmen(opts, in, dir.file("b.lcmlog"));
  EXPECT_EQ(s.messages.at(channels::kGroundTruth), 406);
  const auto log = fl::test::ReadLog(dir.file("b.lcmlog"));
  const auto& t = log.utimes.at(channels::kLaser);
  ASSERT_EQ(t.size(), 406u);
  EXPECT_EQ(t[0], 1134864642914187);  // raw scan 62 (line 64 of mit-csail.clf)
  for (size_t i = 1; i < t.size(); ++i) ASSERT_GT(t[i], t[i - 1]) << "scan " << i;
  EXPECT_EQ(log.utimes.at(channels::kGroundTruth), t);
}

TEST(CarmenTest, RawCsailGetsGroundTruthFromTheCorrectedLog) {
  const std::string raw = Laser("mit-csail.clf");
  const std::string ref = Laser("csail-corrected.log.gz");
  FL_REQUIRE_SHARED_FILE(raw);
  FL_REQUIRE_SHARED_FILE(ref);
  TempDir dir;
  CarmenOptions opts;
  opts.ground_truth_from = ref;
  const ConvertSummary s = ConvertCarmen(opts, raw, dir.file("o.lcmlog"));
  EXPECT_EQ(s.messages.at(channels::kLaser), 1988);
  EXPECT_EQ(s.messages.at(channels::kGroundTruth), 406);
  const auto log = fl::test::ReadLog(dir.file("o.lcmlog"));
  const auto& laser_t = log.utimes.at(channels::kLaser);
  const auto& gt_t = log.utimes.at(channels::kGroundTruth);
  EXPECT_EQ(gt_t[0], 1134864642914187);
  for (const Utime t : gt_t) {
    ASSERT_TRUE(std::binary_search(laser_t.begin(), laser_t.end(), t)) << t;
  }
  const CarmenLog corrected = ReadCarmenLog(ref);
  const auto gt = log.Decode<bot_core::pose_t>(channels::kGroundTruth, 405);
  EXPECT_DOUBLE_EQ(gt.pos[0], corrected.scans[405].pose.x);
  EXPECT_DOUBLE_EQ(gt.pos[1], corrected.scans[405].pose.y);
  // The raw log's own odometry is kept.
  const auto odo = log.Decode<fusionloc::wheel_odometry_t>(channels::kOdometry, 0);
  EXPECT_DOUBLE_EQ(odo.x, 576.536523);
  // The raw odometry's error against the reference is reported (docs/IMPORTERS.md).
  bool fitted = false;
  for (const auto& n : s.notes)
    fitted |= n.find("108 translation steps: a1 0.0474") != std::string::npos;
  EXPECT_TRUE(fitted);

  // Not for a corrected input, and not together with timestamps_from.
  EXPECT_THROW(ConvertCarmen(opts, ref, dir.file("p.lcmlog")), std::invalid_argument);
  opts.timestamps_from = raw;
  EXPECT_FALSE(opts.Validate().ok());
}

TEST(CarmenTest, UnmatchedScanInTimestampRecoveryIsAnError) {
  TempDir dir;
  fl::test::WriteText(dir.file("raw.clf"), fl::test::CarmenArcLog(5));
  std::string corrected = fl::test::CarmenArcLog(3);
  corrected += fl::test::CarmenFlaser(181, 7.5, 1, 1, 0, 200);  // not in the raw log
  fl::test::WriteText(dir.file("x-corrected.log"), corrected);
  CarmenOptions opts;
  opts.timestamps_from = dir.file("raw.clf");
  const std::string msg =
      ExpectConvertError(opts, dir.file("x-corrected.log"), dir.file("out.lcmlog"));
  EXPECT_NE(msg.find("x-corrected.log:6:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("same ranges"), std::string::npos) << msg;
}

TEST(CarmenTest, CorrectedDetectionByNameOrOption) {
  CarmenOptions o;
  EXPECT_TRUE(IsCorrectedCarmenLog(o, "/x/intel-CORRECTED.log.gz"));
  EXPECT_FALSE(IsCorrectedCarmenLog(o, "/corrected/mit-csail.clf"));  // the file name decides
  o.noisy_odometry = "true";
  EXPECT_TRUE(IsCorrectedCarmenLog(o, "raw.clf"));
  o.noisy_odometry = "false";
  EXPECT_FALSE(IsCorrectedCarmenLog(o, "intel-corrected.log"));
}

TEST(CarmenTest, RawLogKeepsOdomLinesInFileOrder) {
  TempDir dir;
  std::string text = fl::test::CarmenFlaser(5, 1.0, 1, 2, 0.1, 10.0);
  text += "ODOM 1.5 2.5 0.2 0.3 0.05 0 10.05 host 10.05\n";
  text += fl::test::CarmenFlaser(5, 1.0, 2, 3, 0.3, 10.1);
  fl::test::WriteText(dir.file("small.log"), text);
  const ConvertSummary s =
      ConvertCarmen(CarmenOptions{}, dir.file("small.log"), dir.file("o.lcmlog"));
  EXPECT_EQ(s.messages.at(channels::kOdometry), 3);
  EXPECT_EQ(s.messages.at(channels::kLaser), 2);
  const auto log = fl::test::ReadLog(dir.file("o.lcmlog"));
  const std::vector<std::string> expected = {channels::kOdometry, channels::kLaser,
                                             channels::kOdometry, channels::kOdometry,
                                             channels::kLaser};
  EXPECT_EQ(log.channel_order, expected);
  const auto mid = log.Decode<fusionloc::wheel_odometry_t>(channels::kOdometry, 1);
  EXPECT_DOUBLE_EQ(mid.x, 1.5);
  EXPECT_DOUBLE_EQ(mid.v, 0.3);
  EXPECT_DOUBLE_EQ(mid.omega, 0.05);
  EXPECT_EQ(mid.utime, 10050000);
  const auto last = log.Decode<fusionloc::wheel_odometry_t>(channels::kOdometry, 2);
  EXPECT_DOUBLE_EQ(last.x, 2.0);
  EXPECT_EQ(last.utime, 10100000);
  EXPECT_NEAR(last.omega, 0.2 / 0.1, 1e-9);  // from consecutive scan odometry
  EXPECT_TRUE(s.warnings.empty());

  text += "ODOM 1.5 2.5 0.2 0.3 0.05 0 10.0 host 10.0\n";  // earlier than the scan before
  fl::test::WriteText(dir.file("back.log"), text);
  const ConvertSummary b =
      ConvertCarmen(CarmenOptions{}, dir.file("back.log"), dir.file("b.lcmlog"));
  ASSERT_EQ(b.warnings.size(), 1u);
  EXPECT_NE(b.warnings[0].find("1 ODOM lines have a time stamp earlier"), std::string::npos);

  // x y theta drifting away from the odometry: a localised pose, flagged.
  std::string loc = fl::test::CarmenFlaser(5, 1.0, 0, 0, 0, 10.0, 0, 0, 0);
  loc += fl::test::CarmenFlaser(5, 1.0, 1.0, 0, 0, 10.1, 1.1, 0, 0.02);
  fl::test::WriteText(dir.file("loc.log"), loc);
  const ConvertSummary l =
      ConvertCarmen(CarmenOptions{}, dir.file("loc.log"), dir.file("l.lcmlog"));
  ASSERT_EQ(l.warnings.size(), 1u);
  EXPECT_NE(l.warnings[0].find("localised or corrected pose"), std::string::npos);
  EXPECT_TRUE(l.notes.empty());
}

// ROBOTLASER1 with n beams, m remissions, laser 0.2 m ahead of the robot.
std::string RobotLaser(int n, int m, double robot_x, double t) {
  std::ostringstream ss;
  ss << "ROBOTLASER1 0 -1.5 3.0 0.01 30 0.01 0 " << n;
  for (int i = 0; i < n; ++i) ss << " " << 1.0 + 0.1 * i;
  ss << " " << m;
  for (int i = 0; i < m; ++i) ss << " " << 10 * i;
  ss << " " << robot_x + 0.2 << " 0 0 " << robot_x << " 0 0 0.5 0 0.1 0.1 0 " << t << " host " << t
     << "\n";
  return ss.str();
}

TEST(CarmenTest, RobotLaser1Lines) {
  TempDir dir;
  fl::test::WriteText(dir.file("rl.log"), RobotLaser(4, 4, 0.0, 5.0) + RobotLaser(4, 0, 1.0, 5.5));
  const ConvertSummary s = ConvertCarmen(CarmenOptions{}, dir.file("rl.log"), dir.file("o.lcmlog"));
  EXPECT_EQ(s.messages.at(channels::kLaser), 2);
  ASSERT_EQ(s.notes.size(), 1u);
  EXPECT_NE(s.notes[0].find("(0.2 m, 0 m, 0 rad)"), std::string::npos) << s.notes[0];
  const auto log = fl::test::ReadLog(dir.file("o.lcmlog"));
  const auto scan = log.Decode<bot_core::planar_lidar_t>(channels::kLaser, 0);
  EXPECT_FLOAT_EQ(scan.rad0, -1.5f);
  EXPECT_FLOAT_EQ(scan.radstep, 0.01f);
  ASSERT_EQ(scan.nranges, 4);
  EXPECT_FLOAT_EQ(scan.ranges[3], 1.3f);
  ASSERT_EQ(scan.nintensities, 4);
  EXPECT_FLOAT_EQ(scan.intensities[2], 20.0f);
  EXPECT_EQ(log.Decode<bot_core::planar_lidar_t>(channels::kLaser, 1).nintensities, 0);
  const auto odo = log.Decode<fusionloc::wheel_odometry_t>(channels::kOdometry, 1);
  EXPECT_DOUBLE_EQ(odo.x, 1.0);  // the robot pose, not the laser pose
  EXPECT_NEAR(odo.v, 2.0, 1e-9);
  EXPECT_EQ(odo.utime, 5500000);

  // Cut short, and mixed with FLASER lines: errors naming the file (and line).
  const std::string cut = RobotLaser(4, 4, 0.0, 5.0);
  fl::test::WriteText(dir.file("cut.log"),
                      RobotLaser(4, 4, 0.0, 4.0) + cut.substr(0, 40) + "\n" + cut);
  const std::string msg =
      ExpectConvertError(CarmenOptions{}, dir.file("cut.log"), dir.file("p.lcmlog"));
  EXPECT_NE(msg.find("cut.log:2: truncated ROBOTLASER1 line"), std::string::npos) << msg;
  fl::test::WriteText(dir.file("mixed.log"),
                      RobotLaser(4, 4, 0.0, 4.0) + fl::test::CarmenFlaser(4, 1, 0, 0, 0, 4.0));
  const std::string msg2 =
      ExpectConvertError(CarmenOptions{}, dir.file("mixed.log"), dir.file("p.lcmlog"));
  EXPECT_NE(msg2.find("both FLASER (1) and ROBOTLASER1 (1)"), std::string::npos) << msg2;
}

TEST(CarmenTest, LoggerTimestampOption) {
  TempDir dir;
  fl::test::WriteText(dir.file("a.log"), fl::test::CarmenArcLog(2));
  CarmenOptions opts;
  opts.timestamp = "logger";
  ConvertCarmen(opts, dir.file("a.log"), dir.file("o.lcmlog"));
  const auto log = fl::test::ReadLog(dir.file("o.lcmlog"));
  EXPECT_EQ(log.utimes.at(channels::kLaser)[0], 100001000);  // 100.0 + 0.001 s
}

TEST(CarmenTest, NoiseIsDeterministicPerSeed) {
  TempDir dir;
  fl::test::WriteText(dir.file("arc-corrected.log"), fl::test::CarmenArcLog(50));
  CarmenOptions opts;
  opts.seed = 42;
  ConvertCarmen(opts, dir.file("arc-corrected.log"), dir.file("a.lcmlog"));
  ConvertCarmen(opts, dir.file("arc-corrected.log"), dir.file("b.lcmlog"));
  opts.seed = 43;
  ConvertCarmen(opts, dir.file("arc-corrected.log"), dir.file("c.lcmlog"));
  const std::string a = fl::test::ReadFileBytes(dir.file("a.lcmlog"));
  EXPECT_FALSE(a.empty());
  EXPECT_EQ(a, fl::test::ReadFileBytes(dir.file("b.lcmlog")));
  EXPECT_NE(a, fl::test::ReadFileBytes(dir.file("c.lcmlog")));
}

TEST(CarmenTest, NoiseHasTheDocumentedStatistics) {
  // A straight drive of 0.2 m steps: per-step errors of the noisy increments must have
  // sigma_xy = a1 * d and sigma_theta = a4 * d (no rotation), mean zero.
  std::vector<Pose2> truth;
  const int n = 20001;
  for (int k = 0; k < n; ++k) truth.emplace_back(0.2 * k, 0.0, 0.0);
  CarmenNoiseModel noise;
  const std::vector<Pose2> odom = SynthesizeNoisyOdometry(noise, 7, truth);
  ASSERT_EQ(odom.size(), truth.size());
  EXPECT_DOUBLE_EQ(odom[0].x, truth[0].x);
  double sx = 0, sxx = 0, syy = 0, stt = 0;
  for (int k = 1; k < n; ++k) {
    const Pose2 u = odom[k - 1].between(odom[k]);
    const double ex = u.x - 0.2, ey = u.y, et = u.theta;
    sx += ex;
    sxx += ex * ex;
    syy += ey * ey;
    stt += et * et;
  }
  const double m = n - 1;
  const double sigma_xy = noise.a1 * 0.2, sigma_th = noise.a4 * 0.2;
  EXPECT_NEAR(sx / m, 0.0, 4.0 * sigma_xy / std::sqrt(m));
  EXPECT_NEAR(std::sqrt(sxx / m), sigma_xy, 0.03 * sigma_xy);
  EXPECT_NEAR(std::sqrt(syy / m), sigma_xy, 0.03 * sigma_xy);
  EXPECT_NEAR(std::sqrt(stt / m), sigma_th, 0.03 * sigma_th);
}

TEST(CarmenTest, FitOdometryErrorRecoversTheNoiseModel) {
  // Alternating 0.5 m straight steps and 0.5 rad turns in place.
  std::vector<Pose2> truth = {Pose2()};
  for (int k = 0; k < 20000; ++k) {
    truth.push_back(truth.back() * (k % 2 == 0 ? Pose2(0.5, 0, 0) : Pose2(0, 0, 0.5)));
  }
  CarmenNoiseModel model;
  model.a1 = 0.05;
  model.a2 = 0.02;
  model.a3 = 0.1;
  model.a4 = 0.02;
  model.min_sigma_xy = model.min_sigma_theta = 0.0;
  const OdometryErrorFit fit = FitOdometryError(SynthesizeNoisyOdometry(model, 11, truth), truth);
  EXPECT_EQ(fit.translation_steps, 10000);
  EXPECT_EQ(fit.rotation_steps, 10000);
  EXPECT_NEAR(fit.a1, model.a1, 0.03 * model.a1);
  EXPECT_NEAR(fit.a2, model.a2, 0.03 * model.a2);
  EXPECT_NEAR(fit.a3, model.a3, 0.03 * model.a3);
  EXPECT_NEAR(fit.a4, model.a4, 0.03 * model.a4);
  EXPECT_NEAR(fit.scale_error, 0.0, 0.002);

  CarmenNoiseModel biased{};
  biased.a1 = biased.a2 = biased.a3 = biased.a4 = 0.0;
  biased.min_sigma_xy = biased.min_sigma_theta = 0.0;
  biased.scale_error = -0.015;
  biased.yaw_bias = 0.003;
  const OdometryErrorFit b = FitOdometryError(SynthesizeNoisyOdometry(biased, 1, truth), truth);
  EXPECT_NEAR(b.scale_error, -0.015, 1e-9);
  EXPECT_NEAR(b.yaw_bias, 0.003, 1e-9);
  EXPECT_THROW(FitOdometryError({Pose2()}, {}), std::invalid_argument);
}

TEST(CarmenTest, StandingStillGetsNoNoiseAndBiasIsApplied) {
  std::vector<Pose2> truth(10, Pose2(1.0, 2.0, 0.5));
  const auto still = SynthesizeNoisyOdometry(CarmenNoiseModel{}, 3, truth);
  for (const auto& p : still) {
    EXPECT_DOUBLE_EQ(p.x, 1.0);
    EXPECT_DOUBLE_EQ(p.y, 2.0);
    EXPECT_DOUBLE_EQ(p.theta, 0.5);
  }
  CarmenNoiseModel exact{};
  exact.a1 = exact.a2 = exact.a3 = exact.a4 = exact.min_sigma_xy = exact.min_sigma_theta = 0;
  exact.scale_error = 0.1;
  exact.yaw_bias = 0.01;
  const auto biased =
      SynthesizeNoisyOdometry(exact, 3, {Pose2(0, 0, 0), Pose2(1, 0, 0), Pose2(2, 0, 0)});
  EXPECT_NEAR(biased[1].x, 1.1, 1e-12);
  EXPECT_NEAR(biased[1].theta, 0.01, 1e-12);
  EXPECT_NEAR(biased[2].theta, 0.02, 1e-12);
}

TEST(CarmenTest, RawOptionKeepsTheLinesOdometry) {
  TempDir dir;
  fl::test::WriteText(dir.file("b-corrected.log"), fl::test::CarmenArcLog(5));
  CarmenOptions opts;
  opts.noisy_odometry = "false";
  const ConvertSummary s = ConvertCarmen(opts, dir.file("b-corrected.log"), dir.file("o.lcmlog"));
  EXPECT_EQ(s.messages.count(channels::kGroundTruth), 0u);
  const auto log = fl::test::ReadLog(dir.file("o.lcmlog"));
  const CarmenLog parsed = ReadCarmenLog(dir.file("b-corrected.log"));
  const auto odo = log.Decode<fusionloc::wheel_odometry_t>(channels::kOdometry, 4);
  EXPECT_DOUBLE_EQ(odo.x, parsed.scans[4].odom.x);
  EXPECT_DOUBLE_EQ(odo.theta, parsed.scans[4].odom.theta);
}

TEST(CarmenTest, TimeGoingBackwardsIsKeptAndCounted) {
  TempDir dir;
  std::string text = fl::test::CarmenFlaser(5, 1.0, 0, 0, 0, 10.0);
  text += fl::test::CarmenFlaser(5, 1.0, 0, 0, 0, 9.5);
  text += fl::test::CarmenFlaser(5, 1.0, 0, 0, 0, 9.5);
  fl::test::WriteText(dir.file("t.log"), text);
  CarmenOptions keep;
  keep.repeated_stamps = "keep";
  const ConvertSummary s = ConvertCarmen(keep, dir.file("t.log"), dir.file("o.lcmlog"));
  ASSERT_EQ(s.warnings.size(), 2u);
  EXPECT_NE(s.warnings[0].find("1 scans have a time stamp earlier"), std::string::npos);
  EXPECT_NE(s.warnings[1].find("1 scans share the time stamp"), std::string::npos);
  const auto log = fl::test::ReadLog(dir.file("o.lcmlog"));
  const std::vector<Utime> expected = {10000000, 9500000, 9500000};
  EXPECT_EQ(log.utimes.at(channels::kLaser), expected);
}

// A corrected log printed with 6 significant digits (csail-corrected.log.gz's shape: its 406
// scans share 2 stamps 10^4 s apart) is stamped by order, so that the scans, their synthetic
// odometry and the ground truth pair up one to one.
TEST(CarmenTest, RepeatedStampsOfACorrectedLogAreStampedByOrder) {
  TempDir dir;
  std::string text;
  for (int k = 0; k < 8; ++k) {
    text += fl::test::CarmenFlaser(181, 2.0 + 0.01 * k, 0.5 * k, 0, 0.1 * k,
                                   k < 6 ? 1.13486e9 : 1.13487e9);
  }
  fl::test::WriteText(dir.file("s-corrected.log"), text);
  const ConvertSummary s =
      ConvertCarmen(CarmenOptions{}, dir.file("s-corrected.log"), dir.file("o.lcmlog"));
  ASSERT_FALSE(s.warnings.empty());
  EXPECT_NE(s.warnings[0].find("6 of 8 scans repeat the time stamp"), std::string::npos)
      << s.warnings[0];
  EXPECT_NE(s.warnings[0].find("stamped by its order instead, 1.0 s apart"), std::string::npos);
  const auto log = fl::test::ReadLog(dir.file("o.lcmlog"));
  const std::vector<Utime>& laser = log.utimes.at(channels::kLaser);
  ASSERT_EQ(laser.size(), 8u);
  for (size_t k = 0; k < laser.size(); ++k) {
    EXPECT_EQ(laser[k], 1134860000000000 + static_cast<Utime>(k) * 1000000) << k;
  }
  EXPECT_EQ(log.utimes.at(channels::kGroundTruth), laser);
  EXPECT_EQ(log.utimes.at(channels::kOdometry), laser);
  // The ground truth keeps each scan's own pose, in order.
  const auto gt = log.Decode<bot_core::pose_t>(channels::kGroundTruth, 5);
  EXPECT_NEAR(gt.pos[0], 2.5, 1e-9);

  // keep: the stamps as printed; by_order with another spacing.
  CarmenOptions keep;
  keep.repeated_stamps = "keep";
  ConvertCarmen(keep, dir.file("s-corrected.log"), dir.file("k.lcmlog"));
  const auto kept = fl::test::ReadLog(dir.file("k.lcmlog")).utimes.at(channels::kLaser);
  EXPECT_EQ(kept[0], kept[5]);
  CarmenOptions fast;
  fast.by_order_interval_s = 0.1;
  ConvertCarmen(fast, dir.file("s-corrected.log"), dir.file("f.lcmlog"));
  const auto spaced = fl::test::ReadLog(dir.file("f.lcmlog")).utimes.at(channels::kLaser);
  EXPECT_EQ(spaced[7] - spaced[0], 700000);
}

TEST(CarmenTest, AFewRepeatedStampsAreKeptUnderAuto) {
  TempDir dir;
  std::string text;
  for (int k = 0; k < 8; ++k) {
    text += fl::test::CarmenFlaser(181, 2.0, 0.5 * k, 0, 0, 10.0 + (k == 4 ? 0.3 : 0.1 * k));
  }
  fl::test::WriteText(dir.file("a-corrected.log"), text);
  const ConvertSummary s =
      ConvertCarmen(CarmenOptions{}, dir.file("a-corrected.log"), dir.file("o.lcmlog"));
  const auto laser = fl::test::ReadLog(dir.file("o.lcmlog")).utimes.at(channels::kLaser);
  EXPECT_EQ(laser[3], laser[4]);  // 1 of 8: kept and warned
  bool warned = false;
  for (const auto& w : s.warnings) warned |= w.find("1 scans share the time stamp") != std::string::npos;
  EXPECT_TRUE(warned);
}

TEST(CarmenOptionsTest, RepeatedStampsSettingsAreValidated) {
  CarmenOptions o;
  o.repeated_stamps = "spread";
  EXPECT_NE(o.Validate().message().find("auto, keep, by_order"), std::string::npos);
  o = CarmenOptions{};
  o.by_order_interval_s = 0.0;
  EXPECT_FALSE(o.Validate().ok());
}

// ---- bad input ----

TEST(CarmenBadInputTest, TruncatedLineNamesFileAndLine) {
  TempDir dir;
  std::string text = fl::test::CarmenArcLog(3);  // lines 1-2 header, 3-5 scans
  const std::string line = fl::test::CarmenFlaser(181, 2.0, 0, 0, 0, 50.0);
  text += line.substr(0, line.size() / 2) + "\n";  // line 6: cut short, and more follows
  text += fl::test::CarmenFlaser(181, 2.0, 0, 0, 0, 51.0);
  fl::test::WriteText(dir.file("cut.log"), text);
  const std::string msg =
      ExpectConvertError(CarmenOptions{}, dir.file("cut.log"), dir.file("o.lcmlog"));
  EXPECT_NE(msg.find(dir.file("cut.log") + ":6:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("truncated FLASER line"), std::string::npos) << msg;
}

// Real files in the wild (docs/RELIABILITY.md).

// A log cut short while it was written: its incomplete last line is dropped with a warning
// naming FILE:LINE, and everything before it converted.
TEST(CarmenWildFilesTest, TruncatedLastLineIsDroppedWithAWarning) {
  TempDir dir;
  std::string text = fl::test::CarmenArcLog(3);  // lines 1-2 header, 3-5 scans
  const std::string line = fl::test::CarmenFlaser(181, 2.0, 0, 0, 0, 50.0);
  for (const std::string& cut : {line.substr(0, line.size() / 2),       // no newline at all
                                 line.substr(0, line.size() / 2) + "\n",  // cut at a field
                                 std::string("ODOM 1.0 2.0 0.1 0")}) {
    fl::test::WriteText(dir.file("cut.log"), text + cut);
    const CarmenLog log = ReadCarmenLog(dir.file("cut.log"));
    EXPECT_EQ(log.scans.size(), 3u) << cut;
    EXPECT_EQ(log.dropped_last_line, 6) << cut;
    const ConvertSummary s = ConvertCarmen(CarmenOptions{}, dir.file("cut.log"), dir.file("o.lcmlog"));
    EXPECT_EQ(s.messages.at(channels::kLaser), 3);
    ASSERT_FALSE(s.warnings.empty());
    EXPECT_NE(s.warnings.back().find(dir.file("cut.log") + ":6"), std::string::npos)
        << s.warnings.back();
  }
  // A complete log has nothing dropped; a last line that is complete but wrong (a bad number,
  // too many fields) is still an error.
  fl::test::WriteText(dir.file("whole.log"), text);
  EXPECT_EQ(ReadCarmenLog(dir.file("whole.log")).dropped_last_line, 0);
  fl::test::WriteText(dir.file("bad-last.log"), text + "ODOM 1 2 x 0 0 0 1 h 1\n");
  const std::string msg =
      ExpectConvertError(CarmenOptions{}, dir.file("bad-last.log"), dir.file("bad.lcmlog"));
  EXPECT_NE(msg.find("bad-last.log:6: ODOM field 'theta'"), std::string::npos) << msg;
}

// CARMEN loggers print tiny values such as 9.53173e-312 (subnormal: strtod says ERANGE): they
// are numbers and are read; inf, nan and overflow are still errors naming the field.
TEST(CarmenWildFilesTest, SubnormalNumbersAreAccepted) {
  TempDir dir;
  fl::test::WriteText(dir.file("sub.log"),
                      "FLASER 3 1.0 2.0 3.0 0 0 9.53173e-312 4.9e-324 0 -2.2e-310 10.0 host 1e-320\n"
                      "ODOM 1e-315 0 0 0 0 0 10.5 host 1e-400\n");
  const CarmenLog log = ReadCarmenLog(dir.file("sub.log"));
  ASSERT_EQ(log.scans.size(), 1u);
  EXPECT_DOUBLE_EQ(log.scans[0].pose.theta, 9.53173e-312);
  EXPECT_GT(log.scans[0].pose.theta, 0.0);
  EXPECT_LT(log.scans[0].odom.theta, 0.0);
  EXPECT_EQ(log.scans[0].utime, 10000000);
  ASSERT_EQ(log.odom.size(), 1u);
  EXPECT_DOUBLE_EQ(log.odom[0].pose.x, 1e-315);
  EXPECT_EQ(ConvertCarmen(CarmenOptions{}, dir.file("sub.log"), dir.file("o.lcmlog"))
                .messages.at(channels::kLaser),
            1);
  for (const char* bad : {"inf", "nan", "1e400", "-1e999"}) {
    fl::test::WriteText(dir.file("bad.log"), std::string("FLASER 3 1.0 2.0 3.0 0 0 ") + bad +
                                                 " 0 0 0 10.0 host 1.0\n" +
                                                 "FLASER 3 1 1 1 0 0 0 0 0 0 11.0 host 1.0\n");
    const std::string msg =
        ExpectConvertError(CarmenOptions{}, dir.file("bad.log"), dir.file("bad.lcmlog"));
    EXPECT_NE(msg.find("bad.log:1: FLASER field 'theta'"), std::string::npos) << msg;
  }
}

// Lines the conversion ignores (other message types, comments, blank or odd lines) never
// abort it, whatever they hold; they are counted per type.
TEST(CarmenWildFilesTest, IgnoredLinesNeverAbortTheConversion) {
  TempDir dir;
  std::string text = "# CARMEN Logfile\r\n";
  text += "PARAM robot_front_laser_max 81.9 nohost 0.0\r\n";
  text += "   \t  \n\n";
  text += "RAWLASER1 0 -1.57 3.14 0.0174 81.9 0.01 0 3 x y z 0 123.4 host 1e-400\n";
  text += "NEFF nan inf -\n";
  text += "SYNC\n";
  text += "TRUEPOS 1 2 3 4 5 6 " + std::string(20000, '9') + "\n";  // longer than a read buffer
  text += std::string("\x01\x02\xff\xfe garbage\n");
  text += "  # an indented comment FLASER 1 x\n";
  text += fl::test::CarmenFlaser(5, 1.0, 0, 0, 0, 10.0);
  text += "flaser 3 not FLASER (case matters)\n";
  text += fl::test::CarmenFlaser(5, 1.0, 0.1, 0, 0, 10.1);
  fl::test::WriteText(dir.file("odd.log"), text);
  const CarmenLog log = ReadCarmenLog(dir.file("odd.log"));
  EXPECT_EQ(log.scans.size(), 2u);
  EXPECT_EQ(log.skipped_types.at("PARAM"), 1);
  EXPECT_EQ(log.skipped_types.at("RAWLASER1"), 1);
  EXPECT_EQ(log.skipped_types.at("NEFF"), 1);
  EXPECT_EQ(log.skipped_types.at("TRUEPOS"), 1);
  EXPECT_EQ(log.skipped_types.at("flaser"), 1);
  EXPECT_EQ(log.dropped_last_line, 0);
  const ConvertSummary s = ConvertCarmen(CarmenOptions{}, dir.file("odd.log"), dir.file("o.lcmlog"));
  EXPECT_EQ(s.messages.at(channels::kLaser), 2);
}

TEST(CarmenBadInputTest, NonNumericField) {
  TempDir dir;
  std::string text = fl::test::CarmenFlaser(5, 1.0, 0, 0, 0, 10.0);
  text += "FLASER 5 1.0 1.0 abc 1.0 1.0 0 0 0 0 0 0 11.0 host 11.0\n";
  fl::test::WriteText(dir.file("nan.log"), text);
  const std::string msg =
      ExpectConvertError(CarmenOptions{}, dir.file("nan.log"), dir.file("o.lcmlog"));
  EXPECT_NE(msg.find("nan.log:2:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("'abc'"), std::string::npos) << msg;

  fl::test::WriteText(dir.file("odom.log"),
                      text.substr(0, text.find('\n') + 1) + "ODOM 1 2 x 0 0 0 1 h 1\n");
  const std::string msg2 =
      ExpectConvertError(CarmenOptions{}, dir.file("odom.log"), dir.file("o.lcmlog"));
  EXPECT_NE(msg2.find("odom.log:2: ODOM field 'theta'"), std::string::npos) << msg2;

  fl::test::WriteText(dir.file("n.log"), "FLASER five 1 2 3 4 5 0 0 0 0 0 0 1 h 1\n");
  const std::string msg3 =
      ExpectConvertError(CarmenOptions{}, dir.file("n.log"), dir.file("o.lcmlog"));
  EXPECT_NE(msg3.find("n.log:1: FLASER beam count 'five'"), std::string::npos) << msg3;
}

TEST(CarmenBadInputTest, BeamCountDoesNotMatchN) {
  TempDir dir;
  // n says 4 but 5 ranges follow: one field too many.
  fl::test::WriteText(dir.file("n.log"), "# c\nFLASER 4 1 1 1 1 1 0 0 0 0 0 0 10.0 host 10.0\n");
  const std::string msg =
      ExpectConvertError(CarmenOptions{}, dir.file("n.log"), dir.file("o.lcmlog"));
  EXPECT_NE(msg.find("n.log:2:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("n = 4 beams need 15"), std::string::npos) << msg;
}

TEST(CarmenBadInputTest, EmptyFileAndMissingFile) {
  TempDir dir;
  fl::test::WriteText(dir.file("empty.log"), "");
  const std::string msg =
      ExpectConvertError(CarmenOptions{}, dir.file("empty.log"), dir.file("o.lcmlog"));
  EXPECT_NE(msg.find("empty.log: no FLASER or ROBOTLASER1 line"), std::string::npos) << msg;
  fl::test::WriteText(dir.file("params.log"), "PARAM a 1 h 0\nPARAM b 2 h 0\n");
  const std::string msg2 =
      ExpectConvertError(CarmenOptions{}, dir.file("params.log"), dir.file("o.lcmlog"));
  EXPECT_NE(msg2.find("PARAM x2"), std::string::npos) << msg2;
  const std::string msg3 =
      ExpectConvertError(CarmenOptions{}, dir.file("nope.log"), dir.file("o.lcmlog"));
  EXPECT_NE(msg3.find("nope.log: no such file"), std::string::npos) << msg3;
}

TEST(CarmenBadInputTest, TruncatedGzip) {
  TempDir dir;
  const std::string text = fl::test::CarmenArcLog(400);
  {
    gzFile gz = gzopen(dir.file("full.log.gz").c_str(), "wb");
    ASSERT_NE(gz, nullptr);
    ASSERT_EQ(gzwrite(gz, text.data(), static_cast<unsigned>(text.size())),
              static_cast<int>(text.size()));
    gzclose(gz);
  }
  const std::string bytes = fl::test::ReadFileBytes(dir.file("full.log.gz"));
  // The whole file reads back the same through the gzip path.
  EXPECT_EQ(ReadCarmenLog(dir.file("full.log.gz")).scans.size(), 400u);
  fl::test::WriteText(dir.file("cut-corrected.log.gz"), bytes.substr(0, bytes.size() / 2));
  const std::string msg =
      ExpectConvertError(CarmenOptions{}, dir.file("cut-corrected.log.gz"), dir.file("o.lcmlog"));
  EXPECT_NE(msg.find("cut-corrected.log.gz:"), std::string::npos) << msg;
  EXPECT_TRUE(msg.find("truncated") != std::string::npos) << msg;
}

TEST(CarmenBadInputTest, InvalidOptions) {
  CarmenOptions o;
  o.noisy_odometry = "maybe";
  EXPECT_NE(o.Validate().message().find("noisy_odometry"), std::string::npos);
  o = CarmenOptions{};
  o.noise.a1 = -1;
  EXPECT_NE(o.Validate().message().find("noise.a1"), std::string::npos);
  o = CarmenOptions{};
  o.timestamp = "gps";
  EXPECT_FALSE(o.Validate().ok());
  EXPECT_THROW(ConvertCarmen(o, "in.log", "out.lcmlog"), std::invalid_argument);
  // YAML round trip of the defaults, and an unknown key is rejected.
  const CarmenOptions back = LoadYamlString<CarmenOptions>(SaveYamlString(CarmenOptions{}));
  EXPECT_EQ(back.noise.a3, CarmenOptions{}.noise.a3);
  EXPECT_THROW(LoadYamlString<CarmenOptions>("noise: {a5: 1}"), ConfigError);
}

}  // namespace
}  // namespace fl::importers
