// Paths for tests: the source tree, the build tree and the shared real data.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <string>

namespace fl::test {

inline std::string SourceDir() { return FL_SOURCE_DIR; }
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

// Skips the test (with the reason) when shared data is not present.
#define FL_REQUIRE_SHARED_FILE(path)                                                       \
  do {                                                                                     \
    if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared data missing: " << (path); \
  } while (0)

}  // namespace fl::test
