// Stereo calibration recovers a known rig from rendered chessboard views (pinhole +
// distortion, a rotated right camera): focal lengths within 0.5 %, baseline within 1 %; the
// program writes a calibration file the driver reads and the rectified preview.
#include "fusionloc/stereo/chessboard_calibration.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>

#include "chessboard_renderer.hpp"
#include "test_paths.hpp"

namespace fl::stereo {
namespace {

using fl::test::Chessboard;
using fl::test::ChessboardCamera;
using fl::test::Rot;

RigCalibration TrueRig() {
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

// Views of the board at several distances and tilts, seen by both cameras.
void RenderViews(const RigCalibration& c, const Chessboard& b, int n, std::vector<cv::Mat>* left,
                 std::vector<cv::Mat>* right) {
  const ChessboardCamera lc(c.left.K(), c.left.D(), {c.width, c.height}, 2);
  const ChessboardCamera rc(c.right.K(), c.right.D(), {c.width, c.height}, 2);
  const cv::Matx33d R(c.rotation.data());
  const cv::Vec3d T(c.translation[0], c.translation[1], c.translation[2]);
  const cv::Vec3d centre(0.5 * (b.inner_cols + 1) * b.square, 0.5 * (b.inner_rows + 1) * b.square,
                         0);
  for (int k = 0; k < n; ++k) {
    const cv::Matx33d R_cb =
        Rot(0.4 * std::sin(1.3 * k), 0.4 * std::cos(0.9 * k), 0.2 * std::sin(2.1 * k));
    const double z = 0.6 + 0.25 * ((k % 4) / 3.0);
    const cv::Vec3d where(0.06 + 0.07 * std::sin(1.7 * k), 0.05 * std::cos(1.1 * k), z);
    const cv::Vec3d t_cb = where - R_cb * centre;
    left->push_back(lc.Render(b, R_cb, t_cb));
    right->push_back(rc.Render(b, R * R_cb, R * t_cb + T));
  }
}

TEST(ChessboardCalibration, RecoversAKnownRig) {
  const RigCalibration truth = TrueRig();
  const Chessboard board;  // 9 x 6 inner corners, 35 mm
  std::vector<cv::Mat> left, right;
  RenderViews(truth, board, 14, &left, &right);
  ChessboardOptions o;
  o.square_m = board.square;
  const StereoCalibrationResult r = CalibrateStereo(left, right, o);
  ASSERT_GE(r.used.size(), 10u);
  const RigCalibration& e = r.rig;
  auto rel = [](double est, double ref) { return std::abs(est - ref) / ref; };
  std::cout << "pairs " << r.used.size() << ", RMS " << r.rms_px << " px; focal error left fx "
            << 100 * rel(e.left.fx, truth.left.fx) << " %, fy "
            << 100 * rel(e.left.fy, truth.left.fy) << " %, right fx "
            << 100 * rel(e.right.fx, truth.right.fx) << " %, fy "
            << 100 * rel(e.right.fy, truth.right.fy) << " %; baseline " << cv::norm(e.T())
            << " m (true " << cv::norm(truth.T()) << ", error "
            << 100 * rel(cv::norm(e.T()), cv::norm(truth.T())) << " %); k1 " << e.left.distortion[0]
            << " (true -0.25)\n";
  EXPECT_LT(r.rms_px, 0.5);
  EXPECT_LT(rel(e.left.fx, truth.left.fx), 0.005);
  EXPECT_LT(rel(e.left.fy, truth.left.fy), 0.005);
  EXPECT_LT(rel(e.right.fx, truth.right.fx), 0.005);
  EXPECT_LT(rel(e.right.fy, truth.right.fy), 0.005);
  EXPECT_LT(rel(cv::norm(e.T()), cv::norm(truth.T())), 0.01);
  EXPECT_NEAR(e.left.cx, truth.left.cx, 3.0);
  EXPECT_NEAR(e.left.cy, truth.left.cy, 3.0);
  EXPECT_NEAR(e.left.distortion[0], -0.25, 0.02);
  EXPECT_NEAR(e.translation[0], -0.12, 0.0012);
  EXPECT_EQ(e.rms_reprojection_px, r.rms_px);
  EXPECT_TRUE(e.Validate().ok()) << e.Validate().message();
}

TEST(ChessboardCalibration, TooFewBoardsAndBadOptionsAreClearErrors) {
  std::vector<cv::Mat> blank(4, cv::Mat(480, 640, CV_8U, cv::Scalar(128)));
  ChessboardOptions o;
  try {
    CalibrateStereo(blank, blank, o);
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("found in both views of 0 of 4 pairs; need 8"),
              std::string::npos)
        << e.what();
  }
  o.inner_rows = o.inner_cols;
  EXPECT_FALSE(o.Validate().ok());
}

TEST(StereoCalibrateProgram, WritesTheCalibrationTheDriverReadsAndAPreview) {
  fl::test::TempDir dir;
  const RigCalibration truth = TrueRig();
  Chessboard board;
  board.square = 0.03;
  std::vector<cv::Mat> left, right;
  RenderViews(truth, board, 10, &left, &right);
  std::filesystem::create_directories(dir.file("pairs/left"));
  std::filesystem::create_directories(dir.file("pairs/right"));
  for (size_t i = 0; i < left.size(); ++i) {
    cv::imwrite(dir.file("pairs/left/" + std::to_string(i) + ".png"), left[i]);
    cv::imwrite(dir.file("pairs/right/" + std::to_string(i) + ".png"), right[i]);
  }
  {
    std::ofstream cfg(dir.file("board.yaml"));
    cfg << "square_m: 0.03\n";
  }
  const auto r = fl::test::RunCommand(fl::test::BinDir() +
                                          "/fl-stereo-calibrate pairs --config board.yaml "
                                          "--out rig.yaml",
                                      dir);
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("RMS reprojection error"), std::string::npos) << r.out;
  const RigCalibration rig = LoadRigCalibration(dir.file("rig.yaml"));
  EXPECT_NEAR(cv::norm(rig.T()), 0.12, 0.0012);
  EXPECT_GT(rig.rms_reprojection_px, 0.0);
  const cv::Mat preview = cv::imread(dir.file("rig_preview.png"));
  EXPECT_EQ(preview.cols, 2 * 640);
  EXPECT_EQ(preview.rows, 480);
  const auto bad = fl::test::RunCommand(
      fl::test::BinDir() + "/fl-stereo-calibrate pairs --out rig2.yaml", dir);  // 25 mm: wrong
  EXPECT_EQ(bad.status, 0) << bad.err;  // a wrong square size scales the baseline, nothing else
  EXPECT_NEAR(cv::norm(LoadRigCalibration(dir.file("rig2.yaml")).T()), 0.12 * 25 / 30, 0.0012);
  const auto none = fl::test::RunCommand(
      fl::test::BinDir() + "/fl-stereo-calibrate " + dir.file("nothing") + " --out x.yaml", dir);
  EXPECT_EQ(none.status, 1) << none.err;
  EXPECT_NE(none.err.find("does not exist"), std::string::npos) << none.err;
}

}  // namespace
}  // namespace fl::stereo
