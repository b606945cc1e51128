// Tests of features, stereo/temporal matching, sub-pixel patch alignment and the quadrilateral
// closed-loop check.
#include "fusionloc/stereo_vo/matching.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>
#include <random>
#include <string>

#include "stereo_fixtures.hpp"

namespace fl::vo {
namespace {

// Features at given positions with given descriptor seeds (same seed = same descriptor).
Features MakeFeatures(const std::vector<cv::Point2f>& pts, const std::vector<int>& seeds) {
  Features f;
  f.descriptors.create(static_cast<int>(pts.size()), 32, CV_8U);
  for (size_t i = 0; i < pts.size(); ++i) {
    cv::KeyPoint kp(pts[i], 31.f);
    kp.octave = 0;
    f.keypoints.push_back(kp);
    std::mt19937 rng(static_cast<uint32_t>(seeds[i]));
    for (int b = 0; b < 32; ++b) {
      f.descriptors.at<uint8_t>(static_cast<int>(i), b) = static_cast<uint8_t>(rng() & 0xff);
    }
  }
  f.BuildIndex(640, 480);
  return f;
}

// A smooth texture evaluated at (x - sx, y - sy): an exact sub-pixel shift (no resampling).
cv::Mat ShiftedTexture(double sx, double sy) {
  cv::Mat img(120, 160, CV_8UC1);
  for (int y = 0; y < img.rows; ++y) {
    for (int x = 0; x < img.cols; ++x) {
      const double u = x - sx, v = y - sy;
      const double f = 128 + 50 * std::sin(0.31 * u + 0.7) * std::cos(0.23 * v) +
                       40 * std::sin(0.17 * u - 0.29 * v + 1.3) +
                       20 * std::cos(0.53 * v - 0.11 * u);
      img.at<uint8_t>(y, x) = cv::saturate_cast<uint8_t>(f);
    }
  }
  return img;
}

TEST(StereoVoMatching, AlignPatchRecoversSubPixelShifts) {
  const cv::Mat base = ShiftedTexture(0, 0);
  for (const auto& [sx, sy] :
       std::vector<std::pair<double, double>>{{0.3, 0.0}, {-0.45, 0.2}, {1.2, -0.7}, {-2.5, 0.4}}) {
    const cv::Mat moved = ShiftedTexture(sx, sy);
    for (const cv::Point2f p :
         {cv::Point2f(50, 40), cv::Point2f(100, 70), cv::Point2f(80.5f, 60.25f)}) {
      for (int half : {5, 7}) {
        cv::Point2f q = p;  // start at the unshifted position
        ASSERT_TRUE(AlignPatch(base, p, moved, half, &q)) << sx << " " << sy << " at " << p;
        EXPECT_NEAR(q.x - p.x, sx, 0.05) << "half " << half << " at " << p;
        EXPECT_NEAR(q.y - p.y, sy, 0.05) << "half " << half << " at " << p;
      }
    }
  }
}

TEST(StereoVoMatching, AlignPatchRefusesFlatPatchesEdgesAndBorders) {
  const cv::Mat flat(100, 100, CV_8UC1, cv::Scalar(90));
  cv::Point2f q(50, 50);
  EXPECT_FALSE(AlignPatch(flat, {50, 50}, flat, 5, &q)) << "no texture";
  cv::Mat edge(100, 100, CV_8UC1, cv::Scalar(40));
  edge.colRange(50, 100).setTo(200);  // vertical edge: vertical shift unconstrained
  q = cv::Point2f(50, 50);
  EXPECT_FALSE(AlignPatch(edge, {50, 50}, edge, 5, &q)) << "aperture problem";
  const cv::Mat tex = ShiftedTexture(0, 0);
  q = cv::Point2f(3, 60);
  EXPECT_FALSE(AlignPatch(tex, {80, 60}, tex, 5, &q)) << "target patch leaves the image";
  q = cv::Point2f(80, 60);
  EXPECT_FALSE(AlignPatch(tex, {2, 60}, tex, 5, &q)) << "template patch leaves the image";
  EXPECT_FALSE(AlignPatch(tex, {80, 60}, tex, 1, &q)) << "window too small";
  cv::Mat color;
  cv::cvtColor(tex, color, cv::COLOR_GRAY2BGR);
  EXPECT_FALSE(AlignPatch(color, {80, 60}, color, 5, &q)) << "8-bit gray only";
}

TEST(StereoVoMatching, StereoMatchingHonoursEpipolarAndDisparityLimits) {
  MatchOptions opts;
  opts.max_disparity_px = 100;
  opts.epipolar_tolerance_px = 3;
  // Left features 0..4 (seeds 1..5).
  const Features left =
      MakeFeatures({{300, 100}, {300, 200}, {300, 300}, {300, 400}, {50, 50}}, {1, 2, 3, 4, 5});
  // Right: 0 is a true match (d = 20, dy = 2); 1 is 5 px off the row; 2 has negative
  // disparity; 3 has disparity 150 > d_max; 4 matches feature 4 with disparity 0 (not > 0).
  const Features right =
      MakeFeatures({{280, 102}, {290, 205}, {310, 300}, {150, 400}, {50, 50}}, {1, 2, 3, 4, 5});
  const std::vector<int> m = MatchStereo(left, right, opts);
  ASSERT_EQ(m.size(), 5u);
  EXPECT_EQ(m[0], 0);
  EXPECT_EQ(m[1], -1) << "outside the epipolar tolerance";
  EXPECT_EQ(m[2], -1) << "negative disparity";
  EXPECT_EQ(m[3], -1) << "disparity above d_max";
  EXPECT_EQ(m[4], -1) << "zero disparity";
}

TEST(StereoVoMatching, StereoMatchingIsMutualAndUsesDescriptors) {
  MatchOptions opts;
  // Two left features share a row; the right one resembles left 1 only.
  const Features left = MakeFeatures({{300, 100}, {320, 100}}, {7, 8});
  const Features right = MakeFeatures({{290, 100}}, {8});
  const std::vector<int> m = MatchStereo(left, right, opts);
  EXPECT_EQ(m[0], -1);
  EXPECT_EQ(m[1], 0);
}

TEST(StereoVoMatching, TemporalMatchingSearchesOnlyThePredictedWindow) {
  MatchOptions opts;
  const Features a = MakeFeatures({{100, 100}, {200, 200}}, {1, 2});
  const Features b = MakeFeatures({{130, 100}, {260, 200}}, {1, 2});
  const std::vector<int> m = MatchTemporal(a, b, {{128, 101}, {200, 200}}, 20.0, opts);
  EXPECT_EQ(m[0], 0);
  EXPECT_EQ(m[1], -1) << "60 px away from the prediction, window 20 px";
  const std::vector<int> none = MatchTemporal(a, b, {{-1, -1}, {-1, -1}}, 100.0, opts);
  EXPECT_EQ(none[0], -1) << "no prediction: not searched";
}

// Four images of five scene points; quads are crafted consistent or not.
TEST(StereoVoMatching, QuadrilateralCheckRejectsInconsistentMatches) {
  MatchOptions opts;
  opts.slope_threshold = 0.35;
  std::vector<cv::Point2f> la, ra, lb, rb;
  // 0: consistent (d 20 -> 21, flows (10,2) and (9,2)).
  la.push_back({100, 100});
  ra.push_back({80, 100});
  lb.push_back({110, 102});
  rb.push_back({89, 102});
  // 1: consistent geometry, but the right temporal match lands on another feature.
  la.push_back({300, 100});
  ra.push_back({280, 100});
  lb.push_back({305, 100});
  rb.push_back({285, 100});
  // 2: slope test fails: flows (4, 3) and (-3, 3) point different ways (d 20 -> 27).
  la.push_back({400, 300});
  ra.push_back({380, 300});
  lb.push_back({404, 303});
  rb.push_back({377, 303});
  // 3: parallax fails: disparity 10 -> 21 (ratio 2.1 > 1.6).
  la.push_back({500, 50});
  ra.push_back({490, 50});
  lb.push_back({501, 50});
  rb.push_back({480, 50});
  // 4: vertical flows disagree by 6 px (> epipolar tolerance).
  la.push_back({200, 400});
  ra.push_back({180, 400});
  lb.push_back({210, 400});
  rb.push_back({189, 406});
  const std::vector<int> seeds = {1, 2, 3, 4, 5};
  const Features fla = MakeFeatures(la, seeds), fra = MakeFeatures(ra, seeds),
                 flb = MakeFeatures(lb, seeds), frb = MakeFeatures(rb, seeds);
  const std::vector<int> stereo_a = {0, 1, 2, 3, 4};
  const std::vector<int> stereo_b = {0, 1, 2, 3, 4};
  const std::vector<int> temporal_left = {0, 1, 2, 3, 4};
  std::vector<int> temporal_right = {0, 3, 2, 3, 4};  // 1 -> 3: the loop does not close
  QuadStats stats;
  std::vector<Quad> quads = CloseQuadrilaterals(fla, fra, flb, frb, stereo_a, stereo_b,
                                                temporal_left, temporal_right, opts, &stats);
  ASSERT_EQ(quads.size(), 1u);
  EXPECT_EQ(quads[0].left_a, 0);
  EXPECT_EQ(quads[0].right_b, 0);
  EXPECT_EQ(stats.candidates, 5);
  EXPECT_EQ(stats.not_closed, 1);
  EXPECT_EQ(stats.slope_rejected, 2);
  EXPECT_EQ(stats.parallax_rejected, 1);
  // Closing the loop of point 1 makes it pass.
  temporal_right[1] = 1;
  quads = CloseQuadrilaterals(fla, fra, flb, frb, stereo_a, stereo_b, temporal_left, temporal_right,
                              opts, &stats);
  EXPECT_EQ(quads.size(), 2u);
  // A missing stereo match at b breaks the loop too.
  const std::vector<int> stereo_b_missing = {-1, 1, 2, 3, 4};
  quads = CloseQuadrilaterals(fla, fra, flb, frb, stereo_a, stereo_b_missing, temporal_left,
                              temporal_right, opts, &stats);
  EXPECT_EQ(quads.size(), 1u);
  EXPECT_EQ(quads[0].left_a, 1);
}

// The paper's rules (MSIF §2) as this project's defaults, written out here so that a changed
// default fails the tests below as much as a changed rule in matching.cpp does.
constexpr double kSlopeK = 0.35;            // eq. 9: tan of the angle between the flows
constexpr double kEpipolarPx = 3.0;         // |v_left - v_right|
constexpr double kMaxDisparityPx = 160.0;   // d_max
constexpr double kMaxDisparityRatio = 1.6;  // d_t+1 / d_t within [1/r, r]
// Each rule is probed this much inside and outside its bound.
constexpr double kInside = 0.99, kOutside = 1.01;

// What CloseQuadrilaterals (default options) makes of one quadrilateral: "kept", "slope",
// "parallax" or "not closed".
std::string CloseOne(cv::Point2f la, cv::Point2f ra, cv::Point2f lb, cv::Point2f rb) {
  const Features fla = MakeFeatures({la}, {1}), fra = MakeFeatures({ra}, {1}),
                 flb = MakeFeatures({lb}, {1}), frb = MakeFeatures({rb}, {1});
  QuadStats s;
  const std::vector<int> one = {0};
  CloseQuadrilaterals(fla, fra, flb, frb, one, one, one, one, MatchOptions(), &s);
  if (s.kept == 1) return "kept";
  if (s.slope_rejected == 1) return "slope";
  if (s.parallax_rejected == 1) return "parallax";
  return "not closed";
}

// The tan of the angle between the lines of two flows as matching.hpp defines it:
// |k_l - k_r| / |1 + k_l k_r| with the slopes k = dy / dx.
double SlopeTan(cv::Point2f fl, cv::Point2f fr) {
  const double kl = static_cast<double>(fl.y) / fl.x, kr = static_cast<double>(fr.y) / fr.x;
  return std::abs(kl - kr) / std::abs(1 + kl * kr);
}

// Both flows point the same way with the same vertical part (the epipolar check passes) and
// their lines meet at an angle whose tan is just below or just above K, the right flow turned
// either way from the left one.
TEST(StereoVoMatching, SlopeTestRejectsJustAboveKAndKeepsJustBelow) {
  const double a = 10, h = 60;                   // left flow (a, h); right flow (b, h)
  const cv::Point2f la(400, 200), ra(300, 200);  // disparity 100
  for (const int side : {+1, -1}) {
    for (const double factor : {kInside, kOutside}) {
      const double t = factor * kSlopeK;
      // h |a - b| / (a b + h²) = t with b on the given side of a.
      const double b =
          side > 0 ? (h * a + t * h * h) / (h - t * a) : (h * a - t * h * h) / (h + t * a);
      const cv::Point2f lb = la + cv::Point2f(static_cast<float>(a), static_cast<float>(h));
      const cv::Point2f rb = ra + cv::Point2f(static_cast<float>(b), static_cast<float>(h));
      const cv::Point2f fl = lb - la, fr = rb - ra;
      ASSERT_GT(fl.dot(fr), 0.f) << "same direction";
      ASSERT_NEAR(SlopeTan(fl, fr), t, 1e-4 * kSlopeK);
      EXPECT_EQ(CloseOne(la, ra, lb, rb), factor < 1 ? "kept" : "slope")
          << "tan " << SlopeTan(fl, fr) << " (K = " << kSlopeK << "), right flow " << fr
          << ", left flow " << fl;
    }
  }
}

// The vertical parts of the two flows (the epipolar tolerance at t+1 given it at t) agree
// within just less or just more than the tolerance, the right one above or below the left one;
// the lines of both flows are well within K of each other.
TEST(StereoVoMatching, QuadrilateralFlowsAgreeVerticallyWithinTheEpipolarTolerance) {
  const cv::Point2f la(400, 200), ra(340, 200), fl(20, 5);
  for (const int side : {+1, -1}) {
    for (const double factor : {kInside, kOutside}) {
      const float dy = static_cast<float>(side * factor * kEpipolarPx);
      const cv::Point2f fr = fl + cv::Point2f(0, dy);
      ASSERT_LT(SlopeTan(fl, fr), 0.5 * kSlopeK);
      EXPECT_EQ(CloseOne(la, ra, la + fl, ra + fr), factor < 1 ? "kept" : "slope")
          << "vertical flows differ by " << dy << " px (tolerance " << kEpipolarPx << ")";
    }
  }
}

TEST(StereoVoMatching, StereoMatchesLieWithinTheEpipolarToleranceOfTheRow) {
  // One left feature per row, 60 px apart; its right twin 40 px to the left and just inside or
  // outside the tolerance above or below.
  std::vector<cv::Point2f> left, right;
  std::vector<int> expected;
  for (const int side : {+1, -1}) {
    for (const double factor : {kInside, kOutside}) {
      const float y = 60.f * static_cast<float>(left.size() + 1);
      left.emplace_back(300.f, y);
      right.emplace_back(260.f, y + static_cast<float>(side * factor * kEpipolarPx));
      expected.push_back(factor < 1 ? static_cast<int>(left.size()) - 1 : -1);
    }
  }
  const std::vector<int> seeds = {1, 2, 3, 4};
  const std::vector<int> m =
      MatchStereo(MakeFeatures(left, seeds), MakeFeatures(right, seeds), MatchOptions());
  EXPECT_EQ(m, expected) << "right rows " << right[0].y - left[0].y << ", "
                         << right[1].y - left[1].y << ", " << right[2].y - left[2].y << ", "
                         << right[3].y - left[3].y << " px off (tolerance " << kEpipolarPx << ")";
}

TEST(StereoVoMatching, StereoMatchesHaveDisparityUpToDmax) {
  const std::vector<cv::Point2f> left = {{600, 100}, {600, 200}};
  const std::vector<cv::Point2f> right = {
      {static_cast<float>(600 - kInside * kMaxDisparityPx), 100},
      {static_cast<float>(600 - kOutside * kMaxDisparityPx), 200}};
  const std::vector<int> m =
      MatchStereo(MakeFeatures(left, {1, 2}), MakeFeatures(right, {1, 2}), MatchOptions());
  EXPECT_EQ(m, (std::vector<int>{0, -1}))
      << "disparities " << left[0].x - right[0].x << " and " << left[1].x - right[1].x << " (d_max "
      << kMaxDisparityPx << ")";
}

// A quadrilateral with disparities da at t and db at t+1 (|da - db| < 70 px), both flows
// horizontal and forward (the slope and epipolar checks pass).
std::string CloseWithDisparities(double da, double db) {
  const cv::Point2f la(560, 100), lb(630, 100);
  const float fr = static_cast<float>(70 + da - db);  // right flow making db
  const cv::Point2f ra(static_cast<float>(560 - da), 100);
  return CloseOne(la, ra, lb, ra + cv::Point2f(fr, 0));
}

TEST(StereoVoMatching, QuadrilateralDisparitiesAreAtMostDmax) {
  const double in = kInside * kMaxDisparityPx, out = kOutside * kMaxDisparityPx;
  EXPECT_EQ(CloseWithDisparities(in, in), "kept") << in << " px at both times";
  EXPECT_EQ(CloseWithDisparities(out, in), "parallax") << out << " px at t";
  EXPECT_EQ(CloseWithDisparities(in, out), "parallax") << out << " px at t+1";
}

TEST(StereoVoMatching, QuadrilateralDisparityChangesAtMostByTheRatio) {
  const double d = 90;
  for (const double factor : {kInside, kOutside}) {
    const double d2 = factor * kMaxDisparityRatio * d;
    const std::string verdict = factor < 1 ? "kept" : "parallax";
    EXPECT_EQ(CloseWithDisparities(d, d2), verdict) << d << " -> " << d2 << " px";
    EXPECT_EQ(CloseWithDisparities(d2, d), verdict) << d2 << " -> " << d << " px";
  }
}

TEST(StereoVoMatching, FeaturesAreSpreadOverTheGrid) {
  const cv::Mat tex = fl::test::stereo::Texture(640, 480, 3);
  FeatureOptions opts;
  opts.cell_size_px = 40;
  opts.features_per_cell = 3;
  FeatureExtractor extractor(opts);
  Features f;
  extractor.Extract(tex, &f);
  ASSERT_GT(f.size(), 200);
  ASSERT_EQ(f.descriptors.rows, f.size());
  std::vector<int> per_cell(16 * 12, 0);
  for (const auto& kp : f.keypoints) {
    ++per_cell[static_cast<size_t>(static_cast<int>(kp.pt.y) / 40 * 16 +
                                   static_cast<int>(kp.pt.x) / 40)];
  }
  int covered = 0;
  for (int c : per_cell) {
    EXPECT_LE(c, 3);
    covered += c > 0 ? 1 : 0;
  }
  EXPECT_GT(covered, 0.8 * 16 * 12) << "features should cover the image evenly";
}

TEST(StereoVoMatching, OptionsValidateWithClearMessages) {
  MatchOptions m;
  EXPECT_TRUE(m.Validate().ok());
  m.max_disparity_px = 0;
  EXPECT_NE(m.Validate().message().find("max_disparity_px"), std::string::npos);
  FeatureOptions f;
  f.pyramid_levels = 0;
  EXPECT_NE(f.Validate().message().find("pyramid_levels"), std::string::npos);
}

}  // namespace
}  // namespace fl::vo
