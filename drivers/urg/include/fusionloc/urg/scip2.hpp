// SCIP 2.0, the protocol of Hokuyo URG laser range finders (Hokuyo document C-42-03320B,
// "Communication Protocol Specification for SCIP2.0"): pure functions, no I/O.
//
//   host -> sensor:  "MD0044072501000\n"             (command symbol, parameters, optional
//                                                     ";tag" of up to 16 characters, LF or CR)
//   sensor -> host:  "MD0044072501000\n"  echo-back
//                    "00P\n"              status (2 characters) + checksum character
//                    ...data lines, each ending in its own checksum character...
//                    "\n"                 an empty line ends the response ("\n\n")
//
// Checksum of a line: (sum of the bytes of its data) & 0x3F, plus 0x30. Data lines of a scan
// hold up to 64 data characters plus the checksum; a value may be split across two lines and
// is decoded after the lines are joined. Encodings: a value is written in 2, 3 or 4
// characters of 6 bits each, most significant first, each plus 0x30 ("1Dh" = 5432).
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "fusionloc/common/status.hpp"

namespace fl::urg::scip2 {

constexpr int kMaxDataLine = 64;                 // [chars] data characters per line of a data block
constexpr uint32_t kTimestampModulo = 1u << 24;  // [ms] the sensor's 24-bit millisecond timer

// The checksum character of `data`.
char Checksum(std::string_view data);

// `value` in `chars` characters (2, 3 or 4); the value must fit in 6 * chars bits.
std::string Encode(uint32_t value, int chars);
// Decodes 1..4 characters; false if a character is outside 0x30..0x6F.
bool Decode(std::string_view text, uint32_t* value);

// A line with its checksum: false (and a message naming the line) if the checksum is wrong or
// the line is empty. *data is the line without its checksum character.
Status VerifyLine(std::string_view line, std::string_view* data);

// One response: the lines between the terminators, without their LFs. lines[0] is the echo.
struct Response {
  std::vector<std::string> lines;
  const std::string& echo() const { return lines.front(); }
};

// Splits a byte stream into responses: LF ends a line (a CR before it is dropped, so CR LF
// works), an empty line ends a response. Lines are bounded (a stream of garbage without LF
// gives an error instead of growing without limit).
class ResponseReader {
 public:
  // Appends bytes; complete responses are queued.
  void Feed(std::string_view bytes);
  // Pops the next complete response; false if none is complete yet.
  bool Next(Response* out);
  // Bytes dropped because a line was longer than any SCIP line can be.
  int64_t overlong_lines() const { return overlong_lines_; }
  // Drops everything buffered (after a reconnect).
  void Clear();

 private:
  std::string line_;
  Response current_;
  std::vector<Response> ready_;
  size_t ready_head_ = 0;
  int64_t overlong_lines_ = 0;
  bool skipping_ = false;  // in an overlong line: drop up to its LF
};

// The status of a response (lines[1], two characters + checksum), checked.
Status ParseStatus(const Response& r, std::string* status);
// English text of a status for the command (e.g. MD "04" -> "End Step is out of range").
std::string DescribeStatus(std::string_view command, std::string_view status);

// "KEY:VALUE;S" lines (VV, PP, II; the checksum covers "KEY:VALUE") from lines[2...].
Status ParseInfo(const Response& r, std::map<std::string, std::string>* info);

// Parameters of an MD/MS/GD/GS command (as sent, and as echoed back).
struct ScanCommand {
  char kind = 'M';      // 'M' (MD/MS: streaming) or 'G' (GD/GS: one scan)
  int encoding = 3;     // [chars] 3 (MD/GD) or 2 (MS/GS)
  int start_step = 44;  // [step] first step
  int end_step = 725;   // [step] last step
  int cluster = 1;      // [steps] merged into one value (0 and 1 both mean 1)
  int skip = 0;         // [scans] MD/MS only: scans skipped between two sent (0..9)
  int scans = 0;        // [count] MD/MS only: scans to send, 0 = until QT; in an echo of a
                        // data response: the remaining scans
  std::string tag;      // optional string characters (";tag" in the command)
};
// The command line, LF-terminated ("MD0044072501000\n").
std::string FormatScanCommand(const ScanCommand& c);
// Parses an echo line ("MD0044072501000" or with ";tag"); false if it is not one.
bool ParseScanEcho(std::string_view echo, ScanCommand* c);

// A decoded scan: the sensor time of step 0 and one value per cluster.
struct ScanData {
  uint32_t timestamp_ms = 0;     // [ms] 24-bit sensor time
  std::vector<uint32_t> values;  // [mm] distances or error codes (URG-04LX: < 20 = no return)
};
// Decodes the timestamp line and the data block of a data response (lines[2] = timestamp,
// lines[3...] = data lines), verifying every checksum and joining values split across lines.
Status DecodeScanResponse(const Response& r, int encoding, ScanData* scan);

// The data block of `values` as lines of at most 64 characters, each with its checksum and LF
// (for the emulator and tests).
std::string EncodeDataBlock(const std::vector<uint32_t>& values, int encoding);
// "KEY:VALUE;S\n".
std::string FormatInfoLine(const std::string& key, const std::string& value);
// "SS\n" status line with checksum.
std::string FormatStatusLine(std::string_view status);

// Steps in a scan of `c` (ceil((end - start + 1) / cluster)).
int ValuesInScan(const ScanCommand& c);

}  // namespace fl::urg::scip2
