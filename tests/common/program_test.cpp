// The program edge: built-in flags, options files, --print-config and the exit-code policy.
#include "fusionloc/common/program.hpp"

#include <gtest/gtest.h>

#include <fstream>

#include "fusionloc/common/channel_map.hpp"
#include "fusionloc/common/log.hpp"
#include "test_paths.hpp"

namespace fl {
namespace {

using test::Args;

struct DemoOptions {
  double sigma = 0.2;  // [m]
  int particles = 30;
  template <class A>
  void Serialize(A* a) {
    a->Visit("sigma", &sigma);
    a->Visit("particles", &particles);
  }
  Status Validate() const {
    return particles > 0 ? Status::Ok() : Status::Error("particles must be > 0");
  }
};

TEST(Program, PrintConfigShowsTheLoadedOptionsWithShortestFloats) {
  test::TempDir dir;
  {
    std::ofstream f(dir.file("o.yaml"));
    f << "particles: 12\n";
  }
  Program program("fl-demo", "demo");
  DemoOptions options;
  program.AddOptions(&options, "o.yaml");
  testing::internal::CaptureStdout();
  Args a({"fl-demo", "--config", dir.file("o.yaml"), "--print-config"});
  EXPECT_FALSE(program.Parse(a.argc(), a.argv()));
  const std::string out = testing::internal::GetCapturedStdout();
  EXPECT_EQ(program.exit_code(), kExitOk);
  EXPECT_NE(out.find("sigma: 0.2\n"), std::string::npos) << out;  // not 0.20000000000000001
  EXPECT_NE(out.find("particles: 12"), std::string::npos) << out;
  EXPECT_EQ(options.particles, 12);
}

TEST(Program, BadConfigIsAUsageErrorNamingTheFile) {
  test::TempDir dir;
  {
    std::ofstream f(dir.file("bad.yaml"));
    f << "particels: 12\n";
  }
  {
    std::ofstream f(dir.file("invalid.yaml"));
    f << "particles: 0\n";
  }
  for (const std::string& file :
       {dir.file("bad.yaml"), dir.file("invalid.yaml"), dir.file("missing.yaml")}) {
    Program program("fl-demo", "demo");
    DemoOptions options;
    program.AddOptions(&options, "o.yaml");
    Args a({"fl-demo", "--config", file});
    testing::internal::CaptureStderr();
    EXPECT_FALSE(program.Parse(a.argc(), a.argv()));
    const std::string err = testing::internal::GetCapturedStderr();
    EXPECT_EQ(program.exit_code(), kExitUsage) << file;
    EXPECT_NE(err.find(file), std::string::npos) << err;
  }
  // The defaults are validated too, without a file.
  Program program("fl-demo", "demo");
  DemoOptions options;
  options.particles = -1;
  program.AddOptions(&options, "o.yaml");
  Args a({"fl-demo"});
  testing::internal::CaptureStderr();
  EXPECT_FALSE(program.Parse(a.argc(), a.argv()));
  EXPECT_NE(testing::internal::GetCapturedStderr().find("particles must be > 0"),
            std::string::npos);
  EXPECT_EQ(program.exit_code(), kExitUsage);
}

TEST(Program, RunMapsExceptionsToTheExitCodePolicy) {
  Program program("fl-demo", "demo");
  testing::internal::CaptureStderr();
  EXPECT_EQ(program.Run([] { return 0; }), kExitOk);
  EXPECT_EQ(program.Run([]() -> int { throw UsageError("missing IN"); }), kExitUsage);
  EXPECT_EQ(program.Run([]() -> int { throw ConfigError("x.yaml: bad"); }), kExitUsage);
  EXPECT_EQ(program.Run([]() -> int { throw std::runtime_error("cannot open log"); }),
            kExitFailure);
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("fl-demo: missing IN (see fl-demo --help)"), std::string::npos) << err;
  EXPECT_NE(err.find("fl-demo: cannot open log"), std::string::npos) << err;
}

TEST(Program, LogLevelAndFlagsAsYamlAreBuiltIn) {
  Program program("fl-tool", "a tool without an options file");
  double rate = 0.1;
  std::vector<std::string> channels;
  std::string in;
  program.cli().AddFlag("rate", &rate, "rate");
  program.cli().AddRepeatedFlag("channel", &channels, "rename");
  program.cli().AddPositional("IN", &in, "input");
  Args bad({"fl-tool", "--log-level", "loud", "x"});
  testing::internal::CaptureStderr();
  EXPECT_FALSE(program.Parse(bad.argc(), bad.argv()));
  testing::internal::GetCapturedStderr();
  EXPECT_EQ(program.exit_code(), kExitUsage);

  // --print-config needs no positional and prints the flags' values.
  Args print(
      {"fl-tool", "--log-level=warn", "--channel", "A=B", "--channel=C=D", "--print-config"});
  testing::internal::CaptureStdout();
  EXPECT_FALSE(program.Parse(print.argc(), print.argv()));
  const std::string out = testing::internal::GetCapturedStdout();
  EXPECT_EQ(program.exit_code(), kExitOk);
  EXPECT_NE(out.find("rate: 0.1\n"), std::string::npos) << out;
  EXPECT_NE(out.find("channel: [A=B, C=D]"), std::string::npos) << out;
  EXPECT_NE(out.find("log-level: warn"), std::string::npos) << out;
  EXPECT_EQ(GetLogLevel(), LogLevel::WARN);
  SetLogLevel(LogLevel::INFO);
}

TEST(Program, DeclaringAFlagTwiceIsAProgrammingError) {
  Program program("fl-tool", "t");
  bool b = false;
  EXPECT_THROW(program.cli().AddFlag("print-config", &b, "again"), std::logic_error);
}

TEST(ChannelMap, RenamesKnownChannelsOnly) {
  ChannelMap map;
  EXPECT_EQ(map.Add("LASER=FRONT", {"LASER", "ODOMETRY"}), "");
  EXPECT_EQ(map("LASER"), "FRONT");
  EXPECT_EQ(map("ODOMETRY"), "ODOMETRY");
  EXPECT_NE(map.Add("LASER=OTHER", {"LASER"}).find("twice"), std::string::npos);
  EXPECT_NE(map.Add("LASR=X", {"LASER", "ODOMETRY"}).find("its channels: LASER, ODOMETRY"),
            std::string::npos);
  EXPECT_NE(map.Add("LASER", {}).find("NAME=OTHER"), std::string::npos);
  EXPECT_NE(map.Add("=X", {}).find("NAME=OTHER"), std::string::npos);
}

}  // namespace
}  // namespace fl
