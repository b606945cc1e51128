#include "fusionloc/procman/launch.hpp"

#include <gtest/gtest.h>

#include <cstdlib>

#include "fusionloc/common/yaml_options.hpp"

namespace fl::procman {
namespace {

TEST(ProcmanLaunch, LoadsTheShippedDemoLaunchFile) {
  const LaunchFile l = LoadLaunchFile(std::string(FL_SOURCE_DIR) + "/config/launch/sim_demo.yaml");
  EXPECT_TRUE(l.Validate().ok());
  ASSERT_GE(l.processes.size(), 4u);
  int stop_all = 0;
  for (const ProcessSpec& p : l.processes) stop_all += p.on_exit == "stop_all";
  EXPECT_EQ(stop_all, 1);  // the simulator ends the run
}

TEST(ProcmanLaunch, BadLaunchFilesAreClearErrors) {
  auto error_of = [](const std::string& yaml) {
    try {
      LoadYamlString<LaunchFile>(yaml, "", "launch.yaml");
    } catch (const ConfigError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error_of("processes: []").find("no processes"), std::string::npos);
  EXPECT_NE(error_of("processes:\n  - {name: a, command: x, restrat: never}").find("restrat"),
            std::string::npos);
  EXPECT_NE(error_of("processes:\n  - {name: a, command: x, restart: sometimes}")
                .find("restart 'sometimes' unknown"),
            std::string::npos);
  EXPECT_NE(error_of("processes:\n  - {name: a, command: x}\n  - {name: a, command: y}")
                .find("used twice"),
            std::string::npos);
  EXPECT_NE(error_of("processes:\n  - {name: 'a b', command: x}").find("letters, digits"),
            std::string::npos);
  EXPECT_NE(error_of("processes:\n  - {name: a}").find("no command"), std::string::npos);
  EXPECT_NE(error_of("processes:\n  - {name: a, command: x, on_exit: panic}").find("on_exit"),
            std::string::npos);
}

TEST(ProcmanLaunch, ExpandsVariablesFromVarsThenEnvironment) {
  setenv("FL_PROCMAN_TEST_ENV", "from-env", 1);
  std::string out, error;
  ASSERT_TRUE(ExpandVariables("${A}/x ${FL_PROCMAN_TEST_ENV} $HOME {B}", {{"A", "1"}}, &out,
                              &error));
  EXPECT_EQ(out, "1/x from-env $HOME {B}");
  EXPECT_FALSE(ExpandVariables("run ${NOPE_NOT_SET_ANYWHERE}", {}, &out, &error));
  EXPECT_NE(error.find("${NOPE_NOT_SET_ANYWHERE} is not set"), std::string::npos) << error;
  EXPECT_NE(error.find("--var"), std::string::npos) << error;
  EXPECT_FALSE(ExpandVariables("run ${OPEN", {}, &out, &error));
  EXPECT_NE(error.find("closing"), std::string::npos) << error;
}

TEST(ProcmanLaunch, SplitsCommandsWithQuotes) {
  std::vector<std::string> argv;
  std::string error;
  ASSERT_TRUE(SplitCommand("  sh -c \"echo a  b\"  x\"y z\" ", &argv, &error));
  EXPECT_EQ(argv, (std::vector<std::string>{"sh", "-c", "echo a  b", "xy z"}));
  EXPECT_FALSE(SplitCommand("sh -c \"open", &argv, &error));
  EXPECT_NE(error.find("unclosed"), std::string::npos);
  EXPECT_FALSE(SplitCommand("   ", &argv, &error));
}

}  // namespace
}  // namespace fl::procman
