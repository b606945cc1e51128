#include "fusionloc/viewer/scene.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "viewer_fixtures.hpp"

namespace fl::viewer {
namespace {

std::string Header(const Frame& f) {
  std::string h, p;
  EXPECT_TRUE(DecodeFrame(f.bytes, &h, &p));
  return h;
}
std::string Payload(const Frame& f) {
  std::string h, p;
  EXPECT_TRUE(DecodeFrame(f.bytes, &h, &p));
  return p;
}
int CountType(const std::vector<Frame>& frames, const std::string& type) {
  int n = 0;
  for (const Frame& f : frames) n += Header(f).find("\"type\":\"" + type + "\"") != std::string::npos;
  return n;
}
const Frame* FindType(const std::vector<Frame>& frames, const std::string& type) {
  for (const Frame& f : frames) {
    if (Header(f).find("\"type\":\"" + type + "\"") != std::string::npos) return &f;
  }
  return nullptr;
}

GridView FixtureGrid(Utime utime) {
  const test::ViewerGridFixture g;
  GridView v;
  v.utime = utime;
  v.resolution = g.resolution;
  v.width = g.width;
  v.height = g.height;
  v.origin_x = g.origin_x;
  v.origin_y = g.origin_y;
  v.cells = g.Cells();
  return v;
}

TEST(Scene, SendsTheGridOnlyWhenItChangedAndNotMoreOftenThanItsPeriod) {
  SceneOptions o;
  o.grid_period_s = 1.0;
  Scene s(o);
  s.SetGrid(FixtureGrid(1));
  std::vector<Frame> f = s.TakeChanges(10.0);
  ASSERT_EQ(CountType(f, "grid"), 1);
  const Frame* g = FindType(f, "grid");
  EXPECT_NE(Header(*g).find("\"width\":24,\"height\":16"), std::string::npos);
  const std::string cells = Payload(*g);
  ASSERT_EQ(cells.size(), 24u * 16u);
  EXPECT_EQ(static_cast<int8_t>(cells[3 * 24 + 5]), 100);  // row 3, col 5
  EXPECT_EQ(static_cast<int8_t>(cells[14 * 24 + 5]), -1);
  // The same cells again (a new time stamp): nothing to send.
  s.SetGrid(FixtureGrid(2));
  EXPECT_EQ(CountType(s.TakeChanges(20.0), "grid"), 0);
  // Changed, but within the period: held back, then sent once.
  GridView changed = FixtureGrid(3);
  changed.cells[0] = 100;
  s.SetGrid(changed);
  EXPECT_EQ(CountType(s.TakeChanges(20.5), "grid"), 1);  // 10.5 s after the last one sent
  changed.cells[1] = 100;
  s.SetGrid(changed);
  EXPECT_EQ(CountType(s.TakeChanges(20.7), "grid"), 0);
  EXPECT_EQ(CountType(s.TakeChanges(21.6), "grid"), 1);
  EXPECT_EQ(CountType(s.TakeChanges(30.0), "grid"), 0);
}

TEST(Scene, TrailsGoOutAsTheirNewPosesThinnedAndTheSnapshotHoldsThemAll) {
  SceneOptions o;
  o.trail_period_s = 0.1;
  o.trail_min_distance_m = 0.05;
  Scene s(o);
  // 10 s at 100 Hz, 1 m/s: thinned to 10 Hz -> about 100 poses.
  for (int i = 0; i < 1000; ++i) s.AddPose("FUSED_POSE", {i * 10000, i * 0.01, 0, 0, 0});
  std::vector<Frame> f = s.TakeChanges(1.0);
  const Frame* t = FindType(f, "trail");
  ASSERT_NE(t, nullptr);
  EXPECT_NE(Header(*t).find("\"replace\":false"), std::string::npos);
  const size_t n = Payload(*t).size() / (4 * sizeof(float));
  EXPECT_GE(n, 95u);
  EXPECT_LE(n, 101u);
  EXPECT_EQ(s.trail_size("FUSED_POSE"), n);
  ASSERT_NE(FindType(f, "poses"), nullptr);
  // Nothing new: no trail frame. Ten more poses 1 s on: one append of about one pose.
  EXPECT_EQ(CountType(s.TakeChanges(2.0), "trail"), 0);
  s.AddPose("FUSED_POSE", {10100000, 10.1, 0, 0, 0});
  f = s.TakeChanges(3.0);
  t = FindType(f, "trail");
  ASSERT_NE(t, nullptr);
  EXPECT_EQ(Payload(*t).size(), 4 * sizeof(float));
  // The snapshot carries the whole trail, as a replacement.
  const std::vector<Frame> snap = s.Snapshot();
  t = FindType(snap, "trail");
  ASSERT_NE(t, nullptr);
  EXPECT_NE(Header(*t).find("\"replace\":true"), std::string::npos);
  EXPECT_EQ(Payload(*t).size() / (4 * sizeof(float)), n + 1);
}

TEST(Scene, ATimeJumpBackRestartsTheTrail) {
  Scene s(SceneOptions{});
  for (int i = 0; i < 50; ++i) s.AddPose("RBPF_POSE", {1000000 + i * 100000, i * 0.1, 0, 0, 0});
  s.TakeChanges(1.0);
  s.AddPose("RBPF_POSE", {1000000, 0, 0, 0, 0});  // a new run
  const std::vector<Frame> f = s.TakeChanges(2.0);
  const Frame* t = FindType(f, "trail");
  ASSERT_NE(t, nullptr);
  EXPECT_NE(Header(*t).find("\"replace\":true"), std::string::npos);
  EXPECT_EQ(s.trail_size("RBPF_POSE"), 1u);
}

TEST(Scene, TheScanIsDrawnAtTheBestRecentPoseInTheBaseFrame) {
  Scene s(SceneOptions{});
  s.SetLaserToBase(Pose2(0.2, 0, 0));
  s.AddPose("ODOMETRY", {1000000, 5, 5, 0, 0});
  s.AddPose("FUSED_POSE", {1000000, 1, 2, 0, 0.5});
  ScanView scan;
  scan.utime = 1000000;
  scan.rad0 = 0;
  scan.radstep = M_PI / 2;
  scan.ranges = {1.0f, 0.0f, 2.0f};  // ahead, no return, behind
  s.SetScan(scan);
  const std::vector<Frame> f = s.TakeChanges(1.0);
  const Frame* sc = FindType(f, "scan");
  ASSERT_NE(sc, nullptr);
  EXPECT_NE(Header(*sc).find("\"source\":\"FUSED_POSE\""), std::string::npos);
  EXPECT_NE(Header(*sc).find("\"count\":2"), std::string::npos);
  const std::string p = Payload(*sc);
  ASSERT_EQ(p.size(), 4 * sizeof(float));
  float xy[4];
  std::memcpy(xy, p.data(), sizeof(xy));
  EXPECT_NEAR(xy[0], 1.2, 1e-6);  // 1 m ahead of the laser, 0.2 m ahead of the base
  EXPECT_NEAR(xy[2], -1.8, 1e-6);
  EXPECT_NEAR(xy[3], 0.0, 1e-6);
  // The fused pose goes stale (3 s of data time without it): the odometry takes over.
  s.AddPose("ODOMETRY", {4100000, 5, 5, 0, 0});
  s.SetScan(scan);
  const std::vector<Frame> later = s.TakeChanges(2.0);
  sc = FindType(later, "scan");
  ASSERT_NE(sc, nullptr);
  EXPECT_NE(Header(*sc).find("\"source\":\"ODOMETRY\""), std::string::npos);
}

TEST(Scene, TheVoCloudGrowsByItsNewVoxelsOnly) {
  SceneOptions o;
  o.cloud_voxel_m = 0.5;
  o.cloud_period_s = 0;
  Scene s(o);
  std::vector<float> pts = {0.1f, 0.1f, 1.0f, 0.2f, 0.1f, 1.1f, 3.0f, 0.0f, 1.0f};
  s.AddKeyframePoints(1, pts.data(), 3);  // no pose yet: nowhere to put them
  EXPECT_EQ(s.cloud_size("VO_POINTS"), 0u);
  s.AddPose("VO_POSE", {1, 10, 0, 0, 0});
  s.AddKeyframePoints(2, pts.data(), 3);
  EXPECT_EQ(s.cloud_size("VO_POINTS"), 2u);
  std::vector<Frame> f = s.TakeChanges(1.0);
  const Frame* c = FindType(f, "cloud");
  ASSERT_NE(c, nullptr);
  EXPECT_NE(Header(*c).find("\"count\":2"), std::string::npos);
  float first[3];
  std::memcpy(first, Payload(*c).data(), sizeof(first));
  EXPECT_NEAR(first[0], 10.1, 1e-5);  // placed at the VO pose (identity camera mounting)
  s.AddKeyframePoints(3, pts.data(), 3);  // the same points: no new voxel, no frame
  EXPECT_EQ(CountType(s.TakeChanges(2.0), "cloud"), 0);
}

TEST(Scene, ProcessTableAndRatesComeOutOncePerPeriod) {
  SceneOptions o;
  o.status_period_s = 1.0;
  o.rates_window_s = 1.0;
  Scene s(o);
  ProcessView p;
  p.channel = "STATUS_FL_FUSION";
  p.process = "fl-fusion";
  p.message = "window solve \"ok\"";
  p.values = {{"nodes", 12}};
  s.SetProcess(p);
  DeputyView d;
  d.host = "robot";
  d.commands.push_back({"fusion", "", "fl-fusion", 42, 1, 0, 0.5f, 1 << 20});
  s.SetDeputy(d);
  for (int i = 0; i <= 20; ++i) s.CountMessage("LASER", 1000000 + i * 100000, 100);
  std::vector<Frame> f = s.TakeChanges(5.0);
  const Frame* pr = FindType(f, "processes");
  ASSERT_NE(pr, nullptr);
  const std::string h = Header(*pr);
  EXPECT_NE(h.find("\"process\":\"fl-fusion\""), std::string::npos);
  EXPECT_NE(h.find("window solve \\\"ok\\\""), std::string::npos);  // escaped
  EXPECT_NE(h.find("\"nodes\":12"), std::string::npos);
  EXPECT_NE(h.find("\"name\":\"fusion\""), std::string::npos);
  const Frame* r = FindType(f, "rates");
  ASSERT_NE(r, nullptr);
  EXPECT_NE(Header(*r).find("\"name\":\"LASER\",\"count\":21,\"bytes\":2100,\"hz\":11"),
            std::string::npos)
      << Header(*r);  // 11 messages within the last 1 s of data time
  EXPECT_EQ(CountType(s.TakeChanges(5.5), "rates"), 0);
  EXPECT_EQ(CountType(s.TakeChanges(6.1), "processes"), 0);  // unchanged
}

TEST(Scene, ResetForgetsEverything) {
  Scene s(SceneOptions{});
  s.SetGrid(FixtureGrid(1));
  s.AddPose("FUSED_POSE", {1, 0, 0, 0, 0});
  s.Reset();
  EXPECT_FALSE(s.has_grid());
  EXPECT_EQ(s.trail_size("FUSED_POSE"), 0u);
  EXPECT_EQ(CountType(s.Snapshot(), "grid"), 0);
}

TEST(Scene, ATrajectoryMessageReplacesThePosesFromItsFirstTimeOn) {
  // FUSED_TRAJECTORY sends its latest part (trajectory_t.lcm): poses 0-9, then 5-14 re-estimated.
  Scene s{SceneOptions()};
  std::vector<ViewPose> whole, latest;
  for (int k = 0; k < 10; ++k) whole.push_back({1000 + k, 1.0 * k, 0.0, 0.0, 0.0});
  for (int k = 5; k < 15; ++k) latest.push_back({1000 + k, 1.0 * k, 0.5, 0.0, 0.0});
  s.SetTrajectory("FUSED_TRAJECTORY", 1009, whole);
  s.SetTrajectory("FUSED_TRAJECTORY", 1014, latest);
  const std::vector<Frame> f = s.TakeChanges(10.0);
  const Frame* t = FindType(f, "trajectory");
  ASSERT_NE(t, nullptr);
  EXPECT_NE(Header(*t).find("\"count\":15"), std::string::npos) << Header(*t);
  const std::string payload = Payload(*t);
  ASSERT_EQ(payload.size(), 15u * 4u * sizeof(float));
  std::vector<float> v(15 * 4);
  std::memcpy(v.data(), payload.data(), payload.size());
  EXPECT_FLOAT_EQ(v[4 * 4 + 1], 0.0f);  // pose 4 kept: y 0
  EXPECT_FLOAT_EQ(v[5 * 4 + 1], 0.5f);  // pose 5 replaced: y 0.5
}

TEST(SceneOptions, ValidateNamesTheBadField) {
  SceneOptions o;
  EXPECT_TRUE(o.Validate().ok());
  o.cloud_voxel_m = 0;
  EXPECT_NE(o.Validate().message().find("cloud_voxel_m"), std::string::npos);
}

}  // namespace
}  // namespace fl::viewer
