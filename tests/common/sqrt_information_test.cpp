#include "fusionloc/common/sqrt_information.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace fl {
namespace {

Eigen::Matrix3d RandomSpd3(std::mt19937* rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Matrix3d a;
  for (int i = 0; i < 9; ++i) a.data()[i] = n(*rng);
  return a * a.transpose() + Eigen::Matrix3d::Identity();
}

TEST(SqrtInformation, ExactGivesOmega) {
  std::mt19937 rng(1);
  const Eigen::Matrix3d omega = RandomSpd3(&rng);
  Eigen::Matrix3d s;
  ASSERT_TRUE(SqrtInformation<3>(omega, &s));
  EXPECT_LT((s.transpose() * s - omega).norm(), 1e-9);
  EXPECT_TRUE(s.isUpperTriangular());
  // Ceres-example convention S = L: S S^T = Omega.
  ASSERT_TRUE(SqrtInformation<3>(omega, &s, SqrtConvention::kCeresExample));
  EXPECT_LT((s * s.transpose() - omega).norm(), 1e-9);
}

TEST(SqrtInformation, SixBySix) {
  std::mt19937 rng(4);
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Matrix<double, 6, 6> a;
  for (int i = 0; i < 36; ++i) a.data()[i] = n(rng);
  const Eigen::Matrix<double, 6, 6> omega =
      a * a.transpose() + Eigen::Matrix<double, 6, 6>::Identity();
  Eigen::Matrix<double, 6, 6> s;
  ASSERT_TRUE(SqrtInformation<6>(omega, &s));
  EXPECT_LT((s.transpose() * s - omega).norm(), 1e-9);
}

TEST(SqrtInformation, RejectsBadMatrices) {
  Eigen::Matrix3d s = Eigen::Matrix3d::Constant(7.0);
  Eigen::Matrix3d m = Eigen::Matrix3d::Identity();
  m(0, 1) = 0.5;  // not symmetric
  EXPECT_FALSE(SqrtInformation<3>(m, &s));
  m = Eigen::Matrix3d::Identity();
  m(2, 2) = 0.0;  // singular
  EXPECT_FALSE(SqrtInformation<3>(m, &s));
  m(2, 2) = -1.0;  // indefinite
  EXPECT_FALSE(SqrtInformation<3>(m, &s));
  m(2, 2) = std::nan("");
  EXPECT_FALSE(SqrtInformation<3>(m, &s));
  EXPECT_FALSE(SqrtInformation<3>(Eigen::Matrix3d::Zero(), &s));
  EXPECT_TRUE(s.isApprox(Eigen::Matrix3d::Constant(7.0)));  // left unchanged
  m << 1, 1, 0, 1, 1, 0, 0, 0, 1;  // rows 0 and 1 dependent
  EXPECT_FALSE(SqrtInformation<3>(m, &s));
  m << 1e12, 1e12 * (1 - 1e-14), 0, 1e12 * (1 - 1e-14), 1e12, 0, 0, 0, 1;  // nearly so
  EXPECT_FALSE(SqrtInformation<3>(m, &s));
}

// Positive definite information whose entries span 24 orders of magnitude (a real-file case,
// docs/RELIABILITY.md) is accepted, and S still gives Ω back.
TEST(SqrtInformation, AcceptsEntriesSpanningManyOrdersOfMagnitude) {
  Eigen::Matrix3d omega;
  omega << 1e15, 1e4, 0, 1e4, 1e-2, 1e-6, 0, 1e-6, 1e-9;
  Eigen::Matrix3d s;
  ASSERT_TRUE(SqrtInformation<3>(omega, &s));
  const Eigen::Matrix3d back = s.transpose() * s;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(back(r, c), omega(r, c), 1e-9 * std::sqrt(omega(r, r) * omega(c, c))) << r << c;
    }
  }
  EXPECT_TRUE(SqrtInformation<3>(Eigen::Vector3d(1e15, 1.0, 1e-9).asDiagonal().toDenseMatrix(), &s));
}

TEST(SqrtInformation, SymmetricPartOfANearlySymmetricMatrix) {
  // As the RBPF passes an ICP information: ½(Ω + Ωᵀ) of an Ω asymmetric by rounding.
  std::mt19937 rng(5);
  Eigen::Matrix3d omega = RandomSpd3(&rng);
  omega(0, 2) += 1e-12;
  const Eigen::Matrix3d sym = 0.5 * (omega + omega.transpose());
  Eigen::Matrix3d s;
  ASSERT_TRUE(SqrtInformation<3>(sym, &s));
  EXPECT_LT((s.transpose() * s - sym).norm(), 1e-9);
}

}  // namespace
}  // namespace fl
