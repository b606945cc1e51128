#include "fusionloc/procman/procman_config.hpp"

#include <gtest/gtest.h>

#include <map>
#include <set>

#include "fusionloc/common/yaml_options.hpp"
#include "fusionloc/procman/shell_words.hpp"
#include "test_paths.hpp"

namespace fl::procman {
namespace {

std::string ErrorOf(const std::string& text) {
  try {
    ParseProcmanConfig(text, "t.cfg");
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "no error";
}

#define EXPECT_ERROR(text, part) \
  EXPECT_NE(ErrorOf(text).find(part), std::string::npos) << ErrorOf(text)

TEST(ProcmanConfig, EveryCommandAttribute) {
  const ProcmanConfig c = ParseProcmanConfig(
      "# comment\n"
      "cmd \"a\" { exec = \"sh -c 'exit 3'\"; host = \"h1\"; auto_respawn = \"true\";\n"
      "  stop_signal = 15; stop_time_allowed = 3; }  # trailing comment\n"
      "cmd \"b\" { deputy = \"h2\"; exec = \"x \\\"q\\\"\"; auto_respawn = \"false\"; }\n"
      "cmd { exec = \"unnamed\"; host = \"h1\"; }\n",
      "t.cfg");
  ASSERT_EQ(c.commands.size(), 3u);
  const CommandConfig& a = c.commands[0];
  EXPECT_EQ(a.name, "a");
  EXPECT_EQ(a.exec, "sh -c 'exit 3'");
  EXPECT_EQ(a.host, "h1");
  EXPECT_TRUE(a.auto_respawn);
  EXPECT_EQ(a.stop_signal, 15);
  EXPECT_EQ(a.stop_time_allowed_s, 3.0);
  EXPECT_EQ(a.line, 2);
  const CommandConfig& b = c.commands[1];
  EXPECT_EQ(b.host, "h2");  // deputy = is host =
  EXPECT_EQ(b.exec, "x \"q\"");
  EXPECT_FALSE(b.auto_respawn);
  EXPECT_EQ(b.stop_signal, 2);  // libbot2's defaults: SIGINT, 7 s
  EXPECT_EQ(b.stop_time_allowed_s, 7.0);
  EXPECT_EQ(c.commands[2].name, "unnamed");  // no name: the exec string, as libbot2
}

TEST(ProcmanConfig, NestedGroupsAndReferences) {
  const ProcmanConfig c = ParseProcmanConfig(
      "group \"est\" {\n"
      "  cmd \"slam\" { exec = \"s\"; host = \"h\"; }\n"
      "  group \"vision\" { cmd \"vo\" { exec = \"v\"; host = \"h\"; } }\n"
      "}\n"
      "group \"other\" { cmd \"vo\" { exec = \"v2\"; host = \"h\"; } }\n"
      "cmd \"top\" { exec = \"t\"; host = \"h\"; }\n",
      "t.cfg");
  ASSERT_EQ(c.commands.size(), 4u);
  EXPECT_EQ(c.commands[0].path(), "est/slam");
  EXPECT_EQ(c.commands[1].path(), "est/vision/vo");
  EXPECT_EQ(c.commands[2].path(), "other/vo");
  EXPECT_EQ(c.groups, (std::vector<std::string>{"est", "est/vision", "other"}));
  using V = std::vector<size_t>;
  EXPECT_EQ(c.Resolve(TargetKind::kGroup, "est"), (V{0, 1}));
  EXPECT_EQ(c.Resolve(TargetKind::kGroup, "est/vision"), (V{1}));
  EXPECT_EQ(c.Resolve(TargetKind::kGroup, "es"), V{});  // a prefix is not a group
  EXPECT_EQ(c.Resolve(TargetKind::kCmd, "slam"), (V{0}));
  EXPECT_EQ(c.Resolve(TargetKind::kCmd, "other/vo"), (V{2}));
  bool ambiguous = false;
  EXPECT_EQ(c.Resolve(TargetKind::kCmd, "vo", &ambiguous), V{});
  EXPECT_TRUE(ambiguous);
  EXPECT_EQ(c.Resolve(TargetKind::kEverything, ""), (V{0, 1, 2, 3}));
}

TEST(ProcmanConfig, Scripts) {
  const ProcmanConfig c = ParseProcmanConfig(
      "group \"g\" { cmd \"x\" { exec = \"x\"; host = \"h\"; } }\n"
      "script \"s\" {\n"
      "  start cmd \"x\" wait \"running\";\n"
      "  wait ms 1000;\n"
      "  start group \"g\";\n"
      "  stop group \"g\" wait \"stopped\";\n"
      "  restart cmd \"g/x\";\n"
      "  start everything;\n"
      "  wait cmd \"x\" status \"running\";\n"
      "  wait group \"g\" status \"stopped\";\n"
      "  run_script \"t\";\n"
      "}\n"
      "script \"t\" { stop everything wait \"stopped\"; }\n",
      "t.cfg");
  const ScriptConfig* s = c.FindScript("s");
  ASSERT_NE(s, nullptr);
  ASSERT_EQ(s->actions.size(), 9u);
  const auto& a = s->actions;
  EXPECT_EQ(a[0].kind, ActionKind::kStart);
  EXPECT_EQ(a[0].target, TargetKind::kCmd);
  EXPECT_EQ(a[0].ident, "x");
  EXPECT_EQ(a[0].wait_status, "running");
  EXPECT_EQ(a[0].line, 3);
  EXPECT_EQ(a[1].kind, ActionKind::kWaitMs);
  EXPECT_EQ(a[1].wait_ms, 1000);
  EXPECT_EQ(a[2].target, TargetKind::kGroup);
  EXPECT_EQ(a[2].wait_status, "");
  EXPECT_EQ(a[3].kind, ActionKind::kStop);
  EXPECT_EQ(a[3].wait_status, "stopped");
  EXPECT_EQ(a[4].kind, ActionKind::kRestart);
  EXPECT_EQ(a[5].target, TargetKind::kEverything);
  EXPECT_EQ(a[6].kind, ActionKind::kWaitStatus);
  EXPECT_EQ(a[6].wait_status, "running");
  EXPECT_EQ(a[7].target, TargetKind::kGroup);
  EXPECT_EQ(a[8].kind, ActionKind::kRunScript);
  EXPECT_EQ(a[8].ident, "t");
  EXPECT_EQ(c.FindScript("nope"), nullptr);
}

TEST(ProcmanConfig, SyntaxErrorsNameFileLineColumnAndWhatWasExpected) {
  EXPECT_ERROR("cmd \"a\" {\n  exec = \"x\"\n  host = \"h\"; }",
               "t.cfg:3:3: expected ';' after exec");
  EXPECT_ERROR("cmd \"a\" { exec \"x\"; }", "t.cfg:1:16: expected '=' after exec");
  EXPECT_ERROR("cmd \"a\" { exec = x; }", "t.cfg:1:18: expected a \"string\" for exec, found 'x'");
  EXPECT_ERROR("cmd \"a\" { stop_signal = \"15\"; }", "expected an integer for stop_signal");
  EXPECT_ERROR("cmd \"a\" { colour = \"red\"; }", "t.cfg:1:11: expected a cmd attribute");
  EXPECT_ERROR("cmd \"a\" { exec = \"x; }", "t.cfg:1:18: unterminated string");
  EXPECT_ERROR("cmd \"a\" { exec = \"x\"; host = \"h\";",
               "expected a cmd attribute or '}', found the end");
  EXPECT_ERROR("widget \"a\" {}", "t.cfg:1:1: expected 'cmd', 'group' or 'script', found 'widget'");
  EXPECT_ERROR("cmd \"a\" { exec = \"x\"; host = \"h\"; } @", "t.cfg:1:37: invalid character '@'");
  EXPECT_ERROR("group { }", "expected a group name");
  EXPECT_ERROR("group \"g\" { script \"s\" {} }", "expected 'cmd', 'group' or '}' in group \"g\"");
  EXPECT_ERROR("cmd \"a/b\" { }", "'/' is not allowed in a cmd name");
  EXPECT_ERROR("group \"a/b\" { }", "'/' is not allowed in a group name");
  EXPECT_ERROR("script \"s\" { launch cmd \"x\"; }", "t.cfg:1:14: expected a script action");
  EXPECT_ERROR("script \"s\" { start cmd \"x\" now; }", "expected ';' or 'wait'");
  EXPECT_ERROR("script \"s\" { start thing \"x\"; }", "expected 'cmd', 'group' or 'everything'");
  EXPECT_ERROR("script \"s\" { start cmd \"x\" wait \"done\"; }",
               "expected \"running\" or \"stopped\", found string \"done\"");
  EXPECT_ERROR("script \"s\" { wait ms soon; }", "expected a number of milliseconds");
  EXPECT_ERROR("script \"s\" { wait cmd \"x\" \"running\"; }", "expected 'status'");
  EXPECT_ERROR("script \"s\" { run_script; }", "expected the script's name");
}

TEST(ProcmanConfig, ValueErrors) {
  EXPECT_ERROR("cmd \"a\" { exec = \"x\"; host = \"h\"; auto_respawn = \"yes\"; }",
               "t.cfg:1:50: expected auto_respawn = \"true\" or \"false\"");
  EXPECT_ERROR("cmd \"a\" { exec = \"x\"; host = \"h\"; stop_signal = 0; }", "signal number 1..64");
  EXPECT_ERROR("cmd \"a\" { exec = \"x\"; host = \"h\"; stop_time_allowed = 0; }",
               "stop_time_allowed >= 1");
  EXPECT_ERROR("cmd \"a\" { host = \"h\"; }", "t.cfg:1: cmd \"a\" has no exec");
  EXPECT_ERROR("cmd \"a\" { exec = \"x\"; }", "has no host");
  EXPECT_ERROR("cmd \"a\" { exec = \"x\"; host = \"h\"; deputy = \"i\"; }",
               "attribute given twice");
  EXPECT_ERROR(
      "cmd \"a\" { exec = \"x\"; host = \"h\"; }\n\ncmd \"a\" { exec = \"y\"; host = \"h\"; }",
      "t.cfg:3: cmd \"a\" is defined twice");
}

TEST(ProcmanConfig, ScriptReferenceErrors) {
  const std::string cmds =
      "group \"g\" { cmd \"x\" { exec = \"x\"; host = \"h\"; } }\n"
      "group \"k\" { cmd \"x\" { exec = \"x\"; host = \"h\"; } }\n";
  EXPECT_ERROR(cmds + "script \"s\" {\n start cmd \"nope\"; }",
               "t.cfg:4: script \"s\": cmd \"nope\" is not defined");
  EXPECT_ERROR(cmds + "script \"s\" { stop group \"nope\"; }", "group \"nope\" is not defined");
  EXPECT_ERROR(cmds + "script \"s\" { start cmd \"x\"; }", "names several commands");
  EXPECT_ERROR(cmds + "script \"s\" { run_script \"t\"; }", "run_script \"t\": no such script");
  EXPECT_ERROR(cmds + "script \"s\" { run_script \"t\"; }\nscript \"t\" { run_script \"s\"; }",
               "run_script loop: s -> t -> s");
  EXPECT_ERROR("script \"s\" { }\nscript \"s\" { }", "t.cfg:2: script \"s\" is defined twice");
}

TEST(ProcmanConfig, MissingFileIsAClearError) {
  try {
    LoadProcmanConfig("/nonexistent/x.cfg");
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("cannot read procman config '/nonexistent/x.cfg'"),
              std::string::npos);
  }
}

}  // namespace
}  // namespace fl::procman

namespace fl::procman {
namespace {

// The shipped configs parse, and every exec splits with the variables ./fusionloc gives.
TEST(ProcmanConfig, ShippedConfigsParseAndSplit) {
  const std::map<std::string, std::string> vars = {
      {"BIN", "/b"},
      {"CONFIG", "/c"},
      {"RUN_DIR", "/r"},
      {"WORLD", "paper"},
      {"RATE", "1"},
      {"ROBOT", "sim"},
      {"DURATION", "-1"},
      {"LOG", "/l.lcmlog"},
      {"LCM_URL", "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=16777216"}};
  for (const char* name : {"sim", "robot", "replay"}) {
    const ProcmanConfig c =
        LoadProcmanConfig(std::string(FL_SOURCE_DIR) + "/config/procman/" + name + ".cfg");
    EXPECT_GE(c.commands.size(), 5u) << name;
    for (const CommandConfig& cmd : c.commands) {
      std::vector<std::string> words;
      std::string error;
      EXPECT_TRUE(SplitShellWords(cmd.exec, vars, &words, &error))
          << name << " " << cmd.name << ": " << error;
    }
  }
  const ProcmanConfig sim =
      LoadProcmanConfig(std::string(FL_SOURCE_DIR) + "/config/procman/sim.cfg");
  ASSERT_NE(sim.FindScript("demo"), nullptr);
  std::set<std::string> hosts;
  for (const CommandConfig& cmd : sim.commands) hosts.insert(cmd.host);
  EXPECT_EQ(hosts.size(), 1u);  // one computer: --lone-ranger names its deputy after it
  const ProcmanConfig robot =
      LoadProcmanConfig(std::string(FL_SOURCE_DIR) + "/config/procman/robot.cfg");
  for (const CommandConfig& cmd : robot.commands) {
    EXPECT_EQ(cmd.host, cmd.group == "drivers" ? "sensors" : "compute") << cmd.path();
  }
  const ProcmanConfig replay =
      LoadProcmanConfig(std::string(FL_SOURCE_DIR) + "/config/procman/replay.cfg");
  std::vector<std::string> words;
  std::string error;
  ASSERT_TRUE(SplitShellWords(replay.commands.back().exec, vars, &words, &error));
  EXPECT_EQ(words[2],
            "--regexp=^(LASER|ODOMETRY|STEREO|STEREO_CALIBRATION|LASER_TO_BASE|CAMERA_TO_BASE|"
            "GROUND_TRUTH)$");
}

}  // namespace
}  // namespace fl::procman
