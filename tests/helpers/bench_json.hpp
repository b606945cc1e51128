// Reading the JSON that the bench programs write (fl::bench::Report): one run per line,
// {"name": "...", ..., "metrics": {"key": value, ...}}.
#pragma once

#include <cmath>
#include <regex>
#include <string>

namespace fl::test {

// The value of `key` in the metrics of the run named `run` in a bench JSON (NaN if absent).
inline double BenchMetric(const std::string& json, const std::string& run,
                          const std::string& key) {
  const size_t at = json.find("{\"name\": \"" + run + "\"");
  if (at == std::string::npos) return std::nan("");
  const size_t end = json.find("\n", at);
  const std::string row = json.substr(at, end - at);
  std::smatch m;
  if (!std::regex_search(row, m, std::regex("\"" + key + "\": ([-0-9.e+]+)"))) return std::nan("");
  return std::stod(m[1]);
}

}  // namespace fl::test
