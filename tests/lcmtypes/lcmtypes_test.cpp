// Every message type survives encode -> decode -> encode byte for byte, and the libbot2
// compatible types keep bot_core's fingerprints.
#include <gtest/gtest.h>

#include <cstdint>
#include <vector>

#include "bot_core/image_t.hpp"
#include "bot_core/images_t.hpp"
#include "bot_core/planar_lidar_t.hpp"
#include "bot_core/pose_t.hpp"
#include "bot_core/rigid_transform_t.hpp"
#include "fusionloc/fused_pose_t.hpp"
#include "fusionloc/occupancy_grid_t.hpp"
#include "fusionloc/point_cloud_t.hpp"
#include "fusionloc/relative_pose_factor_t.hpp"
#include "fusionloc/status_t.hpp"
#include "fusionloc/stereo_calibration_t.hpp"
#include "fusionloc/trajectory_t.hpp"
#include "fusionloc/wheel_odometry_t.hpp"

namespace {

template <class Msg>
Msg RoundTrip(const Msg& in) {
  std::vector<uint8_t> a(in.getEncodedSize());
  EXPECT_EQ(in.encode(a.data(), 0, a.size()), static_cast<int>(a.size()));
  Msg out;
  EXPECT_EQ(out.decode(a.data(), 0, a.size()), static_cast<int>(a.size()));
  std::vector<uint8_t> b(out.getEncodedSize());
  out.encode(b.data(), 0, b.size());
  EXPECT_EQ(a, b) << Msg::getTypeName();
  // A truncated buffer must be rejected, not read past its end.
  Msg bad;
  EXPECT_LT(bad.decode(a.data(), 0, a.size() - 1), 0) << Msg::getTypeName();
  return out;
}

bot_core::image_t MakeImage(int w, int h, int seed) {
  bot_core::image_t img;
  img.utime = 1000 + seed;
  img.width = w;
  img.height = h;
  img.row_stride = w;
  img.pixelformat = bot_core::image_t::PIXEL_FORMAT_GRAY;
  img.size = w * h;
  img.data.resize(img.size);
  for (int i = 0; i < img.size; ++i) img.data[i] = static_cast<uint8_t>(i * 7 + seed);
  bot_core::image_metadata_t md;
  md.key = "exposure_us";
  md.n = 2;
  md.value = {1, 2};
  img.nmetadata = 1;
  img.metadata = {md};
  return img;
}

TEST(LcmTypes, PlanarLidarFingerprintMatchesBotCore) {
  EXPECT_EQ(static_cast<uint64_t>(bot_core::planar_lidar_t::getHash()), 0xe3d17423180b5e8dULL);
}

TEST(LcmTypes, PlanarLidarRoundTrip) {
  bot_core::planar_lidar_t m;
  m.utime = 123456789;
  m.nranges = 682;
  for (int i = 0; i < m.nranges; ++i) m.ranges.push_back(0.02f * i);
  m.nintensities = 2;
  m.intensities = {1.f, 2.f};
  m.rad0 = -2.0944f;
  m.radstep = 0.00614f;
  const auto out = RoundTrip(m);
  EXPECT_EQ(out.ranges, m.ranges);
  EXPECT_FLOAT_EQ(out.rad0, m.rad0);
}

TEST(LcmTypes, ImagesRoundTrip) {
  bot_core::images_t m;
  m.utime = 42;
  m.n_images = 2;
  m.image_types = {bot_core::images_t::LEFT, bot_core::images_t::RIGHT};
  m.images = {MakeImage(16, 8, 1), MakeImage(16, 8, 2)};
  const auto out = RoundTrip(m);
  EXPECT_EQ(out.images[1].data, m.images[1].data);
  EXPECT_EQ(out.images[0].metadata[0].key, "exposure_us");
}

TEST(LcmTypes, PoseAndTransformRoundTrip) {
  bot_core::pose_t p{};
  p.utime = 7;
  p.pos[0] = 1.5;
  p.orientation[0] = 1.0;
  EXPECT_DOUBLE_EQ(RoundTrip(p).pos[0], 1.5);
  bot_core::rigid_transform_t t{};
  t.trans[2] = -0.25;
  t.quat[0] = 1.0;
  EXPECT_DOUBLE_EQ(RoundTrip(t).trans[2], -0.25);
}

TEST(LcmTypes, ProjectTypesRoundTrip) {
  fusionloc::wheel_odometry_t odo{};
  odo.utime = 5;
  odo.theta = 0.3;
  EXPECT_DOUBLE_EQ(RoundTrip(odo).theta, 0.3);

  fusionloc::stereo_calibration_t cal{};
  cal.width = 640;
  cal.fx = 500;
  cal.baseline = 0.12;
  cal.rectified = true;
  EXPECT_DOUBLE_EQ(RoundTrip(cal).baseline, 0.12);

  bot_core::rigid_transform_t mount{};  // LASER_TO_BASE / CAMERA_TO_BASE
  mount.trans[0] = 0.2;
  mount.quat[0] = 1;
  EXPECT_DOUBLE_EQ(RoundTrip(mount).trans[0], 0.2);

  fusionloc::relative_pose_factor_t f{};
  f.utime_i = 1;
  f.utime_j = 2;
  f.quat[0] = 1;
  for (int i = 0; i < 36; ++i) f.information[i] = (i % 7 == 0) ? 100.0 : 0.0;
  // lcm-gen 1.3.1 declares constants without definitions: copy them, never bind a reference.
  const int vision = fusionloc::relative_pose_factor_t::SOURCE_VISION;
  f.source = static_cast<int8_t>(vision);
  EXPECT_EQ(int(RoundTrip(f).source), vision);

  fusionloc::fused_pose_t fp{};
  fp.x = 3;
  fp.covariance[8] = 0.01;
  EXPECT_DOUBLE_EQ(RoundTrip(fp).covariance[8], 0.01);

  fusionloc::trajectory_t tr{};
  tr.num_poses = 2;
  tr.utimes = {1, 2};
  tr.x = {0, 1};
  tr.y = {0, 0};
  tr.z = {0, 0};
  tr.theta = {0, 0.1};
  EXPECT_EQ(RoundTrip(tr).utimes[1], 2);

  fusionloc::occupancy_grid_t g{};
  g.resolution = 0.05;
  g.width = 3;
  g.height = 2;
  g.num_cells = 6;
  g.cells = {-1, 0, 100, 50, -1, 0};
  EXPECT_EQ(RoundTrip(g).cells[2], 100);

  fusionloc::point_cloud_t pc{};
  pc.frame = "camera";
  pc.num_points = 2;
  pc.points = {{1.f, 2.f, 3.f}, {4.f, 5.f, 6.f}};
  pc.num_intensities = 0;
  EXPECT_FLOAT_EQ(RoundTrip(pc).points[1][2], 6.f);

  fusionloc::status_t st{};
  st.process = "fl-test";
  st.level = int8_t{fusionloc::status_t::LEVEL_WARN};
  st.message = "ok";
  st.num_keys = 1;
  st.keys = {"particles"};
  st.values = {30};
  EXPECT_EQ(RoundTrip(st).keys[0], "particles");
}

}  // namespace
