#include "fusionloc/rbpf_slam/icp.hpp"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <cmath>

#include "laser_fixtures.hpp"

namespace fl::rbpf {
namespace {

std::vector<Eigen::Vector2d> ScanPoints(const test::LaserWorld& w, const fl::Pose2& pose,
                                        double noise, unsigned seed) {
  std::mt19937 rng(seed);
  const auto r = w.Scan(pose, 361, -M_PI / 2, M_PI / 360, 25.0, noise, &rng);
  std::vector<Eigen::Vector2d> pts;
  for (int k = 0; k < 361; ++k) {
    if (!std::isfinite(r[k])) continue;
    const double a = -M_PI / 2 + k * M_PI / 360;
    pts.emplace_back(r[k] * std::cos(a), r[k] * std::sin(a));
  }
  return pts;
}

TEST(Icp, RecoversAKnownTransformOnSyntheticScans) {
  const test::LaserWorld world = test::LaserWorld::RoomWithBoxes();
  const fl::Pose2 pose_i(-6.0, -4.5, 0.1);
  const fl::Pose2 T_i_j(0.45, 0.12, 0.15);
  const fl::Pose2 pose_j = pose_i * T_i_j;
  const auto ref = ComputeNormals(ScanPoints(world, pose_i, 0.005, 1));
  const auto query = ScanPoints(world, pose_j, 0.005, 2);
  IcpOptions o;
  // Start 10 cm / 3 degrees away from the truth.
  const IcpResult r = AlignPointToLine(ref, query, T_i_j * fl::Pose2(-0.08, 0.06, -0.05), o);
  ASSERT_TRUE(r.ok) << r.failure;
  EXPECT_NEAR(r.T_ref_query.x, T_i_j.x, 0.01);
  EXPECT_NEAR(r.T_ref_query.y, T_i_j.y, 0.01);
  EXPECT_NEAR(r.T_ref_query.theta, T_i_j.theta, 0.003);
  EXPECT_LT(r.rms, 0.01);
  EXPECT_GT(r.inlier_fraction, 0.8);
  // Information: symmetric positive definite, scaled by 1/σ².
  EXPECT_TRUE(r.information.isApprox(r.information.transpose()));
  EXPECT_GT(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(r.information).eigenvalues().minCoeff(), 0.0);
}

TEST(Icp, InformationIsSmallAlongACorridor) {
  // Two parallel walls along x: x is unobservable, y and θ are.
  test::LaserWorld corridor;
  corridor.AddSegment({-50, -1.5}, {50, -1.5});
  corridor.AddSegment({-50, 1.5}, {50, 1.5});
  const auto ref = ComputeNormals(ScanPoints(corridor, fl::Pose2(), 0.0, 1));
  const auto query = ScanPoints(corridor, fl::Pose2(0.2, 0.0, 0.0), 0.0, 2);
  const IcpResult r = AlignPointToLine(ref, query, fl::Pose2(0.2, 0.05, 0.02), IcpOptions());
  EXPECT_NEAR(r.T_ref_query.y, 0.0, 0.005);
  EXPECT_NEAR(r.T_ref_query.theta, 0.0, 0.002);
  EXPECT_LT(r.information(0, 0), 1e-3 * r.information(1, 1));
}

TEST(Icp, FailsClearlyWithTooFewPoints) {
  std::vector<PointNormal> ref(3);
  const IcpResult r = AlignPointToLine(ref, {{1, 0}, {2, 0}}, fl::Pose2(), IcpOptions());
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.failure.find("too few points"), std::string::npos);
}

}  // namespace
}  // namespace fl::rbpf
