#include "fusionloc/common/command_line.hpp"

#include <gtest/gtest.h>

#include "test_paths.hpp"

namespace fl {
namespace {

using test::Args;

TEST(CommandLine, ParsesFlagsAndPositionals) {
  CommandLine cli("fl-x", "test");
  std::string url = "memq://", log;
  double d = 1;
  int n = 2;
  bool v = false;
  cli.AddFlag("lcm-url", &url, "url");
  cli.AddFlag("duration", &d, "seconds");
  cli.AddFlag("n", &n, "count");
  cli.AddFlag("verbose", &v, "talk");
  cli.AddPositional("LOG", &log, "log");
  Args a({"fl-x", "--duration=2.5", "--n", "7", "--verbose", "in.lcmlog"});
  ASSERT_TRUE(cli.Parse(a.argc(), a.argv()));
  EXPECT_DOUBLE_EQ(d, 2.5);
  EXPECT_EQ(n, 7);
  EXPECT_TRUE(v);
  EXPECT_EQ(log, "in.lcmlog");
}

TEST(CommandLine, RejectsBadInput) {
  CommandLine cli("fl-x", "test");
  int n = 2;
  std::string log;
  cli.AddFlag("n", &n, "count");
  cli.AddPositional("LOG", &log, "log");
  Args bad_value({"fl-x", "--n=abc", "x"});
  EXPECT_FALSE(cli.Parse(bad_value.argc(), bad_value.argv()));
  EXPECT_EQ(cli.exit_code(), 2);
  Args unknown({"fl-x", "--m=1", "x"});
  EXPECT_FALSE(cli.Parse(unknown.argc(), unknown.argv()));
  Args missing({"fl-x"});
  EXPECT_FALSE(cli.Parse(missing.argc(), missing.argv()));
  EXPECT_EQ(cli.exit_code(), 2);
  Args help({"fl-x", "--help"});
  EXPECT_FALSE(cli.Parse(help.argc(), help.argv()));
  EXPECT_EQ(cli.exit_code(), 0);
  EXPECT_NE(cli.Help().find("--n=VALUE"), std::string::npos);
}

}  // namespace
}  // namespace fl
