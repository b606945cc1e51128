// Tests of the stages of StereoVo::AddStereoFrame (stereo_vo_stages.hpp) against known answers
// on synthetic data: square corners, the disparity and motion of a textured plane, 3D-3D
// correspondences with outliers under a known motion, and hand-made tracks and keyframes.
#include "fusionloc/stereo_vo/stereo_vo_stages.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "stereo_fixtures.hpp"

namespace fl::vo::stages {
namespace {

using fl::test::stereo::MakeMotion;
using fl::test::stereo::PlanePair;
using fl::test::stereo::TestCalibration;
using fl::test::stereo::Texture;

constexpr double kDepth = 5.0;  // [m] plane distance: disparity 500 * 0.2 / 5 = 20 px
constexpr double kStep = 0.05;  // [m] camera x per frame: 500 * 0.05 / 5 = 5 px image motion

class StereoVoStagesTest : public ::testing::Test {
 protected:
  StereoVoStagesTest()
      : calib_(TestCalibration()),
        camera_(calib_.camera()),
        texture_(Texture(900, 700, 17)),
        extractor_(options_.features) {}
  // The plane at depth z seen from the camera at (cam_x, cam_y), detected and stereo matched.
  StereoFrame PlaneFrame(double cam_x, double cam_y = 0.0, double z = kDepth) {
    StereoFrame f;
    PlanePair(texture_, calib_, z, cam_x, cam_y, &f.left, &f.right);
    DetectFeatures(&extractor_, &f);
    MatchStereoFrame(options_, &f);
    return f;
  }
  // A textureless pair: no features, nothing to match.
  StereoFrame FlatFrame() {
    StereoFrame f;
    f.left = cv::Mat(calib_.height, calib_.width, CV_8UC1, cv::Scalar(120));
    f.right = f.left;
    DetectFeatures(&extractor_, &f);
    MatchStereoFrame(options_, &f);
    return f;
  }
  // Quadrilaterals between the plane frames before and after one step (velocity prediction).
  QuadMatches StepQuads(const StereoFrame& prev, const StereoFrame& cur, TemporalMatches* t) {
    const TemporalPrediction p =
        PredictByVelocity(camera_, prev, MakeMotion(0, 0, 0, kStep, 0, 0), options_.matching);
    *t = MatchTemporalPair(prev, cur, p, options_.matching);
    return CheckQuadrilaterals(prev, cur, *t, options_.matching);
  }
  StereoCalibration calib_;
  StereoCamera camera_;
  cv::Mat texture_;
  StereoVoOptions options_;
  FeatureExtractor extractor_;
};

// Fraction of the predicted/matched points p (not (-1, -1)) within tol of expected(i).
template <class F>
double FractionNear(const std::vector<cv::Point2f>& p, F&& expected, double tol, int* n) {
  int near = 0;
  *n = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    if (p[i].x < 0) continue;
    ++*n;
    const cv::Point2f d = p[i] - expected(i);
    if (std::hypot(d.x, d.y) <= tol) ++near;
  }
  return *n > 0 ? static_cast<double>(near) / *n : 0.0;
}

TEST_F(StereoVoStagesTest, CheckImagesConvertsColourAndNamesTheProblem) {
  cv::Mat l, r, gl, gr;
  PlanePair(texture_, calib_, kDepth, 0, 0, &l, &r);
  EXPECT_EQ(CheckImages(l, r, calib_, &gl, &gr), "");
  EXPECT_EQ(gl.data, l.data);  // gray input: a view, no copy
  cv::Mat lc, rc;
  cv::cvtColor(l, lc, cv::COLOR_GRAY2BGR);
  cv::cvtColor(r, rc, cv::COLOR_GRAY2BGRA);
  EXPECT_EQ(CheckImages(lc, rc, calib_, &gl, &gr), "");
  ASSERT_EQ(gl.type(), CV_8UC1);
  ASSERT_EQ(gr.type(), CV_8UC1);
  EXPECT_EQ(cv::norm(gl, l, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(gr, r, cv::NORM_INF), 0.0);
  EXPECT_EQ(CheckImages(l, cv::Mat(), calib_, &gl, &gr), "right image is empty");
  EXPECT_NE(CheckImages(l, r(cv::Rect(0, 0, 320, 240)), calib_, &gl, &gr)
                .find("left 640x480, right 320x240 do not match the calibration 640x480"),
            std::string::npos);
  cv::Mat lf;
  l.convertTo(lf, CV_32F);
  EXPECT_NE(CheckImages(lf, lf, calib_, &gl, &gr).find("unsupported pixel type"),
            std::string::npos);
}

TEST_F(StereoVoStagesTest, CheckTimeStampAndExposure) {
  EXPECT_EQ(CheckTimeStamp(100, -1), "");
  EXPECT_EQ(CheckTimeStamp(101, 100), "");
  EXPECT_NE(CheckTimeStamp(100, 100).find("not after the previous 100 us"), std::string::npos);
  EXPECT_NE(CheckTimeStamp(99, 100), "");
  const cv::Mat mid(48, 64, CV_8UC1, cv::Scalar(120));
  EXPECT_EQ(CheckExposure(mid, mid, options_), "");
  EXPECT_EQ(CheckExposure(mid, cv::Mat(48, 64, CV_8UC1, cv::Scalar(5)), options_),
            "black frame (mean gray 5)");
  EXPECT_EQ(CheckExposure(cv::Mat(48, 64, CV_8UC1, cv::Scalar(250)), mid, options_),
            "saturated frame (mean gray 250)");
}

TEST_F(StereoVoStagesTest, DetectFeaturesFindsTheSquareCornersInBothImages) {
  std::vector<cv::Point2f> corners_l, corners_r;
  StereoFrame f;
  f.left = fl::test::stereo::Squares(640, 480, 10, 40, 0, &corners_l);
  f.right = fl::test::stereo::Squares(640, 480, 10, 40, -12, &corners_r);
  DetectFeatures(&extractor_, &f);
  for (const auto& [features, corners] :
       {std::make_pair(&f.fl, &corners_l), std::make_pair(&f.fr, &corners_r)}) {
    ASSERT_GT(features->size(), 0);
    EXPECT_EQ(features->descriptors.rows, features->size());
    std::vector<bool> found(corners->size(), false);
    for (const cv::KeyPoint& kp : features->keypoints) {
      double best = 1e9;
      size_t best_c = 0;
      for (size_t c = 0; c < corners->size(); ++c) {
        const double d = std::hypot(kp.pt.x - (*corners)[c].x, kp.pt.y - (*corners)[c].y);
        if (d < best) best = d, best_c = c;
      }
      EXPECT_LE(best, 1.5) << "keypoint at " << kp.pt << " is no square corner";
      found[best_c] = true;
    }
    // Corners within the detector's border band are not kept; most of the others are.
    const auto n_found = std::count(found.begin(), found.end(), true);
    EXPECT_GT(n_found, static_cast<long>(corners->size()) * 3 / 4)
        << n_found << " of " << corners->size();
  }
}

TEST_F(StereoVoStagesTest, MatchStereoFrameMeasuresTheKnownSubPixelDisparity) {
  const double z = 4.3;  // disparity 100 / 4.3 = 23.256 px
  const double disparity = calib_.fx * calib_.baseline / z;
  StereoFrame f = PlaneFrame(0.0, 0.0, z);
  ASSERT_EQ(f.stereo.size(), static_cast<size_t>(f.fl.size()));
  int matches = 0, close = 0;
  for (size_t i = 0; i < f.stereo.size(); ++i) {
    EXPECT_EQ(f.track_id[i], -1);
    if (f.stereo[i] < 0) continue;
    ++matches;
    const double d = f.fl.keypoints[i].pt.x - f.right_x[i];
    if (std::abs(d - disparity) < 0.1) ++close;
    EXPECT_NEAR(d, disparity, 1.0) << "feature " << i;
  }
  EXPECT_EQ(f.stereo_matches, matches);
  EXPECT_GT(matches, 150);
  EXPECT_GT(close, matches * 9 / 10) << close << " of " << matches << " within 0.1 px";
  // Without the sub-pixel step the right x are the integer corners: at best 0.256 px off.
  StereoVoOptions o = options_;
  o.subpixel_refinement = false;
  StereoFrame g;
  g.left = f.left;
  g.right = f.right;
  DetectFeatures(&extractor_, &g);
  EXPECT_EQ(MatchStereoFrame(o, &g), 0);
  for (size_t i = 0; i < g.stereo.size(); ++i) {
    if (g.stereo[i] < 0) continue;
    EXPECT_EQ(g.right_x[i], g.fr.keypoints[static_cast<size_t>(g.stereo[i])].pt.x);
    EXPECT_GT(std::abs(g.fl.keypoints[i].pt.x - g.right_x[i] - disparity), 0.2);
  }
}

TEST_F(StereoVoStagesTest, PredictByVelocityMovesThePointsByTheKnownMotion) {
  const StereoFrame prev = PlaneFrame(0.0);
  const TemporalPrediction p =
      PredictByVelocity(camera_, prev, MakeMotion(0, 0, 0, kStep, 0, 0), options_.matching);
  EXPECT_EQ(p.radius_px, options_.matching.window_px);
  ASSERT_EQ(p.left.size(), static_cast<size_t>(prev.fl.size()));
  ASSERT_EQ(p.right.size(), static_cast<size_t>(prev.fr.size()));
  const double flow = calib_.fx * kStep / kDepth;  // 5 px to the left
  // Both images: every stereo feature predicted, nearly all at the known flow.
  for (const auto& [pred, features] :
       {std::make_pair(&p.left, &prev.fl), std::make_pair(&p.right, &prev.fr)}) {
    int n = 0;
    const Features* f = features;
    const auto moved = [f, flow](size_t i) {
      return f->keypoints[i].pt - cv::Point2f(static_cast<float>(flow), 0);
    };
    EXPECT_GT(FractionNear(*pred, moved, 0.3, &n), 0.95);
    EXPECT_EQ(n, prev.stereo_matches);
  }
}

TEST_F(StereoVoStagesTest, GlobalShiftIsTheMedianImageMotion) {
  const StereoFrame prev = PlaneFrame(0.0);
  // 30 px right and 10 px down: beyond the narrow window, inside the wide one.
  const StereoFrame cur = PlaneFrame(-0.3, -0.1);
  const GlobalShift g = EstimateGlobalShift(prev, cur, options_.matching);
  ASSERT_TRUE(g.found);
  EXPECT_NEAR(g.shift.x, 30.0, 0.5);
  EXPECT_NEAR(g.shift.y, 10.0, 0.5);
  const TemporalPrediction p = PredictByShift(prev, g, options_.matching);
  EXPECT_EQ(p.radius_px, 3 * options_.matching.window_px);
  int n = 0;
  EXPECT_EQ(FractionNear(
                p.left, [&](size_t i) { return prev.fl.keypoints[i].pt + g.shift; }, 1e-4, &n),
            1.0);
  EXPECT_EQ(n, prev.stereo_matches);
  // Nothing to match: no shift, the wide window.
  const StereoFrame empty = FlatFrame();
  const GlobalShift none = EstimateGlobalShift(prev, empty, options_.matching);
  EXPECT_FALSE(none.found);
  EXPECT_EQ(PredictByShift(prev, none, options_.matching).radius_px,
            options_.matching.window_unpredicted_px);
}

TEST_F(StereoVoStagesTest, TemporalMatchesAndQuadrilateralsFollowTheKnownMotion) {
  const StereoFrame prev = PlaneFrame(0.0), cur = PlaneFrame(kStep);
  TemporalMatches t;
  const QuadMatches q = StepQuads(prev, cur, &t);
  ASSERT_EQ(t.left.size(), static_cast<size_t>(prev.fl.size()));
  ASSERT_EQ(t.right.size(), static_cast<size_t>(prev.fr.size()));
  int n = 0, good = 0;
  for (size_t i = 0; i < t.left.size(); ++i) {
    if (t.left[i] < 0) continue;
    ++n;
    const cv::Point2f d = cur.fl.keypoints[static_cast<size_t>(t.left[i])].pt -
                          prev.fl.keypoints[i].pt - cv::Point2f(-5.0f, 0.0f);
    if (std::hypot(d.x, d.y) <= 1.0) ++good;
  }
  EXPECT_GT(n, 150);
  EXPECT_GT(good, n * 95 / 100) << good << " of " << n;

  EXPECT_GT(q.quads.size(), 150u);
  EXPECT_EQ(q.stats.kept, static_cast<int>(q.quads.size()));
  EXPECT_EQ(q.stats.candidates, prev.stereo_matches);
  for (const Quad& quad : q.quads) {
    // A closed loop: the four links agree.
    EXPECT_EQ(prev.stereo[static_cast<size_t>(quad.left_a)], quad.right_a);
    EXPECT_EQ(cur.stereo[static_cast<size_t>(quad.left_b)], quad.right_b);
    EXPECT_EQ(t.left[static_cast<size_t>(quad.left_a)], quad.left_b);
    EXPECT_EQ(t.right[static_cast<size_t>(quad.right_a)], quad.right_b);
  }
}

TEST_F(StereoVoStagesTest, CorrespondencesTriangulateTheKnownDepthAndMotion) {
  const StereoFrame prev = PlaneFrame(0.0), cur = PlaneFrame(kStep);
  TemporalMatches t;
  const QuadMatches q = StepQuads(prev, cur, &t);
  const Correspondences c = BuildCorrespondences(camera_, prev, cur, q.quads, 0.0);
  ASSERT_EQ(c.corr.size(), c.quad.size());
  EXPECT_EQ(c.corr.size(), q.quads.size());  // all disparities positive
  int good = 0;
  for (size_t k = 0; k < c.corr.size(); ++k) {
    const StereoCorrespondence& s = c.corr[k];
    const Quad& quad = q.quads[static_cast<size_t>(c.quad[k])];
    EXPECT_EQ(s.obs_a(0), prev.fl.keypoints[static_cast<size_t>(quad.left_a)].pt.x);
    EXPECT_EQ(s.obs_a(2), prev.right_x[static_cast<size_t>(quad.left_a)]);
    EXPECT_NEAR(s.p_a.z(), kDepth, 0.05);
    EXPECT_NEAR(s.p_b.z(), kDepth, 0.05);
    // p_a = T_a_b p_b with T_a_b a translation of kStep along x.
    if ((s.p_a - s.p_b - Eigen::Vector3d(kStep, 0, 0)).norm() < 0.01) ++good;
  }
  EXPECT_GT(good, static_cast<int>(c.corr.size()) * 9 / 10);

  // A disparity offset estimate corrects every right x.
  const double offset = 0.5;
  const Correspondences co = BuildCorrespondences(camera_, prev, cur, q.quads, offset);
  ASSERT_EQ(co.corr.size(), c.corr.size());
  for (size_t k = 0; k < co.corr.size(); ++k) {
    const double u = c.corr[k].obs_b(2);
    EXPECT_DOUBLE_EQ(co.corr[k].obs_b(2), u + offset * OffsetBasis(camera_, u));
    EXPECT_GT(co.corr[k].p_b.z(), c.corr[k].p_b.z());  // smaller disparity: farther
  }
}

TEST_F(StereoVoStagesTest, SearchMotionFindsTheMotionAndRetriesAfterABadPrediction) {
  const StereoFrame prev = PlaneFrame(0.0), cur = PlaneFrame(kStep);
  const Eigen::Isometry3d truth = MakeMotion(0, 0, 0, kStep, 0, 0);
  // Velocity prediction right: attempt 0 is kept.
  FrameMatch m = SearchMotion(camera_, prev, cur, true, truth, 0.0, options_);
  ASSERT_TRUE(m.ransac.ok);
  EXPECT_EQ(m.attempt, 0);
  EXPECT_LT((m.ransac.T_a_b.translation() - truth.translation()).norm(), 0.005);
  EXPECT_GT(static_cast<int>(m.ransac.inliers.size()), 2 * options_.min_quads);
  EXPECT_EQ(m.corr.corr.size(), m.quads.quads.size());
  // No prediction: the global shift.
  m = SearchMotion(camera_, prev, cur, false, truth, 0.0, options_);
  ASSERT_TRUE(m.ransac.ok);
  EXPECT_EQ(m.attempt, 1);
  EXPECT_LT((m.ransac.T_a_b.translation() - truth.translation()).norm(), 0.005);
  // A prediction 0.5 m (50 px) off fails; the retry with the global shift finds the motion.
  m = SearchMotion(camera_, prev, cur, true, MakeMotion(0, 0, 0, -0.5, 0, 0), 0.0, options_);
  ASSERT_TRUE(m.ransac.ok);
  EXPECT_EQ(m.attempt, 1);
  EXPECT_LT((m.ransac.T_a_b.translation() - truth.translation()).norm(), 0.005);
  // Nothing to match: no motion, no RANSAC run.
  const StereoFrame empty = FlatFrame();
  m = SearchMotion(camera_, prev, empty, true, truth, 0.0, options_);
  EXPECT_FALSE(m.ransac.ok);
  EXPECT_EQ(m.ransac.iterations, 0);
  EXPECT_EQ(m.attempt, 1);
  EXPECT_TRUE(m.corr.corr.empty());
}

TEST(StereoVoStages, VelocityPredictsOnlyForASimilarTimeStep) {
  EXPECT_FALSE(VelocityPredicts(0.1, 0.0));
  EXPECT_TRUE(VelocityPredicts(0.1, 0.1));
  EXPECT_TRUE(VelocityPredicts(0.12, 0.1));
  EXPECT_FALSE(VelocityPredicts(0.2, 0.1));
  EXPECT_FALSE(VelocityPredicts(0.05, 0.1));
}

// 200 correspondences under a known motion, the first 20 with wrong observations at b.
class StereoVoStagesMotionTest : public ::testing::Test {
 protected:
  StereoVoStagesMotionTest()
      : camera_(TestCalibration().camera()),
        truth_(MakeMotion(0.01, -0.02, 0.015, 0.3, -0.05, 1.2)) {}
  std::vector<StereoCorrespondence> Corr(double noise_px) const {
    return fl::test::stereo::MakeCorrespondences(camera_, truth_, 200, kOutliers, noise_px, 7);
  }
  static constexpr int kOutliers = 20;
  StereoCamera camera_;
  Eigen::Isometry3d truth_;
};

TEST_F(StereoVoStagesMotionTest, SelectInliersRejectsTheOutliers) {
  // Exact observations: every correct correspondence fits, both ways.
  const std::vector<StereoCorrespondence> corr = Corr(0.0);
  const std::vector<int> in = SelectInliers(camera_, corr, truth_, 2.0);
  int outliers_in = 0;
  for (int i : in) outliers_in += i < kOutliers ? 1 : 0;
  EXPECT_EQ(static_cast<int>(in.size()) - outliers_in, 200 - kOutliers);
  EXPECT_LE(outliers_in, 1);  // an outlier moved by less than the threshold may pass
  for (int i : in) {
    if (i < kOutliers) {
      EXPECT_LE(ForwardReprojectionError(camera_, truth_, corr[size_t(i)]), 2.0);
    }
  }
  // Under a wrong motion hardly anything fits.
  EXPECT_LT(SelectInliers(camera_, corr, MakeMotion(0, 0, 0, 0.5, 0, 1.2), 2.0).size(), 20u);
}

TEST_F(StereoVoStagesMotionTest, RefineStageRefinesTheRansacMotion) {
  const std::vector<StereoCorrespondence> corr = Corr(0.1);
  StereoVoOptions o;
  const RansacResult ransac = RansacMotion(camera_, corr, o.ransac);
  ASSERT_TRUE(ransac.ok);
  const Refinement r = RefineStage(camera_, corr, ransac, nullptr, o);
  ASSERT_TRUE(r.ok);
  EXPECT_TRUE(r.last.ok);
  EXPECT_FALSE(r.last.offset_estimated);
  // RANSAC's motion is about 13 mm off, the refined one about 1 mm.
  EXPECT_LT((r.T_a_b.translation() - truth_.translation()).norm(), 0.004);
  EXPECT_LT(Eigen::AngleAxisd(r.T_a_b.linear().transpose() * truth_.linear()).angle(), 2e-3);
  EXPECT_NEAR(r.rms_px, 0.07, 0.03);  // below the noise: the points are estimated too
  EXPECT_EQ(r.rms_px, r.last.rms_px);
  // The second round's inliers: SelectInliers under the first round's motion.
  EXPECT_GE(static_cast<int>(r.inliers.size()), 150);
  int outliers_in = 0;
  for (int i : r.inliers) outliers_in += i < kOutliers ? 1 : 0;
  EXPECT_LE(outliers_in, 1);
  EXPECT_LT(r.covariance.norm(), 1e-3);
  EXPECT_EQ(r.covariance, r.last.covariance);
  // With an offset prior the increment is estimated (no offset in the data: near 0).
  OffsetPrior prior;
  const Refinement ro = RefineStage(camera_, corr, ransac, &prior, o);
  ASSERT_TRUE(ro.ok);
  EXPECT_TRUE(ro.last.offset_estimated);
  EXPECT_NEAR(ro.last.offset_px, 0.0, 0.1);
  // Without refinement: the RANSAC motion and inliers.
  o.use_refinement = false;
  const Refinement rs = RefineStage(camera_, corr, ransac, nullptr, o);
  ASSERT_TRUE(rs.ok);
  EXPECT_EQ(rs.T_a_b.matrix(), ransac.T_a_b.matrix());
  EXPECT_EQ(rs.inliers, ransac.inliers);
  EXPECT_EQ(rs.covariance, (Matrix6d::Identity() * 1e-2).eval());
  EXPECT_EQ(rs.rms_px, 0.0);
  EXPECT_FALSE(rs.last.ok);
}

TEST(StereoVoStages, TracksFollowTheInlierQuads) {
  StereoFrame prev, cur;
  prev.track_id = {7, 3, -1, 9};
  cur.stereo = {0, -1, 2, 3, 4};
  cur.track_id.assign(cur.stereo.size(), -1);
  FrameMatch m;
  // Quads: prev 0 -> cur 2, prev 1 -> cur 0, prev 3 -> cur 4; correspondence k -> quad.
  m.quads.quads = {{0, 0, 2, 2}, {1, 1, 0, 0}, {3, 3, 4, 4}};
  m.corr.quad = {2, 0, 1};
  // Inliers: correspondences 0 (prev 3 -> cur 4) and 1 (prev 0 -> cur 2); keyframe ids <= 8.
  EXPECT_EQ(PropagateTracks(prev, m, {0, 1}, 8, &cur), 1);
  EXPECT_EQ(cur.track_id, (std::vector<int64_t>{-1, -1, 7, -1, 9}));
  int64_t next = 20;
  AssignNewTracks(&cur, &next);
  // Stereo features without an id get 20, 21; feature 1 has no stereo match.
  EXPECT_EQ(cur.track_id, (std::vector<int64_t>{20, -1, 7, 21, 9}));
  EXPECT_EQ(next, 22);
}

TEST(StereoVoStages, NeedsKeyframeAtEachThreshold) {
  StereoVoOptions o;  // 1 m, 10 deg, overlap 0.5, 2 s
  const Eigen::Isometry3d still = Eigen::Isometry3d::Identity();
  EXPECT_FALSE(NeedsKeyframe(still, 60, 100, 1000000, o));
  EXPECT_FALSE(NeedsKeyframe(MakeMotion(0, 0, 0, 0, 0, 0.99), 60, 100, 1000000, o));
  EXPECT_TRUE(NeedsKeyframe(MakeMotion(0, 0, 0, 0, 0, 1.0), 60, 100, 1000000, o));
  EXPECT_FALSE(NeedsKeyframe(MakeMotion(0, 9.9 * M_PI / 180, 0, 0, 0, 0), 60, 100, 1000000, o));
  EXPECT_TRUE(NeedsKeyframe(MakeMotion(0, 10.1 * M_PI / 180, 0, 0, 0, 0), 60, 100, 1000000, o));
  EXPECT_FALSE(NeedsKeyframe(still, 50, 100, 1000000, o));
  EXPECT_TRUE(NeedsKeyframe(still, 49, 100, 1000000, o));
  EXPECT_TRUE(NeedsKeyframe(still, 0, 0, 1000000, o));  // a keyframe without tracks
  EXPECT_FALSE(NeedsKeyframe(still, 60, 100, 1999999, o));
  EXPECT_TRUE(NeedsKeyframe(still, 60, 100, 2000000, o));
}

TEST(StereoVoStages, KeyframeFactorIsInTheBaseFrame) {
  const StereoCalibration calib = TestCalibration();
  // 1 m forward (camera z) and a yaw to the left (about camera -y) of 0.1 rad.
  const Eigen::Isometry3d T_kf = MakeMotion(0, -0.1, 0, 0, 0, 1.0);
  Matrix6d cov = Matrix6d::Zero();
  cov.diagonal() << 1e-4, 4e-4, 9e-4, 1e-6, 4e-6, 9e-6;  // camera x, y, z, rx, ry, rz
  const KeyframeFactor f = MakeKeyframeFactor(calib.T_base_camera, T_kf, cov);
  // Base x = camera z, y = -camera x, z = -camera y. The camera sits off the base origin, so
  // the yaw moves it sideways too: T_i_j = T_bc T_kf T_bc^-1.
  const Eigen::Isometry3d expected = calib.T_base_camera * T_kf * calib.T_base_camera.inverse();
  EXPECT_TRUE(f.T_i_j.isApprox(expected, 1e-12));
  EXPECT_NEAR(Eigen::AngleAxisd(f.T_i_j.linear()).angle(), 0.1, 1e-12);
  EXPECT_NEAR((f.T_i_j.linear() * Eigen::Vector3d::UnitZ()).z(), 1.0, 1e-12);  // a yaw
  // Variances: base x <- camera z, base y <- camera x, base z <- camera y (same for rotations).
  Eigen::Matrix<double, 6, 1> expected_diag;
  expected_diag << 9e-4, 1e-4, 4e-4, 9e-6, 1e-6, 4e-6;
  // The lever arm of the camera adds rotation variance to the translation; none to rotation.
  EXPECT_TRUE(f.covariance.diagonal().tail<3>().isApprox(expected_diag.tail<3>(), 1e-9));
  EXPECT_TRUE(
      (f.covariance.diagonal().head<3>().array() >= expected_diag.head<3>().array() - 1e-12).all());
  EXPECT_TRUE((f.information * f.covariance).isApprox(Matrix6d::Identity(), 1e-9));
  // Symmetrised (to rounding: the in-place 0.5 (A + A^T) reads entries it already wrote).
  EXPECT_LT((f.information - f.information.transpose()).norm(), 1e-12 * f.information.norm());
  EXPECT_LT((f.covariance - f.covariance.transpose()).norm(), 1e-12 * f.covariance.norm());
}

TEST_F(StereoVoStagesTest, KeyframePointsLieOnThePlane) {
  const StereoFrame f = PlaneFrame(0.0);
  std::vector<Eigen::Vector3f> points;
  std::vector<float> gray;
  KeyframePoints(camera_, f, 0.0, &points, &gray);
  ASSERT_EQ(points.size(), gray.size());
  EXPECT_EQ(static_cast<int>(points.size()), f.stereo_matches);
  size_t k = 0;
  for (size_t i = 0; i < f.stereo.size(); ++i) {
    if (f.stereo[i] < 0) continue;
    const cv::Point2f pl = f.fl.keypoints[i].pt;
    EXPECT_NEAR(points[k].z(), kDepth, 0.05);
    // The point projects back to its left corner.
    EXPECT_NEAR(points[k].x() / points[k].z() * calib_.fx + calib_.cx, pl.x, 1e-3);
    EXPECT_EQ(gray[k], f.left.at<uint8_t>(cvRound(pl.y), cvRound(pl.x)) / 255.0f);
    ++k;
  }
  // An offset estimate shrinks the disparities: the plane comes out farther.
  std::vector<Eigen::Vector3f> far;
  KeyframePoints(camera_, f, 1.0, &far, &gray);
  ASSERT_EQ(far.size(), points.size());
  EXPECT_GT(far[0].z(), points[0].z() + 0.1);
}

}  // namespace
}  // namespace fl::vo::stages
