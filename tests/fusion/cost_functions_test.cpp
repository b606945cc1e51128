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

TEST(FusionCostFunctions, Se3BetweenGradientChecker) {
  std::mt19937 rng(4);
  std::normal_distribution<double> n(0.0, 1.0);
  ceres::EigenQuaternionManifold quat;
  const std::vector<const ceres::Manifold*> manifolds = {nullptr, &quat, nullptr, &quat};
  for (int trial = 0; trial < 10; ++trial) {
    Eigen::Matrix<double, 6, 6> a;
    for (int i = 0; i < 36; ++i) a.data()[i] = n(rng);
    Eigen::Matrix<double, 6, 6> s;
    ASSERT_TRUE(
        SqrtInformation<6>(a * a.transpose() + Eigen::Matrix<double, 6, 6>::Identity(), &s));
    const Eigen::Quaterniond q_ij = Eigen::Quaterniond(n(rng), n(rng), n(rng), n(rng)).normalized();
    std::unique_ptr<ceres::CostFunction> cost(
        Se3BetweenCost::Create(Eigen::Vector3d(n(rng), n(rng), n(rng)), q_ij, s));
    ceres::GradientChecker checker(cost.get(), &manifolds, CheckerOptions());
    Eigen::Vector3d p_i(n(rng), n(rng), n(rng)), p_j(n(rng), n(rng), n(rng));
    Eigen::Quaterniond q_i = Eigen::Quaterniond(n(rng), n(rng), n(rng), n(rng)).normalized();
    Eigen::Quaterniond q_j = Eigen::Quaterniond(n(rng), n(rng), n(rng), n(rng)).normalized();
    const double* params[4] = {p_i.data(), q_i.coeffs().data(), p_j.data(), q_j.coeffs().data()};
    ceres::GradientChecker::ProbeResults results;
    EXPECT_TRUE(checker.Probe(params, 1e-7, &results)) << results.error_log;
  }
}

TEST(FusionCostFunctions, Se3BetweenZeroAtTruth) {
  const Eigen::Quaterniond q_i(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()));
  const Eigen::Quaterniond q_ij(Eigen::AngleAxisd(-0.7, Eigen::Vector3d(0, 1, 1).normalized()));
  const Eigen::Vector3d p_i(1, 2, 3), p_ij(0.5, -0.2, 0.1);
  const Eigen::Vector3d p_j = p_i + q_i * p_ij;
  const Eigen::Quaterniond q_j = q_i * q_ij;
  std::unique_ptr<ceres::CostFunction> cost(
      Se3BetweenCost::Create(p_ij, q_ij, Eigen::Matrix<double, 6, 6>::Identity()));
  const double* params[4] = {p_i.data(), q_i.coeffs().data(), p_j.data(), q_j.coeffs().data()};
  double r[6];
  ASSERT_TRUE(cost->Evaluate(params, r, nullptr));
  for (double v : r) EXPECT_NEAR(v, 0.0, 1e-12);
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
