#include "fusionloc/fusion/pose_graph.hpp"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>

#include <random>
#include <sstream>

#include "fusionloc/common/geometry.hpp"
#include "test_paths.hpp"

namespace fl::fusion {
namespace {

// A noisy 2D square loop written as g2o text, optimised back to the truth shape.
TEST(FusionPoseGraph, Noisy2dLoopConvergesAndFixesFirstPose) {
  std::mt19937 rng(7);
  std::normal_distribution<double> n(0.0, 1.0);
  std::ostringstream t;
  std::vector<Eigen::Vector3d> truth;
  for (int side = 0; side < 4; ++side) {
    for (int k = 0; k < 5; ++k) {
      const double th = side * M_PI / 2;
      Eigen::Vector3d p = truth.empty() ? Eigen::Vector3d::Zero() : truth.back();
      if (!truth.empty()) {
        const double prev_th = truth.back()[2];
        const bool turn = k == 0;
        p = Eigen::Vector3d(p[0] + std::cos(prev_th), p[1] + std::sin(prev_th),
                            turn ? NormalizeAngle(th) : prev_th);
      }
      truth.push_back(p);
    }
  }
  // Initial values drift: accumulate noisy odometry.
  Eigen::Vector3d drift = truth[0];
  for (size_t i = 0; i < truth.size(); ++i) {
    if (i > 0) {
      const Eigen::Vector3d& a = truth[i - 1];
      const Eigen::Vector3d& b = truth[i];
      const double c = std::cos(a[2]), s = std::sin(a[2]);
      const double dx = c * (b[0] - a[0]) + s * (b[1] - a[1]);
      const double dy = -s * (b[0] - a[0]) + c * (b[1] - a[1]);
      const double dth = NormalizeAngle(b[2] - a[2]) + 0.05;  // heading bias
      drift = Eigen::Vector3d(drift[0] + std::cos(drift[2]) * dx - std::sin(drift[2]) * dy,
                              drift[1] + std::sin(drift[2]) * dx + std::cos(drift[2]) * dy,
                              NormalizeAngle(drift[2] + dth));
    }
    t << "VERTEX_SE2 " << i << " " << drift[0] << " " << drift[1] << " " << drift[2] << "\n";
  }
  auto edge = [&](size_t i, size_t j) {
    const Eigen::Vector3d& a = truth[i];
    const Eigen::Vector3d& b = truth[j];
    const double c = std::cos(a[2]), s = std::sin(a[2]);
    t << "EDGE_SE2 " << i << " " << j << " " << c * (b[0] - a[0]) + s * (b[1] - a[1]) << " "
      << -s * (b[0] - a[0]) + c * (b[1] - a[1]) << " " << NormalizeAngle(b[2] - a[2])
      << " 100 0 0 100 0 400\n";
  };
  for (size_t i = 1; i < truth.size(); ++i) edge(i - 1, i);
  edge(truth.size() - 1, 0);  // loop closure
  std::istringstream in(t.str());
  G2oGraph g;
  ASSERT_TRUE(ReadG2o(in, "square", &g).ok());
  const Eigen::Vector3d first = g.poses2.at(0);
  PoseGraphResult result;
  const Status s = OptimizePoseGraph(&g, PoseGraphSolveOptions(), &result);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_TRUE(result.converged) << result.brief_report;
  EXPECT_LT(result.final_cost, 1e-6);
  EXPECT_EQ(g.poses2.at(0), first);  // gauge: the first pose is held
  for (size_t i = 0; i < truth.size(); ++i) {
    EXPECT_NEAR(g.poses2.at(i)[0], truth[i][0], 1e-4);
    EXPECT_NEAR(g.poses2.at(i)[1], truth[i][1], 1e-4);
    EXPECT_NEAR(NormalizeAngle(g.poses2.at(i)[2] - truth[i][2]), 0.0, 1e-4);
  }
}

TEST(FusionPoseGraph, BadInformationIsRejectedNamingTheEdge) {
  std::istringstream in("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 0 0 1\n");
  G2oGraph g;
  ASSERT_TRUE(ReadG2o(in, "bad", &g).ok());
  PoseGraphResult result;
  const Status s = OptimizePoseGraph(&g, PoseGraphSolveOptions(), &result);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("EDGE_SE2 #0 (0 -> 1)"), std::string::npos) << s.message();
}

// The real intel graph reaches Ceres' reference cost (full benchmark: fl-bench-posegraph).
TEST(FusionPoseGraph, IntelMatchesReferenceCost) {
  const std::string path = fl::test::SharedDataDir() + "/posegraph/intel.g2o";
  FL_REQUIRE_SHARED_FILE(path);
  G2oGraph g;
  ASSERT_TRUE(ReadG2oFile(path, &g).ok());
  PoseGraphResult result;
  ASSERT_TRUE(OptimizePoseGraph(&g, PoseGraphSolveOptions(), &result).ok());
  EXPECT_NEAR(result.final_cost, 22.939, 22.939 * 1e-3);
}

}  // namespace

// ---- real files in the wild (docs/RELIABILITY.md) ----

// A 2D graph of edges only (no VERTEX lines): a closed loop of 8 poses with exact edges, the
// chain and one loop closure, written out of order. The poses come from the odometry chain, so
// they equal the truth, and the solve keeps them.
TEST(FusionWildG2o, EdgesOnly2dAreInitialisedFromTheOdometryChain) {
  std::vector<Eigen::Vector3d> truth;
  for (int k = 0; k < 8; ++k) {
    const double a = k * M_PI / 4;
    truth.emplace_back(2 * std::cos(a), 2 * std::sin(a), NormalizeAngle(a + M_PI / 2));
  }
  const auto edge = [&](size_t i, size_t j, double noise) {
    const Pose2 a(truth[i][0], truth[i][1], truth[i][2]), b(truth[j][0], truth[j][1], truth[j][2]);
    const Pose2 d = a.inverse() * b;
    std::ostringstream t;
    t.precision(17);
    t << "EDGE_SE2 " << i << " " << j << " " << d.x + noise << " " << d.y << " " << d.theta
      << " 100 0 0 100 0 400\n";
    return t.str();
  };
  // The loop closure 0 -> 5 is off by 0.3 m: the chain, not it, must place vertex 5.
  std::string text = edge(0, 5, 0.3) + edge(7, 0, 0.0);
  for (size_t i = 7; i-- > 0;) text += edge(i, i + 1, 0.0);
  std::istringstream in(text);
  G2oGraph g;
  const Status s = ReadG2o(in, "edges.g2o", &g);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_TRUE(g.initialised_from_edges);
  ASSERT_EQ(g.poses2.size(), 8u);
  EXPECT_EQ(g.edges2.size(), 9u);
  const Pose2 T0(truth[0][0], truth[0][1], truth[0][2]);
  for (int i = 0; i < 8; ++i) {  // the truth expressed in the frame of vertex 0
    const Pose2 e = T0.inverse() * Pose2(truth[i][0], truth[i][1], truth[i][2]);
    EXPECT_NEAR(g.poses2.at(i)[0], e.x, 1e-9) << i;
    EXPECT_NEAR(g.poses2.at(i)[1], e.y, 1e-9) << i;
    EXPECT_NEAR(NormalizeAngle(g.poses2.at(i)[2] - e.theta), 0.0, 1e-9) << i;
  }
  PoseGraphResult result;
  ASSERT_TRUE(OptimizePoseGraph(&g, PoseGraphSolveOptions(), &result).ok());
  EXPECT_TRUE(result.converged) << result.brief_report;
}

// 3D edges only, and two unconnected parts: each starts at the origin.
TEST(FusionWildG2o, EdgesOnly3dAndUnconnectedParts) {
  std::istringstream in(
      "EDGE_SE3:QUAT 0 1 1 0 0 0 0 0.7071067811865476 0.7071067811865476 " +
      std::string("1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 1\n") +
      "EDGE_SE3:QUAT 1 2 1 0 0 0 0 0 1 1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 1\n"
      "EDGE_SE3:QUAT 10 11 0 0 2 0 0 0 1 1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 1\n");
  G2oGraph g;
  const Status s = ReadG2o(in, "edges3.g2o", &g);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(g.poses3.size(), 5u);
  EXPECT_TRUE(g.poses3.at(0).p.isZero());
  EXPECT_TRUE(g.poses3.at(1).p.isApprox(Eigen::Vector3d(1, 0, 0)));
  // Vertex 1 is turned 90 degrees about z: its x step of 1 m goes along world y.
  EXPECT_TRUE(g.poses3.at(2).p.isApprox(Eigen::Vector3d(1, 1, 0), 1e-12));
  EXPECT_TRUE(g.poses3.at(10).p.isZero());
  EXPECT_TRUE(g.poses3.at(11).p.isApprox(Eigen::Vector3d(0, 0, 2)));
}

// Information matrices whose entries span 24 orders of magnitude (metre-level covariances
// next to nanometre ones, strong cross terms) but are positive definite are accepted and
// solved; an indefinite one is still refused.
TEST(FusionWildG2o, InformationSpanningManyOrdersOfMagnitudeIsAccepted) {
  const std::string wide =
      "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_SE2 2 2 0.1 0\n"
      "EDGE_SE2 0 1 1 0 0 1e12 1e4 0 1e-2 0 1e-6\n"  // I11 I12 I13 I22 I23 I33
      "EDGE_SE2 1 2 1 0.1 0 1e-9 0 0 1e3 -2e-2 1e15\n";
  std::istringstream in(wide);
  G2oGraph g;
  ASSERT_TRUE(ReadG2o(in, "wide.g2o", &g).ok());
  for (const auto& e : g.edges2) {
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(e.information);
    ASSERT_GT(eig.eigenvalues().minCoeff(), 0.0) << e.information;  // the fixture is SPD
    EXPECT_GT(eig.eigenvalues().maxCoeff() / eig.eigenvalues().minCoeff(), 1e15);
  }
  PoseGraphSolveOptions options;
  options.sqrt_convention = SqrtConvention::kExact;
  PoseGraphResult result;
  const Status s = OptimizePoseGraph(&g, options, &result);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_LT(result.final_cost, result.initial_cost + 1e-9);

  std::istringstream bad("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n"
                         "EDGE_SE2 0 1 1 0 0 1e12 2e12 0 1e12 0 1\n");  // indefinite
  ASSERT_TRUE(ReadG2o(bad, "bad.g2o", &g).ok());
  EXPECT_FALSE(OptimizePoseGraph(&g, options, &result).ok());
}

}  // namespace fl::fusion
