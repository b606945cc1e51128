#include "fusionloc/fusion/pose_graph.hpp"

#include <gtest/gtest.h>

#include <random>
#include <sstream>

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
}  // namespace fl::fusion
