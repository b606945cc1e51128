#include "fusionloc/common/process_memory.hpp"

#include <cstdlib>  // defines __GLIBC__ on glibc

#if defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) || \
    __has_feature(memory_sanitizer)
#define FL_SANITIZED_ALLOCATOR 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define FL_SANITIZED_ALLOCATOR 1
#endif

#if defined(__GLIBC__) && !defined(FL_SANITIZED_ALLOCATOR)
#include <malloc.h>
#define FL_GLIBC_ALLOCATOR 1
#endif

namespace fl {

HeapUsage ReadHeapUsage() {
  HeapUsage u;
#ifdef FL_GLIBC_ALLOCATOR
  const struct mallinfo2 m = mallinfo2();  // every arena
  u.supported = true;
  u.in_use_mb = static_cast<double>(m.uordblks + m.hblkhd) / 1e6;
  u.free_mb = static_cast<double>(m.fordblks) / 1e6;
#endif
  return u;
}

bool ReturnFreeHeapToSystem() {
#ifdef FL_GLIBC_ALLOCATOR
  return malloc_trim(0) != 0;
#else
  return false;
#endif
}

}  // namespace fl
