// UrgDriver: one Hokuyo URG from connection to scans in metres with host-time stamps, on its
// own thread, with no LCM (the adapter in drivers/urg/lcm publishes what it produces).
//
//   connect (port, or the USB Hokuyo libusb finds) -> UrgSensor::Connect (QT, VV, PP, II, SS)
//   -> TM time synchronisation -> MD/MS stream (or BM + GD/GS polling) -> scans:
//      ranges [m] (error codes < DMIN and values > DMAX: no return, published as 0),
//      angles from PP (AMIN, AMAX, AFRT, ARES), utime = host time of the first beam.
//   A stalled stream is restarted; a device that is gone is closed and reopened when it is
//   back (hotplug or polling); scans with a bad checksum are dropped and counted.
#pragma once

#include <atomic>
#include <cstdint>
#include <deque>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "fusionloc/common/status.hpp"
#include "fusionloc/common/time.hpp"
#include "fusionloc/urg/clock_sync.hpp"
#include "fusionloc/urg/urg_sensor.hpp"

namespace fl::urg {

struct UrgDriverOptions {
  std::string port = "";           // serial device, e.g. /dev/hokuyo or /dev/ttyACM0; "": find a
                                   // USB Hokuyo (vendor 0x15d1) and its ttyACM node with libusb
  int baud = 115200;               // [bit/s] host bit rate at open (RS-232: the sensor's current
                                   // rate, 19200 out of the box; USB-ACM and pty ignore it)
  int target_baud = 0;             // [bit/s] RS-232: SS to this rate after connecting (0: keep)
  std::string model = "URG-04LX";  // VV PROD / PP MODL must contain this ("": any SCIP 2.0 URG)
  int start_step = -1;             // [step] first step (-1: AMIN from PP)
  int end_step = -1;               // [step] last step (-1: AMAX from PP)
  int cluster = 1;                 // [steps] adjacent steps merged into one beam (1..99; the
                                   // sensor sends the nearest); the beam's angle is the centre
  int skip = 0;                    // [scans] scans skipped between two sent (MD scan interval 0..9)
  int encoding = 3;                // [chars] 3: MD/GD (18-bit); 2: MS/GS (12-bit: ranges from
                                   // 4.095 m on come out as 4.095 m)
  bool streaming = true;           // true: MD/MS stream; false: BM, then one GD/GS per scan period
  double reply_timeout_s = 1.0;    // [s] wait for the reply to a command
  double stall_timeout_s = 1.0;    // [s] no scan for this long: the stream is restarted
  double reconnect_interval_s = 0.5;  // [s] between attempts to reopen a device that is gone
  int tm_samples = 10;                // [count] TM1 requests per time synchronisation (0: no TM,
                                      // stamps from arrival times)
  ClockSyncOptions clock;             // drift filter

  template <class A>
  void Serialize(A* a) {
    a->Visit("port", &port);
    a->Visit("baud", &baud);
    a->Visit("target_baud", &target_baud);
    a->Visit("model", &model);
    a->Visit("start_step", &start_step);
    a->Visit("end_step", &end_step);
    a->Visit("cluster", &cluster);
    a->Visit("skip", &skip);
    a->Visit("encoding", &encoding);
    a->Visit("streaming", &streaming);
    a->Visit("reply_timeout_s", &reply_timeout_s);
    a->Visit("stall_timeout_s", &stall_timeout_s);
    a->Visit("reconnect_interval_s", &reconnect_interval_s);
    a->Visit("tm_samples", &tm_samples);
    a->Visit("clock", &clock);
  }
  Status Validate() const;
};

// One scan as published: planar_lidar_t's fields.
struct LaserScan {
  Utime utime = 0;                // [us] host time of the first beam
  std::vector<float> ranges;      // [m] 0 = no return
  float rad0 = 0.0f;              // [rad] angle of the first beam, CCW from the front
  float radstep = 0.0f;           // [rad] angle between beams
  uint32_t raw_timestamp_ms = 0;  // [ms] the sensor's 24-bit time of step 0
  int no_return = 0;              // [count] beams with an error code or beyond DMAX
};

// Counters and state for the status message.
struct DriverStats {
  int64_t scans = 0;            // published
  int64_t checksum_errors = 0;  // scans dropped for a bad checksum
  int64_t malformed = 0;        // responses dropped as malformed
  int64_t reconnects = 0;       // connections made again after the device was lost
  int64_t stalls = 0;           // streams restarted after stall_timeout_s without a scan
  int64_t device_errors = 0;    // error statuses reported by the sensor
  bool connected = false;
  std::string device;          // the port in use
  std::string sensor;          // VV/PP: "URG-04LX serial H0614967, firmware ..."
  std::string last_error;      // last problem, "" if none
  Utime last_error_utime = 0;  // [us] monotonic time of last_error
  double residual_ms = 0.0, skew_ppm = 0.0, latency_ms = 0.0, tm_round_trip_ms = 0.0;
};

// Beam angles and ranges of a scan (a pure function of the scan and the sensor's parameters).
LaserScan ConvertScan(const Scan& scan, const SensorInfo& info, const ClockSync& clock);

class UrgDriver {
 public:
  explicit UrgDriver(const UrgDriverOptions& options);
  ~UrgDriver();
  UrgDriver(const UrgDriver&) = delete;
  UrgDriver& operator=(const UrgDriver&) = delete;

  // Connects once (the first connection's errors are returned: a port that is not a device,
  // permission denied, a wrong model, ...; with port "" it waits for a USB Hokuyo until
  // `give_up_s`), then runs the reading thread.
  Status Start(double give_up_s = 1e9);
  void Stop();

  // Scans read since the last call.
  std::vector<LaserScan> TakeScans();
  DriverStats stats() const;

 private:
  void Run();
  Status ConnectOnce(std::string* path);
  std::string ResolvePort(std::string* why);
  // Runs the stream until the device is lost or Stop(); returns why it ended.
  std::string Stream();
  void SetError(const std::string& e);

  UrgDriverOptions options_;
  std::unique_ptr<SerialPort> port_;
  std::unique_ptr<UrgSensor> sensor_;
  ClockSync clock_;
  scip2::ScanCommand command_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  mutable std::mutex mu_;
  std::deque<LaserScan> queue_;
  DriverStats stats_;
};

}  // namespace fl::urg
