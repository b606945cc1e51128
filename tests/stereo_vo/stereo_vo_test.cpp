// Tests of fl::vo::StereoVo on synthetic stereo pairs of a textured plane: tracking, keyframe
// factors in the base frame, and every bad-input case (sizes, calibration, black / saturated /
// textureless frames, repeated time stamps, gaps).
#include "fusionloc/stereo_vo/stereo_vo.hpp"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <filesystem>

#include "fusionloc/common/yaml_options.hpp"
#include "stereo_fixtures.hpp"
#include "test_paths.hpp"

namespace fl::vo {
namespace {

using fl::test::stereo::PlanePair;
using fl::test::stereo::TestCalibration;
using fl::test::stereo::Texture;

constexpr Utime kT0 = 1000000000;
constexpr Utime kDt = 100000;   // 10 Hz
constexpr double kDepth = 5.0;  // [m] plane distance
constexpr double kStep = 0.05;  // [m] camera x per frame (5 px of image motion)

class StereoVoTest : public ::testing::Test {
 protected:
  StereoVoTest() : calib_(TestCalibration()), texture_(Texture(900, 700, 17)) {}
  // The pair seen after the camera moved k steps along its x axis.
  void Pair(int k, cv::Mat* left, cv::Mat* right) const {
    PlanePair(texture_, calib_, kDepth, k * kStep, 0.0, left, right);
  }
  StereoCalibration calib_;
  cv::Mat texture_;
};

TEST_F(StereoVoTest, TracksSidewaysMotionOfAPlane) {
  StereoVoOptions opts;
  opts.keyframe_translation_m = 0.12;
  StereoVo vo(opts, calib_);
  cv::Mat l, r;
  int factors = 0;
  for (int k = 0; k <= 6; ++k) {
    Pair(k, &l, &r);
    const StereoVoResult res = vo.AddStereoFrame(kT0 + k * kDt, l, r);
    if (k == 0) {
      EXPECT_EQ(res.state, TrackingState::kInitialized) << res.message;
      EXPECT_TRUE(res.is_keyframe);
      EXPECT_GT(res.keyframe_points.size(), 100u);
      ASSERT_EQ(res.keyframe_points.size(), res.keyframe_intensities.size());
      for (const auto& p : res.keyframe_points) EXPECT_NEAR(p.z(), kDepth, 0.1);
      continue;
    }
    ASSERT_EQ(res.state, TrackingState::kTracked) << res.message;
    EXPECT_GT(res.stats.inliers, 50);
    EXPECT_NEAR(res.T_prev_camera.translation().x(), kStep, 0.002);
    EXPECT_NEAR(res.T_prev_camera.translation().y(), 0.0, 0.002);
    EXPECT_NEAR(res.T_prev_camera.translation().z(), 0.0, 0.01);
    // Base frame: camera x (right) is base -y.
    EXPECT_NEAR(res.T_world_base.translation().y(), -k * kStep, 0.005 * k);
    if (res.factor) {
      ++factors;
      const KeyframeFactor& f = *res.factor;
      EXPECT_EQ(f.keyframe_id_j, f.keyframe_id_i + 1);
      EXPECT_LT(f.utime_i, f.utime_j);
      EXPECT_EQ(f.utime_j, res.utime);
      // 3 frames per keyframe (0.15 m >= 0.12 m), motion along base -y.
      EXPECT_NEAR(f.T_i_j.translation().y(), -3 * kStep, 0.01);
      EXPECT_NEAR(f.T_i_j.translation().x(), 0.0, 0.03);
      // Information: symmetric, positive definite; sideways (y) best observed.
      EXPECT_LT((f.information - f.information.transpose()).norm(), 1e-9 * f.information.norm());
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> eig(f.information);
      EXPECT_GT(eig.eigenvalues().minCoeff(), 0.0);
      EXPECT_GT(f.information(1, 1), f.information(0, 0));
    }
  }
  EXPECT_EQ(factors, 2);
}

// The overlap rule counts the keyframe's tracks as the first frame after it carried them: a
// camera that keeps seeing the same plane makes no keyframe for overlap until its view has
// moved on (with all stereo matches as the reference, a fraction of which never closes a
// quadrilateral, nearly every frame became a keyframe).
TEST_F(StereoVoTest, OverlapKeyframesFollowTheViewNotTheMatchCount) {
  StereoVoOptions opts;
  opts.keyframe_translation_m = 100.0;
  opts.keyframe_rotation_deg = 90.0;
  opts.keyframe_max_interval_s = 100.0;
  cv::Mat l, r;
  // k frames of sideways motion (5 px each); returns the frames at which factors were made.
  auto run = [&](double min_overlap, int frames) {
    opts.keyframe_min_overlap = min_overlap;
    StereoVo vo(opts, calib_);
    std::vector<int> factor_frames;
    for (int k = 0; k < frames; ++k) {
      Pair(k, &l, &r);
      const StereoVoResult res = vo.AddStereoFrame(kT0 + k * kDt, l, r);
      EXPECT_TRUE(k == 0 || res.state == TrackingState::kTracked) << k << ": " << res.message;
      if (res.factor) factor_frames.push_back(k);
    }
    return factor_frames;
  };
  // 20 frames move the view by 100 of its 640 px: more than half of the tracks stay.
  EXPECT_TRUE(run(0.5, 20).empty());
  // Asking for 90 % overlap makes keyframes, but not every frame: each needs ~10 % of the
  // tracks to leave (the old reference made all 19 frames keyframes here).
  const std::vector<int> dense = run(0.9, 20);
  ASSERT_FALSE(dense.empty());
  EXPECT_GE(dense.front(), 3);
  EXPECT_LE(dense.size(), 6u);
}

// The scan of the plane at kDepth in the left camera frame (scan lines every 3 px, a point
// every 2 px along them).
LaserCloud PlaneCloud(const StereoCalibration& c, Utime utime) {
  LaserCloud cloud;
  cloud.utime = utime;
  for (double v = 0.5; v < c.height; v += 3.0) {
    for (double u = 0.5; u < c.width; u += 2.0) {
      cloud.points.emplace_back(static_cast<float>((u - c.cx) * kDepth / c.fx),
                                static_cast<float>((v - c.cy) * kDepth / c.fy),
                                static_cast<float>(kDepth));
    }
  }
  return cloud;
}

TEST_F(StereoVoTest, LaserAidedModeUsesTheScanAndFallsBackOnBadInput) {
  StereoVoOptions opts;
  opts.laser_depth.enabled = true;
  StereoVo vo(opts, calib_);
  cv::Mat l, r;
  for (int k = 0; k <= 5; ++k) {
    Pair(k, &l, &r);
    const Utime t = kT0 + k * kDt;
    LaserCloud cloud = PlaneCloud(calib_, t);
    const LaserCloud* input = &cloud;
    std::string expect;
    if (k == 2) {
      input = nullptr;
      expect = "no laser scan";
    } else if (k == 3) {
      cloud.points.clear();
      expect = "0 of 0 points";
    } else if (k == 4) {  // left in a laser frame (x forward, y left, z up)
      for (auto& p : cloud.points) p = Eigen::Vector3f(p.z(), -p.x(), -p.y());
      expect = "is its extrinsic T_camera_laser right?";
    } else if (k == 5) {
      cloud.utime = t + 200000;
      expect = "0.2";
    }
    const StereoVoResult res = vo.AddStereoFrame(t, l, r, input);
    if (k == 0) {
      ASSERT_EQ(res.state, TrackingState::kInitialized) << res.message;
      continue;
    }
    ASSERT_EQ(res.state, TrackingState::kTracked) << k << ": " << res.message;
    EXPECT_NEAR(res.T_prev_camera.translation().x(), kStep, 0.002) << k;
    EXPECT_NEAR(res.T_prev_camera.translation().z(), 0.0, 0.01) << k;
    if (expect.empty()) {
      EXPECT_EQ(res.laser_message, "") << k;
      EXPECT_GT(res.stats.laser_points_in_view, 20000) << k;
      EXPECT_GT(res.stats.laser_depth_cur, 50) << k;
      EXPECT_GT(res.stats.laser_depth_prev, 50) << k;
    } else {
      EXPECT_NE(res.laser_message.find(expect), std::string::npos)
          << k << ": " << res.laser_message;
      EXPECT_NE(res.laser_message.find("plain stereo"), std::string::npos) << res.laser_message;
      EXPECT_NE(res.message.find("laser: "), std::string::npos) << res.message;
      EXPECT_EQ(res.stats.laser_depth_cur, 0) << k;
    }
  }
}

TEST_F(StereoVoTest, LaserModeOffIgnoresTheScanBitForBit) {
  StereoVoOptions opts;
  StereoVo plain(opts, calib_), given(opts, calib_);
  cv::Mat l, r;
  for (int k = 0; k <= 3; ++k) {
    Pair(k, &l, &r);
    const LaserCloud cloud = PlaneCloud(calib_, kT0 + k * kDt);
    const StereoVoResult a = plain.AddStereoFrame(kT0 + k * kDt, l, r);
    const StereoVoResult b = given.AddStereoFrame(kT0 + k * kDt, l, r, &cloud);
    EXPECT_EQ(a.state, b.state);
    EXPECT_TRUE(a.T_world_camera.matrix() == b.T_world_camera.matrix()) << k;
    EXPECT_EQ(b.laser_message, "");
    EXPECT_EQ(b.stats.laser_points_in_view, 0);
  }
}

TEST(StereoVoOptionsLaserTest, LaserModeNeedsTheAnalyticSolver) {
  StereoVoOptions o;
  o.laser_depth.enabled = true;
  EXPECT_TRUE(o.Validate().ok());
  o.refine.use_ceres = true;
  o.estimate_disparity_offset = false;
  const fl::Status s = o.Validate();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("laser_depth.enabled"), std::string::npos) << s.message();
  o = StereoVoOptions();
  o.laser_depth.search_radius_px = 0;
  EXPECT_NE(o.Validate().message().find("laser_depth.search_radius_px"), std::string::npos);
  EXPECT_THROW(fl::LoadYamlString<StereoVoOptions>("laser_depth: {enabeld: true}\n"),
               fl::ConfigError);
  EXPECT_TRUE(
      fl::LoadYamlString<StereoVoOptions>("laser_depth: {enabled: true}\n").laser_depth.enabled);
}

TEST_F(StereoVoTest, RejectsImagesThatDoNotMatchTheCalibration) {
  StereoVo vo(StereoVoOptions(), calib_);
  cv::Mat l, r;
  Pair(0, &l, &r);
  const cv::Mat small = l(cv::Rect(0, 0, 320, 240)).clone();
  StereoVoResult res = vo.AddStereoFrame(kT0, l, small);
  EXPECT_EQ(res.state, TrackingState::kRejected);
  EXPECT_NE(res.message.find("do not match the calibration"), std::string::npos) << res.message;
  res = vo.AddStereoFrame(kT0, small, small);
  EXPECT_EQ(res.state, TrackingState::kRejected);
  res = vo.AddStereoFrame(kT0, cv::Mat(), r);
  EXPECT_EQ(res.state, TrackingState::kRejected);
  EXPECT_NE(res.message.find("empty"), std::string::npos);
  cv::Mat float_image;
  l.convertTo(float_image, CV_32F);
  res = vo.AddStereoFrame(kT0, float_image, float_image);
  EXPECT_EQ(res.state, TrackingState::kRejected);
  EXPECT_NE(res.message.find("pixel type"), std::string::npos);
  // The rejections changed nothing: the same time stamp still initializes.
  res = vo.AddStereoFrame(kT0, l, r);
  EXPECT_EQ(res.state, TrackingState::kInitialized) << res.message;
  // BGR input is converted.
  cv::Mat lc, rc;
  Pair(1, &l, &r);
  cv::cvtColor(l, lc, cv::COLOR_GRAY2BGR);
  cv::cvtColor(r, rc, cv::COLOR_GRAY2BGR);
  res = vo.AddStereoFrame(kT0 + kDt, lc, rc);
  EXPECT_EQ(res.state, TrackingState::kTracked) << res.message;
}

TEST_F(StereoVoTest, RejectsCalibrationThatIsNotRectifiedOrInvalid) {
  StereoCalibration c = calib_;
  c.rectified = false;
  EXPECT_NE(c.Validate().message().find("not rectified"), std::string::npos);
  EXPECT_THROW(StereoVo(StereoVoOptions(), c), std::invalid_argument);
  c = calib_;
  c.baseline = 0;
  EXPECT_NE(c.Validate().message().find("baseline"), std::string::npos);
  c = calib_;
  c.fx = -1;
  EXPECT_FALSE(c.Validate().ok());
  c = calib_;
  c.T_base_camera.linear() *= 2.0;
  EXPECT_NE(c.Validate().message().find("rigid"), std::string::npos);
  StereoVoOptions o;
  o.matching.max_disparity_px = -3;
  try {
    StereoVo vo(o, calib_);
    FAIL() << "expected invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("max_disparity_px"), std::string::npos);
  }
}

TEST_F(StereoVoTest, BlackSaturatedAndTexturelessFramesAreNotTrackedAndTrackingRecovers) {
  StereoVo vo(StereoVoOptions(), calib_);
  cv::Mat l, r;
  Pair(0, &l, &r);
  ASSERT_EQ(vo.AddStereoFrame(kT0, l, r).state, TrackingState::kInitialized);
  Pair(1, &l, &r);
  ASSERT_EQ(vo.AddStereoFrame(kT0 + kDt, l, r).state, TrackingState::kTracked);

  const cv::Mat black(calib_.height, calib_.width, CV_8UC1, cv::Scalar(0));
  const cv::Mat white(calib_.height, calib_.width, CV_8UC1, cv::Scalar(255));
  const cv::Mat flat(calib_.height, calib_.width, CV_8UC1, cv::Scalar(120));
  StereoVoResult res = vo.AddStereoFrame(kT0 + 2 * kDt, black, black);
  EXPECT_EQ(res.state, TrackingState::kNotTracked);
  EXPECT_NE(res.message.find("black"), std::string::npos) << res.message;
  EXPECT_FALSE(res.factor.has_value());
  res = vo.AddStereoFrame(kT0 + 3 * kDt, white, white);
  EXPECT_EQ(res.state, TrackingState::kNotTracked);
  EXPECT_NE(res.message.find("saturated"), std::string::npos) << res.message;
  res = vo.AddStereoFrame(kT0 + 4 * kDt, flat, flat);
  EXPECT_EQ(res.state, TrackingState::kNotTracked);
  EXPECT_NE(res.message.find("low texture"), std::string::npos) << res.message;
  // The pose is held while not tracked.
  EXPECT_NEAR(res.T_world_base.translation().y(), -kStep, 0.005);

  // Frame 5 is matched against frame 1 (the last good one): 4 steps of motion in one go.
  Pair(5, &l, &r);
  res = vo.AddStereoFrame(kT0 + 5 * kDt, l, r);
  ASSERT_EQ(res.state, TrackingState::kTracked) << res.message;
  EXPECT_FALSE(res.new_segment);
  EXPECT_NEAR(res.T_prev_camera.translation().x(), 4 * kStep, 0.005);
  EXPECT_NEAR(res.T_world_base.translation().y(), -5 * kStep, 0.01);
}

TEST_F(StereoVoTest, RepeatedOrBackwardTimeStampsAreRejected) {
  StereoVo vo(StereoVoOptions(), calib_);
  cv::Mat l, r;
  Pair(0, &l, &r);
  ASSERT_EQ(vo.AddStereoFrame(kT0, l, r).state, TrackingState::kInitialized);
  Pair(1, &l, &r);
  StereoVoResult res = vo.AddStereoFrame(kT0, l, r);
  EXPECT_EQ(res.state, TrackingState::kRejected);
  EXPECT_NE(res.message.find("not after the previous"), std::string::npos) << res.message;
  res = vo.AddStereoFrame(kT0 - kDt, l, r);
  EXPECT_EQ(res.state, TrackingState::kRejected);
  res = vo.AddStereoFrame(kT0 + kDt, l, r);
  EXPECT_EQ(res.state, TrackingState::kTracked) << res.message;
}

TEST_F(StereoVoTest, AGapLongerThanMaxGapStartsANewSegment) {
  StereoVoOptions opts;
  opts.max_gap_s = 0.5;
  StereoVo vo(opts, calib_);
  cv::Mat l, r;
  Pair(0, &l, &r);
  ASSERT_EQ(vo.AddStereoFrame(kT0, l, r).state, TrackingState::kInitialized);
  Pair(1, &l, &r);
  const StereoVoResult res = vo.AddStereoFrame(kT0 + 2000000, l, r);
  EXPECT_EQ(res.state, TrackingState::kInitialized);
  EXPECT_TRUE(res.new_segment);
  EXPECT_EQ(res.segment, 1);
  EXPECT_TRUE(res.is_keyframe);
  EXPECT_FALSE(res.factor.has_value()) << "no factor across an unknown gap";
  EXPECT_NE(res.message.find("new segment"), std::string::npos) << res.message;
}

TEST_F(StereoVoTest, UnrelatedImagesAreNotTrackedWithoutAFactor) {
  StereoVo vo(StereoVoOptions(), calib_);
  cv::Mat l, r;
  Pair(0, &l, &r);
  ASSERT_EQ(vo.AddStereoFrame(kT0, l, r).state, TrackingState::kInitialized);
  const cv::Mat other = Texture(900, 700, 99);
  PlanePair(other, calib_, kDepth, 0.0, 0.0, &l, &r);
  const StereoVoResult res = vo.AddStereoFrame(kT0 + kDt, l, r);
  EXPECT_EQ(res.state, TrackingState::kNotTracked) << res.message;
  EXPECT_FALSE(res.factor.has_value());
}

TEST(StereoVoOptionsTest, ConfigFileLoadsAndDefaultsValidate) {
  EXPECT_TRUE(StereoVoOptions().Validate().ok());
  const std::string path = fl::test::SourceDir() + "/config/stereo_vo.yaml";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "no " << path;
  const StereoVoOptions o = fl::LoadYamlFile<StereoVoOptions>(path);
  EXPECT_TRUE(o.Validate().ok());
  EXPECT_THROW(fl::LoadYamlString<StereoVoOptions>("matching: {slope_treshold: 0.3}\n"),
               fl::ConfigError);
  // The file states the defaults.
  EXPECT_EQ(o.features.fast_threshold, StereoVoOptions().features.fast_threshold);
  EXPECT_EQ(o.estimate_disparity_offset, StereoVoOptions().estimate_disparity_offset);
  EXPECT_EQ(o.disparity_offset_drift_px, StereoVoOptions().disparity_offset_drift_px);
  EXPECT_EQ(o.use_odometry_prior, StereoVoOptions().use_odometry_prior);
  EXPECT_EQ(o.local_ba.enabled, StereoVoOptions().local_ba.enabled);
  EXPECT_EQ(o.local_ba.window_keyframes, StereoVoOptions().local_ba.window_keyframes);
  EXPECT_EQ(o.local_ba.motion_prior_covariance_scale,
            StereoVoOptions().local_ba.motion_prior_covariance_scale);
  // The 2 Hz variant changes only what it says, and keeps the local BA's prior (the product of
  // the two covariance scales) as it is at 10 Hz.
  const StereoVoOptions slow =
      fl::LoadYamlFile<StereoVoOptions>(fl::test::SourceDir() + "/config/stereo_vo_2hz.yaml");
  EXPECT_TRUE(slow.Validate().ok());
  EXPECT_TRUE(o.use_odometry_prior);
  EXPECT_FALSE(slow.use_odometry_prior);
  EXPECT_EQ(o.refine.covariance_scale, 10.0);
  EXPECT_EQ(slow.refine.covariance_scale, 1.0);
  EXPECT_EQ(slow.refine.covariance_scale * slow.local_ba.motion_prior_covariance_scale,
            o.refine.covariance_scale * o.local_ba.motion_prior_covariance_scale);
  EXPECT_EQ(slow.keyframe_translation_m, o.keyframe_translation_m);
}

TEST(StereoVoOptionsTest, DisparityOffsetOptionsAreChecked) {
  StereoVoOptions o;
  o.refine.use_ceres = true;  // Ceres does not model the offset
  fl::Status s = o.Validate();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("estimate_disparity_offset"), std::string::npos) << s.message();
  o.estimate_disparity_offset = false;
  EXPECT_TRUE(o.Validate().ok()) << "Ceres without the offset is fine";
  o = StereoVoOptions();
  o.disparity_offset_initial_sd_px = 0;
  EXPECT_FALSE(o.Validate().ok());
  o = StereoVoOptions();
  o.disparity_offset_initial_px = 3.0;  // beyond disparity_offset_max_px
  EXPECT_FALSE(o.Validate().ok());
  EXPECT_THROW(StereoVo(o, fl::test::stereo::TestCalibration()), std::invalid_argument);
}

TEST_F(StereoVoTest, OffsetStaysAtItsPriorWhenUnobservable) {
  // A fronto-parallel plane moved sideways: one depth, no change of disparity, so the data
  // cannot tell an offset from a depth and the estimate must stay near its start value.
  StereoVoOptions opts;
  opts.disparity_offset_initial_px = -0.2;
  StereoVo vo(opts, calib_);
  cv::Mat l, r;
  for (int k = 0; k <= 4; ++k) {
    Pair(k, &l, &r);
    const StereoVoResult res = vo.AddStereoFrame(kT0 + k * kDt, l, r);
    ASSERT_NE(res.state, TrackingState::kNotTracked) << res.message;
    EXPECT_NEAR(res.stats.disparity_offset_px, -0.2, 0.1);
    EXPECT_GT(res.stats.disparity_offset_sd_px, 0.0);
  }
}

}  // namespace
}  // namespace fl::vo
