// Every fuzz target's committed seeds (tests/fuzz/corpus/NAME/) and kept crashing inputs
// (tests/fuzz/regressions/NAME/) through the same entry function as the fuzzer, in the normal
// (gcc) suite: an input that crashed before its fix crashes or aborts this test again.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

#include "fuzz_entry.hpp"
#include "test_paths.hpp"

#define FL_FUZZ_TARGET(name) int Fuzz_##name(const uint8_t* data, size_t size);
#include "fl_fuzz_targets.inc"
#undef FL_FUZZ_TARGET

namespace {

namespace fs = std::filesystem;
using Entry = int (*)(const uint8_t*, size_t);

struct Target {
  std::string name;
  Entry entry;
};

const std::vector<Target>& Targets() {
#define FL_FUZZ_TARGET(name) {#name, &Fuzz_##name},
  static const std::vector<Target> targets = {
#include "fl_fuzz_targets.inc"
  };
#undef FL_FUZZ_TARGET
  return targets;
}

std::vector<fs::path> Files(const fs::path& dir) {
  std::vector<fs::path> out;
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return out;
  for (const auto& e : fs::directory_iterator(dir)) {
    if (e.is_regular_file()) out.push_back(e.path());
  }
  std::sort(out.begin(), out.end());
  return out;
}

int RunInput(const Target& t, const fs::path& file) {
  const std::string bytes = fl::test::ReadFile(file.string());
  return t.entry(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
}

const fs::path kFuzzDir = fs::path(FL_SOURCE_DIR) / "tests/fuzz";

class FuzzInputs : public ::testing::TestWithParam<Target> {};

TEST_P(FuzzInputs, EverySeedRuns) {
  const auto files = Files(kFuzzDir / "corpus" / GetParam().name);
  ASSERT_FALSE(files.empty()) << "no seeds in tests/fuzz/corpus/" << GetParam().name
                              << " (tests/fuzz/make_corpus.py writes them)";
  for (const auto& f : files) EXPECT_EQ(RunInput(GetParam(), f), 0) << f;
}

TEST_P(FuzzInputs, EveryKeptCrashRunsClean) {
  for (const auto& f : Files(kFuzzDir / "regressions" / GetParam().name)) {
    SCOPED_TRACE(f.string());
    EXPECT_EQ(RunInput(GetParam(), f), 0) << f;
  }
}

INSTANTIATE_TEST_SUITE_P(All, FuzzInputs, ::testing::ValuesIn(Targets()),
                         [](const auto& info) { return info.param.name; });

}  // namespace
