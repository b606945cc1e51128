#include "fusionloc/rbpf_slam/pose_graph.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <memory>
#include <random>
#include <string>

namespace fl::rbpf {
namespace {

// A square of 4 x 10 steps of 0.5 m with exact odometry edges and a loop closure (Huber 1) from
// the last node to the first; the initial values drift by `drift_rad` of heading per step.
PoseGraph2D SquareLoop(double drift_rad, std::vector<fl::Pose2>* truth) {
  PoseGraph2D g;
  truth->clear();
  fl::Pose2 p;
  for (int k = 0; k < 40; ++k) {
    truth->push_back(p);
    p = p * fl::Pose2(0.5, 0, (k % 10 == 9) ? M_PI / 2 : 0.0);
  }
  const std::vector<fl::Pose2>& t = *truth;
  fl::Pose2 drifted;
  for (int k = 0; k < 40; ++k) {
    g.AddNode(drifted);
    if (k + 1 < 40) drifted = drifted * t[k].between(t[k + 1]) * fl::Pose2(0, 0, drift_rad);
  }
  const Eigen::Matrix3d info = Eigen::Vector3d(1e4, 1e4, 1e4).asDiagonal();
  for (int k = 0; k + 1 < 40; ++k) g.AddEdge({k, k + 1, t[k].between(t[k + 1]), info, 0.0});
  g.AddEdge({39, 0, t[39].between(t[0]), info, 1.0});  // loop closure
  return g;
}

TEST(PoseGraph2D, LoopClosureCorrectsDrift) {
  std::vector<fl::Pose2> truth;
  PoseGraph2D g = SquareLoop(0.01, &truth);
  const Eigen::Matrix3d info = Eigen::Vector3d(1e4, 1e4, 1e4).asDiagonal();
  const double before = (g.pose(39).translation() - truth[39].translation()).norm();
  bool converged = false;
  g.Optimize(50, &converged);
  EXPECT_TRUE(converged);
  EXPECT_GT(before, 0.3);
  for (int k = 0; k < 40; ++k) {
    EXPECT_NEAR((g.pose(k).translation() - truth[k].translation()).norm(), 0.0, 1e-4) << k;
  }
  EXPECT_THROW(g.AddEdge({0, 77, fl::Pose2(), info, 0.0}), std::invalid_argument);
}

// A loose function tolerance stops the solve while steps still lower the cost by a few per cent:
// its cost stays above the converged one, which the default tolerance reaches.
TEST(PoseGraph2D, FunctionToleranceStopsEarly) {
  std::vector<fl::Pose2> truth;
  PoseGraph2D tight = SquareLoop(0.05, &truth), loose = SquareLoop(0.05, &truth);
  const double tight_cost = tight.Optimize(50);
  const double loose_cost = loose.Optimize(50, nullptr, 0.5);
  EXPECT_LT(tight_cost, 1e-12);
  EXPECT_GT(loose_cost, 1e-6);
}

// The graph keeps its Ceres problem between optimisations. Grown in stages, with a wrong loop
// closure added and then disabled, it must give what a graph built at once from the same edges
// and start values gives (a copy builds its problem afresh).
TEST(PoseGraph2D, KeptProblemFollowsNewAndDisabledEdges) {
  std::vector<fl::Pose2> truth;
  fl::Pose2 p;
  for (int k = 0; k < 30; ++k) {
    truth.push_back(p);
    p = p * fl::Pose2(0.5, 0, (k % 10 == 9) ? M_PI / 2 : 0.05);
  }
  const Eigen::Matrix3d info = Eigen::Vector3d(1e4, 1e4, 1e4).asDiagonal();
  auto odom = [&](int k) {  // slightly wrong odometry: the loop closures have work to do
    return truth[k].between(truth[k + 1]) * fl::Pose2(0.01, 0.0, 0.004);
  };
  auto expect_same = [](const PoseGraph2D& a, const PoseGraph2D& b, const std::string& stage) {
    ASSERT_EQ(a.num_nodes(), b.num_nodes());
    for (int k = 0; k < a.num_nodes(); ++k) {
      EXPECT_NEAR(a.pose(k).x, b.pose(k).x, 1e-9) << stage << " node " << k;
      EXPECT_NEAR(a.pose(k).y, b.pose(k).y, 1e-9) << stage << " node " << k;
      EXPECT_NEAR(a.pose(k).theta, b.pose(k).theta, 1e-9) << stage << " node " << k;
    }
  };
  PoseGraph2D g;
  fl::Pose2 dead_reckoning;
  auto grow = [&](int from, int to) {
    for (int k = from; k < to; ++k) {
      if (k > 0) dead_reckoning = dead_reckoning * odom(k - 1);
      g.AddNode(dead_reckoning);
      if (k > 0) g.AddEdge({k - 1, k, odom(k - 1), info, 0.0});
    }
  };
  grow(0, 20);
  g.AddEdge({0, 19, truth[0].between(truth[19]), info, 1.0});
  PoseGraph2D fresh = g;
  g.Optimize(50);
  fresh.Optimize(50);
  expect_same(g, fresh, "first optimisation");

  grow(20, 30);
  g.AddEdge({5, 29, truth[5].between(truth[29]), info, 1.0});
  const int wrong = g.num_edges();
  g.AddEdge({10, 28, fl::Pose2(1.0, -2.0, 0.5), info, 0.0});  // an aliased closure
  fresh = g;
  g.Optimize(50);
  fresh.Optimize(50);
  expect_same(g, fresh, "after new edges");

  auto max_error = [&]() {
    double e = 0.0;
    for (int k = 0; k < 30; ++k) {
      e = std::max(e, (g.pose(k).translation() - truth[k].translation()).norm());
    }
    return e;
  };
  const double error_with_wrong = max_error();
  const double cost_with_wrong = g.Cost();
  g.DisableEdge(wrong);
  fresh = g;
  EXPECT_LT(g.Cost(), cost_with_wrong);  // the disabled edge no longer counts
  EXPECT_NEAR(g.Cost(), fresh.Cost(), 1e-9 * cost_with_wrong);
  g.Optimize(50);
  fresh.Optimize(50);
  expect_same(g, fresh, "after disabling an edge");
  EXPECT_GT(error_with_wrong, 0.3);
  EXPECT_LT(max_error(), 0.1);
}

}  // namespace
}  // namespace fl::rbpf
