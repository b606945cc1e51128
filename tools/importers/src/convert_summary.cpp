#include "fusionloc/importers/convert_summary.hpp"

#include <sstream>

namespace fl::importers {

std::string ConvertSummary::ToString() const {
  std::ostringstream ss;
  ss << "wrote " << output << " from " << input << ": " << total_messages << " messages";
  if (total_messages > 0) {
    ss << " over " << UtimeToSeconds(last_utime - first_utime) << " s";
  }
  ss << "\n";
  for (const auto& [channel, count] : messages) ss << "  " << channel << ": " << count << "\n";
  for (const auto& n : notes) ss << "  note: " << n << "\n";
  for (const auto& w : warnings) ss << "  warning: " << w << "\n";
  return ss.str();
}

}  // namespace fl::importers
