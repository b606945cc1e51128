#include "fusionloc/common/process_memory.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <fstream>
#include <memory>
#include <vector>

namespace fl {
namespace {

// Resident pages of this process [MB] (/proc/self/statm, second field).
double ResidentMb() {
  std::ifstream statm("/proc/self/statm");
  long size = 0, resident = 0;
  statm >> size >> resident;
  return static_cast<double>(resident) * static_cast<double>(sysconf(_SC_PAGESIZE)) / 1e6;
}

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
  const double resident_full = ResidentMb();
  for (size_t k = 0; k + 1 < blocks.size(); ++k) blocks[k].reset();
  const HeapUsage freed = ReadHeapUsage();
  EXPECT_LT(freed.in_use_mb - before.in_use_mb, 5.0);
  EXPECT_GT(freed.free_mb, 35.0);
  const double resident_freed = ResidentMb();
  EXPECT_GT(resident_freed, resident_full - 10.0) << "glibc returned the pages by itself";
  EXPECT_TRUE(ReturnFreeHeapToSystem());
  EXPECT_LT(ResidentMb(), resident_freed - 30.0);
}

}  // namespace
}  // namespace fl
