#include "fusionloc/urg/scip2.hpp"

#include <cstdio>

namespace fl::urg::scip2 {
namespace {

constexpr size_t kMaxLineLength = 256;  // longer than any SCIP 2.0 line (II lines are ~80)

bool ParseDecimal(std::string_view s, int* v) {
  if (s.empty()) return false;
  int x = 0;
  for (char c : s) {
    if (c < '0' || c > '9') return false;
    x = x * 10 + (c - '0');
  }
  *v = x;
  return true;
}

std::string Digits(int v, int width) {
  char buf[16];
  std::snprintf(buf, sizeof(buf), "%0*d", width, v);
  return buf;
}

}  // namespace

char Checksum(std::string_view data) {
  unsigned sum = 0;
  for (unsigned char c : data) sum += c;
  return static_cast<char>((sum & 0x3F) + 0x30);
}

std::string Encode(uint32_t value, int chars) {
  std::string out(static_cast<size_t>(chars), '0');
  for (int i = chars - 1; i >= 0; --i) {
    out[static_cast<size_t>(i)] = static_cast<char>((value & 0x3F) + 0x30);
    value >>= 6;
  }
  return out;
}

bool Decode(std::string_view text, uint32_t* value) {
  if (text.empty() || text.size() > 4) return false;
  uint32_t v = 0;
  for (unsigned char c : text) {
    if (c < 0x30 || c > 0x6F) return false;
    v = (v << 6) | static_cast<uint32_t>(c - 0x30);
  }
  *value = v;
  return true;
}

Status VerifyLine(std::string_view line, std::string_view* data) {
  if (line.empty()) return Status::Error("empty line where a line with a checksum was expected");
  const std::string_view d = line.substr(0, line.size() - 1);
  const char expected = Checksum(d);
  if (line.back() != expected) {
    return Status::Error("checksum error in line '" + std::string(line) + "': sum character '" +
                         std::string(1, line.back()) + "', expected '" + std::string(1, expected) +
                         "'");
  }
  *data = d;
  return Status::Ok();
}

void ResponseReader::Feed(std::string_view bytes) {
  for (char c : bytes) {
    if (c == '\n') {
      if (skipping_) {
        skipping_ = false;
        continue;
      }
      if (!line_.empty() && line_.back() == '\r') line_.pop_back();
      if (line_.empty()) {
        if (!current_.lines.empty()) ready_.push_back(std::move(current_));
        current_ = Response();
      } else {
        current_.lines.push_back(std::move(line_));
      }
      line_.clear();
      continue;
    }
    if (skipping_) continue;
    if (line_.size() >= kMaxLineLength) {
      ++overlong_lines_;
      skipping_ = true;
      line_.clear();
      current_ = Response();
      continue;
    }
    line_.push_back(c);
  }
}

bool ResponseReader::Next(Response* out) {
  if (ready_head_ >= ready_.size()) return false;
  *out = std::move(ready_[ready_head_++]);
  if (ready_head_ == ready_.size()) {
    ready_.clear();
    ready_head_ = 0;
  }
  return true;
}

void ResponseReader::Clear() {
  skipping_ = false;
  line_.clear();
  current_ = Response();
  ready_.clear();
  ready_head_ = 0;
}

Status ParseStatus(const Response& r, std::string* status) {
  if (r.lines.size() < 2) {
    return Status::Error("response to '" + (r.lines.empty() ? std::string() : r.echo()) +
                         "' has no status line");
  }
  const std::string& line = r.lines[1];
  // SCIP 2.0 status lines are two characters and a checksum. (Firmware of early URG-04LX
  // answers "SCIP2.0" with a bare "0"; accept a single character without checksum there.)
  if (line.size() == 1 && r.echo() == "SCIP2.0") {
    *status = line;
    return Status::Ok();
  }
  if (line.size() != 3) {
    return Status::Error("malformed status line '" + line + "' in the response to '" + r.echo() +
                         "' (expected two characters and a checksum)");
  }
  std::string_view data;
  if (Status s = VerifyLine(line, &data); !s.ok()) {
    return Status::Error(s.message() + " (status of '" + r.echo() + "')");
  }
  *status = std::string(data);
  return Status::Ok();
}

std::string DescribeStatus(std::string_view command, std::string_view status) {
  const std::string cmd(command.substr(0, 2));
  const std::string st(status);
  if (st == "00") return "OK";
  if (st == "99") return "data follows";
  if (st == "0A") return "sensor cannot create the reply internally";
  if (st == "0B") return "buffer shortage, or the command repeats one being processed";
  if (st == "0C" || st == "0F") return "command with insufficient parameters";
  if (st == "0D" || st == "0E") return "undefined command";
  if (st == "0G") return "string characters longer than 16";
  if (st == "0H") return "string characters with invalid letters";
  if (st == "0I") return "sensor is in firmware update mode (send RS and power-cycle it)";
  if (cmd == "MD" || cmd == "MS" || cmd == "GD" || cmd == "GS") {
    if (st == "01") return "Starting Step has a non-numeric value";
    if (st == "02") return "End Step has a non-numeric value";
    if (st == "03") return "Cluster Count has a non-numeric value";
    if (st == "04") return "End Step is out of range";
    if (st == "05") return "End Step is smaller than Starting Step";
    if (st == "06") return "Scan Interval has a non-numeric value";
    if (st == "07") return "Number of Scans has a non-numeric value";
    if (st == "10") return "laser is off (send BM first)";
    int code = 0;
    if (ParseDecimal(st, &code)) {
      if (code >= 21 && code <= 49) return "processing stopped to verify an error";
      if (code >= 50 && code <= 97) return "hardware trouble (laser or motor malfunction)";
      if (code == 98) return "resumption after confirming normal laser operation";
    }
  }
  if (cmd == "BM") {
    if (st == "01") return "unable to control the laser (laser malfunction)";
    if (st == "02") return "laser is already on";
  }
  if (cmd == "TM") {
    if (st == "01") return "invalid control code";
    if (st == "02") return "adjust mode is already on";
    if (st == "03") return "adjust mode is already off";
    if (st == "04") return "adjust mode is off when the time was requested";
  }
  if (cmd == "SS") {
    if (st == "01") return "bit rate has a non-numeric value";
    if (st == "02") return "invalid bit rate";
    if (st == "03") return "sensor already runs at this bit rate";
    if (st == "04") return "bit rate not supported by this sensor model";
  }
  return "status " + st;
}

Status ParseInfo(const Response& r, std::map<std::string, std::string>* info) {
  info->clear();
  for (size_t i = 2; i < r.lines.size(); ++i) {
    const std::string& line = r.lines[i];
    // KEY:VALUE;S. The checksum S may itself be ';' or ':', so the separator is found from
    // the end: it is the second-last character.
    const size_t semi = line.size() >= 3 ? line.size() - 2 : std::string::npos;
    const size_t colon = line.find(':');
    if (semi == std::string::npos || line[semi] != ';' || colon == std::string::npos ||
        colon > semi) {
      return Status::Error("malformed line '" + line + "' in the reply to " + r.echo() +
                           " (expected KEY:VALUE;checksum)");
    }
    const std::string_view data(line.data(), semi);
    if (Checksum(data) != line.back()) {
      return Status::Error("checksum error in line '" + line + "' of the reply to " + r.echo() +
                           ": sum character '" + std::string(1, line.back()) + "', expected '" +
                           std::string(1, Checksum(data)) + "'");
    }
    (*info)[line.substr(0, colon)] = line.substr(colon + 1, semi - colon - 1);
  }
  return Status::Ok();
}

std::string FormatScanCommand(const ScanCommand& c) {
  std::string s(1, c.kind);
  s += c.encoding == 2 ? 'S' : 'D';
  s += Digits(c.start_step, 4) + Digits(c.end_step, 4) + Digits(c.cluster, 2);
  if (c.kind == 'M') s += Digits(c.skip, 1) + Digits(c.scans, 2);
  if (!c.tag.empty()) s += ";" + c.tag;
  return s + "\n";
}

bool ParseScanEcho(std::string_view echo, ScanCommand* c) {
  ScanCommand out;
  const size_t semi = echo.find(';');
  if (semi != std::string_view::npos) {
    out.tag = std::string(echo.substr(semi + 1));
    echo = echo.substr(0, semi);
  }
  if (echo.size() < 2 || (echo[0] != 'M' && echo[0] != 'G') || (echo[1] != 'D' && echo[1] != 'S'))
    return false;
  out.kind = echo[0];
  out.encoding = echo[1] == 'S' ? 2 : 3;
  const size_t expected = out.kind == 'M' ? 15 : 12;
  if (echo.size() != expected) return false;
  if (!ParseDecimal(echo.substr(2, 4), &out.start_step) ||
      !ParseDecimal(echo.substr(6, 4), &out.end_step) ||
      !ParseDecimal(echo.substr(10, 2), &out.cluster)) {
    return false;
  }
  if (out.kind == 'M' && (!ParseDecimal(echo.substr(12, 1), &out.skip) ||
                          !ParseDecimal(echo.substr(13, 2), &out.scans)))
    return false;
  *c = out;
  return true;
}

int ValuesInScan(const ScanCommand& c) {
  const int cluster = c.cluster <= 1 ? 1 : c.cluster;
  const int steps = c.end_step - c.start_step + 1;
  return steps <= 0 ? 0 : (steps + cluster - 1) / cluster;
}

Status DecodeScanResponse(const Response& r, int encoding, ScanData* scan) {
  if (r.lines.size() < 3) {
    return Status::Error("data response to '" + r.echo() + "' has no timestamp line");
  }
  std::string_view ts;
  if (Status s = VerifyLine(r.lines[2], &ts); !s.ok())
    return Status::Error("timestamp: " + s.message());
  if (ts.size() != 4 || !Decode(ts, &scan->timestamp_ms)) {
    return Status::Error("malformed timestamp line '" + r.lines[2] + "' (expected 4 characters)");
  }
  std::string joined;
  for (size_t i = 3; i < r.lines.size(); ++i) {
    std::string_view data;
    if (Status s = VerifyLine(r.lines[i], &data); !s.ok()) {
      return Status::Error("data line " + std::to_string(i - 2) + ": " + s.message());
    }
    if (data.size() > static_cast<size_t>(kMaxDataLine)) {
      return Status::Error("data line " + std::to_string(i - 2) + " has " +
                           std::to_string(data.size()) + " characters (at most 64)");
    }
    joined.append(data);
  }
  if (joined.size() % static_cast<size_t>(encoding) != 0) {
    return Status::Error("data block of " + std::to_string(joined.size()) +
                         " characters is not a multiple of " + std::to_string(encoding) +
                         " (a line is missing or cut)");
  }
  scan->values.resize(joined.size() / static_cast<size_t>(encoding));
  for (size_t k = 0; k < scan->values.size(); ++k) {
    if (!Decode(std::string_view(joined).substr(k * encoding, encoding), &scan->values[k])) {
      return Status::Error("invalid character in value " + std::to_string(k));
    }
  }
  return Status::Ok();
}

std::string EncodeDataBlock(const std::vector<uint32_t>& values, int encoding) {
  std::string joined;
  joined.reserve(values.size() * static_cast<size_t>(encoding));
  for (uint32_t v : values) joined += Encode(v, encoding);
  std::string out;
  for (size_t i = 0; i < joined.size(); i += kMaxDataLine) {
    const std::string_view line = std::string_view(joined).substr(i, kMaxDataLine);
    out.append(line);
    out.push_back(Checksum(line));
    out.push_back('\n');
  }
  return out;
}

std::string FormatInfoLine(const std::string& key, const std::string& value) {
  const std::string data = key + ":" + value;
  return data + ";" + Checksum(data) + "\n";
}

std::string FormatStatusLine(std::string_view status) {
  return std::string(status) + Checksum(status) + "\n";
}

}  // namespace fl::urg::scip2
