#include "fusionloc/rbpf_slam/scan_matcher.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "laser_fixtures.hpp"

namespace fl::rbpf {
namespace {

TEST(ScanMatcher, LikelihoodFollowsEquation3) {
  GridOptions go;
  TiledGrid g(go);
  g.UpdateCell(0, 0, 300);  // obstacle centre at (0.025, 0.025)
  MatcherOptions mo;
  mo.sigma = 0.05;
  mo.z_hit = 0.9;
  mo.z_rand = 0.1;
  // Points at 0, 0.1 and beyond the field (0.4 m) from the obstacle, all in observed cells.
  g.UpdateCell(2, 0, -30);
  g.UpdateCell(40, 40, -30);
  const std::vector<Eigen::Vector2d> pts = {{0.025, 0.025}, {0.125, 0.025}, {2.0, 2.0}};
  int inliers = 0;
  const double ll = ScanLogLikelihood(g, pts, fl::Pose2(), mo, &inliers);
  auto p = [&](double d) { return std::log(0.9 * std::exp(-d * d / (2 * 0.05 * 0.05)) + 0.1); };
  EXPECT_NEAR(ll, p(0.0) + p(0.1) + p(0.4), 1e-3);
  EXPECT_EQ(inliers, 2);
  // Moving away from the obstacle lowers the likelihood.
  EXPECT_LT(ScanLogLikelihood(g, pts, fl::Pose2(0.05, 0, 0), mo), ll);
  // A point in a never-observed cell is scored at the mean of the others (skip_unexplored).
  const std::vector<Eigen::Vector2d> with_unknown = {{0.025, 0.025}, {0.125, 0.025}, {-5.0, -5.0}};
  mo.skip_unexplored = true;
  mo.unexplored_margin = 0.0;
  EXPECT_NEAR(ScanLogLikelihood(g, with_unknown, fl::Pose2(), mo), 1.5 * (p(0.0) + p(0.1)), 1e-3);
  mo.skip_unexplored = false;
  EXPECT_NEAR(ScanLogLikelihood(g, with_unknown, fl::Pose2(), mo), p(0.0) + p(0.1) + p(0.4), 1e-3);
}

TEST(ScanMatcher, DegenerateDirectionOfACorridorIsDetected) {
  // Hessian of a corridor along x (points on walls y = ±1.25, normals ±y) plus a weak x term.
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  for (double x = -8.0; x <= 8.0; x += 0.05) {
    for (double side : {-1.0, 1.0}) {
      const Eigen::Vector3d J(0.0, side,
                              side * x);  // d/d(x, y, θ) of the distance to wall y = ±1.25
      H += J * J.transpose();
    }
  }
  H(0, 0) += 1.0;
  int degenerate = 0;
  const Eigen::Matrix3d P = WellConstrainedProjector(H, 5.0, 0.1, &degenerate);
  EXPECT_EQ(degenerate, 1);
  // A step along x is removed, steps along y and θ are kept.
  EXPECT_NEAR((P * Eigen::Vector3d(1, 0, 0)).norm(), 0.0, 1e-9);
  EXPECT_NEAR((P * Eigen::Vector3d(0, 1, 0) - Eigen::Vector3d(0, 1, 0)).norm(), 0.0, 1e-9);
  EXPECT_NEAR((P * Eigen::Vector3d(0, 0, 1) - Eigen::Vector3d(0, 0, 1)).norm(), 0.0, 1e-9);
  // Off (ratio 0) or a well-constrained scene: identity.
  EXPECT_TRUE(WellConstrainedProjector(H, 5.0, 0.0).isIdentity());
  EXPECT_TRUE(WellConstrainedProjector(Eigen::Matrix3d::Identity() * 100, 1.0, 0.1, &degenerate)
                  .isIdentity());
  EXPECT_EQ(degenerate, 0);
}

// A map of the room from a few exact scans around `truth`, and a 181-beam scan taken at it.
void RoomMapAndScan(const fl::Pose2& truth, TiledGrid* g, std::vector<Eigen::Vector2d>* pts) {
  const test::LaserWorld world = test::LaserWorld::RoomWithBoxes();
  for (double dx : {-0.5, 0.0, 0.5}) {
    const fl::Pose2 p = truth * fl::Pose2(dx, 0, 0);
    const auto r = world.Scan(p, 361, -M_PI / 2, M_PI / 360, 25.0);
    std::vector<Eigen::Vector2d> ends;
    for (int k = 0; k < 361; ++k) {
      if (!std::isfinite(r[k])) continue;
      const double a = -M_PI / 2 + k * M_PI / 360;
      ends.push_back(p * Eigen::Vector2d(r[k] * std::cos(a), r[k] * std::sin(a)));
    }
    g->IntegrateScan(p.translation(), ends, std::vector<uint8_t>(ends.size(), 1));
  }
  const auto r = world.Scan(truth, 181, -M_PI / 2, M_PI / 180, 25.0);
  pts->clear();
  for (int k = 0; k < 181; ++k) {
    if (!std::isfinite(r[k])) continue;
    const double a = -M_PI / 2 + k * M_PI / 180;
    pts->emplace_back(r[k] * std::cos(a), r[k] * std::sin(a));
  }
}

// The room's map and the scan taken at `truth` in it.
class RoomMatch : public ::testing::Test {
 protected:
  void SetUp() override { RoomMapAndScan(truth, &g, &pts); }
  TiledGrid g{GridOptions()};
  const fl::Pose2 truth{-6.0, -4.5, 0.3};
  std::vector<Eigen::Vector2d> pts;
};

TEST_F(RoomMatch, RecoversAPerturbedPoseInTheRoom) {
  MatcherOptions mo;
  mo.max_iterations = 30;
  const fl::Pose2 start = truth * fl::Pose2(0.12, -0.08, 0.06);
  const MatchResult m = MatchScan(g, pts, start, mo);
  ASSERT_TRUE(m.ok);
  EXPECT_NEAR(m.T_world_base.x, truth.x, 0.02);
  EXPECT_NEAR(m.T_world_base.y, truth.y, 0.02);
  EXPECT_NEAR(m.T_world_base.theta, truth.theta, 0.01);
  EXPECT_GT(m.log_likelihood, ScanLogLikelihood(g, pts, start, mo));
}

// The matcher's Jacobian of each point (PoseJacobian of the field gradient) against central
// differences of the interpolated field at the moved point, at poses around the truth with
// headings far from zero (so the sin θ terms count as much as the cos θ ones).
TEST_F(RoomMatch, PointJacobianMatchesNumericDifferentiation) {
  const double res = g.resolution();
  const double dmax = g.field_radius_cells() * res * 0.999;
  const double h = 1e-6;
  // Away from the cell lines the bilinear field is smooth (within `margin` cells).
  auto inside_cell = [&](const Eigen::Vector2d& w) {
    const double margin = 1e-3;
    const double u = w.x() / res - 0.5, v = w.y() / res - 0.5;
    const double fu = u - std::floor(u), fv = v - std::floor(v);
    return fu > margin && fu < 1 - margin && fv > margin && fv < 1 - margin;
  };
  int checked = 0;
  for (const fl::Pose2& offset :
       {fl::Pose2(0, 0, 0), fl::Pose2(0.04, -0.03, 0.02), fl::Pose2(-0.05, 0.02, -0.03)}) {
    const fl::Pose2 T = truth * offset;
    const double c = std::cos(T.theta), s = std::sin(T.theta);
    for (const Eigen::Vector2d& p : pts) {
      Eigen::Vector2d grad;
      const double d = g.Distance(T * p, &grad);
      if (d >= dmax || !inside_cell(T * p)) continue;
      const Eigen::Vector3d J = PoseJacobian(grad, p, c, s);
      Eigen::Vector3d numeric;
      bool smooth = true;
      for (int k = 0; k < 3; ++k) {
        Eigen::Vector3d step = Eigen::Vector3d::Zero();
        step(k) = h;
        const fl::Pose2 plus(T.x + step.x(), T.y + step.y(), T.theta + step.z());
        const fl::Pose2 minus(T.x - step.x(), T.y - step.y(), T.theta - step.z());
        smooth = smooth && inside_cell(plus * p) && inside_cell(minus * p) &&
                 g.Distance(plus * p) < dmax && g.Distance(minus * p) < dmax;
        numeric(k) = (g.Distance(plus * p) - g.Distance(minus * p)) / (2 * h);
      }
      if (!smooth) continue;
      ++checked;
      EXPECT_NEAR(J.x(), numeric.x(), 1e-6) << "point " << p.transpose();
      EXPECT_NEAR(J.y(), numeric.y(), 1e-6) << "point " << p.transpose();
      EXPECT_NEAR(J.z(), numeric.z(), 1e-6 * (1 + p.norm())) << "point " << p.transpose();
    }
  }
  EXPECT_GT(checked, 200);
}

// Noisy scans (3 cm range noise, 361 beams) matched from starts 0.25 rad off in heading and
// about 10 cm off in position, with the default options (12 iterations, function tolerance): the
// right Jacobian lands within 0.7 mrad and 1.6 cm of the truth; a sign wrong in the θ entry
// stops its steps short of it (6-14 mrad off with one term flipped) or sends them astray.
TEST_F(RoomMatch, RecoversNoisyScansFromALargeRotation) {
  const test::LaserWorld world = test::LaserWorld::RoomWithBoxes();
  unsigned seed = 40;
  for (const fl::Pose2& offset : {fl::Pose2(0.1, -0.05, 0.25), fl::Pose2(-0.08, 0.1, -0.25),
                                  fl::Pose2(0.05, 0.08, 0.25), fl::Pose2(-0.1, -0.06, -0.25)}) {
    const std::vector<Eigen::Vector2d> noisy = test::ScanPoints(world, truth, 0.03, seed++);
    const MatchResult m = MatchScan(g, noisy, truth * offset, MatcherOptions());
    const fl::Pose2 e = truth.between(m.T_world_base);
    EXPECT_TRUE(m.ok) << "from " << offset.theta << " rad";
    EXPECT_LT(std::hypot(e.x, e.y), 0.025) << "from " << offset.theta << " rad";
    EXPECT_LT(std::abs(e.theta), 0.002)
        << "from " << offset.theta << " rad, " << m.evaluations << " evaluations";
  }
}

// The function tolerance ends the search once the steps stop paying: from the same starts it
// lands where the full search does (within 5 mm, a tenth of a cell; 3 mm on this map since the
// default free-space margin is 4 cells, 1 mm with 1 cell) with fewer passes over the points.
TEST_F(RoomMatch, FunctionToleranceStopsEarlierAtTheSamePose) {
  MatcherOptions full;
  full.max_iterations = 30;
  full.function_tolerance = 0.0;
  MatcherOptions early = full;
  early.function_tolerance = 3e-4;
  int evals_full = 0, evals_early = 0;
  for (const fl::Pose2& offset : {fl::Pose2(0.12, -0.08, 0.06), fl::Pose2(-0.1, 0.05, -0.04),
                                  fl::Pose2(0.04, 0.1, 0.02), fl::Pose2(-0.06, -0.06, -0.05)}) {
    const fl::Pose2 start = truth * offset;
    const MatchResult a = MatchScan(g, pts, start, full);
    const MatchResult b = MatchScan(g, pts, start, early);
    ASSERT_TRUE(a.ok && b.ok);
    const fl::Pose2 d = a.T_world_base.between(b.T_world_base);
    EXPECT_LT(std::hypot(d.x, d.y), 5e-3);
    EXPECT_LT(std::abs(d.theta), 1e-3);
    evals_full += a.evaluations;
    evals_early += b.evaluations;
  }
  EXPECT_LT(evals_early, evals_full);
  RecordProperty("evaluations_full", evals_full);
  RecordProperty("evaluations_early", evals_early);
}

}  // namespace
}  // namespace fl::rbpf
