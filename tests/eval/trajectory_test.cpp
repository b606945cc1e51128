#include "fusionloc/eval/trajectory.hpp"

#include <gtest/gtest.h>

#include <fstream>

#include "bot_core/planar_lidar_t.hpp"
#include "bot_core/pose_t.hpp"
#include "eval_fixtures.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/eval/metrics.hpp"
#include "fusionloc/fused_pose_t.hpp"
#include "fusionloc/trajectory_t.hpp"
#include "fusionloc/wheel_odometry_t.hpp"
#include "test_paths.hpp"

namespace fl::eval {
namespace {

void WriteText(const std::string& path, const std::string& text) {
  std::ofstream f(path);
  f << text;
}

std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const EvalError& e) {
    return e.what();
  }
  return "(no EvalError thrown)";
}

TEST(EvalReadText, TumValuesAndQuaternionOrder) {
  fl::test::TempDir dir;
  const double h = std::sqrt(0.5);
  WriteText(dir.file("a.tum"),
            "# timestamp tx ty tz qx qy qz qw\n\n"
            "1305031102.175304 1.0 2.0 3.0 0 0 0 1\n"
            "1305031102.275304 1.5 2.0 3.0 0 0 " +
                std::to_string(h) + " " + std::to_string(h) + "\n");
  const Trajectory t = ReadTrajectoryText(dir.file("a.tum"));
  ASSERT_EQ(t.size(), 2u);
  EXPECT_EQ(t[0].utime, 1305031102175304);
  EXPECT_EQ(t[1].utime, 1305031102275304);
  EXPECT_TRUE(t[0].T_world_base.translation().isApprox(Eigen::Vector3d(1, 2, 3)));
  EXPECT_NEAR(Yaw(t[1].T_world_base), M_PI / 2, 1e-6);  // qz = qw = sqrt(1/2): 90 deg yaw

  // Round trip through the writer.
  const Trajectory helix = fl::test::MakeHelixTrajectory(20);
  WriteTrajectoryTum(helix, dir.file("h.tum"));
  const Trajectory back = ReadTrajectoryText(dir.file("h.tum"), "tum");
  ASSERT_EQ(back.size(), helix.size());
  for (size_t i = 0; i < helix.size(); ++i) {
    EXPECT_EQ(back[i].utime, helix[i].utime);
    EXPECT_TRUE(back[i].T_world_base.isApprox(helix[i].T_world_base, 1e-7));
  }
}

TEST(EvalReadText, KittiWithAndWithoutTimes) {
  fl::test::TempDir dir;
  WriteText(dir.file("k.txt"),
            "1 0 0 0.5 0 1 0 0 0 0 1 1.0\n"
            "0 -1 0 1.5 1 0 0 0 0 0 1 2.0\n"
            "1 0 0 2.5 0 1 0 0 0 0 1 3.0\n");
  Trajectory t = ReadTrajectoryText(dir.file("k.txt"));
  ASSERT_EQ(t.size(), 3u);
  EXPECT_EQ(t[0].utime, 0);
  EXPECT_EQ(t[2].utime, 2 * kKittiDefaultFramePeriodUs);
  EXPECT_TRUE(t[1].T_world_base.translation().isApprox(Eigen::Vector3d(1.5, 0, 2.0)));
  EXPECT_NEAR(Yaw(t[1].T_world_base), M_PI / 2, 1e-12);

  WriteText(dir.file("times.txt"),
            "2011-09-26 13:02:25.967790592\n2011-09-26 13:02:26.070920448\n"
            "2011-09-26 13:02:26.174049536\n");
  t = ReadTrajectoryText(dir.file("k.txt"), "kitti", dir.file("times.txt"));
  EXPECT_EQ(t[0].utime, 1317042145967791);  // 2011-09-26T13:02:25Z = 1317042145 s
  EXPECT_EQ(t[1].utime - t[0].utime, 103129);
  WriteText(dir.file("secs.txt"), "0.0\n0.1\n");
  const std::string msg =
      ErrorOf([&] { ReadTrajectoryText(dir.file("k.txt"), "kitti", dir.file("secs.txt")); });
  EXPECT_NE(msg.find("has 2 times but"), std::string::npos) << msg;

  WriteText(dir.file("notrot.txt"), "2 0 0 0 0 1 0 0 0 0 1 0\n");
  EXPECT_NE(
      ErrorOf([&] { ReadTrajectoryText(dir.file("notrot.txt"), "kitti"); }).find("not a rotation"),
      std::string::npos);
}

TEST(EvalReadText, Planar2d) {
  fl::test::TempDir dir;
  WriteText(dir.file("p.txt"), "1.5 1 2 0.5\n2.5,3,4,-0.25\n");
  const Trajectory t = ReadTrajectoryText(dir.file("p.txt"), "2d");
  ASSERT_EQ(t.size(), 2u);
  EXPECT_EQ(t[0].utime, 1500000);
  EXPECT_TRUE(t[1].T_world_base.translation().isApprox(Eigen::Vector3d(3, 4, 0)));
  EXPECT_NEAR(Yaw(t[0].T_world_base), 0.5, 1e-12);
  EXPECT_NEAR(Yaw(t[1].T_world_base), -0.25, 1e-12);
}

TEST(EvalReadText, BadInputsNameFileAndLine) {
  fl::test::TempDir dir;
  WriteText(dir.file("nan.txt"), "0 0 0 0\n1 nan 0 0\n");
  std::string msg = ErrorOf([&] { ReadTrajectoryText(dir.file("nan.txt")); });
  EXPECT_NE(msg.find("nan.txt:2"), std::string::npos) << msg;
  EXPECT_NE(msg.find("NaN"), std::string::npos) << msg;

  WriteText(dir.file("five.txt"), "0 1 2 3 4\n");
  msg = ErrorOf([&] { ReadTrajectoryText(dir.file("five.txt")); });
  EXPECT_NE(msg.find("cannot tell the trajectory format"), std::string::npos) << msg;

  EXPECT_NE(ErrorOf([&] {
              ReadTrajectoryText(dir.file("five.txt"), "euroc");
            }).find("unknown trajectory format 'euroc'"),
            std::string::npos);

  WriteText(dir.file("back.txt"), "0 0 0 0\n2 0 0 0\n1 0 0 0\n");
  msg = ErrorOf([&] { ReadTrajectoryText(dir.file("back.txt")); });
  EXPECT_NE(msg.find("back.txt:3"), std::string::npos) << msg;
  EXPECT_NE(msg.find("sorted"), std::string::npos) << msg;

  WriteText(dir.file("word.txt"), "0 0 0 zero\n");
  EXPECT_NE(
      ErrorOf([&] { ReadTrajectoryText(dir.file("word.txt")); }).find("'zero' is not a number"),
      std::string::npos);

  WriteText(dir.file("empty.txt"), "# nothing\n\n");
  EXPECT_NE(ErrorOf([&] { ReadTrajectoryText(dir.file("empty.txt")); }).find("no poses"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { ReadTrajectoryText(dir.file("missing.txt")); }).find("cannot open"),
            std::string::npos);

  WriteText(dir.file("mixed.txt"), "0 0 0 0\n1 0 0 0 0 0 0 1\n");
  EXPECT_NE(ErrorOf([&] { ReadTrajectoryText(dir.file("mixed.txt")); }).find("expected 4 values"),
            std::string::npos);
}

TEST(EvalReadLcm, PoseFusedAndTrajectoryChannels) {
  fl::test::TempDir dir;
  const std::string log = dir.file("run.lcmlog");
  {
    LcmLogWriter w(log);
    for (int i = 0; i < 5; ++i) {
      bot_core::pose_t p{};
      p.utime = 1000000 + i * 100000;
      p.pos[0] = i;
      p.pos[1] = 2.0;
      p.orientation[0] = std::cos(0.05 * i);
      p.orientation[3] = std::sin(0.05 * i);  // yaw 0.1 i
      w.Write("GROUND_TRUTH", p, p.utime + 50);

      fusionloc::fused_pose_t f{};
      f.utime = p.utime;
      f.x = i + 0.5;
      f.theta = -0.1 * i;
      w.Write("FUSED_POSE", f, p.utime + 100);

      fusionloc::wheel_odometry_t o{};
      o.utime = p.utime;
      o.x = 2.0 * i;
      o.theta = 0.05;
      w.Write("ODOMETRY", o, p.utime);

      bot_core::planar_lidar_t scan{};
      scan.utime = p.utime;
      w.Write("LASER", scan, p.utime);
    }
    for (int k = 1; k <= 2; ++k) {  // two optimisations; the last one counts
      fusionloc::trajectory_t t{};
      t.utime = 2000000 + k;
      t.num_poses = 3 * k;
      for (int i = 0; i < t.num_poses; ++i) {
        t.utimes.push_back(1000000 + i * 100000);
        t.x.push_back(10.0 * k + i);
        t.y.push_back(0.0);
        t.z.push_back(0.0);
        t.theta.push_back(0.0);
      }
      w.Write("FUSED_TRAJECTORY", t, t.utime);
    }
    // The fusion's periodic messages carry the latest part of the trajectory (trajectory_t.lcm):
    // poses 0-3, then 2-5 re-estimated; merged, 0-1 of the first and 2-5 of the second.
    for (int k = 0; k < 2; ++k) {
      fusionloc::trajectory_t t{};
      t.utime = 3000000 + k;
      t.num_poses = 4;
      for (int i = 2 * k; i < 2 * k + 4; ++i) {
        t.utimes.push_back(1000000 + i * 100000);
        t.x.push_back(100.0 * (k + 1) + i);
        t.y.push_back(0.0);
        t.z.push_back(0.0);
        t.theta.push_back(0.0);
      }
      w.Write("PARTIAL_TRAJECTORY", t, t.utime);
    }
    w.Close();
  }
  ASSERT_TRUE(IsLcmLog(log));
  const Trajectory gt = ReadTrajectoryLcm(log, "GROUND_TRUTH");
  ASSERT_EQ(gt.size(), 5u);
  EXPECT_EQ(gt[3].utime, 1300000);  // message time of validity, not log time
  EXPECT_TRUE(gt[3].T_world_base.translation().isApprox(Eigen::Vector3d(3, 2, 0)));
  EXPECT_NEAR(Yaw(gt[3].T_world_base), 0.3, 1e-12);

  const Trajectory fused = ReadTrajectory(log, "FUSED_POSE");
  ASSERT_EQ(fused.size(), 5u);
  EXPECT_NEAR(fused[2].T_world_base.translation().x(), 2.5, 1e-12);
  EXPECT_NEAR(Yaw(fused[2].T_world_base), -0.2, 1e-12);

  const Trajectory odom = ReadTrajectoryLcm(log, "ODOMETRY");
  ASSERT_EQ(odom.size(), 5u);
  EXPECT_NEAR(odom[4].T_world_base.translation().x(), 8.0, 1e-12);
  EXPECT_NEAR(Yaw(odom[4].T_world_base), 0.05, 1e-12);

  const Trajectory traj = ReadTrajectoryLcm(log, "FUSED_TRAJECTORY");
  ASSERT_EQ(traj.size(), 6u);
  EXPECT_NEAR(traj[0].T_world_base.translation().x(), 20.0, 1e-12);
  const Trajectory partial = ReadTrajectoryLcm(log, "PARTIAL_TRAJECTORY");
  ASSERT_EQ(partial.size(), 6u);
  EXPECT_NEAR(partial[1].T_world_base.translation().x(), 101.0, 1e-12);
  EXPECT_NEAR(partial[2].T_world_base.translation().x(), 202.0, 1e-12);
  EXPECT_NEAR(partial[5].T_world_base.translation().x(), 205.0, 1e-12);

  std::string msg = ErrorOf([&] { ReadTrajectoryLcm(log, "VO_POSE"); });
  EXPECT_NE(msg.find("channel 'VO_POSE' not found"), std::string::npos) << msg;
  EXPECT_NE(msg.find("GROUND_TRUTH (5)"), std::string::npos) << msg;
  msg = ErrorOf([&] { ReadTrajectoryLcm(log, "LASER"); });
  EXPECT_NE(msg.find("carries bot_core.planar_lidar_t, not a pose type"), std::string::npos) << msg;
  EXPECT_NE(ErrorOf([&] { ReadTrajectoryText(log); }).find("is an LCM log"), std::string::npos);

  // Log trajectories evaluate against each other.
  const AteResult ate = ComputeAte(fused, gt, Alignment::kNone, 1000);
  EXPECT_NEAR(ate.trans_m.rmse, std::sqrt(0.25 + 4.0), 1e-9);
}

TEST(EvalReadLcm, NaNPoseIsAnError) {
  fl::test::TempDir dir;
  const std::string log = dir.file("nan.lcmlog");
  {
    LcmLogWriter w(log);
    fusionloc::fused_pose_t f{};
    f.utime = 5;
    f.x = std::nan("");
    w.Write("FUSED_POSE", f, 5);
    w.Close();
  }
  EXPECT_NE(ErrorOf([&] { ReadTrajectoryLcm(log, "FUSED_POSE"); }).find("NaN"), std::string::npos);
}

TEST(EvalReadText, RealKittiGroundTruth) {
  const std::string dir = fl::test::SharedDataDir() + "/stereo/kitti_raw_2011_09_26_drive_0001";
  FL_REQUIRE_SHARED_FILE(dir + "/poses_cam0_from_oxts.txt");
  const Trajectory t = ReadTrajectoryText(dir + "/poses_cam0_from_oxts.txt", "auto",
                                          dir + "/image_00/timestamps.txt");
  ASSERT_EQ(t.size(), 108u);
  EXPECT_NEAR(PathLength(t), 107.0, 3.0);
  EXPECT_NEAR(UtimeToSeconds(t.back().utime - t.front().utime), 11.04, 0.01);  // ~9.7 Hz
}

}  // namespace
}  // namespace fl::eval
