#include "fusionloc/common/trajectory_merge.hpp"

#include <gtest/gtest.h>

#include <vector>

namespace fl {
namespace {

struct P {
  Utime utime;
  double x;
};
Utime UtimeOf(const P& p) { return p.utime; }

std::vector<Utime> Times(const std::vector<P>& v) {
  std::vector<Utime> t;
  for (const P& p : v) t.push_back(p.utime);
  return t;
}

TEST(MergeTrajectoryTail, KeepsTheOlderPosesAndReplacesTheRest) {
  std::vector<P> traj;
  MergeTrajectoryTail(&traj, {{1, 0.0}, {2, 0.0}, {3, 0.0}, {4, 0.0}}, UtimeOf);
  // The latest part from time 3 on, re-estimated, one pose more.
  MergeTrajectoryTail(&traj, {{3, 1.0}, {4, 1.0}, {5, 1.0}}, UtimeOf);
  EXPECT_EQ(Times(traj), (std::vector<Utime>{1, 2, 3, 4, 5}));
  EXPECT_EQ(traj[1].x, 0.0);
  EXPECT_EQ(traj[2].x, 1.0);
  EXPECT_EQ(traj[4].x, 1.0);
  // A first time between two kept poses: the later one is replaced too.
  MergeTrajectoryTail(&traj, {{2, 2.0}, {6, 2.0}}, UtimeOf);
  EXPECT_EQ(Times(traj), (std::vector<Utime>{1, 2, 6}));
}

TEST(MergeTrajectoryTail, AWholeTrajectoryReplacesEverythingAndAnEmptyOneNothing) {
  std::vector<P> traj = {{5, 0.0}, {6, 0.0}};
  MergeTrajectoryTail(&traj, {}, UtimeOf);
  EXPECT_EQ(Times(traj), (std::vector<Utime>{5, 6}));
  MergeTrajectoryTail(&traj, {{1, 3.0}, {7, 3.0}}, UtimeOf);  // starts before everything kept
  EXPECT_EQ(Times(traj), (std::vector<Utime>{1, 7}));
  EXPECT_EQ(traj[0].x, 3.0);
}

}  // namespace
}  // namespace fl
