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

// Two laps of a 4 x 4 m square, nodes every 0.5 m; the second lap's nodes lie 0.1-0.2 m beside
// the first's. Odometry edges with noise and a correlated, anisotropic information; loop
// closures (Huber) from lap-2 nodes to lap-1 nodes; initial values by dead reckoning.
struct TwoLaps {
  PoseGraph2D graph;
  std::vector<fl::Pose2> truth;
  int per_lap = 0;
};
TwoLaps TwoLapGraph() {
  TwoLaps out;
  const int per_side = 8;
  out.per_lap = 4 * per_side;
  for (int lap = 0; lap < 2; ++lap) {
    const double offset = lap == 0 ? 0.0 : 0.15;  // the second lap runs inside the first
    for (int k = 0; k < out.per_lap; ++k) {
      const int side = k / per_side, step = k % per_side;
      const double a = side * M_PI / 2;
      const double along = -2.0 + offset + 0.5 * step;
      const double across = -2.0 + offset;
      // Side 0 along +x at y = across, rotated by a for the others.
      const Eigen::Vector2d local(along, across);
      const Eigen::Vector2d t = fl::Pose2(0, 0, a).rotation() * local;
      out.truth.emplace_back(t.x(), t.y(), fl::WrapAngle(a + 0.02 * lap));
    }
  }
  std::mt19937 rng(7);
  std::normal_distribution<double> n_xy(0.0, 0.02), n_th(0.0, 0.01);
  Eigen::Matrix3d info;
  info << 4000, 1500, 300,  //
      1500, 2500, -200,     //
      300, -200, 9000;
  fl::Pose2 dead_reckoning = out.truth[0];
  for (size_t k = 0; k < out.truth.size(); ++k) {
    if (k > 0) {
      const fl::Pose2 meas = out.truth[k - 1].between(out.truth[k]) *
                             fl::Pose2(n_xy(rng), n_xy(rng), n_th(rng));
      dead_reckoning = dead_reckoning * meas;
      out.graph.AddNode(dead_reckoning);
      out.graph.AddEdge({static_cast<int>(k) - 1, static_cast<int>(k), meas, info, 0.0});
    } else {
      out.graph.AddNode(dead_reckoning);
    }
  }
  for (int k = 2; k < out.per_lap; k += 5) {
    const int j = out.per_lap + k;
    const fl::Pose2 meas =
        out.truth[k].between(out.truth[j]) * fl::Pose2(n_xy(rng), n_xy(rng), n_th(rng));
    PoseGraphEdge e{k, j, meas, info, 2.0};
    e.loop_closure = true;
    out.graph.AddEdge(e);
  }
  return out;
}

// Merging a node at the relative pose it has keeps every residual: the cost at the same poses
// is the same (to first order in the angle errors of the edges arriving at it), and so is
// the optimum of the others.
TEST(PoseGraph2D, AMergedNodeKeepsTheResidualsOfItsEdges) {
  TwoLaps laps = TwoLapGraph();
  PoseGraph2D& g = laps.graph;
  g.Optimize(100);
  std::vector<fl::Pose2> optimum(g.num_nodes());
  for (int k = 0; k < g.num_nodes(); ++k) optimum[k] = g.pose(k);
  const double cost = g.Cost();
  ASSERT_GT(cost, 1.0) << "noisy edges: a cost to keep";
  // Every other lap-2 node into the lap-1 node beside it (not those with a loop closure
  // between them: an edge between the two is dropped, its residual a constant once merged).
  PoseGraph2D merged = g;
  std::vector<int> gone;
  int edges_moved = 0;
  for (int k = 1; k < laps.per_lap; k += 2) {
    const int j = laps.per_lap + k;
    bool linked = false;
    for (const PoseGraphEdge& e : g.edges()) linked = linked || (e.i == k && e.j == j);
    if (linked) continue;
    edges_moved += merged.MergeNode(j, k, merged.pose(k).between(merged.pose(j)));
    gone.push_back(j);
  }
  EXPECT_EQ(merged.num_active_nodes(), g.num_nodes() - static_cast<int>(gone.size()));
  EXPECT_GE(edges_moved, 2 * static_cast<int>(gone.size()) - 1);  // the last node has one
  for (const PoseGraphEdge& e : merged.edges()) {
    EXPECT_FALSE(merged.merged(e.i) || merged.merged(e.j)) << e.i << " -> " << e.j;
    EXPECT_NE(e.i, e.j);
  }
  EXPECT_NEAR(merged.Cost(), cost, 1e-3 * cost);
  merged.Optimize(100);
  for (int k = 0; k < g.num_nodes(); ++k) {
    if (merged.merged(k)) continue;
    EXPECT_NEAR((merged.pose(k).translation() - optimum[k].translation()).norm(), 0.0, 2e-4) << k;
    EXPECT_NEAR(fl::WrapAngle(merged.pose(k).theta - optimum[k].theta), 0.0, 1e-4) << k;
  }
  // A merged node follows no optimisation and takes no edges.
  for (int j : gone) {
    EXPECT_TRUE(merged.merged(j));
    EXPECT_EQ(merged.pose(j).x, optimum[j].x);
  }
  const Eigen::Matrix3d info = Eigen::Matrix3d::Identity();
  EXPECT_THROW(merged.AddEdge({0, gone[0], fl::Pose2(), info, 0.0}), std::invalid_argument);
  EXPECT_THROW(merged.MergeNode(gone[0], 0, fl::Pose2()), std::invalid_argument);
  EXPECT_THROW(merged.MergeNode(5, gone[0], fl::Pose2()), std::invalid_argument);
  EXPECT_THROW(merged.MergeNode(0, 5, fl::Pose2()), std::invalid_argument) << "node 0 is fixed";
}

// Away from the optimum: merging j into i at T_i_j solves the same problem as holding j there
// with a stiff edge, from the same dead-reckoned start (an edge between i and j, dropped by
// the merge, only adds a constant there).
TEST(PoseGraph2D, MergingEqualsHoldingTheNodeRigidly) {
  TwoLaps laps = TwoLapGraph();
  PoseGraph2D stiff = laps.graph, merged = laps.graph;
  const Eigen::Matrix3d rigid = Eigen::Vector3d(1e12, 1e12, 1e12).asDiagonal();
  std::vector<int> gone;
  for (int k = 0; k < laps.per_lap; k += 3) {
    const int i = k, j = laps.per_lap + k;
    if (i == 0) continue;
    const fl::Pose2 T_i_j = laps.truth[i].between(laps.truth[j]);
    stiff.AddEdge({i, j, T_i_j, rigid, 0.0});
    merged.MergeNode(j, i, T_i_j);
    gone.push_back(j);
  }
  bool converged_stiff = false, converged_merged = false;
  stiff.Optimize(200, &converged_stiff, 1e-12);
  merged.Optimize(200, &converged_merged, 1e-12);
  EXPECT_TRUE(converged_stiff);
  EXPECT_TRUE(converged_merged);
  double worst = 0.0;
  for (int k = 0; k < stiff.num_nodes(); ++k) {
    if (merged.merged(k)) continue;
    worst = std::max(worst, (stiff.pose(k).translation() - merged.pose(k).translation()).norm());
    EXPECT_NEAR(fl::WrapAngle(stiff.pose(k).theta - merged.pose(k).theta), 0.0, 2e-4) << k;
  }
  EXPECT_LT(worst, 5e-4);
}

}  // namespace
}  // namespace fl::rbpf
