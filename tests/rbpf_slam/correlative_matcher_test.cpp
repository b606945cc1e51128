#include "fusionloc/rbpf_slam/correlative_matcher.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "laser_fixtures.hpp"

namespace fl::rbpf {
namespace {

using test::ScanPoints;

// Brute force over the same discrete poses, for comparison with the branch and bound.
double ExhaustiveBest(const std::vector<Eigen::Vector2d>& ref,
                      const std::vector<Eigen::Vector2d>& query, const fl::Pose2& initial,
                      const CorrelativeOptions& o, double step) {
  CorrelativeOptions one = o;
  one.linear_window = o.resolution * 0.5;  // a single translation
  one.angular_window = 0.0;
  one.coarse_factor = 1;
  double best = -1.0;
  const int nt = static_cast<int>(std::ceil(o.linear_window / o.resolution - 1e-9));
  const int na = static_cast<int>(std::ceil(o.angular_window / step - 1e-9));
  for (int a = -na; a <= na; ++a) {
    for (int iy = -nt; iy <= nt; ++iy) {
      for (int ix = -nt; ix <= nt; ++ix) {
        const fl::Pose2 T(initial.x + ix * o.resolution, initial.y + iy * o.resolution,
                          initial.theta + a * step);
        best = std::max(best, CorrelativeMatch(ref, query, T, one).score);
      }
    }
  }
  return best;
}

TEST(CorrelativeMatcher, FindsAnOffsetFarBeyondIcpsBasin) {
  const test::LaserWorld world = test::LaserWorld::RoomWithBoxes();
  const fl::Pose2 pose_i(-6.0, -4.5, 0.1);
  const fl::Pose2 T_i_j(0.45, 0.12, 0.15);
  const auto ref = ScanPoints(world, pose_i, 0.01, 1);
  const auto query = ScanPoints(world, pose_i * T_i_j, 0.01, 2);
  CorrelativeOptions o;
  // The guess is 0.7 m and 0.12 rad off.
  const fl::Pose2 guess = T_i_j * fl::Pose2(-0.5, 0.5, -0.12);
  const CorrelativeResult r = CorrelativeMatch(ref, query, guess, o);
  ASSERT_TRUE(r.ok);
  EXPECT_FALSE(r.at_window_edge);
  EXPECT_NEAR(r.T_ref_query.x, T_i_j.x, 0.06);
  EXPECT_NEAR(r.T_ref_query.y, T_i_j.y, 0.06);
  EXPECT_NEAR(r.T_ref_query.theta, T_i_j.theta, 0.015);
  EXPECT_GT(r.score, 0.6);
  // The wrong pose scores far lower.
  CorrelativeOptions none = o;
  none.linear_window = o.resolution * 0.5;
  none.angular_window = 0.0;
  EXPECT_LT(CorrelativeMatch(ref, query, guess, none).score, 0.3);
}

TEST(CorrelativeMatcher, BranchAndBoundEqualsExhaustiveSearchWithFewerEvaluations) {
  const test::LaserWorld world = test::LaserWorld::RoomWithBoxes();
  const fl::Pose2 pose_i(-5.0, -4.0, 0.3);
  const fl::Pose2 T_i_j(0.3, -0.2, -0.05);
  const auto ref = ScanPoints(world, pose_i, 0.02, 3);
  const auto query = ScanPoints(world, pose_i * T_i_j, 0.02, 4);
  CorrelativeOptions o;
  o.linear_window = 0.3;
  o.angular_window = 0.04;
  o.angular_step = 0.01;
  o.max_points = 0;
  const fl::Pose2 guess = T_i_j * fl::Pose2(0.2, 0.1, 0.03);
  const CorrelativeResult r = CorrelativeMatch(ref, query, guess, o);
  const double exhaustive = ExhaustiveBest(ref, query, guess, o, o.angular_step);
  EXPECT_NEAR(r.score, exhaustive, 1e-6);
  const int all_poses = 13 * 13 * 9;
  EXPECT_LT(r.evaluated, all_poses / 4) << "the coarse bound prunes most translations";
}

TEST(CorrelativeMatcher, FlagsAnOptimumOnTheWindowsBorder) {
  // A closed 4 m x 3 m room: every shift is penalised; a wide kernel makes the score grow
  // towards the truth.
  test::LaserWorld room;
  room.AddSegment({-2.0, -1.5}, {2.0, -1.5});
  room.AddSegment({2.0, -1.5}, {2.0, 1.5});
  room.AddSegment({2.0, 1.5}, {-2.0, 1.5});
  room.AddSegment({-2.0, 1.5}, {-2.0, -1.5});
  const auto ref = ScanPoints(room, fl::Pose2(-0.5, 0.0, 0.0), 0.0, 1);
  const auto query = ScanPoints(room, fl::Pose2(-0.5, 0.0, 0.0), 0.0, 2);
  CorrelativeOptions o;
  o.linear_window = 0.3;
  o.angular_window = 0.05;
  o.sigma = 0.2;
  // The truth (identity) is 0.6 m away: the best reachable pose is on the border.
  const CorrelativeResult r = CorrelativeMatch(ref, query, fl::Pose2(0.6, 0.0, 0.0), o);
  EXPECT_TRUE(r.at_window_edge) << r.T_ref_query.x << " " << r.T_ref_query.y << " "
                                << r.T_ref_query.theta << " score " << r.score;
  EXPECT_NEAR(r.T_ref_query.x, 0.3, 1e-9);
  const CorrelativeResult inside = CorrelativeMatch(ref, query, fl::Pose2(0.2, 0.0, 0.0), o);
  EXPECT_FALSE(inside.at_window_edge);
  EXPECT_NEAR(inside.T_ref_query.x, 0.0, 1e-9);
  EXPECT_NEAR(inside.T_ref_query.y, 0.0, 1e-9);
}

TEST(CorrelativeMatcher, EmptyInputsAndBadOptions) {
  const std::vector<Eigen::Vector2d> pts = {{1.0, 0.0}, {0.0, 1.0}};
  EXPECT_FALSE(CorrelativeMatch({}, pts, fl::Pose2(), CorrelativeOptions()).ok);
  EXPECT_FALSE(CorrelativeMatch(pts, {}, fl::Pose2(), CorrelativeOptions()).ok);
  CorrelativeOptions bad;
  bad.resolution = 0.0;
  EXPECT_FALSE(bad.Validate().ok());
  EXPECT_THROW(CorrelativeMatch(pts, pts, fl::Pose2(), bad), std::invalid_argument);
  bad = CorrelativeOptions();
  bad.coarse_factor = 0;
  EXPECT_NE(bad.Validate().message().find("coarse_factor"), std::string::npos);
  bad = CorrelativeOptions();
  bad.linear_window = 50.0;
  EXPECT_NE(bad.Validate().message().find("linear_window"), std::string::npos);
}

}  // namespace
}  // namespace fl::rbpf
