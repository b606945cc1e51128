// End-to-end test of the fl-fusion process: a synthetic LCM log in, replayed through the
// program (log:IN,OUT), the fused outputs and the saved map checked.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <map>

#include "bot_core/pose_t.hpp"
#include "bot_core/rigid_transform_t.hpp"
#include "fusion_fixtures.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/fused_pose_t.hpp"
#include "fusionloc/point_cloud_t.hpp"
#include "fusionloc/relative_pose_factor_t.hpp"
#include "fusionloc/trajectory_t.hpp"
#include "test_paths.hpp"

namespace fl::fusion {
namespace {

fusionloc::relative_pose_factor_t ToMsg(const RelativePoseFactor& f) {
  fusionloc::relative_pose_factor_t m{};
  m.utime_i = f.utime_i;
  m.utime_j = f.utime_j;
  IsometryToArrays(f.T_i_j, m.trans, m.quat);
  for (int k = 0; k < 36; ++k) m.information[k] = f.information(k / 6, k % 6);
  m.source = static_cast<int8_t>(f.source);
  m.is_loop_closure = f.is_loop_closure;
  m.keyframe_id_i = -1;
  m.keyframe_id_j = -1;
  return m;
}

int RunFusion(const std::string& args) {
  const std::string cmd = fl::test::BinDir() + "/fl-fusion " + args + " > /dev/null 2>&1";
  return std::system(cmd.c_str());
}

TEST(FusionMain, ReplaysALogAndPublishesFusedOutputsAndMap) {
  fl::test::TempDir dir;
  fl::test::FusionSimOptions so;
  so.laser_sigma_xy = 0.01;
  so.vision_sigma_xy = 0.01;
  const fl::test::FusionSimData d = fl::test::MakeRoundedSquareSim(so);
  const std::string in = dir.file("in.lcmlog");
  {
    LcmLogWriter log(in);
    bot_core::rigid_transform_t camera_to_base{};  // T_base_camera: 0.2 m ahead, 0.5 m up,
    camera_to_base.utime = d.rbpf.front().utime;   // optical axes: z forward, x right
    const Eigen::Matrix3d R_base_camera =
        (Eigen::Matrix3d() << 0, 0, 1, -1, 0, 0, 0, -1, 0).finished();
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = R_base_camera;
    T.translation() = Eigen::Vector3d(0.2, 0, 0.5);
    IsometryToArrays(T, camera_to_base.trans, camera_to_base.quat);
    log.Write("CAMERA_TO_BASE", camera_to_base, camera_to_base.utime);
    size_t lf = 0, vf = 0;
    for (size_t k = 0; k < d.rbpf.size(); ++k) {
      const Utime t = d.rbpf[k].utime;
      bot_core::pose_t pose{};
      pose.utime = t;
      IsometryToArrays(d.rbpf[k].T_map_base.ToIsometry3(), pose.pos, pose.orientation);
      log.Write("RBPF_POSE", pose, t);
      while (lf < d.laser_factors.size() && d.laser_factors[lf].utime_j <= t) {
        log.Write("RBPF_FACTORS", ToMsg(d.laser_factors[lf++]), t);
      }
      while (vf < d.vision_factors.size() && d.vision_factors[vf].utime_j <= t + 20000) {
        // Vision factors arrive early (before their laser node): they must wait.
        log.Write("VO_FACTORS", ToMsg(d.vision_factors[vf++]), t);
      }
      if (k % 5 == 0) {
        // A keyframe: a wall 3 m ahead of the camera (camera frame), 50 points.
        fusionloc::point_cloud_t pc{};
        pc.utime = t;
        pc.frame = "camera";
        for (int p = 0; p < 50; ++p) pc.points.push_back({-1.0f + 0.04f * p, 0.0f, 3.0f});
        pc.num_points = static_cast<int32_t>(pc.points.size());
        log.Write("VO_POINTS", pc, t);
      }
    }
    // Bad input: a factor with a zero quaternion, and a wrongly typed message.
    fusionloc::relative_pose_factor_t bad = ToMsg(d.laser_factors[3]);
    bad.quat[0] = 0;
    log.Write("RBPF_FACTORS", bad, d.rbpf.back().utime);
    log.Write("RBPF_POSE", "garbage", 7, d.rbpf.back().utime);
    for (const auto& f : d.loop_factors) log.Write("RBPF_FACTORS", ToMsg(f), d.rbpf.back().utime);
    log.Close();
  }
  const std::string out = dir.file("out.lcmlog");
  const std::string map = dir.file("maps/fused");
  ASSERT_EQ(RunFusion("--lcm-url log:" + in + "," + out + " --map-out " + map), 0);
  ASSERT_TRUE(std::filesystem::exists(out));
  EXPECT_TRUE(std::filesystem::exists(map + ".pcd"));
  EXPECT_TRUE(std::filesystem::exists(map + "_top.png"));

  LcmLogReader reader(out);
  LcmLogEvent ev;
  int poses = 0;
  fusionloc::trajectory_t last_traj;
  int trajectories = 0;
  bool map_published = false;
  while (reader.Next(&ev)) {
    const int size = static_cast<int>(ev.data.size());
    if (ev.channel == "FUSED_POSE") {
      fusionloc::fused_pose_t m;
      ASSERT_EQ(m.decode(ev.data.data(), 0, size), size);
      EXPECT_EQ(m.utime, d.rbpf[poses].utime);  // one per laser pose, stamped with its time
      ++poses;
    } else if (ev.channel == "FUSED_TRAJECTORY") {
      ASSERT_EQ(last_traj.decode(ev.data.data(), 0, size), size);
      ++trajectories;
    } else if (ev.channel == "FUSED_MAP") {
      map_published = true;
    }
  }
  EXPECT_EQ(poses, static_cast<int>(d.rbpf.size()));
  EXPECT_GT(trajectories, 1);
  EXPECT_TRUE(map_published);
  // The final trajectory (after the loop closure) is close to the truth: the library gives
  // 0.13 m worst error on this input (random walk of 1 cm per step noise), the drifting
  // RBPF input is metres off.
  ASSERT_EQ(last_traj.num_poses, static_cast<int>(d.truth.size()));
  double worst = 0, worst_rbpf = 0;
  for (int k = 0; k < last_traj.num_poses; ++k) {
    worst = std::max(worst, std::hypot(last_traj.x[k] - d.truth[k].T_map_base.x,
                                       last_traj.y[k] - d.truth[k].T_map_base.y));
    worst_rbpf = std::max(worst_rbpf, std::hypot(d.rbpf[k].T_map_base.x - d.truth[k].T_map_base.x,
                                                 d.rbpf[k].T_map_base.y - d.truth[k].T_map_base.y));
  }
  EXPECT_LT(worst, 0.2);
  EXPECT_GT(worst_rbpf, 1.0);
}

TEST(FusionMain, BadArgumentsAndConfigAreClearErrors) {
  EXPECT_EQ(RunFusion("--help"), 0);
  EXPECT_NE(RunFusion("--no-such-flag"), 0);
  EXPECT_NE(RunFusion("--config /nonexistent/fusion.yaml"), 0);
  EXPECT_NE(RunFusion("--lcm-url log:/nonexistent/in.lcmlog"), 0);
  EXPECT_EQ(RunFusion("--config " + fl::test::SourceDir() + "/config/fusion.yaml --print-config"),
            0);
}

}  // namespace
}  // namespace fl::fusion
