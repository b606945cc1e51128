#include "fusionloc/common/se2_between_cost.hpp"

#include <ceres/gradient_checker.h>
#include <gtest/gtest.h>

#include <memory>
#include <random>
#include <vector>

#include "cost_fixtures.hpp"
#include "fusionloc/common/sqrt_information.hpp"

namespace fl {
namespace {

using test::CheckerOptions;
using test::RandomSpd3;

bool Probe(const ceres::CostFunction& cost, double* T_world_i, double* T_world_j,
           std::string* log) {
  const std::vector<const ceres::Manifold*>* no_manifolds = nullptr;
  ceres::GradientChecker checker(&cost, no_manifolds, CheckerOptions());
  const double* params[2] = {T_world_i, T_world_j};
  ceres::GradientChecker::ProbeResults results;
  const bool ok = checker.Probe(params, 1e-7, &results);
  *log = results.error_log;
  return ok;
}

TEST(Se2BetweenCost, GradientCheckerRandom) {
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  for (int trial = 0; trial < 20; ++trial) {
    const Pose2 T_i_j(u(rng), u(rng), u(rng));
    Eigen::Matrix3d s;
    ASSERT_TRUE(SqrtInformation<3>(RandomSpd3(&rng), &s));
    std::unique_ptr<ceres::CostFunction> cost(Se2BetweenCost::Create(T_i_j, s));
    double T_world_i[3] = {u(rng), u(rng), u(rng)};
    double T_world_j[3] = {u(rng), u(rng), u(rng)};
    std::string log;
    EXPECT_TRUE(Probe(*cost, T_world_i, T_world_j, &log)) << log;
  }
}

TEST(Se2BetweenCost, GradientCheckerNearTheAngleCut) {
  // Headings near ±π: the wrap of the angle residual must not break the derivatives.
  Eigen::Matrix3d info;
  info << 400, 20, 5, 20, 300, -4, 5, -4, 900;
  Eigen::Matrix3d s;
  ASSERT_TRUE(SqrtInformation<3>(info, &s));
  std::unique_ptr<ceres::CostFunction> cost(Se2BetweenCost::Create(Pose2(1.0, -0.3, 0.4), s));
  double T_world_i[3] = {0.2, -0.4, 3.0};
  double T_world_j[3] = {1.1, 0.5, -2.9};
  std::string log;
  EXPECT_TRUE(Probe(*cost, T_world_i, T_world_j, &log)) << log;
}

TEST(Se2BetweenCost, ZeroAtTheMeasurement) {
  const Pose2 T_world_a(1, 2, 0.5), T_a_b(0.3, -0.2, 0.1);
  const Pose2 T_world_b = T_world_a * T_a_b;
  std::unique_ptr<ceres::CostFunction> cost(
      Se2BetweenCost::Create(T_a_b, Eigen::Matrix3d::Identity()));
  const double xi[3] = {T_world_a.x, T_world_a.y, T_world_a.theta};
  const double xj[3] = {T_world_b.x, T_world_b.y, T_world_b.theta};
  const double* p[] = {xi, xj};
  double r[3];
  ASSERT_TRUE(cost->Evaluate(p, r, nullptr));
  EXPECT_NEAR(Eigen::Vector3d(r[0], r[1], r[2]).norm(), 0.0, 1e-12);
}

TEST(Se2BetweenCost, ZeroAcrossTheAngleCutAndWhitened) {
  // Node i faces almost -x (heading pi - 0.01); node j is 1 m ahead and 0.02 rad further
  // left, i.e. across the +-pi cut. The residual must be zero, not 2 pi.
  const double ti = M_PI - 0.01;
  const double pi[3] = {1.0, 2.0, ti};
  const double pj[3] = {1.0 + std::cos(ti), 2.0 + std::sin(ti), ti + 0.02 - 2.0 * M_PI};
  std::unique_ptr<ceres::CostFunction> cost(
      Se2BetweenCost::Create(Pose2(1.0, 0.0, 0.02), Eigen::Matrix3d::Identity()));
  const double* params[2] = {pi, pj};
  double r[3];
  ASSERT_TRUE(cost->Evaluate(params, r, nullptr));
  for (double v : r) EXPECT_NEAR(v, 0.0, 1e-12);
  // A wrong measurement gives the expected whitened residual r = S e.
  std::unique_ptr<ceres::CostFunction> off(
      Se2BetweenCost::Create(Pose2(1.0, 0.0, 0.02), 2.0 * Eigen::Matrix3d::Identity()));
  const double pj2[3] = {pj[0], pj[1], pj[2] + 0.1};
  const double* params2[2] = {pi, pj2};
  ASSERT_TRUE(off->Evaluate(params2, r, nullptr));
  EXPECT_NEAR(r[2], 0.2, 1e-12);
}

TEST(Se2BetweenCost, ResidualInTheFrameOfNodeI) {
  // Node i at (1, 1) facing +y; node j 2 m further along +y: 2 m ahead of i, i.e. x = 2 in
  // frame i. With T_i_j = (1.5, 0.25, 0) the error is (0.5, -0.25, 0).
  const double pi[3] = {1.0, 1.0, M_PI / 2};
  const double pj[3] = {1.0, 3.0, M_PI / 2};
  std::unique_ptr<ceres::CostFunction> cost(
      Se2BetweenCost::Create(Pose2(1.5, 0.25, 0.0), Eigen::Matrix3d::Identity()));
  const double* params[2] = {pi, pj};
  double r[3];
  ASSERT_TRUE(cost->Evaluate(params, r, nullptr));
  EXPECT_NEAR(r[0], 0.5, 1e-12);
  EXPECT_NEAR(r[1], -0.25, 1e-12);
  EXPECT_NEAR(r[2], 0.0, 1e-12);
}

}  // namespace
}  // namespace fl
