// Bounds for the C++ decoders that lcm-gen writes (included by every generated header after
// lcmtypes/patch_decode.cmake has patched it).
//
// LCM 1.3.1's generated _decodeNoHash() resizes an array to the count read from the message
// *before* it checks that the buffer holds that many elements, and its string decoders accept
// a length of 0 or below. So a 20-byte message claiming 2^31-1 ranges makes the decoder
// allocate 8 GB, a negative count throws std::length_error, and a string length of 0 reads
// SIZE_MAX bytes. The patch puts CountFits() before every resize and rejects string lengths
// below 1: a message whose counts cannot fit in the bytes that are left is refused (decode
// returns -1) before anything of that size is allocated. A string with a NUL inside is refused
// too: the generated encoder writes strlen() bytes but getEncodedSize() counts size(), so
// such a string, decoded and published again, would give a message with stale bytes.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>
#include <vector>

namespace fl_lcm_guard {

// The fewest bytes one element of T takes on the wire: its size for numbers, 4 + 1 for a
// string (length and terminating NUL), and (conservatively) 1 for a message or a row.
template <class T>
constexpr int64_t MinEncodedBytes() {
  if constexpr (std::is_arithmetic_v<T>) {
    return static_cast<int64_t>(sizeof(T));
  } else if constexpr (std::is_same_v<T, std::string>) {
    return 5;
  } else {
    return 1;
  }
}

// True if `count` elements of the vector type Vec can be in `remaining` bytes.
template <class Vec>
inline bool CountFits(int64_t count, int remaining) {
  using T = typename std::decay_t<Vec>::value_type;
  return count >= 0 && remaining >= 0 && count * MinEncodedBytes<T>() <= remaining;
}

// True if the `length` bytes at buf + offset hold no NUL (a string's characters).
inline bool NoNul(const void* buf, int offset, int length) {
  return length <= 0 ||
         std::memchr(static_cast<const char*>(buf) + offset, 0, static_cast<size_t>(length)) ==
             nullptr;
}

}  // namespace fl_lcm_guard
