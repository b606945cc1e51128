// The heap of this process, as the C library's allocator sees it, and returning its free
// pages to the system.
//
// A long-running process whose heap goes up and down (a solver's workspace, a journal
// snapshot, a map save) keeps the pages of its largest moments: glibc returns freed memory
// to the system only from the top of each heap, so a resident size (RSS) sampled once a
// minute creeps up in steps although the memory in use is flat (the fusion in a 30-minute
// soak: RSS +2 MB in steps while heaptrack showed the heap in use steady at 13.4 MB). The
// shared process loop (SpinNodes) therefore returns the free pages once a minute and reports
// the heap in use, so that a growing RSS and a growing heap can be told apart.
//
// Under a sanitizer, or a C library other than glibc, the allocator is not glibc's: Read()
// reports supported = false and ReturnFreeHeapToSystem() does nothing.
#pragma once

namespace fl {

struct HeapUsage {
  bool supported = false;
  double in_use_mb = 0.0;  // [MB] allocated and not freed (small blocks and mmapped ones)
  double free_mb = 0.0;    // [MB] freed but held by the allocator (resident or not)
};

HeapUsage ReadHeapUsage();
// Returns the allocator's free pages to the system (glibc malloc_trim(0): also those in the
// middle of a heap, by madvise); true if any were returned.
bool ReturnFreeHeapToSystem();

}  // namespace fl
