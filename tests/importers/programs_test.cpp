// The three programs end to end: exit status, messages on stderr, no output on failure.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>

#include "importer_fixtures.hpp"
#include "test_paths.hpp"

namespace {

namespace fs = std::filesystem;
using fl::test::TempDir;

struct Result {
  int status = -1;
  std::string out, err;
};

Result RunProgram(const TempDir& dir, const std::string& args) {
  const std::string out = dir.file("stdout.txt"), err = dir.file("stderr.txt");
  const std::string cmd = "cd '" + dir.path() + "' && " + fl::test::BinDir() + "/" + args + " > '" +
                          out + "' 2> '" + err + "'";
  const int raw = std::system(cmd.c_str());
  Result r;
  r.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
  r.out = fl::test::ReadFileBytes(out);
  r.err = fl::test::ReadFileBytes(err);
  return r;
}

TEST(ImporterProgramsTest, CarmenUsageHelpAndConfig) {
  TempDir dir;
  EXPECT_EQ(RunProgram(dir, "fl-carmen2lcm --help").status, 0);
  const Result none = RunProgram(dir, "fl-carmen2lcm");
  EXPECT_EQ(none.status, 2);
  EXPECT_NE(none.err.find("missing IN"), std::string::npos) << none.err;
  EXPECT_EQ(RunProgram(dir, "fl-carmen2lcm x.log --noisy-odometry maybe").status, 2);
  const Result cfg = RunProgram(dir, "fl-carmen2lcm --print-config");
  ASSERT_EQ(cfg.status, 0);
  EXPECT_NE(cfg.out.find("noisy_odometry: auto"), std::string::npos) << cfg.out;
  // The printed config reads back, and a bad one is rejected with the key named.
  fl::test::WriteText(dir.file("c.yaml"), cfg.out);
  EXPECT_EQ(RunProgram(dir, "fl-carmen2lcm --config c.yaml --print-config").status, 0);
  fl::test::WriteText(dir.file("bad.yaml"), "noise:\n  a9: 1\n");
  const Result bad = RunProgram(dir, "fl-carmen2lcm --config bad.yaml in.log");
  EXPECT_EQ(bad.status, 2);
  EXPECT_NE(bad.err.find("a9"), std::string::npos) << bad.err;
}

TEST(ImporterProgramsTest, CarmenConvertsAndFailsCleanly) {
  TempDir dir;
  fl::test::WriteText(dir.file("small-corrected.log"), fl::test::CarmenArcLog(20));
  const Result ok = RunProgram(dir, "fl-carmen2lcm small-corrected.log --seed 5");
  ASSERT_EQ(ok.status, 0) << ok.err;
  EXPECT_TRUE(fs::exists(dir.file("small-corrected.lcmlog")));  // default output name
  EXPECT_NE(ok.out.find("GROUND_TRUTH: 20"), std::string::npos) << ok.out;

  std::string text = fl::test::CarmenArcLog(3);
  // Cut short at the end (the log was cut while written): dropped with a warning naming it.
  fl::test::WriteText(dir.file("cut-end.log"), text + "FLASER 3 1 2\n");
  const Result end = RunProgram(dir, "fl-carmen2lcm cut-end.log end.lcmlog");
  EXPECT_EQ(end.status, 0) << end.err;
  EXPECT_NE(end.err.find("cut-end.log:6: truncated FLASER line"), std::string::npos) << end.err;
  EXPECT_TRUE(fs::exists(dir.file("end.lcmlog")));
  // Cut short in the middle: an error.
  text += "FLASER 3 1 2\n" + fl::test::CarmenFlaser(3, 1.0, 0, 0, 0, 5.0);
  fl::test::WriteText(dir.file("cut.log"), text);
  const Result bad = RunProgram(dir, "fl-carmen2lcm cut.log out.lcmlog");
  EXPECT_EQ(bad.status, 1);
  EXPECT_NE(bad.err.find("fl-carmen2lcm: cut.log:6: truncated FLASER line"), std::string::npos)
      << bad.err;
  EXPECT_FALSE(fs::exists(dir.file("out.lcmlog")));
  EXPECT_FALSE(fs::exists(dir.file("out.lcmlog.partial")));
}

TEST(ImporterProgramsTest, KittiAndLogInfo) {
  TempDir dir;
  fl::test::KittiRawFixture().Write(dir.file("drive"));
  const Result ok = RunProgram(dir, "fl-kitti2lcm drive");
  ASSERT_EQ(ok.status, 0) << ok.err;
  ASSERT_TRUE(fs::exists(dir.file("drive.lcmlog")));
  fs::create_directories(dir.file("empty"));
  const Result bad = RunProgram(dir, "fl-kitti2lcm empty e.lcmlog");
  EXPECT_EQ(bad.status, 1);
  EXPECT_NE(bad.err.find("not a KITTI folder"), std::string::npos) << bad.err;
  EXPECT_FALSE(fs::exists(dir.file("e.lcmlog")));

  const Result info = RunProgram(dir, "fl-log-info drive.lcmlog --json --strict");
  ASSERT_EQ(info.status, 0) << info.err;
  EXPECT_NE(info.out.find("\"channel\": \"STEREO\", \"type\": \"bot_core.images_t\""),
            std::string::npos)
      << info.out;
  // A truncated copy: listed as a problem; --strict turns it into exit status 3.
  const std::string bytes = fl::test::ReadFileBytes(dir.file("drive.lcmlog"));
  fl::test::WriteText(dir.file("cut.lcmlog"), bytes.substr(0, bytes.size() - 5));
  const Result cut = RunProgram(dir, "fl-log-info cut.lcmlog --strict");
  EXPECT_EQ(cut.status, 3);
  EXPECT_NE(cut.out.find("truncated"), std::string::npos) << cut.out;
  EXPECT_EQ(RunProgram(dir, "fl-log-info cut.lcmlog").status, 0);
  EXPECT_EQ(RunProgram(dir, "fl-log-info missing.lcmlog").status, 1);
  fl::test::WriteText(dir.file("text.log"), "FLASER 1 2 3\n");
  const Result text = RunProgram(dir, "fl-log-info text.log");
  EXPECT_EQ(text.status, 1);
  EXPECT_NE(text.err.find("not an LCM log"), std::string::npos) << text.err;
  EXPECT_EQ(RunProgram(dir, "fl-log-info").status, 2);
}

}  // namespace
