// A headless summary of any LCM log: channels, message types (identified by the 8-byte
// fingerprint every lcm-gen message starts with, matched against all of the project's types),
// counts, rates, time span, bytes, messages that do not decode as their type, time going
// backwards, and the reader's report of truncated or corrupt bytes.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "fusionloc/common/time.hpp"

namespace fl::importers {

// One lcm-gen type of the project (generated at build time from lcmtypes/*/*.lcm).
struct LcmTypeInfo {
  std::string name;         // "bot_core.planar_lidar_t"
  int64_t fingerprint = 0;  // T::getHash()
  // True if `size` bytes decode completely as this type.
  std::function<bool(const void* data, int size)> decodes;
};

// All of the project's message types.
const std::vector<LcmTypeInfo>& KnownLcmTypes();
// The type with this fingerprint, or nullptr.
const LcmTypeInfo* FindLcmType(int64_t fingerprint);
// "bot_core.pose_t", or "unknown (0x0123456789abcdef)".
std::string LcmTypeName(int64_t fingerprint);

struct ChannelInfo {
  std::string channel;
  int64_t fingerprint = 0;       // of the channel's most common type
  std::string type;              // its name (see LcmTypeName); "too short" if < 8 bytes
  int64_t count = 0;             // [messages]
  int64_t bytes = 0;             // [bytes] payload total
  Utime first_utime = 0;         // [us] log time of the first message
  Utime last_utime = 0;          // [us] log time of the last message
  int64_t decode_errors = 0;     // of a known type, but the bytes do not decode as it
  int64_t other_type_count = 0;  // messages with a different fingerprint than `type`
  int64_t time_backwards = 0;    // log time earlier than the channel's previous message
  double rate_hz() const;        // (count - 1) / span, 0 if span is 0
};

struct LogInfo {
  std::string path;
  int64_t file_bytes = 0;
  int64_t events = 0;
  Utime first_utime = 0;
  Utime last_utime = 0;
  int64_t time_backwards = 0;         // events earlier than the event before (any channel)
  int64_t corrupt_bytes_skipped = 0;  // reader: bytes skipped to resynchronise
  bool truncated = false;             // reader: the last event is incomplete
  std::string reader_problems;        // reader's own account ("" if none)
  std::vector<ChannelInfo> channels;  // sorted by channel name

  bool has_problems() const;
  std::string ToText() const;  // aligned table for terminals
  std::string ToJson() const;  // one JSON object
};

// Reads the whole log. Throws std::runtime_error if it cannot be opened.
LogInfo InspectLcmLog(const std::string& path);

}  // namespace fl::importers
