// What an importer wrote: counts per channel, time span and the warnings a user must see.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "fusionloc/common/time.hpp"

namespace fl::importers {

struct ConvertSummary {
  std::string input;                        // file or folder read
  std::string output;                       // LCM log written (complete: renamed into place)
  std::map<std::string, int64_t> messages;  // [count] per channel
  int64_t total_messages = 0;               // [count] events in the output log
  Utime first_utime = 0;                    // [us] first event time
  Utime last_utime = 0;                     // [us] last event time
  // Problems that did not stop the conversion but change what the output means (e.g. time
  // going backwards, skipped message types). Each is one complete sentence.
  std::vector<std::string> warnings;
  // What the importer did that a user may want to know (skipped message types, where the
  // ground truth or time stamps came from). One sentence each.
  std::vector<std::string> notes;
  // Counts one event written on `channel` at `utime` (keeps the counts and the span).
  void Count(const std::string& channel, Utime utime) {
    ++messages[channel];
    if (total_messages == 0) first_utime = utime;
    last_utime = utime;
    ++total_messages;
  }
  // Multi-line human-readable account (counts, span, warnings), for programs to print.
  std::string ToString() const;
};

}  // namespace fl::importers
