#include "fusionloc/common/number_format.hpp"

#include <charconv>
#include <cmath>

namespace fl {

namespace {

template <class T>
std::string Shortest(T v) {
  if (std::isnan(v)) return ".nan";
  if (std::isinf(v)) return v > 0 ? ".inf" : "-.inf";
  char buf[64];
  const std::to_chars_result r = std::to_chars(buf, buf + sizeof(buf), v);
  std::string s(buf, r.ptr);
  if (s.find_first_of(".eE") == std::string::npos) s += ".0";
  return s;
}

}  // namespace

std::string FormatDouble(double v) { return Shortest(v); }
std::string FormatFloat(float v) { return Shortest(v); }

}  // namespace fl
