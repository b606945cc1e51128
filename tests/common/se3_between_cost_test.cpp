#include "fusionloc/common/se3_between_cost.hpp"

#include <ceres/gradient_checker.h>
#include <ceres/manifold.h>
#include <gtest/gtest.h>

#include <memory>
#include <random>
#include <vector>

#include "cost_fixtures.hpp"
#include "fusionloc/common/sqrt_information.hpp"

namespace fl {
namespace {

using test::CheckerOptions;

TEST(Se3BetweenCost, Se3BetweenGradientChecker) {
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

TEST(Se3BetweenCost, Se3BetweenZeroAtTruth) {
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

TEST(Se3BetweenCost, ErrorCovarianceMapsARightPerturbation) {
  // T_est = T_ij Exp(delta) for a small delta: the cost's error (identity S) is M delta with
  // M = diag(R_ij, -R_ij), the map Se3BetweenErrorCovariance applies.
  const Eigen::Quaterniond q_i(Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, -1, 2).normalized()));
  const Eigen::Quaterniond q_ij(Eigen::AngleAxisd(0.9, Eigen::Vector3d(0, 1, 3).normalized()));
  const Eigen::Vector3d p_i(1, 2, 3), p_ij(2.0, -0.5, 0.3);
  Eigen::Matrix<double, 6, 1> delta;
  delta << 1e-5, -2e-5, 3e-5, 2e-5, 1e-5, -3e-5;
  const Eigen::Quaterniond q_d(
      Eigen::AngleAxisd(delta.tail<3>().norm(), delta.tail<3>().normalized()));
  const Eigen::Quaterniond q_est = q_ij * q_d;
  const Eigen::Vector3d p_est = p_ij + q_ij * delta.head<3>();
  const Eigen::Vector3d p_j = p_i + q_i * p_est;
  const Eigen::Quaterniond q_j = q_i * q_est;
  std::unique_ptr<ceres::CostFunction> cost(
      Se3BetweenCost::Create(p_ij, q_ij, Eigen::Matrix<double, 6, 6>::Identity()));
  const double* params[4] = {p_i.data(), q_i.coeffs().data(), p_j.data(), q_j.coeffs().data()};
  Eigen::Matrix<double, 6, 1> e;
  ASSERT_TRUE(cost->Evaluate(params, e.data(), nullptr));
  // Covariance of a single direction: cov_delta = delta delta^T maps to e e^T.
  const Eigen::Matrix<double, 6, 6> mapped =
      Se3BetweenErrorCovariance(q_ij.toRotationMatrix(), delta * delta.transpose());
  EXPECT_LT((mapped - e * e.transpose()).norm(), 1e-6 * (e * e.transpose()).norm());
}

}  // namespace
}  // namespace fl
