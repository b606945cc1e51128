// Simulator options: defaults, YAML files in config/, and clear errors for bad values.
#include "fusionloc/sim/sim_options.hpp"

#include <gtest/gtest.h>

#include "fusionloc/common/yaml_options.hpp"
#include "fusionloc/sim/simulator.hpp"
#include "test_paths.hpp"

namespace fl::sim {
namespace {

std::string ErrorOf(const SimOptions& o) {
  const Status s = o.Validate();
  return s.ok() ? std::string("<ok>") : s.message();
}

TEST(SimOptionsTest, DefaultsAreThePaperScenario) {
  const SimOptions o;
  EXPECT_TRUE(o.Validate().ok()) << o.Validate().message();
  EXPECT_EQ(o.world.name, "paper");
  EXPECT_EQ(o.steps(), 1000);
  EXPECT_EQ(o.PeriodSteps(o.laser.rate_hz), 1);
  EXPECT_EQ(o.PeriodSteps(o.camera.rate_hz), 1);  // 10 Hz, as real stereo cameras
  EXPECT_EQ(o.laser.beams, 682);
  EXPECT_TRUE(DefaultOptionsForWorld("corridor").Validate().ok());
  EXPECT_THROW(DefaultOptionsForWorld("office"), std::invalid_argument);
}

TEST(SimOptionsTest, ConfigFilesMatchTheDefaults) {
  const auto paper = LoadYamlFile<SimOptions>(test::SourceDir() + "/config/sim_paper.yaml");
  EXPECT_EQ(SaveYamlString(paper), SaveYamlString(DefaultOptionsForWorld("paper")));
  const auto corridor = LoadYamlFile<SimOptions>(test::SourceDir() + "/config/sim_corridor.yaml");
  EXPECT_EQ(SaveYamlString(corridor), SaveYamlString(DefaultOptionsForWorld("corridor")));
}

// The mounting comes from the robot description; config/robot/sim.yaml is the built-in one.
TEST(SimOptionsTest, MountingFromTheRobotDescription) {
  const RobotDescription robot = LoadRobotDescription(test::SourceDir() + "/config/robot/sim.yaml");
  SimOptions o;
  ASSERT_TRUE(o.SetMounting(robot).ok());
  EXPECT_EQ(SaveYamlString(o), SaveYamlString(SimOptions()));
  const SimOptions defaults;
  EXPECT_EQ(o.laser.x_m, defaults.laser.x_m);
  EXPECT_EQ(o.laser.z_m, defaults.laser.z_m);
  EXPECT_EQ(o.camera.y_m, defaults.camera.y_m);
  EXPECT_EQ(o.camera.z_m, defaults.camera.z_m);

  RobotDescription moved = robot;
  moved.laser.xyz_m = {0.3, -0.1, 0.2};
  ASSERT_TRUE(o.SetMounting(moved).ok());
  EXPECT_EQ(o.laser.x_m, 0.3);
  EXPECT_EQ(o.laser.y_m, -0.1);
  EXPECT_EQ(o.laser.z_m, 0.2);

  RobotDescription tilted = robot;  // the simulator cannot render a tilted camera
  tilted.camera.rpy_deg = {-90, 10, -90};
  const Status s = o.SetMounting(tilted);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("camera.rpy_deg must be [-90, 0, -90]"), std::string::npos)
      << s.message();
  RobotDescription high = robot;  // the scan plane must stay below the obstacles' tops
  high.laser.xyz_m = {0, 0, 0.9};
  EXPECT_FALSE(o.SetMounting(high).ok());
}

TEST(SimOptionsTest, BadValuesGiveErrorsNamingTheKey) {
  SimOptions o;
  o.world.name = "office";
  EXPECT_NE(ErrorOf(o).find("world.name = 'office'"), std::string::npos) << ErrorOf(o);
  EXPECT_NE(ErrorOf(o).find("'paper' or 'corridor'"), std::string::npos);

  o = SimOptions();
  o.odometry.trans_sigma_m_per_sqrt_m = -0.1;
  EXPECT_NE(ErrorOf(o).find("odometry.trans_sigma_m_per_sqrt_m"), std::string::npos) << ErrorOf(o);

  o = SimOptions();
  o.laser.range_sigma_m = -1;
  EXPECT_NE(ErrorOf(o).find("laser.range_sigma_m"), std::string::npos) << ErrorOf(o);

  o = SimOptions();
  o.laser.rate_hz = 3.0;  // 10 Hz steps / 3 Hz is not an integer
  EXPECT_NE(ErrorOf(o).find("laser.rate_hz = 3 Hz does not divide"), std::string::npos)
      << ErrorOf(o);

  o = SimOptions();
  o.camera.cx = 700;
  EXPECT_NE(ErrorOf(o).find("camera.cx"), std::string::npos) << ErrorOf(o);

  o = SimOptions();
  o.duration_s = 0.0;
  EXPECT_NE(ErrorOf(o).find("duration_s"), std::string::npos) << ErrorOf(o);

  o = SimOptions();
  o.seed = -5;
  EXPECT_NE(ErrorOf(o).find("seed"), std::string::npos) << ErrorOf(o);

  o = SimOptions();
  o.laser.max_range_m = 0.01;
  EXPECT_FALSE(o.Validate().ok());

  o = SimOptions();
  o.camera.supersampling = 0;
  EXPECT_NE(ErrorOf(o).find("camera.supersampling"), std::string::npos) << ErrorOf(o);
}

TEST(SimOptionsTest, SimulatorRejectsInvalidOptions) {
  SimOptions o;
  o.world.name = "moon";
  try {
    Simulator sim(o);
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("world.name = 'moon'"), std::string::npos) << e.what();
  }
}

TEST(SimOptionsTest, YamlTyposAndWrongTypesAreErrors) {
  EXPECT_THROW(LoadYamlString<SimOptions>("laser:\n  range_sigma: 0.1\n"), ConfigError);
  EXPECT_THROW(LoadYamlString<SimOptions>("camera:\n  width: wide\n"), ConfigError);
  EXPECT_THROW(LoadYamlString<SimOptions>("odometry:\n  rate_hz: -10\n"), ConfigError);
  const auto o = LoadYamlString<SimOptions>("world:\n  name: corridor\nseed: 7\n");
  EXPECT_EQ(o.world.name, "corridor");
  EXPECT_EQ(o.seed, 7);
}

}  // namespace
}  // namespace fl::sim
