// An emulated Hokuyo URG-04LX on a pseudo-terminal, speaking SCIP 2.0 like the real sensor
// (VV/PP/II with the real device's values, MD/MS/GD/GS, BM, QT, RS, TM0/1/2, SS, SCIP2.0),
// streaming scans of a simulator world (fl::sim::World, ray-cast by fl::sim::LaserModel) from
// a fixed pose with Gaussian range noise of known sigma, and injecting faults: bad checksums,
// a line cut in two (two writes with a pause), a stalled stream, and the device vanishing
// (pty closed, link removed) and coming back (a new pty behind the same link).
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
#include "fusionloc/sim/sim_options.hpp"

namespace fl::urg {

struct UrgEmulatorOptions {
  std::string link = "";  // symlink to the pty's slave, e.g. /tmp/hokuyo ("": none; see
                          // slave_path())
  // ---- identity: what a URG-04LX answers to VV and PP ----
  std::string vendor = "Hokuyo Automatic Co.,Ltd.";
  std::string product = "SOKUIKI Sensor URG-04LX";
  std::string firmware = "3.1.00(18/Jan./2007)";
  std::string protocol = "SCIP 2.0";
  std::string serial = "H0614967";
  std::string model = "URG-04LX(Hokuyo Automatic Co.,Ltd.)";
  int dmin_mm = 20;                // [mm] DMIN
  int dmax_mm = 5600;              // [mm] DMAX
  int ares = 1024;                 // [steps] ARES, steps per turn
  int amin = 44;                   // [step] AMIN
  int amax = 725;                  // [step] AMAX
  int afrt = 384;                  // [step] AFRT, the front
  int max_step = 768;              // [step] last step a command may ask for (step D)
  int scan_rpm = 600;              // [rpm] SCAN (10 scans/s)
  bool scip1_at_power_on = false;  // start in SCIP 1.1, like a URG-04LX set so: then only
                                   // "SCIP2.0" is answered ("0": switched), until a restart
  // ---- scene ----
  sim::WorldOptions world = [] {  // the simulator's world; the corridor suits a 5.6 m range
    sim::WorldOptions w;
    w.name = "corridor";
    return w;
  }();
  int64_t seed = 1;             // world layout and range noise
  double x_m = 10.0;            // [m] laser position in the world
  double y_m = 0.0;             // [m]
  double z_m = 0.3;             // [m] scan-plane height
  double yaw_rad = 0.0;         // [rad] laser heading (CCW from world x)
  double range_sigma_m = 0.01;  // [m] Gaussian range noise
  // ---- clock: sensor_ms = clock_start_ms + elapsed * (1 + clock_skew_ppm 1e-6), mod 2^24 ----
  int64_t clock_start_ms = 0;   // [ms] timer at power-on (e.g. 2^24 - 3000 to see a wrap soon)
  double clock_skew_ppm = 0.0;  // [ppm] sensor clock rate error
  // ---- faults, periodic (0: off); tests can also inject them one by one ----
  int checksum_error_every = 0;  // [scans] one data line of every Nth scan has a wrong checksum
  int split_line_every = 0;      // [scans] every Nth scan is written in two parts cut inside
                                 // a line, with split_pause_s between them
  double split_pause_s = 0.02;   // [s]
  double stall_after_s = 0.0;    // [s] after start: stop answering and streaming...
  double stall_for_s = 0.0;      // [s] ...for this long
  double vanish_after_s = 0.0;   // [s] after start: close the pty and remove the link...
  double vanish_for_s = 0.0;     // [s] ...and come back (new pty, same link) after this long

  template <class A>
  void Serialize(A* a) {
    a->Visit("link", &link);
    a->Visit("vendor", &vendor);
    a->Visit("product", &product);
    a->Visit("firmware", &firmware);
    a->Visit("protocol", &protocol);
    a->Visit("serial", &serial);
    a->Visit("model", &model);
    a->Visit("dmin_mm", &dmin_mm);
    a->Visit("dmax_mm", &dmax_mm);
    a->Visit("ares", &ares);
    a->Visit("amin", &amin);
    a->Visit("amax", &amax);
    a->Visit("afrt", &afrt);
    a->Visit("max_step", &max_step);
    a->Visit("scan_rpm", &scan_rpm);
    a->Visit("scip1_at_power_on", &scip1_at_power_on);
    a->Visit("world", &world);
    a->Visit("seed", &seed);
    a->Visit("x_m", &x_m);
    a->Visit("y_m", &y_m);
    a->Visit("z_m", &z_m);
    a->Visit("yaw_rad", &yaw_rad);
    a->Visit("range_sigma_m", &range_sigma_m);
    a->Visit("clock_start_ms", &clock_start_ms);
    a->Visit("clock_skew_ppm", &clock_skew_ppm);
    a->Visit("checksum_error_every", &checksum_error_every);
    a->Visit("split_line_every", &split_line_every);
    a->Visit("split_pause_s", &split_pause_s);
    a->Visit("stall_after_s", &stall_after_s);
    a->Visit("stall_for_s", &stall_for_s);
    a->Visit("vanish_after_s", &vanish_after_s);
    a->Visit("vanish_for_s", &vanish_for_s);
  }
  Status Validate() const;
};

// What the emulator sent, for comparisons with the truth.
struct EmulatedScan {
  uint32_t timestamp_ms = 0;  // [ms] 24-bit sensor time of step 0, as sent
  Utime host_step0 = 0;       // [us] host (wall-clock) time of step 0
  int start_step = 0, cluster = 1;
  std::vector<float> true_ranges;  // [m] noise-free, per step from start_step (0: no return)
  bool corrupted = false;          // sent with a bad checksum
};

class UrgEmulator {
 public:
  explicit UrgEmulator(const UrgEmulatorOptions& options);
  ~UrgEmulator();
  UrgEmulator(const UrgEmulator&) = delete;
  UrgEmulator& operator=(const UrgEmulator&) = delete;

  // Opens the pty (and the link) and starts answering. Errors name what failed.
  Status Start();
  void Stop();

  // The pty's slave ("/dev/pts/7"); the link points to it.
  std::string slave_path() const;
  // The path a driver should open: the link if there is one, else the slave.
  std::string device_path() const;

  // One-off faults: the next `n` scans with a bad checksum; the next `n` scans cut in two;
  // no answers and no scans for `seconds`; the device gone for `seconds`.
  void InjectChecksumErrors(int n);
  void InjectSplitLines(int n);
  void Stall(double seconds);
  void Vanish(double seconds);

  // The sensor's timer at host time `host` [ms, unwrapped] and its 24-bit reading.
  double SensorMs(Utime host) const;
  // Everything sent in scans so far (kept up to the last 10000).
  std::vector<EmulatedScan> sent() const;
  // Noise-free range of every step AMIN..AMAX [m] (0: no return), and the step angles.
  const std::vector<float>& true_ranges() const { return true_ranges_; }
  double StepAngle(int step) const;
  int64_t commands() const { return commands_; }
  // False while in SCIP 1.1 (see scip1_at_power_on).
  bool in_scip2() const { return scip2_; }
  int64_t vanishes() const { return vanishes_; }
  const UrgEmulatorOptions& options() const { return options_; }

 private:
  Status OpenPty();
  void ClosePty();
  void Run();
  void HandleLine(const std::string& line, Utime now);
  void Reply(const std::string& text);
  void SendScan(Utime step0, bool streaming);
  std::string InfoReply(const std::string& echo, char which) const;
  void PowerOn(Utime now);
  bool WriteAll(const std::string& bytes);
  std::vector<uint32_t> ScanValues(int start, int end, int cluster, int encoding);
  int current_baud_ = 19200;

  UrgEmulatorOptions options_;
  std::vector<float> true_ranges_;     // per step amin..amax
  int master_ = -1, slave_keep_ = -1;  // the pty; the emulator holds the slave open too
  std::string slave_;
  mutable std::mutex mu_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<int64_t> commands_{0}, vanishes_{0};
  // Device state (thread only).
  Utime power_on_ = 0;
  Utime start_ = 0;
  bool laser_ = false, adjust_ = false, streaming_ = false;
  std::atomic<bool> scip2_{true};
  int remaining_ = 0, skip_ = 0, skip_count_ = 0, encoding_ = 3;
  int start_step_ = 44, end_step_ = 725, cluster_ = 1;
  bool infinite_ = false;
  std::string tag_;
  Utime next_scan_ = 0;
  std::string input_;
  uint64_t scan_index_ = 0;
  struct Scene;
  std::unique_ptr<Scene> scene_;
  // Faults.
  int checksum_left_ = 0, split_left_ = 0;
  Utime stall_until_ = 0, vanish_at_ = 0, back_at_ = 0;
  bool periodic_stall_done_ = false, periodic_vanish_done_ = false;
  std::deque<EmulatedScan> sent_;
};

}  // namespace fl::urg
