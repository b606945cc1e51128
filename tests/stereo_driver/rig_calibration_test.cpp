// The rig calibration file and rectification: rectified epipolar lines are horizontal (a
// rendered chessboard seen through two distorted, rotated cameras; its corners found again in
// the rectified pair), the maps put points where the rectified projection says, and bad
// calibration files are refused with the reason.
#include "fusionloc/stereo/rig_calibration.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "chessboard_renderer.hpp"
#include "fusionloc/common/yaml_options.hpp"
#include "test_paths.hpp"

namespace fl::stereo {
namespace {

using fl::test::Chessboard;
using fl::test::ChessboardCamera;
using fl::test::Rot;

RigCalibration TestRig() {
  RigCalibration c;
  c.width = 640;
  c.height = 480;
  c.left = {520.0, 518.0, 322.0, 241.0, {-0.25, 0.08, 0.0005, -0.0008, 0.0}};
  c.right = {515.0, 514.0, 318.0, 236.0, {-0.22, 0.06, -0.0004, 0.0006, 0.0}};
  const cv::Matx33d R = Rot(0.01, -0.02, 0.005);
  c.rotation.assign(R.val, R.val + 9);
  c.translation = {-0.12, 0.002, -0.001};
  return c;
}

std::vector<cv::Point2f> FindCorners(const cv::Mat& gray, const Chessboard& b) {
  std::vector<cv::Point2f> corners;
  if (!cv::findChessboardCorners(gray, cv::Size(b.inner_cols, b.inner_rows), corners,
                                 cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE)) {
    return {};
  }
  cv::cornerSubPix(gray, corners, cv::Size(5, 5), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 50, 1e-3));
  if (corners.front().x + corners.front().y > corners.back().x + corners.back().y) {
    std::reverse(corners.begin(), corners.end());
  }
  return corners;
}

TEST(Rectifier, RectifiedEpipolarLinesAreHorizontal) {
  const RigCalibration c = TestRig();
  const Chessboard board;
  const ChessboardCamera left_cam(c.left.K(), c.left.D(), {c.width, c.height}, 3);
  const ChessboardCamera right_cam(c.right.K(), c.right.D(), {c.width, c.height}, 3);
  const Rectifier rect(c);
  ASSERT_TRUE(rect.needs_maps());
  const cv::Matx33d R(c.rotation.data());
  const cv::Vec3d T(c.translation[0], c.translation[1], c.translation[2]);
  double worst = 0.0, worst_raw = 0.0, worst_ideal = 0.0;
  int checked = 0;
  // Two board poses: one near the image centre, one towards a corner (more distortion).
  for (const auto& [R_cb, t_cb] : std::vector<std::pair<cv::Matx33d, cv::Vec3d>>{
           {Rot(0.2, -0.15, 0.05), {-0.15, -0.1, 0.6}},
           {Rot(-0.25, 0.2, 0.1), {-0.06, -0.06, 0.75}}}) {
    const cv::Matx33d R_rb = R * R_cb;
    const cv::Vec3d t_rb = R * t_cb + T;
    const cv::Mat raw_l = left_cam.Render(board, R_cb, t_cb);
    const cv::Mat raw_r = right_cam.Render(board, R_rb, t_rb);
    const auto raw_cl = FindCorners(raw_l, board), raw_cr = FindCorners(raw_r, board);
    cv::Mat rl, rr;
    rect.Rectify(raw_l, raw_r, &rl, &rr);
    const auto cl = FindCorners(rl, board), cr = FindCorners(rr, board);
    ASSERT_EQ(cl.size(), board.Corners().size());
    ASSERT_EQ(cr.size(), cl.size());
    ASSERT_EQ(raw_cl.size(), cl.size());
    ASSERT_EQ(raw_cr.size(), cl.size());
    // Ideal rectified left position of each corner: P1 * R1 * X (pinhole, no distortion).
    const cv::Matx33d R1(reinterpret_cast<const double*>(rect.R1().data));
    const cv::Matx34d P1(reinterpret_cast<const double*>(rect.P1().data));
    const auto corners3 = board.Corners();
    for (size_t i = 0; i < cl.size(); ++i) {
      worst = std::max(worst, static_cast<double>(std::abs(cl[i].y - cr[i].y)));
      worst_raw = std::max(worst_raw, static_cast<double>(std::abs(raw_cl[i].y - raw_cr[i].y)));
      const cv::Vec3d X = R_cb * cv::Vec3d(corners3[i].x, corners3[i].y, corners3[i].z) + t_cb;
      const cv::Vec3d Xr = R1 * X;
      const cv::Vec3d p = P1 * cv::Vec4d(Xr[0], Xr[1], Xr[2], 1.0);
      worst_ideal = std::max(worst_ideal, std::hypot(cl[i].x - p[0] / p[2], cl[i].y - p[1] / p[2]));
      ++checked;
    }
  }
  std::cout << checked << " corner pairs: rectified |y_left - y_right| max " << worst << " px (raw "
            << worst_raw << " px); left corner vs P1 R1 X max " << worst_ideal << " px\n";
  // Found again by the corner detector, whose own error on these renderings is ~0.2-0.25 px
  // (raw corners against cv::projectPoints); the exact check is the next test.
  EXPECT_LT(worst, 0.5);
  EXPECT_GT(worst_raw, 2.0);  // the raw pair is far from row-aligned: the test can fail
  EXPECT_LT(worst_ideal, 0.5);
  // The rectified camera: both views share fx, cx, cy; the baseline is |T|.
  EXPECT_NEAR(rect.camera().baseline, cv::norm(c.T()), 1e-9);
  EXPECT_GT(rect.camera().fx, 400);
}

float Bilinear(const cv::Mat& m, double x, double y) {
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  const double fx = x - x0, fy = y - y0;
  auto at = [&](int r, int c) { return static_cast<double>(m.at<float>(r, c)); };
  return static_cast<float>((1 - fy) * ((1 - fx) * at(y0, x0) + fx * at(y0, x0 + 1)) +
                            fy * ((1 - fx) * at(y0 + 1, x0) + fx * at(y0 + 1, x0 + 1)));
}

// The exact version on a synthetic pattern of 3D points (two planes filling the view): each
// point's raw projections (cv::projectPoints, with distortion) are where the maps, sampled at
// its rectified projections P1 R1 X and P2 R1 X (one row), say they are, and R2 takes the
// right camera's frame to that row.
TEST(Rectifier, MapsSendEveryPointToOneRow) {
  const RigCalibration c = TestRig();
  const Rectifier rect(c);
  const cv::Matx33d R(c.rotation.data()), R1(reinterpret_cast<const double*>(rect.R1().data)),
      R2(reinterpret_cast<const double*>(rect.R2().data));
  const cv::Matx34d P1(reinterpret_cast<const double*>(rect.P1().data)),
      P2(reinterpret_cast<const double*>(rect.P2().data));
  const cv::Vec3d T(c.translation[0], c.translation[1], c.translation[2]);
  double worst_map = 0;
  int n = 0;
  for (double z : {0.7, 3.0}) {
    for (int i = 0; i <= 30; ++i) {
      for (int j = 0; j <= 20; ++j) {
        const cv::Vec3d Xl(z * (-0.55 + 1.1 * i / 30.0), z * (-0.42 + 0.84 * j / 20.0), z);
        const cv::Vec3d Xr = R * Xl + T;
        std::vector<cv::Point2d> raw_l, raw_r;
        cv::projectPoints(std::vector<cv::Point3d>{cv::Point3d(Xl)}, cv::Vec3d(0, 0, 0),
                          cv::Vec3d(0, 0, 0), c.left.K(), c.left.D(), raw_l);
        cv::projectPoints(std::vector<cv::Point3d>{cv::Point3d(Xr)}, cv::Vec3d(0, 0, 0),
                          cv::Vec3d(0, 0, 0), c.right.K(), c.right.D(), raw_r);
        // P1, P2 project points of the left rectified frame (P2 holds the baseline), so both
        // take R1 Xl; R2 Xr is the same point in the right rectified frame (checked below).
        const cv::Vec3d a = R1 * Xl, b = R2 * Xr;
        const cv::Vec3d pl = P1 * cv::Vec4d(a[0], a[1], a[2], 1),
                        pr = P2 * cv::Vec4d(a[0], a[1], a[2], 1);
        const cv::Vec3d pr_own = P1 * cv::Vec4d(b[0], b[1], b[2], 1);
        EXPECT_NEAR(pr_own[0] / pr_own[2], pr[0] / pr[2], 1e-6);
        EXPECT_NEAR(pr_own[1] / pr_own[2], pr[1] / pr[2], 1e-6);
        const double ul = pl[0] / pl[2], vl = pl[1] / pl[2], ur = pr[0] / pr[2], vr = pr[1] / pr[2];
        auto inside = [&](double u, double v) {
          return u >= 0 && v >= 0 && u < c.width - 1 && v < c.height - 1;
        };
        if (!inside(ul, vl) || !inside(ur, vr) || !inside(raw_l[0].x, raw_l[0].y) ||
            !inside(raw_r[0].x, raw_r[0].y)) {
          continue;
        }
        const double el = std::hypot(Bilinear(rect.map_left_x(), ul, vl) - raw_l[0].x,
                                     Bilinear(rect.map_left_y(), ul, vl) - raw_l[0].y);
        const double er = std::hypot(Bilinear(rect.map_right_x(), ur, vr) - raw_r[0].x,
                                     Bilinear(rect.map_right_y(), ur, vr) - raw_r[0].y);
        worst_map = std::max({worst_map, el, er});
        ++n;
      }
    }
  }
  std::cout << n << " points: map error max " << worst_map << " px\n";
  EXPECT_GT(n, 800);
  // Both rectified projections are on row vl; the maps at them point at the true raw pixels
  // to worst_map, so a feature's rows in the rectified pair differ by at most 2 worst_map.
  EXPECT_LT(2 * worst_map, 0.2);
}

TEST(Rectifier, ARectifiedCalibrationPassesImagesThrough) {
  RigCalibration c;
  c.width = 8;
  c.height = 4;
  c.rectified = true;
  c.left = {700.0, 700.0, 4.0, 2.0, {}};
  c.right = c.left;
  c.translation = {-0.5, 0, 0};
  const Rectifier rect(c);
  EXPECT_FALSE(rect.needs_maps());
  EXPECT_EQ(rect.camera().baseline, 0.5);
  EXPECT_EQ(rect.camera().fx, 700.0);
  cv::Mat l(4, 8, CV_8U, cv::Scalar(7)), r(4, 8, CV_8U, cv::Scalar(9)), lo, ro;
  rect.Rectify(l, r, &lo, &ro);
  EXPECT_EQ(cv::countNonZero(lo != 7), 0);
  EXPECT_EQ(cv::countNonZero(ro != 9), 0);
  cv::Mat wrong(5, 8, CV_8U);
  try {
    rect.Rectify(wrong, wrong, &lo, &ro);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("8x5 but the calibration is for 8x4"), std::string::npos)
        << e.what();
  }
}

TEST(RigCalibration, SaveLoadRoundTripAndBadFiles) {
  fl::test::TempDir dir;
  RigCalibration c = TestRig();
  c.rms_reprojection_px = 0.125;
  SaveRigCalibration(c, dir.file("rig.yaml"), "test");
  const RigCalibration back = LoadRigCalibration(dir.file("rig.yaml"));
  EXPECT_EQ(back.width, 640);
  EXPECT_EQ(back.left.distortion, c.left.distortion);
  EXPECT_EQ(back.rotation, c.rotation);
  EXPECT_EQ(back.translation, c.translation);
  EXPECT_EQ(back.rms_reprojection_px, 0.125);

  auto expect_error = [&](const std::string& text, const std::string& what) {
    std::ofstream(dir.file("bad.yaml")) << text;
    try {
      LoadRigCalibration(dir.file("bad.yaml"));
      ADD_FAILURE() << "accepted: " << text;
    } catch (const fl::ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  };
  const std::string ok_intr = "{fx: 500, fy: 500, cx: 320, cy: 240}";
  expect_error("width: 640\nheight: 480\nleft: " + ok_intr + "\nright: " + ok_intr +
                   "\ntranslation: [-0.1, 0, 0]\nrotation: [1, 0, 0, 0, 2, 0, 0, 0, 1]\n",
               "not a rotation matrix");
  expect_error("width: 640\nheight: 480\nleft: " + ok_intr + "\nright: " + ok_intr + "\n",
               "translation (the baseline) is zero");
  expect_error(
      "width: 640\nheight: 480\nleft: {fx: 500, fy: 500, cx: 320, cy: 240, "
      "distortion: [1, 2, 3]}\nright: " +
          ok_intr + "\ntranslation: [-0.1, 0, 0]\n",
      "takes 4, 5 or 8");
  expect_error("width: 640\nheight: 480\nbaseline: 0.1\n", "unknown key 'baseline'");
  expect_error("width: 0\n", "width and height");
}

}  // namespace
}  // namespace fl::stereo
