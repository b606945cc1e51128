// CARMEN log parser (fl-carmen2lcm's reader): any bytes either parse or throw
// std::runtime_error; a parsed log is consistent.
#include <stdexcept>

#include "../fuzz_entry.hpp"
#include "fusionloc/importers/carmen.hpp"

int Fuzz_carmen(const uint8_t* data, size_t size) {
  fl::fuzz::QuietLogs();
  fl::fuzz::MemFile file(data, size);
  try {
    const fl::importers::CarmenLog log = fl::importers::ReadCarmenLog(file.path());
    FL_FUZZ_CHECK(!log.scans.empty());
    FL_FUZZ_CHECK(log.order.size() == log.scans.size() + log.odom.size());
    for (const auto& e : log.order) {
      FL_FUZZ_CHECK(e.index < (e.is_scan ? log.scans.size() : log.odom.size()));
    }
    for (const auto& s : log.scans) FL_FUZZ_CHECK(!s.ranges.empty());
  } catch (const std::runtime_error&) {
  }
  return 0;
}
