// JSON text for files and messages the project writes (bench results, fl-log-info --json, the
// viewer's WebSocket frames). Writing only: nothing in the project parses JSON.
#pragma once

#include <string>

namespace fl {

// The characters of `s` escaped for a JSON string ("a\"b" -> a\"b), without the quotes.
std::string JsonEscape(const std::string& s);
// `s` as a quoted JSON string.
inline std::string JsonString(const std::string& s) { return "\"" + JsonEscape(s) + "\""; }
// `v` with `precision` significant digits; null for NaN and infinities (JSON has no spelling
// for them).
std::string JsonNumber(double v, int precision = 10);

}  // namespace fl
