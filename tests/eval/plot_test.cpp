#include "fusionloc/eval/plot.hpp"

#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "eval_fixtures.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "test_paths.hpp"

namespace fl::eval {
namespace {

// Pixels whose colour is within `tol` of `c` (OpenCV images are BGR).
int CountColor(const cv::Mat& img, const Color& c, int tol = 10) {
  int n = 0;
  for (int r = 0; r < img.rows; ++r) {
    for (int k = 0; k < img.cols; ++k) {
      const cv::Vec3b p = img.at<cv::Vec3b>(r, k);
      if (std::abs(p[0] - c.b) <= tol && std::abs(p[1] - c.g) <= tol && std::abs(p[2] - c.r) <= tol)
        ++n;
    }
  }
  return n;
}

TEST(EvalPlot, TopViewDrawsEveryCurveWithEqualAxes) {
  fl::test::TempDir dir;
  const Trajectory ref = fl::test::MakePlanarTrajectory(
      100, [](size_t i) { return Pose2(std::cos(0.06 * i) * 20, std::sin(0.06 * i) * 5, 0); });
  Trajectory est = ref;
  for (auto& p : est) p.T_world_base.translation().y() += 1.0;
  BackgroundGrid grid;
  grid.resolution = 0.5;
  grid.origin_x = -25;
  grid.origin_y = -10;
  grid.width = 100;
  grid.height = 40;
  grid.cells.assign(100 * 40, 0);
  for (int c = 0; c < 100; ++c) grid.cells[static_cast<size_t>(c)] = 100;  // a wall at the bottom
  TopViewOptions opt;
  opt.title = "test";
  opt.background = &grid;
  const std::string path = dir.file("top.png");
  PlotTrajectoriesTopView(path, {{"ref", ref, kPlotBlack}, {"est", est, kPlotOrange}}, opt);
  const cv::Mat img = cv::imread(path, cv::IMREAD_COLOR);
  ASSERT_FALSE(img.empty());
  EXPECT_EQ(img.cols, opt.width_px);
  EXPECT_EQ(img.rows, opt.height_px);
  EXPECT_GT(CountColor(img, kPlotOrange), 300);
  EXPECT_GT(CountColor(img, Color{85, 85, 85}, 3), 100);  // occupied wall cells
  // No partial file left behind.
  EXPECT_FALSE(std::filesystem::exists(path + ".partial"));
}

TEST(EvalPlot, SeriesAndAteErrors) {
  fl::test::TempDir dir;
  const Trajectory ref = fl::test::MakeHelixTrajectory(50);
  Trajectory est = ref;
  for (auto& p : est) p.T_world_base.translation().x() += 0.2;
  const AteResult ate = ComputeAte(est, ref, Alignment::kNone, 1000);
  PlotAteErrors(dir.file("err.png"), ate, "errors");
  const cv::Mat img = cv::imread(dir.file("err.png"), cv::IMREAD_COLOR);
  ASSERT_FALSE(img.empty());
  EXPECT_EQ(img.cols, 1000);
  EXPECT_GT(img.rows, 3 * 240);
  EXPECT_GT(CountColor(img, kPlotBlue), 500);
  PlotAteErrors(dir.file("err_xz.png"), ate, "errors", "est", "xz");
  EXPECT_TRUE(std::filesystem::exists(dir.file("err_xz.png")));
}

TEST(EvalPlot, BadInputsThrow) {
  fl::test::TempDir dir;
  EXPECT_THROW(PlotTrajectoriesTopView(dir.file("a.png"), {}), EvalError);
  Trajectory nan = fl::test::MakeStraightTrajectory(3, 1.0);
  for (auto& p : nan) p.T_world_base.translation().x() = std::nan("");
  EXPECT_THROW(PlotTrajectoriesTopView(dir.file("a.png"), {{"nan", nan, kPlotRed}}), EvalError);
  EXPECT_THROW(
      PlotTrajectoriesTopView(dir.file("no/such/dir/a.png"),
                              {{"ok", fl::test::MakeStraightTrajectory(3, 1.0), kPlotRed}}),
      EvalError);
  EXPECT_THROW(PlotSeries(dir.file("s.png"), "t", "x",
                          {Panel{"y", {SeriesCurve{"c", {1, 2}, {1}, kPlotRed}}}}),
               EvalError);
  EXPECT_THROW(PlotSeries(dir.file("s.png"), "t", "x", {}), EvalError);
}

}  // namespace
}  // namespace fl::eval

namespace fl::eval {
namespace {

TEST(EvalPlot, BackgroundGridFromLcmLog) {
  fl::test::TempDir dir;
  fusionloc::occupancy_grid_t g;
  g.utime = 1;
  g.resolution = 0.1;
  g.width = 3;
  g.height = 2;
  g.origin_x = -1;
  g.origin_y = 2;
  g.num_cells = 6;
  g.cells = {0, 100, -1, 50, 0, 0};
  {
    LcmLogWriter w(dir.file("map.lcmlog"));
    w.Write("RBPF_MAP", g, 1);
    w.Close();
  }
  const BackgroundGrid b = ReadBackgroundGridLcm(dir.file("map.lcmlog"), "RBPF_MAP");
  EXPECT_EQ(b.width, 3);
  EXPECT_DOUBLE_EQ(b.origin_y, 2.0);
  EXPECT_EQ(b.cells, g.cells);
  EXPECT_THROW(ReadBackgroundGridLcm(dir.file("map.lcmlog"), "FUSED_MAP"), EvalError);
  g.num_cells = 5;
  EXPECT_THROW(BackgroundFromGrid(g), EvalError);
}

}  // namespace
}  // namespace fl::eval
