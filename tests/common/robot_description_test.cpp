#include "fusionloc/common/robot_description.hpp"

#include <gtest/gtest.h>

#include <fstream>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/yaml_options.hpp"
#include "test_paths.hpp"

namespace fl {
namespace {

std::string Write(const test::TempDir& dir, const std::string& text) {
  const std::string path = dir.file("robot.yaml");
  std::ofstream(path) << text;
  return path;
}

std::string LoadError(const std::string& path) {
  try {
    LoadRobotDescription(path);
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(RobotDescription, QuarterTurnsAreExact) {
  // The optical frame in the base frame: x_cam = -y_base, y_cam = -z_base, z_cam = +x_base.
  Eigen::Matrix3d expected;
  expected << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  const Eigen::Matrix3d R = RotationFromRollPitchYawDeg(-90, 0, -90);
  EXPECT_EQ((R - expected).cwiseAbs().maxCoeff(), 0.0) << R;  // exactly, not to 6e-17
  EXPECT_EQ(RotationFromRollPitchYawDeg(0, 0, 450)(0, 0), 0.0);
  EXPECT_EQ(RotationFromRollPitchYawDeg(0, 0, -180)(0, 0), -1.0);
  // Other angles: R = Rz(yaw) Ry(pitch) Rx(roll), as geometry.hpp's radians version.
  const Eigen::Matrix3d a = RotationFromRollPitchYawDeg(10, -20, 30);
  const Eigen::Matrix3d b =
      RotationFromRollPitchYaw(10 * M_PI / 180, -20 * M_PI / 180, 30 * M_PI / 180);
  EXPECT_LT((a - b).cwiseAbs().maxCoeff(), 1e-15);
}

TEST(RobotDescription, TheSimulatedRobotsFile) {
  const RobotDescription r = LoadRobotDescription(test::SourceDir() + "/config/robot/sim.yaml");
  EXPECT_EQ(r.name, "sim");
  const Eigen::Isometry3d T_base_laser = r.laser.T_base_sensor();
  EXPECT_TRUE(T_base_laser.linear().isIdentity(0.0));
  EXPECT_EQ(T_base_laser.translation(), Eigen::Vector3d(0.15, 0, 0.3));
  const Eigen::Isometry3d T_base_camera = r.camera.T_base_sensor();
  EXPECT_EQ(T_base_camera.translation(), Eigen::Vector3d(0.2, 0.06, 0.5));
  // A point 1 m in front of the camera is 1 m ahead of it along base x.
  EXPECT_EQ(T_base_camera * Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(1.2, 0.06, 0.5));
  EXPECT_FALSE(r.base.described());
}

TEST(RobotDescription, BadFilesNameTheKeyAndTheFix) {
  test::TempDir dir;
  EXPECT_NE(
      LoadError(Write(dir, "name: r\nlaser: {xyz_m: [0, 0]}\n")).find("laser.xyz_m must have 3"),
      std::string::npos);
  EXPECT_NE(
      LoadError(Write(dir, "name: r\nlazer: {xyz_m: [0, 0, 0]}\n")).find("unknown key 'lazer'"),
      std::string::npos);
  EXPECT_NE(LoadError(Write(dir, "laser: {xyz_m: [0, 0, 0]}\n")).find("name must be set"),
            std::string::npos);
  EXPECT_NE(LoadError(Write(dir, "name: r\nbase: {wheel_radius_m: 0.035}\n")).find("all be > 0"),
            std::string::npos);
  EXPECT_NE(LoadError(Write(dir, "name: r\ncamera: {rpy_deg: [0, .nan, 0]}\n")).find("finite"),
            std::string::npos);
  EXPECT_NE(LoadError(dir.file("missing.yaml")).find("missing.yaml"), std::string::npos);
  const RobotDescription ok = LoadRobotDescription(Write(
      dir,
      "name: r\nbase: {wheel_radius_m: 0.035, track_m: 0.23, ticks_per_revolution: 2578.33}\n"));
  EXPECT_TRUE(ok.base.described());
  EXPECT_DOUBLE_EQ(ok.base.ticks_per_revolution, 2578.33);
}

}  // namespace
}  // namespace fl
