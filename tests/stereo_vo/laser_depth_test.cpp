// Pixel-level laser depth association (laser_depth.hpp): projection, plane depth, the
// discontinuity and stereo-agreement checks, options.
#include "fusionloc/stereo_vo/laser_depth.hpp"

#include <gtest/gtest.h>

#include <random>

#include "fusionloc/common/yaml_options.hpp"
#include "fusionloc/stereo_vo/stereo_vo.hpp"
#include "stereo_fixtures.hpp"

namespace fl::vo {
namespace {

using fl::test::stereo::TestCalibration;

StereoCamera Camera() { return TestCalibration().camera(); }

// Points on the plane n.p = d sampled on scan-line-like rows (every `row_px` pixels, every
// `col_px` along a row) over the image, with Gaussian range noise along the ray.
std::vector<Eigen::Vector3f> PlanePoints(const Eigen::Vector3d& n, double d, double row_px,
                                         double col_px, double noise_m, uint32_t seed) {
  const StereoCalibration c = TestCalibration();
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, noise_m);
  std::vector<Eigen::Vector3f> out;
  for (double v = 0.5; v < c.height; v += row_px) {
    for (double u = 0.5; u < c.width; u += col_px) {
      const Eigen::Vector3d ray((u - c.cx) / c.fx, (v - c.cy) / c.fy, 1.0);
      const double z = d / n.dot(ray);
      if (!(z > 0)) continue;
      const double zn = z + (noise_m > 0 ? noise(rng) : 0.0);
      out.push_back((zn * ray).cast<float>());
    }
  }
  return out;
}

TEST(StereoVoLaserDepthTest, ProjectedPointLandsOnItsPixel) {
  const StereoCamera cam = Camera();
  const Eigen::Vector3d ray((123.0 - cam.cx) / cam.fx, (45.0 - cam.cy) / cam.fy, 1.0);
  const std::vector<Eigen::Vector3f> pts = {
      (7.5 * ray).cast<float>(),         // at pixel (123, 45)
      Eigen::Vector3f(0.f, 0.f, -5.f),   // behind the camera
      Eigen::Vector3f(100.f, 0.f, 5.f),  // outside the image
      Eigen::Vector3f(0.f, 0.f, 0.5f),   // nearer than min_depth_m
      (-2.0 * ray).cast<float>()};       // on the ray, behind
  LaserDepthOptions o;
  o.min_points_in_view = 1;
  const LaserDepthMap map(o, cam, 640, 480, pts);
  ASSERT_EQ(map.points_in_view(), 1);
  EXPECT_TRUE(map.usable());
  EXPECT_NEAR(map.pixel(0).x(), 123.0, 1e-3);
  EXPECT_NEAR(map.pixel(0).y(), 45.0, 1e-3);
  EXPECT_NEAR(map.point(0).z(), 7.5, 1e-5);
}

// The same points given in a laser frame (x forward, z up, 0.3 m above and 0.2 m behind the
// camera) with T_camera_laser: the map moves them into the camera frame itself.
TEST(StereoVoLaserDepthTest, PointsInTheLaserFrameLandOnTheirPixelThroughTheExtrinsic) {
  const StereoCamera cam = Camera();
  Eigen::Isometry3d T_camera_laser = Eigen::Isometry3d::Identity();
  T_camera_laser.linear() << 0, -1, 0,  //
      0, 0, -1,                          //
      1, 0, 0;
  T_camera_laser.translation() = Eigen::Vector3d(0.05, -0.3, -0.2);
  const Eigen::Vector3d ray((123.0 - cam.cx) / cam.fx, (45.0 - cam.cy) / cam.fy, 1.0);
  const Eigen::Vector3d p_camera = 7.5 * ray;
  const std::vector<Eigen::Vector3f> pts = {
      (T_camera_laser.inverse() * p_camera).cast<float>(),  // at pixel (123, 45)
      Eigen::Vector3f(-5.f, 0.f, 0.f)};                     // behind the camera
  LaserDepthOptions o;
  o.min_points_in_view = 1;
  const LaserDepthMap map(o, cam, 640, 480, pts, T_camera_laser);
  ASSERT_EQ(map.points_in_view(), 1);
  EXPECT_NEAR(map.pixel(0).x(), 123.0, 1e-3);
  EXPECT_NEAR(map.pixel(0).y(), 45.0, 1e-3);
  EXPECT_LT((map.point(0).cast<double>() - p_camera).norm(), 1e-5);
  // Without the extrinsic the same points are not in view.
  EXPECT_EQ(LaserDepthMap(o, cam, 640, 480, pts).points_in_view(), 0);
}

TEST(StereoVoLaserDepthTest, FeatureOnAPlaneGetsThePlanesDepth) {
  const StereoCamera cam = Camera();
  // A wall 12 m ahead, turned 30 deg about the vertical axis; 2 cm range noise.
  const Eigen::Vector3d n = Eigen::Vector3d(std::sin(0.5236), 0.0, std::cos(0.5236));
  const double d = 12.0;
  const LaserDepthOptions o;
  const LaserDepthMap map(o, cam, 640, 480, PlanePoints(n, d, 3.0, 2.0, 0.02, 1));
  ASSERT_TRUE(map.usable());
  int checked = 0;
  for (double u = 50; u < 600; u += 97) {
    for (double v = 40; v < 450; v += 83) {
      const Eigen::Vector3d ray((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0);
      const double z_true = d / n.dot(ray);
      const FeatureDepth fd = map.Associate(u, v, -1.0, 0.0);
      ASSERT_EQ(fd.verdict, LaserDepthVerdict::kOk) << u << ", " << v;
      EXPECT_EQ(fd.source, DepthSource::kLaser);
      // The plane through >= 4 points with 2 cm noise: well within 3 sigma of one point.
      EXPECT_NEAR(fd.depth_m, z_true, 0.06) << u << ", " << v;
      EXPECT_GE(fd.sigma_m, o.range_sigma_m);
      EXPECT_LT(fd.sigma_m, 0.1);
      ++checked;
    }
  }
  EXPECT_GE(checked, 20);
  // With an agreeing stereo depth: both; with a stereo depth 2 m off: rejected, stereo kept.
  const double u = 320, v = 240;
  const Eigen::Vector3d ray((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0);
  const double z_true = d / n.dot(ray);
  const double s_st = StereoDepthSigma(cam, z_true, 0.3);
  const FeatureDepth both = map.Associate(u, v, z_true + s_st, s_st);
  EXPECT_EQ(both.source, DepthSource::kBoth);
  EXPECT_NEAR(both.depth_m, z_true, 0.06);
  const FeatureDepth off = map.Associate(u, v, z_true + 2.0, s_st);
  EXPECT_EQ(off.verdict, LaserDepthVerdict::kStereoDisagrees);
  EXPECT_EQ(off.source, DepthSource::kStereo);
  EXPECT_DOUBLE_EQ(off.depth_m, z_true + 2.0);
  EXPECT_NEAR(off.laser_depth_m, z_true, 0.06);
}

TEST(StereoVoLaserDepthTest, FeatureAcrossADepthDiscontinuityIsRejected) {
  const StereoCamera cam = Camera();
  // Left half of the image: a pole at 5 m; right half: a wall at 15 m (edge at u = 320).
  std::vector<Eigen::Vector3f> pts;
  for (const auto& p : PlanePoints(Eigen::Vector3d::UnitZ(), 5.0, 3.0, 2.0, 0.0, 1)) {
    if (cam.fx * p.x() / p.z() + cam.cx < 320) pts.push_back(p);
  }
  for (const auto& p : PlanePoints(Eigen::Vector3d::UnitZ(), 15.0, 3.0, 2.0, 0.0, 2)) {
    if (cam.fx * p.x() / p.z() + cam.cx >= 320) pts.push_back(p);
  }
  const LaserDepthMap map(LaserDepthOptions(), cam, 640, 480, pts);
  const FeatureDepth edge = map.Associate(320.0, 200.0, -1.0, 0.0);
  EXPECT_EQ(edge.verdict, LaserDepthVerdict::kInconsistent) << edge.laser_depth_m;
  EXPECT_EQ(edge.source, DepthSource::kNone);
  // Away from the edge, each side gets its own depth.
  EXPECT_NEAR(map.Associate(200.0, 200.0, -1.0, 0.0).depth_m, 5.0, 1e-3);
  EXPECT_NEAR(map.Associate(450.0, 200.0, -1.0, 0.0).depth_m, 15.0, 1e-3);

  // One scan line (points on a line, no plane) across the same edge: the depth spread rejects.
  std::vector<Eigen::Vector3f> line;
  for (const auto& p : pts) {
    if (std::abs(cam.fy * p.y() / p.z() + cam.cy - 201.5) < 0.1) line.push_back(p);
  }
  ASSERT_GT(line.size(), 100u);
  const LaserDepthMap line_map(LaserDepthOptions(), cam, 640, 480, line);
  EXPECT_EQ(line_map.Associate(320.0, 200.0, -1.0, 0.0).verdict, LaserDepthVerdict::kInconsistent);
  const FeatureDepth on_line = line_map.Associate(450.0, 201.0, -1.0, 0.0);
  EXPECT_EQ(on_line.verdict, LaserDepthVerdict::kOk);
  EXPECT_NEAR(on_line.depth_m, 15.0, 1e-3);
}

TEST(StereoVoLaserDepthTest, AFeatureOffItsScanLineGetsNoDepthFromIt) {
  // The floor 0.5 m below the camera (depth changes fast across the rows) seen by one scan line
  // at v = 300.5: a feature on the line gets its depth, one 3 px off it does not (there the
  // depth is 5 % different, and the line says nothing about it).
  const StereoCamera cam = Camera();
  std::vector<Eigen::Vector3f> line;
  const double v_line = 300.5, y = 0.5;
  const double z_line = cam.fy * y / (v_line - cam.cy);
  for (double u = 100; u < 540; u += 2.0) {
    const double x = (u - cam.cx) * z_line / cam.fx;
    line.emplace_back(static_cast<float>(x), static_cast<float>(y), static_cast<float>(z_line));
  }
  const LaserDepthMap map(LaserDepthOptions(), cam, 640, 480, line);
  const FeatureDepth on = map.Associate(320.0, 300.8, -1.0, 0.0);
  EXPECT_EQ(on.verdict, LaserDepthVerdict::kOk);
  EXPECT_NEAR(on.depth_m, z_line, 1e-3);
  const FeatureDepth off = map.Associate(320.0, 303.5, -1.0, 0.0);
  EXPECT_EQ(off.verdict, LaserDepthVerdict::kInconsistent) << off.laser_depth_m;
  EXPECT_EQ(off.source, DepthSource::kNone);
  LaserDepthOptions loose;
  loose.max_line_offset_px = 5.0;  // the old rule: the line's depth, 5 % off the truth there
  const FeatureDepth old_rule = LaserDepthMap(loose, cam, 640, 480, line).Associate(320.0, 303.5,
                                                                                    -1.0, 0.0);
  EXPECT_EQ(old_rule.verdict, LaserDepthVerdict::kOk);
  const double z_true = cam.fy * y / (303.5 - cam.cy);
  EXPECT_GT(std::abs(old_rule.depth_m - z_true) / z_true, 0.04);
}

TEST(StereoVoLaserDepthTest, SparsePatchGivesNoLaserDepth) {
  const StereoCamera cam = Camera();
  // Scan lines 20 px apart: a feature between them has too few neighbours.
  const LaserDepthMap map(LaserDepthOptions(), cam, 640, 480,
                          PlanePoints(Eigen::Vector3d::UnitZ(), 10.0, 20.0, 2.0, 0.0, 1));
  const FeatureDepth fd = map.Associate(300.0, 10.5, 9.0, 0.1);
  EXPECT_EQ(fd.verdict, LaserDepthVerdict::kTooFew);
  EXPECT_EQ(fd.source, DepthSource::kStereo);
  EXPECT_DOUBLE_EQ(fd.depth_m, 9.0);
}

TEST(StereoVoLaserDepthTest, CloudInTheWrongFrameIsNotUsable) {
  // A scan left in the laser frame (x forward): almost nothing has camera z > 0 in view.
  std::vector<Eigen::Vector3f> pts;
  for (int i = 0; i < 5000; ++i) {
    const double a = 0.02 * i;
    pts.emplace_back(static_cast<float>(10 * std::cos(a)), static_cast<float>(10 * std::sin(a)),
                     -1.5f);
  }
  const LaserDepthMap map(LaserDepthOptions(), Camera(), 640, 480, pts);
  EXPECT_FALSE(map.usable()) << map.points_in_view();
}

TEST(StereoVoLaserDepthOptionsTest, ValidateAndYaml) {
  EXPECT_TRUE(LaserDepthOptions().Validate().ok());
  LaserDepthOptions o;
  o.min_neighbours = 2;
  EXPECT_NE(o.Validate().message().find("laser_depth.min_neighbours"), std::string::npos);
  o = LaserDepthOptions();
  o.max_depth_m = 0.5;
  EXPECT_FALSE(o.Validate().ok());
  const auto y = fl::LoadYamlString<LaserDepthOptions>("enabled: true\nsearch_radius_px: 4\n");
  EXPECT_TRUE(y.enabled);
  EXPECT_EQ(y.search_radius_px, 4.0);
  EXPECT_THROW(fl::LoadYamlString<LaserDepthOptions>("serch_radius_px: 4\n"), fl::ConfigError);
}

}  // namespace
}  // namespace fl::vo
