#include "fusionloc/fusion/cost_functions.hpp"

#include <ceres/gradient_checker.h>
#include <gtest/gtest.h>

#include <random>

#include "cost_fixtures.hpp"

namespace fl::fusion {
namespace {

using test::CheckerOptions;
using test::RandomSpd3;

TEST(FusionCostFunctions, Se2PriorGradientChecker) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  Pose2Manifold manifold;
  const std::vector<const ceres::Manifold*> manifolds = {&manifold};
  for (int trial = 0; trial < 10; ++trial) {
    Eigen::Matrix3d s;
    ASSERT_TRUE(SqrtInformation<3>(RandomSpd3(&rng), &s));
    std::unique_ptr<ceres::CostFunction> cost(
        Se2PriorCost::Create(Eigen::Vector3d(u(rng), u(rng), u(rng)), s));
    ceres::GradientChecker checker(cost.get(), &manifolds, CheckerOptions());
    double p[3] = {u(rng), u(rng), u(rng)};
    const double* params[1] = {p};
    ceres::GradientChecker::ProbeResults results;
    EXPECT_TRUE(checker.Probe(params, 1e-7, &results)) << results.error_log;
  }
}

TEST(FusionCostFunctions, Pose2ManifoldWrapsAngle) {
  Pose2Manifold m;
  const double x[3] = {1.0, 2.0, M_PI - 0.1};
  const double d[3] = {0.5, -0.5, 0.3};
  double y[3];
  ASSERT_TRUE(m.Plus(x, d, y));
  EXPECT_DOUBLE_EQ(y[0], 1.5);
  EXPECT_NEAR(y[2], -M_PI + 0.2, 1e-12);
  double back[3];
  ASSERT_TRUE(m.Minus(y, x, back));
  EXPECT_NEAR(back[2], 0.3, 1e-12);
}

}  // namespace
}  // namespace fl::fusion
