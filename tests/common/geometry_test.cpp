#include "fusionloc/common/geometry.hpp"

#include <gtest/gtest.h>

namespace fl {
namespace {

TEST(Geometry, WrapAngle) {
  EXPECT_NEAR(WrapAngle(3 * M_PI / 2), -M_PI / 2, 1e-12);
  EXPECT_NEAR(WrapAngle(-3 * M_PI / 2), M_PI / 2, 1e-12);
  EXPECT_NEAR(WrapAngle(0.3), 0.3, 1e-12);
}

TEST(Geometry, Pose2ComposeInverseBetween) {
  const Pose2 a(1, 2, 0.5), b(-0.3, 0.7, -1.2);
  const Pose2 id = a * a.inverse();
  EXPECT_NEAR(id.x, 0, 1e-12);
  EXPECT_NEAR(id.y, 0, 1e-12);
  EXPECT_NEAR(id.theta, 0, 1e-12);
  const Pose2 ab = a * b;
  const Pose2 rel = a.between(ab);
  EXPECT_NEAR(rel.x, b.x, 1e-12);
  EXPECT_NEAR(rel.y, b.y, 1e-12);
  EXPECT_NEAR(rel.theta, b.theta, 1e-12);
  // Agrees with Eigen's isometries.
  const Eigen::Vector2d p(0.4, -2.0);
  EXPECT_TRUE(((a * b) * p).isApprox((a.isometry() * b.isometry()) * p));
  const Pose2 back = Pose2::FromIsometry3(ab.ToIsometry3());
  EXPECT_NEAR(back.theta, ab.theta, 1e-12);
}

TEST(Geometry, NearestRotation) {
  const Eigen::Matrix3d r = RotationFromRollPitchYaw(0.1, -0.2, 2.5);
  EXPECT_TRUE(NearestRotation(r).isApprox(r, 1e-12));
  // A rotation printed with 4 digits comes back orthonormal and next to it.
  const Eigen::Matrix3d printed = (r * 1e4).array().round().matrix() / 1e4;
  const Eigen::Matrix3d fixed = NearestRotation(printed);
  EXPECT_LT((fixed.transpose() * fixed - Eigen::Matrix3d::Identity()).norm(), 1e-12);
  EXPECT_NEAR(fixed.determinant(), 1.0, 1e-12);
  EXPECT_LT(RotationAngle(fixed.transpose() * r), 1e-3);
  // The sum of two rotations about z by +-0.4 rad: their chordal mean is the rotation between.
  const Eigen::Matrix3d sum =
      r * Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitZ()).toRotationMatrix() +
      r * Eigen::AngleAxisd(-0.4, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  EXPECT_TRUE(NearestRotation(sum).isApprox(r, 1e-12));
  // A reflection is not returned: the nearest proper rotation has det +1.
  EXPECT_NEAR(NearestRotation(Eigen::Vector3d(1, 1, -1).asDiagonal().toDenseMatrix()).determinant(),
              1.0, 1e-12);
}

TEST(Geometry, RollPitchYawRoundTrip) {
  const Eigen::Matrix3d r = RotationFromRollPitchYaw(0.1, -0.2, 2.5);
  const Eigen::Vector3d rpy = RollPitchYaw(r);
  EXPECT_NEAR(rpy.x(), 0.1, 1e-12);
  EXPECT_NEAR(rpy.y(), -0.2, 1e-12);
  EXPECT_NEAR(rpy.z(), 2.5, 1e-12);
  EXPECT_NEAR(RotationAngle(
                  Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix()),
              0.7, 1e-12);
  double t[3], q[4];
  Eigen::Isometry3d iso = Eigen::Isometry3d::Identity();
  iso.linear() = r;
  iso.translation() = Eigen::Vector3d(1, 2, 3);
  IsometryToArrays(iso, t, q);
  EXPECT_TRUE(IsometryFromArrays(t, q).isApprox(iso));
}

}  // namespace
}  // namespace fl
