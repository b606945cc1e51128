// Text parsing helpers shared by the trajectory and relations readers (internal).
#pragma once

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <string>
#include <vector>

#include "fusionloc/common/time.hpp"
#include "fusionloc/eval/trajectory.hpp"

namespace fl::eval::internal {

inline std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

inline std::string Trim(const std::string& s) {
  size_t b = 0, e = s.size();
  while (b < e && std::isspace(static_cast<unsigned char>(s[b]))) ++b;
  while (e > b && std::isspace(static_cast<unsigned char>(s[e - 1]))) --e;
  return s.substr(b, e - b);
}

inline std::vector<std::string> SplitTokens(const std::string& line) {
  std::vector<std::string> tokens;
  std::string cur;
  for (char c : line) {
    if (std::isspace(static_cast<unsigned char>(c)) || c == ',') {
      if (!cur.empty()) tokens.push_back(cur);
      cur.clear();
    } else {
      cur.push_back(c);
    }
  }
  if (!cur.empty()) tokens.push_back(cur);
  return tokens;
}

inline std::string Where(const std::string& path, int line_no) {
  return path + ":" + std::to_string(line_no);
}

inline double ParseNumber(const std::string& token, const std::string& where) {
  errno = 0;
  char* end = nullptr;
  const double v = std::strtod(token.c_str(), &end);
  if (end == token.c_str() || *end != '\0' || errno == ERANGE) {
    throw EvalError(where + ": '" + token + "' is not a number");
  }
  if (!std::isfinite(v)) {
    throw EvalError(where + ": value '" + token +
                    "' is NaN or infinite; remove or fix the pose (an estimator that lost track "
                    "must not write it)");
  }
  return v;
}

// Seconds (decimal text) to microseconds, exact for plain decimal numbers.
inline Utime ParseSecondsUtime(const std::string& token, const std::string& where) {
  size_t i = 0;
  bool negative = false;
  if (i < token.size() && (token[i] == '-' || token[i] == '+')) negative = token[i++] == '-';
  const size_t int_begin = i;
  while (i < token.size() && std::isdigit(static_cast<unsigned char>(token[i]))) ++i;
  const size_t int_end = i;
  size_t frac_begin = i, frac_end = i;
  if (i < token.size() && token[i] == '.') {
    frac_begin = ++i;
    while (i < token.size() && std::isdigit(static_cast<unsigned char>(token[i]))) ++i;
    frac_end = i;
  }
  const bool plain = i == token.size() && (int_end > int_begin || frac_end > frac_begin) &&
                     int_end - int_begin <= 12;
  if (!plain) {
    const double s = ParseNumber(token, where);  // exponent notation etc.
    if (std::fabs(s) > 9.0e12) throw EvalError(where + ": time '" + token + "' s is out of range");
    return SecondsToUtime(s);
  }
  Utime whole = 0;
  for (size_t k = int_begin; k < int_end; ++k) whole = whole * 10 + (token[k] - '0');
  Utime micros = 0;
  int digits = 0;
  for (size_t k = frac_begin; k < frac_end && digits < 6; ++k, ++digits) {
    micros = micros * 10 + (token[k] - '0');
  }
  for (; digits < 6; ++digits) micros *= 10;
  // Round on the 7th fractional digit.
  if (frac_end - frac_begin > 6 && token[frac_begin + 6] >= '5') ++micros;
  const Utime t = whole * kUtimePerSecond + micros;
  return negative ? -t : t;
}

}  // namespace fl::eval::internal
