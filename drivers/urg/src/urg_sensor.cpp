#include "fusionloc/urg/urg_sensor.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>

namespace fl::urg {
namespace {

bool ParseInt(const std::map<std::string, std::string>& m, const char* key, int* v) {
  auto it = m.find(key);
  if (it == m.end()) return false;
  const std::string& s = it->second;
  size_t i = 0;
  while (i < s.size() && s[i] == ' ') ++i;  // "DMIN: 20" in some documents
  if (i == s.size()) return false;
  char* end = nullptr;
  const long x = std::strtol(s.c_str() + i, &end, 10);
  if (end == s.c_str() + i) return false;
  *v = static_cast<int>(x);
  return true;
}

std::string Get(const std::map<std::string, std::string>& m, const char* key) {
  auto it = m.find(key);
  return it == m.end() ? std::string() : it->second;
}

std::string Trimmed(const std::string& command) {
  std::string c = command;
  while (!c.empty() && (c.back() == '\n' || c.back() == '\r')) c.pop_back();
  return c;
}

}  // namespace

double SensorInfo::StepAngle(double step) const { return (step - afrt) * 2.0 * M_PI / ares; }

std::string SensorInfo::Describe() const {
  std::string m = model.empty() ? product : model;
  const size_t paren = m.find('(');
  if (paren != std::string::npos) m = m.substr(0, paren);
  return m + " serial " + (serial.empty() ? "?" : serial) + ", firmware " + firmware;
}

Status ParseSensorInfo(const std::map<std::string, std::string>& vv,
                       const std::map<std::string, std::string>& pp,
                       const std::string& expected_model, SensorInfo* info) {
  SensorInfo out;
  out.vendor = Get(vv, "VEND");
  out.product = Get(vv, "PROD");
  out.firmware = Get(vv, "FIRM");
  out.protocol = Get(vv, "PROT");
  out.serial = Get(vv, "SERI");
  out.model = Get(pp, "MODL");
  if (out.product.empty() || out.protocol.empty()) {
    return Status::Error("VV reply has no PROD or PROT line: not a Hokuyo SCIP 2.0 sensor");
  }
  if (out.protocol.find("SCIP 2.0") == std::string::npos &&
      out.protocol.find("SCIP2.0") == std::string::npos) {
    return Status::Error("VV says protocol '" + out.protocol +
                         "'; this driver speaks SCIP 2.0 (switch the sensor with the SCIP2.0 "
                         "command or Hokuyo's URG configurator)");
  }
  if (!expected_model.empty() && out.product.find(expected_model) == std::string::npos &&
      out.model.find(expected_model) == std::string::npos) {
    return Status::Error("VV says product '" + out.product + "' (PP model '" + out.model +
                         "'), not the configured model '" + expected_model + "': connect a " +
                         expected_model +
                         ", or set model: \"\" (any SCIP 2.0 Hokuyo) or the right model in the "
                         "driver's config");
  }
  struct Field {
    const char* key;
    int* value;
  } fields[] = {{"DMIN", &out.dmin_mm}, {"DMAX", &out.dmax_mm}, {"ARES", &out.ares},
                {"AMIN", &out.amin},    {"AMAX", &out.amax},    {"AFRT", &out.afrt},
                {"SCAN", &out.scan_rpm}};
  for (const Field& f : fields) {
    if (!ParseInt(pp, f.key, f.value)) {
      return Status::Error(std::string("PP reply has no number for ") + f.key + " ('" +
                           Get(pp, f.key) + "')");
    }
  }
  if (out.ares <= 0 || out.amin < 0 || out.amax < out.amin || out.amax >= out.ares * 2 ||
      out.afrt < out.amin || out.afrt > out.amax || out.scan_rpm <= 0 || out.dmin_mm < 0 ||
      out.dmax_mm <= out.dmin_mm) {
    return Status::Error("PP parameters are not consistent (ARES " + std::to_string(out.ares) +
                         ", AMIN " + std::to_string(out.amin) + ", AMAX " +
                         std::to_string(out.amax) + ", AFRT " + std::to_string(out.afrt) +
                         ", SCAN " + std::to_string(out.scan_rpm) + ")");
  }
  *info = out;
  return Status::Ok();
}

UrgSensor::UrgSensor(const SensorOptions& options, ByteStream* stream, Utime (*clock)())
    : options_(options), stream_(stream), clock_(clock), name_(stream->name()) {}

int UrgSensor::ReadResponse(scip2::Response* response, int timeout_ms, std::string* error) {
  if (reader_.Next(response)) return 1;
  const Utime deadline = MonotonicUtime() + static_cast<Utime>(timeout_ms) * 1000;
  char buf[4096];
  for (;;) {
    const Utime now = MonotonicUtime();
    const int left = static_cast<int>(std::max<Utime>(0, (deadline - now + 999) / 1000));
    const int n = stream_->Read(buf, sizeof(buf), left, error);
    if (n < 0) return -1;
    if (n > 0) {
      reader_.Feed(std::string_view(buf, static_cast<size_t>(n)));
      if (reader_.Next(response)) return 1;
    }
    if (MonotonicUtime() >= deadline) return 0;
  }
}

Status UrgSensor::WaitFor(const std::string& echo, scip2::Response* response, int timeout_ms) {
  const Utime deadline = MonotonicUtime() + static_cast<Utime>(timeout_ms) * 1000;
  for (;;) {
    const int left =
        static_cast<int>(std::max<Utime>(0, (deadline - MonotonicUtime() + 999) / 1000));
    std::string error;
    const int rc = ReadResponse(response, left, &error);
    if (rc < 0) return Status::Error(error);
    if (rc == 0) {
      return Status::Error("no reply to " + echo + " from '" + name_ + "' within " +
                           std::to_string(timeout_ms) +
                           " ms: is it a Hokuyo URG, powered, and at the right bit rate?");
    }
    if (response->echo() == echo) return Status::Ok();
    ++discarded_;  // a scan still in flight, or a reply to an earlier command
  }
}

Status UrgSensor::Command(const std::string& command, scip2::Response* response) {
  if (Status s = stream_->Write(command); !s.ok()) return s;
  return WaitFor(Trimmed(command), response, static_cast<int>(options_.reply_timeout_s * 1000));
}

Status UrgSensor::Expect(const std::string& command, std::initializer_list<const char*> ok,
                         scip2::Response* response, std::string* status_out) {
  scip2::Response local;
  scip2::Response* r = response ? response : &local;
  if (Status s = Command(command, r); !s.ok()) return s;
  std::string status;
  if (Status s = scip2::ParseStatus(*r, &status); !s.ok()) {
    ++malformed_;
    return Status::Error("'" + name_ + "': " + s.message());
  }
  if (status_out) *status_out = status;
  for (const char* o : ok) {
    if (status == o) return Status::Ok();
  }
  const std::string c = Trimmed(command);
  return Status::Error("'" + name_ + "' answered " + c + " with status " + status + ": " +
                       scip2::DescribeStatus(c, status));
}

Status UrgSensor::Connect() {
  reader_.Clear();
  stream_->DiscardInput();
  unwrapper_.Reset();
  // QT stops a stream left running by an earlier process. A sensor still in SCIP 1.1 does
  // not echo it: switch it to SCIP 2.0 and try again.
  if (Status s = Expect("QT\n", {"00"}); !s.ok()) {
    scip2::Response r;
    if (Status s2 = Command("SCIP2.0\n", &r); !s2.ok()) {
      return Status::Error("'" + name_ + "' does not answer QT or SCIP2.0 (" + s.message() +
                           "): is it a Hokuyo URG, powered, and at the configured bit rate?");
    }
    if (Status s3 = Expect("QT\n", {"00"}); !s3.ok()) return s3;
  }
  scip2::Response vv, pp, ii;
  std::map<std::string, std::string> vv_map, pp_map;
  if (Status s = Expect("VV\n", {"00"}, &vv); !s.ok()) return s;
  if (Status s = scip2::ParseInfo(vv, &vv_map); !s.ok()) {
    return Status::Error("'" + name_ + "': " + s.message());
  }
  if (Status s = Expect("PP\n", {"00"}, &pp); !s.ok()) return s;
  if (Status s = scip2::ParseInfo(pp, &pp_map); !s.ok()) {
    return Status::Error("'" + name_ + "': " + s.message());
  }
  if (Status s = ParseSensorInfo(vv_map, pp_map, options_.model, &info_); !s.ok()) {
    return Status::Error("'" + name_ + "': " + s.message());
  }
  if (Status s = Expect("II\n", {"00"}, &ii); !s.ok()) return s;
  if (Status s = scip2::ParseInfo(ii, &info_.status); !s.ok()) {
    return Status::Error("'" + name_ + "': " + s.message());
  }
  if (options_.target_baud > 0) {
    if (Status s = ChangeBaud(options_.target_baud); !s.ok()) return s;
  }
  return Status::Ok();
}

Status UrgSensor::ChangeBaud(int baud) {
  if (!IsScipBaud(baud)) {
    return Status::Error("bit rate " + std::to_string(baud) +
                         " is not one SCIP's SS knows (19200, 38400, 57600, 115200, 250000, "
                         "500000, 750000)");
  }
  char cmd[16];
  std::snprintf(cmd, sizeof(cmd), "SS%06d\n", baud);
  std::string status;
  // 03: already at this rate; 04: the model has no such rate (USB models accept SS).
  if (Status s = Expect(cmd, {"00", "03"}, nullptr, &status); !s.ok()) return s;
  if (status == "00") return stream_->SetBaud(baud);
  return Status::Ok();
}

Status UrgSensor::SyncTime(ClockSync* sync) {
  sync->Reset();
  if (options_.tm_samples <= 0) return Status::Ok();
  if (Status s = Expect("TM0\n", {"00", "02"}); !s.ok()) return s;
  for (int i = 0; i < options_.tm_samples; ++i) {
    scip2::Response r;
    const Utime before = clock_();
    if (Status s = Expect("TM1\n", {"00"}, &r); !s.ok()) return s;
    const Utime after = clock_();
    std::string_view data;
    uint32_t ms = 0;
    if (r.lines.size() < 3 || !scip2::VerifyLine(r.lines[2], &data).ok() || data.size() != 4 ||
        !scip2::Decode(data, &ms)) {
      ++malformed_;
      return Status::Error("'" + name_ + "': malformed TM1 time line '" +
                           (r.lines.size() < 3 ? std::string() : r.lines[2]) + "'");
    }
    sync->AddTmSample(unwrapper_.Unwrap(ms), before, after);
  }
  if (Status s = Expect("TM2\n", {"00", "03"}); !s.ok()) return s;
  sync->FinishTm();
  return Status::Ok();
}

Status UrgSensor::StartStreaming(const scip2::ScanCommand& command) {
  scip2::ScanCommand c = command;
  c.kind = 'M';
  return Expect(scip2::FormatScanCommand(c), {"00"});
}

Status UrgSensor::LaserOn() { return Expect("BM\n", {"00", "02"}); }

Status UrgSensor::RequestScan(const scip2::ScanCommand& command) {
  scip2::ScanCommand c = command;
  c.kind = 'G';
  return stream_->Write(scip2::FormatScanCommand(c));
}

Status UrgSensor::Stop() { return Expect("QT\n", {"00"}); }

Status UrgSensor::Reset() {
  unwrapper_.Reset();
  return Expect("RS\n", {"00"});
}

ReadResult UrgSensor::ReadScan(Scan* scan, int timeout_ms, std::string* message) {
  const Utime deadline = MonotonicUtime() + static_cast<Utime>(timeout_ms) * 1000;
  for (;;) {
    const int left =
        static_cast<int>(std::max<Utime>(0, (deadline - MonotonicUtime() + 999) / 1000));
    scip2::Response r;
    const int rc = ReadResponse(&r, left, message);
    if (rc < 0) return ReadResult::kDisconnected;
    if (rc == 0) {
      *message = "no scan from '" + name_ + "' for " + std::to_string(timeout_ms) + " ms";
      return ReadResult::kTimeout;
    }
    scip2::ScanCommand echo;
    if (!scip2::ParseScanEcho(r.echo(), &echo)) {
      ++discarded_;
      continue;  // not a scan (a late reply to another command)
    }
    std::string status;
    if (Status s = scip2::ParseStatus(r, &status); !s.ok()) {
      // A damaged status line is a damaged frame: same as a bad checksum.
      ++checksum_errors_;
      *message = "'" + name_ + "': " + s.message();
      return ReadResult::kChecksum;
    }
    if (echo.kind == 'M' && status == "00") continue;  // the acknowledgement of MD/MS
    const bool data = (echo.kind == 'M' && status == "99") || (echo.kind == 'G' && status == "00");
    if (!data) {
      *message = "'" + name_ + "' reports " + r.echo().substr(0, 2) + " status " + status + ": " +
                 scip2::DescribeStatus(r.echo(), status);
      return ReadResult::kDeviceError;
    }
    scip2::ScanData d;
    if (Status s = scip2::DecodeScanResponse(r, echo.encoding, &d); !s.ok()) {
      const bool checksum = s.message().find("checksum") != std::string::npos;
      if (checksum) {
        ++checksum_errors_;
      } else {
        ++malformed_;
      }
      *message = "'" + name_ + "': scan dropped: " + s.message();
      return checksum ? ReadResult::kChecksum : ReadResult::kMalformed;
    }
    if (static_cast<int>(d.values.size()) != scip2::ValuesInScan(echo)) {
      ++malformed_;
      *message = "'" + name_ + "': scan dropped: " + std::to_string(d.values.size()) +
                 " values where " + r.echo() + " gives " +
                 std::to_string(scip2::ValuesInScan(echo));
      return ReadResult::kMalformed;
    }
    scan->host_arrival = clock_();
    scan->raw_timestamp_ms = d.timestamp_ms;
    scan->sensor_ms = unwrapper_.Unwrap(d.timestamp_ms);
    scan->remaining = echo.scans;
    scan->command = echo;
    scan->values = std::move(d.values);
    return ReadResult::kScan;
  }
}

}  // namespace fl::urg
