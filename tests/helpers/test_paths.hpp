// Paths for tests: the source tree, the build tree and the shared real data.
#pragma once

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace fl::test {

inline std::string SourceDir() { return FL_SOURCE_DIR; }

// A text file's whole content ("" if it cannot be read).
inline std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}
inline std::string BinaryDir() { return FL_BINARY_DIR; }
inline std::string BinDir() { return std::string(FL_BINARY_DIR) + "/bin"; }
inline std::string SharedDataDir() { return FL_SHARED_DATA_DIR; }

// A fresh temporary folder for one test, removed at destruction.
class TempDir {
 public:
  TempDir() {
    std::string tmpl = (std::filesystem::temp_directory_path() / "fl_test_XXXXXX").string();
    path_ = mkdtemp(tmpl.data());
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  std::string path() const { return path_; }
  std::string file(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

// argc/argv for a parser under test: Args a({"fl-x", "--n", "7"}); cli.Parse(a.argc(), a.argv()).
struct Args {
  std::vector<std::string> storage;
  std::vector<char*> ptrs;
  explicit Args(std::vector<std::string> a) : storage(std::move(a)) {
    for (auto& s : storage) ptrs.push_back(s.data());
  }
  int argc() { return static_cast<int>(ptrs.size()); }
  char** argv() { return ptrs.data(); }
};

// What a shell command did: its exit status (-1 if killed by a signal), stdout and stderr.
struct CommandResult {
  int status = -1;
  std::string out, err;
};

// Runs `command` with sh in `dir`, capturing stdout and stderr.
inline CommandResult RunCommand(const std::string& command, const TempDir& dir) {
  const std::string out = dir.file("cmd_stdout.txt"), err = dir.file("cmd_stderr.txt");
  const std::string cmd =
      "cd '" + dir.path() + "' && " + command + " > '" + out + "' 2> '" + err + "' < /dev/null";
  const int raw = std::system(cmd.c_str());
  CommandResult r;
  r.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
  auto slurp = [](const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
  };
  r.out = slurp(out);
  r.err = slurp(err);
  return r;
}

// Skips the test (with the reason) when shared data is not present.
#define FL_REQUIRE_SHARED_FILE(path)                                                       \
  do {                                                                                     \
    if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared data missing: " << (path); \
  } while (0)

}  // namespace fl::test
