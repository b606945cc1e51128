#include "fusionloc/common/process_memory.hpp"

#include <gtest/gtest.h>

#include <memory>
#include <vector>

#include "process_fixtures.hpp"

namespace fl {
namespace {

using test::CurrentRssMb;

// 40 MB in 160k small blocks (each below the mmap threshold: on the heap), all written, then
// all but the last freed: the last one pins the top of the heap, so the allocator cannot give
// the freed pages back by shrinking it. What stays resident is what Return... must release.
TEST(ProcessMemory, TheHeapInUseIsReadAndFreedPagesAreReturnedToTheSystem) {
  if (!ReadHeapUsage().supported) GTEST_SKIP() << "not glibc's allocator (a sanitizer build)";
  ReturnFreeHeapToSystem();
  const HeapUsage before = ReadHeapUsage();
  std::vector<std::unique_ptr<char[]>> blocks;
  for (int k = 0; k < 160000; ++k) {
    blocks.emplace_back(new char[256]);
    for (int b = 0; b < 256; b += 64) blocks.back()[b] = static_cast<char>(k);
  }
  const HeapUsage full = ReadHeapUsage();
  EXPECT_GT(full.in_use_mb - before.in_use_mb, 40.0);
  const double resident_full = CurrentRssMb();
  for (size_t k = 0; k + 1 < blocks.size(); ++k) blocks[k].reset();
  const HeapUsage freed = ReadHeapUsage();
  EXPECT_LT(freed.in_use_mb - before.in_use_mb, 5.0);
  EXPECT_GT(freed.free_mb, 35.0);
  const double resident_freed = CurrentRssMb();
  EXPECT_GT(resident_freed, resident_full - 10.0) << "glibc returned the pages by itself";
  EXPECT_TRUE(ReturnFreeHeapToSystem());
  EXPECT_LT(CurrentRssMb(), resident_freed - 30.0);
}

}  // namespace
}  // namespace fl
