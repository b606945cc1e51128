// Runs the fl-rbpf-slam process on a small synthetic LCM log (through log:IN,OUT) with bad
// messages mixed in, and checks what it published.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <map>

#include "bot_core/planar_lidar_t.hpp"
#include "bot_core/pose_t.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/relative_pose_factor_t.hpp"
#include "fusionloc/wheel_odometry_t.hpp"
#include "laser_fixtures.hpp"
#include "test_paths.hpp"

namespace {

TEST(RbpfSlamProcess, ReplaysALogWithBadMessagesAndPublishes) {
  const std::string bin = fl::test::BinDir() + "/fl-rbpf-slam";
  if (!std::filesystem::exists(bin)) GTEST_SKIP() << "build fl-rbpf-slam first: " << bin;
  fl::test::TempDir tmp;
  const fl::test::LaserWorld world = fl::test::LaserWorld::RoomWithBoxes();
  fl::test::LoopRunOptions lo;
  lo.step_m = 0.25;
  const fl::test::LoopRun run = fl::test::MakeLoopRun(world, lo);
  const size_t n = 60;
  int good_scans = 0;
  {
    fl::LcmLogWriter w(tmp.file("in.lcmlog"));
    for (size_t k = 0; k < n; ++k) {
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
      if (k == 20) {  // a scan with a different beam count: rejected
        s.ranges.resize(90);
        s.nranges = 90;
      } else if (k == 30) {  // NaN / inf / zero beams: ignored, the scan is used
        s.ranges[0] = NAN;
        s.ranges[1] = INFINITY;
        s.ranges[2] = 0.0f;
        ++good_scans;
      } else {
        ++good_scans;
      }
      w.Write("LASER", s, s.utime);
      if (k == 40) {  // a stale scan (time going backwards): dropped
        bot_core::planar_lidar_t old = s;
        old.utime = run.utimes[10];
        w.Write("LASER", old, s.utime);
      }
    }
    w.Close();
  }
  const std::string cmd = bin + " --lcm-url log:" + tmp.file("in.lcmlog") + "," +
                          tmp.file("out.lcmlog") + " > " + tmp.file("stderr.txt") + " 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  std::map<std::string, int> count;
  fl::LcmLogReader r(tmp.file("out.lcmlog"));
  fl::LcmLogEvent ev;
  int factors_ok = 0;
  while (r.Next(&ev)) {
    ++count[ev.channel];
    if (ev.channel == "RBPF_FACTORS") {
      fusionloc::relative_pose_factor_t f{};
      ASSERT_GE(f.decode(ev.data.data(), 0, static_cast<int>(ev.data.size())), 0);
      const int8_t laser = fusionloc::relative_pose_factor_t::SOURCE_LASER;
      EXPECT_EQ(f.source, laser);
      EXPECT_LT(f.utime_i, f.utime_j);
      EXPECT_GT(f.information[0], 0.0);    // x
      EXPECT_GT(f.information[35], 0.0);   // yaw
      EXPECT_EQ(f.information[14], 0.0);   // z row left empty (planar)
      ++factors_ok;
    }
  }
  EXPECT_EQ(count["RBPF_POSE"], good_scans);
  EXPECT_GT(factors_ok, 3);
  EXPECT_GE(count["RBPF_TRAJECTORY"], 1);
  EXPECT_GE(count["RBPF_MAP"], 1);
  EXPECT_GE(count["STATUS_FL_RBPF_SLAM"], 1);
}

}  // namespace
