#include "fusionloc/urg/urg_driver.hpp"

#include <chrono>
#include <cmath>

#include "fusionloc/common/log.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/urg/usb_discovery.hpp"

namespace fl::urg {
namespace {

constexpr size_t kMaxQueued = 100;  // scans kept when nobody takes them (10 s at 10 Hz)

void SleepS(double s) { std::this_thread::sleep_for(std::chrono::microseconds(SecondsToUtime(s))); }

}  // namespace

Status UrgDriverOptions::Validate() const {
  if (baud != 19200 && baud != 38400 && baud != 57600 && baud != 115200 && baud != 230400 &&
      baud != 500000) {
    return Status::Error("baud must be 19200, 38400, 57600, 115200, 230400 or 500000 (got " +
                         std::to_string(baud) + ")");
  }
  // SCIP also knows 250000 and 750000, which termios cannot set on the host side.
  if (target_baud != 0 && target_baud != 19200 && target_baud != 38400 && target_baud != 57600 &&
      target_baud != 115200 && target_baud != 500000) {
    return Status::Error(
        "target_baud must be 0 (keep) or 19200, 38400, 57600, 115200 or 500000 "
        "(a rate both SCIP's SS and the host's serial port support), got " +
        std::to_string(target_baud));
  }
  if (start_step < -1 || end_step < -1 ||
      (start_step >= 0 && end_step >= 0 && end_step < start_step))
    return Status::Error(
        "start_step and end_step must be -1 (from PP) or steps with "
        "start_step <= end_step");
  if (cluster < 1 || cluster > 99) return Status::Error("cluster must be 1..99");
  if (skip < 0 || skip > 9) return Status::Error("skip must be 0..9 (SCIP scan interval)");
  if (encoding != 2 && encoding != 3) {
    return Status::Error("encoding must be 3 (MD/GD) or 2 (MS/GS)");
  }
  if (!(reply_timeout_s > 0)) return Status::Error("reply_timeout_s must be > 0");
  if (!(stall_timeout_s > 0)) return Status::Error("stall_timeout_s must be > 0");
  if (!(reconnect_interval_s > 0)) return Status::Error("reconnect_interval_s must be > 0");
  if (tm_samples < 0 || tm_samples > 1000) return Status::Error("tm_samples must be 0..1000");
  return clock.Validate();
}

LaserScan ConvertScan(const Scan& scan, const SensorInfo& info, const ClockSync& clock) {
  LaserScan out;
  const int cluster = scan.command.cluster <= 1 ? 1 : scan.command.cluster;
  const int start = scan.command.start_step;
  const double step_rad = 2.0 * M_PI / info.ares;
  out.rad0 = static_cast<float>(info.StepAngle(start + 0.5 * (cluster - 1)));
  out.radstep = static_cast<float>(cluster * step_rad);
  // The timestamp is the time of step 0 in whole milliseconds (on average half a millisecond
  // late); the first beam is `start` steps of a turn later.
  const double first_beam_ms = static_cast<double>(scan.sensor_ms) + 0.5 +
                               static_cast<double>(start) / info.ares * info.scan_period_s() * 1e3;
  out.utime = clock.ToHost(first_beam_ms);
  out.raw_timestamp_ms = scan.raw_timestamp_ms;
  out.ranges.resize(scan.values.size());
  for (size_t i = 0; i < scan.values.size(); ++i) {
    const uint32_t v = scan.values[i];
    if (v < static_cast<uint32_t>(info.dmin_mm) || v > static_cast<uint32_t>(info.dmax_mm)) {
      out.ranges[i] = 0.0f;  // error code (URG-04LX: 0..19) or out of range: no return
      ++out.no_return;
    } else {
      out.ranges[i] = static_cast<float>(v) * 1e-3f;
    }
  }
  return out;
}

UrgDriver::UrgDriver(const UrgDriverOptions& options) : options_(options), clock_(options.clock) {}

UrgDriver::~UrgDriver() { Stop(); }

void UrgDriver::SetError(const std::string& e) {
  std::lock_guard<std::mutex> lock(mu_);
  stats_.last_error = e;
  stats_.last_error_utime = MonotonicUtime();
}

std::string UrgDriver::ResolvePort(std::string* why) {
  if (!options_.port.empty()) return options_.port;
  std::string error;
  const auto sensors = FindHokuyoSensors(&error);
  for (const auto& s : sensors) {
    if (!s.tty.empty()) return s.tty;
  }
  if (!error.empty()) {
    *why = "cannot look for a USB Hokuyo: " + error + "; give the port (port: /dev/ttyACM0)";
  } else if (!sensors.empty()) {
    *why = "a USB Hokuyo is at " + sensors.front().sysfs_name +
           " but has no ttyACM node: is the cdc_acm kernel module loaded (modprobe cdc_acm)?";
  } else {
    *why =
        "no USB Hokuyo (vendor id 15d1) found: plug it in, or give the port "
        "(port: /dev/ttyUSB0 for RS-232)";
  }
  return "";
}

Status UrgDriver::ConnectOnce(std::string* path) {
  std::string why;
  *path = ResolvePort(&why);
  if (path->empty()) return Status::Error(why);
  auto port = std::make_unique<SerialPort>();
  if (Status s = port->Open(*path, options_.baud); !s.ok()) return s;
  SensorOptions so;
  so.reply_timeout_s = options_.reply_timeout_s;
  so.tm_samples = options_.tm_samples;
  so.target_baud = options_.target_baud;
  so.model = options_.model;
  auto sensor = std::make_unique<UrgSensor>(so, port.get());
  if (Status s = sensor->Connect(); !s.ok()) return s;
  const SensorInfo& info = sensor->info();
  command_ = scip2::ScanCommand();
  command_.encoding = options_.encoding;
  command_.start_step = options_.start_step >= 0 ? options_.start_step : info.amin;
  command_.end_step = options_.end_step >= 0 ? options_.end_step : info.amax;
  command_.cluster = options_.cluster;
  command_.skip = options_.skip;
  command_.scans = 0;
  if (command_.start_step < info.amin || command_.end_step > info.amax) {
    return Status::Error("steps " + std::to_string(command_.start_step) + ".." +
                         std::to_string(command_.end_step) + " are outside the sensor's range " +
                         std::to_string(info.amin) + ".." + std::to_string(info.amax) +
                         " (PP AMIN..AMAX of '" + *path + "'): fix start_step/end_step");
  }
  if (Status s = sensor->SyncTime(&clock_); !s.ok()) return s;
  Status started = options_.streaming ? sensor->StartStreaming(command_) : sensor->LaserOn();
  if (!started.ok()) return started;
  if (!options_.streaming) {
    if (Status s = sensor->RequestScan(command_); !s.ok()) return s;
  }
  port_ = std::move(port);
  sensor_ = std::move(sensor);
  std::lock_guard<std::mutex> lock(mu_);
  stats_.connected = true;
  stats_.device = *path;
  stats_.sensor = info.Describe();
  stats_.tm_round_trip_ms = clock_.tm_round_trip_ms();
  FL_LOG(INFO) << "connected to " << stats_.sensor << " on " << *path << " ("
               << (clock_.synced() ? "TM synchronised" : "no TM") << ")";
  return Status::Ok();
}

Status UrgDriver::Start(double give_up_s) {
  const Utime deadline = MonotonicUtime() + SecondsToUtime(std::min(give_up_s, 1e6));
  std::string path;
  for (;;) {
    Status s = ConnectOnce(&path);
    if (s.ok()) break;
    // With a port given, the first failure is the user's to fix; auto-discovery waits for a
    // sensor to be plugged in.
    if (!options_.port.empty() || path.size() > 0 || MonotonicUtime() >= deadline) return s;
    // SIGINT/SIGTERM while waiting for a sensor: a clean stop, with nothing started.
    if (stop_ || ShutdownRequested()) return Status::Ok();
    if (s.message() != stats().last_error) FL_LOG(INFO) << s.message() << "; waiting";
    SetError(s.message());
    UsbWatcher watcher;
    watcher.WaitForChange(static_cast<int>(options_.reconnect_interval_s * 1000));
  }
  thread_ = std::thread([this] { Run(); });
  return Status::Ok();
}

void UrgDriver::Stop() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
  if (sensor_) sensor_->Stop();  // laser off; an error here (device gone) does not matter
  sensor_.reset();
  port_.reset();
}

std::vector<LaserScan> UrgDriver::TakeScans() {
  std::lock_guard<std::mutex> lock(mu_);
  std::vector<LaserScan> out(std::make_move_iterator(queue_.begin()),
                             std::make_move_iterator(queue_.end()));
  queue_.clear();
  return out;
}

DriverStats UrgDriver::stats() const {
  std::lock_guard<std::mutex> lock(mu_);
  return stats_;
}

std::string UrgDriver::Stream() {
  const int timeout_ms = static_cast<int>(options_.stall_timeout_s * 1000);
  const int poll_ms = 100;  // to notice Stop()
  Utime last_scan = MonotonicUtime();
  while (!stop_) {
    Scan scan;
    std::string message;
    const ReadResult r = sensor_->ReadScan(&scan, poll_ms, &message);
    if (r == ReadResult::kScan) {
      last_scan = MonotonicUtime();
      clock_.AddArrival(scan.sensor_ms, scan.host_arrival);
      LaserScan out = ConvertScan(scan, sensor_->info(), clock_);
      if (!options_.streaming) {
        // Poll the next scan one period after this one.
        const double period = sensor_->info().scan_period_s() * (1 + options_.skip);
        const Utime next = scan.host_arrival + SecondsToUtime(period);
        while (!stop_ && NowUtime() < next) SleepS(0.002);
        if (Status s = sensor_->RequestScan(command_); !s.ok()) return s.message();
      }
      std::lock_guard<std::mutex> lock(mu_);
      queue_.push_back(std::move(out));
      while (queue_.size() > kMaxQueued) queue_.pop_front();
      ++stats_.scans;
      stats_.residual_ms = clock_.residual_ms();
      stats_.skew_ppm = clock_.skew_ppm();
      stats_.latency_ms = clock_.latency_ms();
      stats_.checksum_errors = sensor_->checksum_errors();
      stats_.malformed = sensor_->malformed();
      continue;
    }
    if (r == ReadResult::kDisconnected) return message;
    if (r == ReadResult::kChecksum || r == ReadResult::kMalformed) {
      std::lock_guard<std::mutex> lock(mu_);
      stats_.checksum_errors = sensor_->checksum_errors();
      stats_.malformed = sensor_->malformed();
      stats_.last_error = message;
      stats_.last_error_utime = MonotonicUtime();
      continue;
    }
    if (r == ReadResult::kDeviceError) {
      {
        std::lock_guard<std::mutex> lock(mu_);
        ++stats_.device_errors;
        stats_.last_error = message;
        stats_.last_error_utime = MonotonicUtime();
      }
      FL_LOG(WARN) << message;
    }
    if (r == ReadResult::kTimeout &&
        MonotonicUtime() - last_scan < static_cast<Utime>(timeout_ms) * 1000) {
      continue;
    }
    // A stalled stream (or an error status): stop and start it again.
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (r == ReadResult::kTimeout) ++stats_.stalls;
      stats_.last_error = r == ReadResult::kTimeout
                              ? "stream from '" + sensor_->name() + "' stalled for " +
                                    std::to_string(options_.stall_timeout_s) + " s; restarted"
                              : message;
      stats_.last_error_utime = MonotonicUtime();
    }
    FL_LOG(WARN) << "no scan from " << sensor_->name() << " for " << options_.stall_timeout_s
                 << " s: restarting the stream";
    if (Status s = sensor_->Stop(); !s.ok()) return s.message();
    Status s =
        options_.streaming ? sensor_->StartStreaming(command_) : sensor_->RequestScan(command_);
    if (!s.ok()) return s.message();
    last_scan = MonotonicUtime();
  }
  return "";
}

void UrgDriver::Run() {
  while (!stop_) {
    const std::string why = Stream();
    if (stop_) break;
    FL_LOG(WARN) << "lost the laser: " << why << "; reconnecting";
    {
      std::lock_guard<std::mutex> lock(mu_);
      stats_.connected = false;
      stats_.last_error = why;
      stats_.last_error_utime = MonotonicUtime();
    }
    sensor_.reset();
    port_.reset();
    std::unique_ptr<UsbWatcher> watcher;
    if (options_.port.empty()) watcher = std::make_unique<UsbWatcher>();
    while (!stop_) {
      std::string path;
      const Status s = ConnectOnce(&path);
      if (s.ok()) {
        std::lock_guard<std::mutex> lock(mu_);
        ++stats_.reconnects;
        break;
      }
      SetError(s.message());
      FL_LOG(DEBUG) << "reconnect: " << s.message();
      if (watcher) {
        watcher->WaitForChange(static_cast<int>(options_.reconnect_interval_s * 1000));
      } else {
        SleepS(options_.reconnect_interval_s);
      }
    }
  }
}

}  // namespace fl::urg
