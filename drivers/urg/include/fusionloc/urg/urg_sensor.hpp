// UrgSensor: the SCIP 2.0 command/response state machine of one Hokuyo URG over a ByteStream
// (a SerialPort, or a test's stream): connect (QT, SCIP2.0 if needed, VV, PP, II, SS), TM time
// synchronisation, MD/MS streaming or BM + GD/GS single scans, QT, RS. No threads, no LCM.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "fusionloc/common/status.hpp"
#include "fusionloc/common/time.hpp"
#include "fusionloc/urg/clock_sync.hpp"
#include "fusionloc/urg/scip2.hpp"
#include "fusionloc/urg/serial_port.hpp"

namespace fl::urg {

// What VV, PP and II said.
struct SensorInfo {
  std::string vendor, product, firmware, protocol, serial;  // VV: VEND, PROD, FIRM, PROT, SERI
  std::string model;                                        // PP: MODL
  int dmin_mm = 0, dmax_mm = 0;                             // PP: DMIN, DMAX [mm]
  int ares = 0;                                             // PP: ARES [steps per turn]
  int amin = 0, amax = 0, afrt = 0;                         // PP: AMIN, AMAX, AFRT [step]
  int scan_rpm = 0;                                         // PP: SCAN [rpm]
  std::map<std::string, std::string> status;                // II lines

  // [rad] angle of `step` (may be fractional), counter-clockwise from the front (AFRT).
  double StepAngle(double step) const;
  double scan_period_s() const { return 60.0 / scan_rpm; }
  // "URG-04LX serial H0614967, firmware 3.1.00(18/Jan./2007)".
  std::string Describe() const;
};

// Parses VV and PP replies (checked: Hokuyo, SCIP 2.0, numbers in range, `model` when given).
Status ParseSensorInfo(const std::map<std::string, std::string>& vv,
                       const std::map<std::string, std::string>& pp,
                       const std::string& expected_model, SensorInfo* info);

struct SensorOptions {
  double reply_timeout_s = 1.0;    // [s] wait for a reply to a command
  int tm_samples = 10;             // [count] TM1 requests per time synchronisation (0: no TM)
  int target_baud = 0;             // [bit/s] RS-232: SS to this rate after connecting (0: keep)
  std::string model = "URG-04LX";  // PP MODL / VV PROD must contain this ("" = any SCIP 2.0)
};

// Result of reading one scan.
enum class ReadResult {
  kScan,          // *scan holds a scan
  kTimeout,       // nothing complete within the timeout (a stalled stream)
  kChecksum,      // a scan with a bad checksum was dropped
  kMalformed,     // a malformed response was dropped
  kDeviceError,   // the sensor reported an error status (message says which)
  kDisconnected,  // the device is gone
};

struct Scan {
  uint32_t raw_timestamp_ms = 0;  // [ms] 24-bit sensor time of step 0
  int64_t sensor_ms = 0;          // [ms] the same, unwrapped
  Utime host_arrival = 0;         // [us] host time when the scan was read completely
  int remaining = 0;              // [count] MD/MS: scans still to come (0: until QT)
  scip2::ScanCommand command;     // the echo (start step, cluster, encoding)
  std::vector<uint32_t> values;   // [mm] distances and error codes, one per cluster
};

class UrgSensor {
 public:
  // `stream` is not owned and must outlive this object. `clock` gives host time [us]
  // (NowUtime by default; tests may pass another).
  UrgSensor(const SensorOptions& options, ByteStream* stream, Utime (*clock)() = &NowUtime);

  // QT (and SCIP2.0 if the sensor does not answer in SCIP 2.0), VV, PP, II, then SS if asked.
  Status Connect();
  const SensorInfo& info() const { return info_; }

  // TM0, tm_samples x TM1, TM2 into `sync` (reset first). The laser must be off.
  Status SyncTime(ClockSync* sync);

  // MD/MS: streams until QT (command.scans = 0) or for command.scans scans.
  Status StartStreaming(const scip2::ScanCommand& command);
  // Reads the next scan of the stream (or of a GD/GS request).
  ReadResult ReadScan(Scan* scan, int timeout_ms, std::string* message);
  // BM + GD/GS: one scan now.
  Status RequestScan(const scip2::ScanCommand& command);
  Status LaserOn();
  // QT: stops streaming and turns the laser off; waits for the echo (dropping scans).
  Status Stop();
  // RS: resets the sensor's settings and timer.
  Status Reset();
  // SS: changes the bit rate (RS-232); then the host side too.
  Status ChangeBaud(int baud);

  // Any command: writes it, waits for its echo; returns the response.
  Status Command(const std::string& command, scip2::Response* response);

  int64_t checksum_errors() const { return checksum_errors_; }
  int64_t malformed() const { return malformed_; }
  int64_t discarded_responses() const { return discarded_; }
  const std::string& name() const { return name_; }

 private:
  // Waits for a response whose echo is `echo`; other responses are dropped.
  Status WaitFor(const std::string& echo, scip2::Response* response, int timeout_ms);
  // Reads into the reader until a response is complete or timeout. 1 got one, 0 timeout, -1 gone.
  int ReadResponse(scip2::Response* response, int timeout_ms, std::string* error);
  Status Expect(const std::string& command, std::initializer_list<const char*> ok,
                scip2::Response* response = nullptr, std::string* status = nullptr);

  SensorOptions options_;
  ByteStream* stream_;
  Utime (*clock_)();
  std::string name_;
  scip2::ResponseReader reader_;
  SensorInfo info_;
  TimestampUnwrapper unwrapper_;
  int64_t checksum_errors_ = 0, malformed_ = 0, discarded_ = 0;
};

}  // namespace fl::urg
