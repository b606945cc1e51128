#include "fusionloc/importers/log_info.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <iomanip>
#include <sstream>
#include <unordered_map>

#include "fusionloc/common/json.hpp"
#include "fusionloc/common/lcm_interface.hpp"

namespace fl::importers {
namespace {

std::string Hex(int64_t v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "0x%016llx", static_cast<unsigned long long>(v));
  return buf;
}

std::string Bytes(int64_t b) {
  std::ostringstream ss;
  ss << std::fixed << std::setprecision(1);
  if (b >= (1 << 20)) {
    ss << b / 1048576.0 << " MiB";
  } else if (b >= 1024) {
    ss << b / 1024.0 << " KiB";
  } else {
    ss << b << " B";
  }
  return ss.str();
}

// "2011-09-26 13:02:25.967791 UTC" for plausible Unix times, else "12.345678 s".
std::string TimeText(Utime t) {
  if (t > 315532800LL * 1000000LL) {  // after 1980: a Unix time
    const time_t s = static_cast<time_t>(t / 1000000);
    std::tm tm{};
    gmtime_r(&s, &tm);
    char buf[64];
    std::strftime(buf, sizeof(buf), "%Y-%m-%d %H:%M:%S", &tm);
    char out[96];
    std::snprintf(out, sizeof(out), "%s.%06lld UTC", buf, static_cast<long long>(t % 1000000));
    return out;
  }
  char out[64];
  std::snprintf(out, sizeof(out), "%.6f s", UtimeToSeconds(t));
  return out;
}

struct ChannelAccumulator {
  ChannelInfo info;
  std::unordered_map<int64_t, int64_t> fingerprint_counts;
  std::unordered_map<int64_t, int64_t> fingerprint_decode_errors;
  bool any = false;
};

}  // namespace

std::string LcmTypeName(int64_t fingerprint) {
  const LcmTypeInfo* t = FindLcmType(fingerprint);
  return t ? t->name : "unknown (" + Hex(fingerprint) + ")";
}

const LcmTypeInfo* FindLcmType(int64_t fingerprint) {
  for (const auto& t : KnownLcmTypes()) {
    if (t.fingerprint == fingerprint) return &t;
  }
  return nullptr;
}

double ChannelInfo::rate_hz() const {
  const double span = SecondsBetween(first_utime, last_utime);
  return (count > 1 && span > 0) ? (count - 1) / span : 0.0;
}

bool LogInfo::has_problems() const {
  if (corrupt_bytes_skipped > 0 || truncated || time_backwards > 0) return true;
  if (events == 0 && file_bytes > 0) return true;  // not an LCM log
  for (const auto& c : channels) {
    if (c.decode_errors > 0 || c.other_type_count > 0 || c.time_backwards > 0) return true;
  }
  return false;
}

LogInfo InspectLcmLog(const std::string& path) {
  LcmLogReader reader(path);
  LogInfo info;
  info.path = path;
  info.file_bytes = reader.file_size();
  std::map<std::string, ChannelAccumulator> acc;
  LcmLogEvent e;
  Utime prev = 0;
  while (reader.Next(&e)) {
    if (info.events == 0) {
      info.first_utime = e.utime;
    } else if (e.utime < prev) {
      ++info.time_backwards;
    }
    info.first_utime = std::min(info.first_utime, e.utime);
    info.last_utime = std::max(info.last_utime, e.utime);
    prev = e.utime;
    ++info.events;

    ChannelAccumulator& a = acc[e.channel];
    ChannelInfo& c = a.info;
    if (!a.any) {
      c.channel = e.channel;
      c.first_utime = e.utime;
      c.last_utime = e.utime;
      a.any = true;
    } else if (e.utime < c.last_utime) {
      ++c.time_backwards;
    }
    c.last_utime = std::max(c.last_utime, e.utime);
    ++c.count;
    c.bytes += static_cast<int64_t>(e.data.size());
    int64_t fp = 0;
    if (e.data.size() >= 8) {
      uint64_t u = 0;
      for (int i = 0; i < 8; ++i) u = (u << 8) | e.data[static_cast<size_t>(i)];
      fp = static_cast<int64_t>(u);
      const LcmTypeInfo* t = FindLcmType(fp);
      if (t && !t->decodes(e.data.data(), static_cast<int>(e.data.size()))) {
        ++a.fingerprint_decode_errors[fp];
      }
    } else {
      fp = 0;  // too short to hold a fingerprint
    }
    ++a.fingerprint_counts[fp];
  }
  info.corrupt_bytes_skipped = reader.corrupt_bytes_skipped();
  info.truncated = reader.truncated();
  info.reader_problems = reader.ProblemSummary();
  for (auto& [name, a] : acc) {
    ChannelInfo c = a.info;
    // The channel's type: the most common fingerprint (ties: the smaller value, deterministic).
    int64_t best = 0, best_n = -1;
    for (const auto& [fp, n] : a.fingerprint_counts) {
      if (n > best_n || (n == best_n && fp < best)) {
        best = fp;
        best_n = n;
      }
    }
    c.fingerprint = best;
    c.type = best == 0 ? "too short (< 8 bytes)" : LcmTypeName(best);
    c.other_type_count = c.count - best_n;
    for (const auto& [fp, n] : a.fingerprint_decode_errors) c.decode_errors += n;
    info.channels.push_back(c);
  }
  return info;
}

std::string LogInfo::ToText() const {
  std::ostringstream ss;
  ss << "log: " << path << " (" << Bytes(file_bytes) << ", " << events << " events, "
     << channels.size() << " channels)\n";
  if (events == 0) ss << "no events\n";
  if (events > 0) {
    ss << "time: " << TimeText(first_utime) << " .. " << TimeText(last_utime) << " (span "
       << std::fixed << std::setprecision(3) << SecondsBetween(first_utime, last_utime) << " s)\n";
  }
  size_t wc = 7, wt = 4;
  for (const auto& c : channels) {
    wc = std::max(wc, c.channel.size());
    wt = std::max(wt, c.type.size());
  }
  if (!channels.empty()) {
    ss << std::left << std::setw(static_cast<int>(wc)) << "CHANNEL"
       << "  " << std::setw(static_cast<int>(wt)) << "TYPE" << std::right << std::setw(9) << "COUNT"
       << std::setw(10) << "RATE_HZ" << std::setw(12) << "BYTES" << std::setw(11) << "FIRST_S"
       << std::setw(11) << "LAST_S" << std::setw(9) << "DEC_ERR" << std::setw(9) << "BACKWD"
       << "\n";
  }
  for (const auto& c : channels) {
    ss << std::left << std::setw(static_cast<int>(wc)) << c.channel << "  "
       << std::setw(static_cast<int>(wt)) << c.type << std::right << std::setw(9) << c.count
       << std::setw(10) << std::fixed << std::setprecision(2) << c.rate_hz() << std::setw(12)
       << Bytes(c.bytes) << std::setw(11) << std::setprecision(3)
       << SecondsBetween(first_utime, c.first_utime) << std::setw(11)
       << SecondsBetween(first_utime, c.last_utime) << std::setw(9) << c.decode_errors
       << std::setw(9) << c.time_backwards << "\n";
  }
  bool any = false;
  auto problem = [&](const std::string& text) {
    if (!any) ss << "problems:\n";
    any = true;
    ss << "  " << text << "\n";
  };
  if (events == 0 && file_bytes > 0) {
    problem("no LCM event found in " + std::to_string(file_bytes) +
            " bytes: this is not an LCM log (or it is corrupt from the start)");
  }
  if (!reader_problems.empty()) problem(reader_problems);
  if (time_backwards > 0) {
    problem(std::to_string(time_backwards) + " events are earlier than the event before");
  }
  for (const auto& c : channels) {
    if (c.decode_errors > 0) {
      problem(c.channel + ": " + std::to_string(c.decode_errors) +
              " messages carry a known fingerprint but do not decode (truncated or corrupt)");
    }
    if (c.other_type_count > 0) {
      problem(c.channel + ": " + std::to_string(c.other_type_count) +
              " messages are not of the channel's type " + c.type + " (mixed types)");
    }
    if (c.time_backwards > 0) {
      problem(c.channel + ": " + std::to_string(c.time_backwards) +
              " messages are earlier than the channel's previous message");
    }
  }
  if (!any) ss << "problems: none\n";
  return ss.str();
}

std::string LogInfo::ToJson() const {
  std::ostringstream ss;
  ss << std::setprecision(10);
  ss << "{\"path\": " << JsonString(path) << ", \"file_bytes\": " << file_bytes
     << ", \"events\": " << events << ", \"first_utime\": " << first_utime
     << ", \"last_utime\": " << last_utime
     << ", \"span_s\": " << SecondsBetween(first_utime, last_utime)
     << ", \"time_backwards\": " << time_backwards
     << ", \"corrupt_bytes_skipped\": " << corrupt_bytes_skipped
     << ", \"truncated\": " << (truncated ? "true" : "false")
     << ", \"reader_problems\": " << JsonString(reader_problems)
     << ", \"has_problems\": " << (has_problems() ? "true" : "false") << ", \"channels\": [";
  for (size_t i = 0; i < channels.size(); ++i) {
    const ChannelInfo& c = channels[i];
    ss << (i ? ", " : "") << "{\"channel\": " << JsonString(c.channel)
       << ", \"type\": " << JsonString(c.type) << ", \"fingerprint\": \"" << Hex(c.fingerprint)
       << "\", \"count\": " << c.count << ", \"rate_hz\": " << c.rate_hz()
       << ", \"bytes\": " << c.bytes << ", \"first_utime\": " << c.first_utime
       << ", \"last_utime\": " << c.last_utime << ", \"decode_errors\": " << c.decode_errors
       << ", \"other_type_count\": " << c.other_type_count
       << ", \"time_backwards\": " << c.time_backwards << "}";
  }
  ss << "]}\n";
  return ss.str();
}

}  // namespace fl::importers
