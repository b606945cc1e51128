#include "fusionloc/urg/urg_emulator.hpp"

#include <fcntl.h>
#include <poll.h>
#include <stdlib.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include "fusionloc/sim/random.hpp"
#include "fusionloc/sim/sensors.hpp"
#include "fusionloc/sim/world.hpp"
#include "fusionloc/urg/scip2.hpp"

namespace fl::urg {
namespace {

namespace fs = std::filesystem;

// URG-04LX error codes (C-42-03320B table 3), cycled over the steps without a return.
constexpr uint32_t kErrorCodes[] = {0, 1, 2, 6, 7, 8, 9, 18, 19};
constexpr size_t kMaxSent = 10000;

bool AllDigits(const std::string& s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
}

}  // namespace

struct UrgEmulator::Scene {
  sim::World world;
  std::unique_ptr<sim::LaserModel> laser;
  fl::Pose2 pose;
  sim::Rng rng{1};
};

Status UrgEmulatorOptions::Validate() const {
  if (ares <= 0 || amin < 0 || amax < amin || afrt < amin || afrt > amax || max_step < amax)
    return Status::Error(
        "ares, amin, afrt, amax, max_step must satisfy 0 <= amin <= afrt <= "
        "amax <= max_step, ares > 0");
  if (dmin_mm <= 0 || dmax_mm <= dmin_mm) return Status::Error("need 0 < dmin_mm < dmax_mm");
  if (scan_rpm <= 0) return Status::Error("scan_rpm must be > 0");
  if (!(range_sigma_m >= 0)) return Status::Error("range_sigma_m must be >= 0");
  if (clock_start_ms < 0) return Status::Error("clock_start_ms must be >= 0");
  if (checksum_error_every < 0 || split_line_every < 0)
    return Status::Error("checksum_error_every and split_line_every must be >= 0");
  if (stall_after_s < 0 || stall_for_s < 0 || vanish_after_s < 0 || vanish_for_s < 0 ||
      split_pause_s < 0)
    return Status::Error("fault times must be >= 0");
  return world.Validate();
}

UrgEmulator::UrgEmulator(const UrgEmulatorOptions& options)
    : options_(options), scene_(std::make_unique<Scene>()) {
  sim::SimOptions so;
  so.seed = options.seed;
  so.world = options.world;
  scene_->world = sim::World::Build(so);
  sim::LaserOptions lo;
  lo.first_angle_deg = (options.amin - options.afrt) * 360.0 / options.ares;
  lo.step_deg = 360.0 / options.ares;
  lo.beams = options.amax - options.amin + 1;
  lo.min_range_m = options.dmin_mm * 1e-3;
  lo.max_range_m = options.dmax_mm * 1e-3;
  lo.range_sigma_m = options.range_sigma_m;
  lo.x_m = lo.y_m = 0.0;
  lo.z_m = options.z_m;
  scene_->laser = std::make_unique<sim::LaserModel>(lo);
  scene_->pose = fl::Pose2(options.x_m, options.y_m, options.yaw_rad);
  scene_->rng = sim::Rng(static_cast<uint64_t>(options.seed) * 7919 + 17);
  scene_->laser->TrueRanges(scene_->world, scene_->pose, &true_ranges_);
}

UrgEmulator::~UrgEmulator() { Stop(); }

double UrgEmulator::StepAngle(int step) const {
  return (step - options_.afrt) * 2.0 * M_PI / options_.ares;
}

Status UrgEmulator::OpenPty() {
  const int m = ::posix_openpt(O_RDWR | O_NOCTTY);
  if (m < 0) return Status::Error(std::string("posix_openpt failed: ") + std::strerror(errno));
  if (::grantpt(m) != 0 || ::unlockpt(m) != 0) {
    const int e = errno;
    ::close(m);
    return Status::Error(std::string("grantpt/unlockpt failed: ") + std::strerror(e));
  }
  const char* name = ::ptsname(m);
  if (name == nullptr) {
    ::close(m);
    return Status::Error("ptsname failed");
  }
  const std::string slave = name;
  const int s = ::open(slave.c_str(), O_RDWR | O_NOCTTY | O_CLOEXEC);
  if (s < 0) {
    const int e = errno;
    ::close(m);
    return Status::Error("cannot open the pty slave " + slave + ": " + std::strerror(e));
  }
  struct termios tio;
  ::tcgetattr(s, &tio);
  ::cfmakeraw(&tio);
  ::tcsetattr(s, TCSANOW, &tio);
  ::fcntl(m, F_SETFL, ::fcntl(m, F_GETFL) | O_NONBLOCK);
  ::fcntl(m, F_SETFD, FD_CLOEXEC);
  if (!options_.link.empty()) {
    // A new link beside the old one, then rename: the link is never missing or half-written.
    const std::string tmp = options_.link + ".tmp";
    std::error_code ec;
    fs::remove(tmp, ec);
    fs::create_symlink(slave, tmp, ec);
    if (!ec) fs::rename(tmp, options_.link, ec);
    if (ec) {
      ::close(s);
      ::close(m);
      return Status::Error("cannot create the link " + options_.link + " -> " + slave + ": " +
                           ec.message());
    }
  }
  std::lock_guard<std::mutex> lock(mu_);
  master_ = m;
  slave_keep_ = s;
  slave_ = slave;
  return Status::Ok();
}

void UrgEmulator::ClosePty() {
  std::lock_guard<std::mutex> lock(mu_);
  if (slave_keep_ >= 0) ::close(slave_keep_);
  if (master_ >= 0) ::close(master_);
  slave_keep_ = master_ = -1;
  if (!options_.link.empty()) {
    std::error_code ec;
    fs::remove(options_.link, ec);
  }
}

std::string UrgEmulator::slave_path() const {
  std::lock_guard<std::mutex> lock(mu_);
  return slave_;
}

std::string UrgEmulator::device_path() const {
  return options_.link.empty() ? slave_path() : options_.link;
}

void UrgEmulator::PowerOn(Utime now) {
  std::lock_guard<std::mutex> lock(mu_);
  power_on_ = now;
  scip2_ = !options_.scip1_at_power_on;
  laser_ = adjust_ = streaming_ = false;
  current_baud_ = 19200;
  input_.clear();
}

double UrgEmulator::SensorMs(Utime host) const {
  std::lock_guard<std::mutex> lock(mu_);
  return static_cast<double>(options_.clock_start_ms) +
         static_cast<double>(host - power_on_) * 1e-3 * (1.0 + options_.clock_skew_ppm * 1e-6);
}

Status UrgEmulator::Start() {
  if (Status s = options_.Validate(); !s.ok()) return s;
  if (Status s = OpenPty(); !s.ok()) return s;
  start_ = NowUtime();
  PowerOn(start_);
  stop_ = false;
  thread_ = std::thread([this] { Run(); });
  return Status::Ok();
}

void UrgEmulator::Stop() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
  ClosePty();
}

void UrgEmulator::InjectChecksumErrors(int n) {
  std::lock_guard<std::mutex> lock(mu_);
  checksum_left_ += n;
}
void UrgEmulator::InjectSplitLines(int n) {
  std::lock_guard<std::mutex> lock(mu_);
  split_left_ += n;
}
void UrgEmulator::Stall(double seconds) {
  std::lock_guard<std::mutex> lock(mu_);
  stall_until_ = NowUtime() + SecondsToUtime(seconds);
}
void UrgEmulator::Vanish(double seconds) {
  std::lock_guard<std::mutex> lock(mu_);
  vanish_at_ = NowUtime();
  back_at_ = vanish_at_ + SecondsToUtime(seconds);
}

std::vector<EmulatedScan> UrgEmulator::sent() const {
  std::lock_guard<std::mutex> lock(mu_);
  return std::vector<EmulatedScan>(sent_.begin(), sent_.end());
}

bool UrgEmulator::WriteAll(const std::string& bytes) {
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(master_, bytes.data() + done, bytes.size() - done);
    if (n > 0) {
      done += static_cast<size_t>(n);
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && errno == EAGAIN) {
      // Nobody reads (no driver): like the real sensor, the data is lost.
      struct pollfd p = {master_, POLLOUT, 0};
      if (::poll(&p, 1, 100) <= 0) return false;
      continue;
    }
    return false;
  }
  return true;
}

void UrgEmulator::Reply(const std::string& text) { WriteAll(text); }

std::string UrgEmulator::InfoReply(const std::string& echo, char which) const {
  using scip2::FormatInfoLine;
  std::string r = echo + "\n" + scip2::FormatStatusLine("00");
  const UrgEmulatorOptions& o = options_;
  if (which == 'V') {
    r += FormatInfoLine("VEND", o.vendor) + FormatInfoLine("PROD", o.product) +
         FormatInfoLine("FIRM", o.firmware) + FormatInfoLine("PROT", o.protocol) +
         FormatInfoLine("SERI", o.serial);
  } else if (which == 'P') {
    r += FormatInfoLine("MODL", o.model) + FormatInfoLine("DMIN", std::to_string(o.dmin_mm)) +
         FormatInfoLine("DMAX", std::to_string(o.dmax_mm)) +
         FormatInfoLine("ARES", std::to_string(o.ares)) +
         FormatInfoLine("AMIN", std::to_string(o.amin)) +
         FormatInfoLine("AMAX", std::to_string(o.amax)) +
         FormatInfoLine("AFRT", std::to_string(o.afrt)) +
         FormatInfoLine("SCAN", std::to_string(o.scan_rpm));
  } else {
    char time[16];
    std::snprintf(time, sizeof(time), "%06X",
                  static_cast<unsigned>(static_cast<int64_t>(SensorMs(NowUtime())) & 0xFFFFFF));
    r += FormatInfoLine("MODL", o.model) + FormatInfoLine("LASR", laser_ ? "ON" : "OFF") +
         FormatInfoLine(
             "SCSP", "Initial(" + std::to_string(o.scan_rpm) + "[rpm])<-Default setting by user") +
         FormatInfoLine("MESM", streaming_ ? "Measuring by Normal Mode" : "IDLE") +
         FormatInfoLine("SBPS", std::to_string(current_baud_) + "[bps]<-Default setting by user") +
         FormatInfoLine("TIME", time) + FormatInfoLine("STAT", "Sensor works well.");
  }
  return r + "\n";
}

std::vector<uint32_t> UrgEmulator::ScanValues(int start, int end, int cluster, int encoding) {
  std::vector<float> noisy;
  scene_->laser->Scan(scene_->world, scene_->pose, &scene_->rng, &noisy);
  const UrgEmulatorOptions& o = options_;
  const uint32_t max_value = encoding == 2 ? 4095u : static_cast<uint32_t>(o.dmax_mm);
  auto step_value = [&](int step) -> uint32_t {
    if (step < o.amin || step > o.amax) return 19;  // "non-measurable step"
    const float r = noisy[static_cast<size_t>(step - o.amin)];
    if (r <= 0.0f) return kErrorCodes[static_cast<size_t>(step) % std::size(kErrorCodes)];
    const long mm = std::lround(static_cast<double>(r) * 1000.0);
    return std::min<uint32_t>(max_value,
                              static_cast<uint32_t>(std::clamp<long>(mm, o.dmin_mm, o.dmax_mm)));
  };
  std::vector<uint32_t> out;
  const int c = std::max(1, cluster);
  for (int s = start; s <= end; s += c) {
    uint32_t best = 0;
    bool have = false;
    uint32_t first_code = 0;
    for (int k = s; k < std::min(end + 1, s + c); ++k) {
      const uint32_t v = step_value(k);
      if (v >= static_cast<uint32_t>(o.dmin_mm)) {
        if (!have || v < best) best = v;
        have = true;
      } else if (k == s) {
        first_code = v;
      }
    }
    out.push_back(have ? best : first_code);
  }
  return out;
}

void UrgEmulator::SendScan(Utime step0, bool streaming) {
  const double ms = SensorMs(step0);
  const uint32_t ts =
      static_cast<uint32_t>(static_cast<int64_t>(std::floor(ms)) % (int64_t{1} << 24));
  std::string echo;
  if (streaming) {
    char buf[32];
    std::snprintf(buf, sizeof(buf), "M%c%04d%04d%02d%01d%02d", encoding_ == 2 ? 'S' : 'D',
                  start_step_, end_step_, cluster_, skip_, infinite_ ? 0 : remaining_);
    echo = buf;
  } else {
    char buf[32];
    std::snprintf(buf, sizeof(buf), "G%c%04d%04d%02d", encoding_ == 2 ? 'S' : 'D', start_step_,
                  end_step_, cluster_);
    echo = buf;
  }
  if (!tag_.empty()) echo += ";" + tag_;
  const std::vector<uint32_t> values = ScanValues(start_step_, end_step_, cluster_, encoding_);
  std::string block = scip2::EncodeDataBlock(values, encoding_);
  bool corrupt = false, split = false;
  {
    std::lock_guard<std::mutex> lock(mu_);
    ++scan_index_;
    const uint64_t k = scan_index_;
    if (checksum_left_ > 0) {
      --checksum_left_;
      corrupt = true;
    } else if (options_.checksum_error_every > 0 && k % options_.checksum_error_every == 0) {
      corrupt = true;
    }
    if (split_left_ > 0) {
      --split_left_;
      split = true;
    } else if (options_.split_line_every > 0 && k % options_.split_line_every == 0) {
      split = true;
    }
  }
  if (corrupt) {
    // The checksum character of the second data line (or the first if there is one).
    size_t first_lf = block.find('\n');
    size_t second_lf = block.find('\n', first_lf + 1);
    const size_t pos = (second_lf != std::string::npos ? second_lf : first_lf) - 1;
    block[pos] = block[pos] == '0' ? '1' : static_cast<char>(block[pos] - 1);
  }
  const std::string text = echo + "\n" + scip2::FormatStatusLine(streaming ? "99" : "00") +
                           scip2::Encode(ts, 4) + scip2::Checksum(scip2::Encode(ts, 4)) + "\n" +
                           block + "\n";
  if (split) {
    // Cut in the middle of the second data line (in a value, most likely).
    const size_t header = text.find('\n', text.find('\n', text.find('\n') + 1) + 1) + 1;
    const size_t cut = std::min(text.size() - 2, header + 64 + 1 + 31);
    WriteAll(text.substr(0, cut));
    std::this_thread::sleep_for(std::chrono::microseconds(SecondsToUtime(options_.split_pause_s)));
    WriteAll(text.substr(cut));
  } else {
    WriteAll(text);
  }
  EmulatedScan e;
  e.timestamp_ms = ts;
  e.host_step0 = step0;
  e.start_step = start_step_;
  e.cluster = cluster_;
  e.corrupted = corrupt;
  for (int s = start_step_; s <= end_step_; ++s) {
    e.true_ranges.push_back(s >= options_.amin && s <= options_.amax
                                ? true_ranges_[static_cast<size_t>(s - options_.amin)]
                                : 0.0f);
  }
  std::lock_guard<std::mutex> lock(mu_);
  sent_.push_back(std::move(e));
  while (sent_.size() > kMaxSent) sent_.pop_front();
}

void UrgEmulator::HandleLine(const std::string& raw, Utime now) {
  ++commands_;
  const std::string line = raw;
  auto status_reply = [&](const std::string& st) {
    Reply(line + "\n" + scip2::FormatStatusLine(st) + "\n");
  };
  const size_t semi = line.find(';');
  const std::string body = line.substr(0, semi);
  const std::string tag = semi == std::string::npos ? "" : line.substr(semi + 1);
  if (!scip2_) {
    // SCIP 1.1: the switch command answers a bare "0" (C-42-03320B section 2); SCIP 2.0
    // commands mean nothing here and get no SCIP 2.0 reply.
    if (line == "SCIP2.0") {
      scip2_ = true;
      Reply("SCIP2.0\n0\n\n");
    }
    return;
  }
  if (tag.size() > 16) return status_reply("0G");
  if (body == "SCIP2.0") return status_reply("0E");  // already in SCIP 2.0
  if (body.size() < 2) return status_reply("0D");
  const std::string cmd = body.substr(0, 2);
  const std::string args = body.substr(2);
  const double period_us = 60.0e6 / options_.scan_rpm;
  if (cmd == "VV" || cmd == "PP" || cmd == "II") {
    if (!args.empty()) return status_reply("0C");
    return Reply(InfoReply(line, cmd[0]));
  }
  if (cmd == "BM") {
    if (laser_) return status_reply("02");
    laser_ = true;
    return status_reply("00");
  }
  if (cmd == "QT") {
    laser_ = streaming_ = false;
    return status_reply("00");
  }
  if (cmd == "RS") {
    laser_ = streaming_ = adjust_ = false;
    current_baud_ = 19200;
    {
      std::lock_guard<std::mutex> lock(mu_);
      power_on_ = now;  // the timer is reset
    }
    return status_reply("00");
  }
  if (cmd == "TM") {
    if (args == "0") {
      if (adjust_) return status_reply("02");
      adjust_ = true;
      laser_ = streaming_ = false;
      return status_reply("00");
    }
    if (args == "2") {
      if (!adjust_) return status_reply("03");
      adjust_ = false;
      return status_reply("00");
    }
    if (args == "1") {
      if (!adjust_) return status_reply("04");
      const uint32_t ts = static_cast<uint32_t>(
          static_cast<int64_t>(std::floor(SensorMs(NowUtime()))) % (int64_t{1} << 24));
      const std::string t = scip2::Encode(ts, 4);
      return Reply(line + "\n" + scip2::FormatStatusLine("00") + t + scip2::Checksum(t) + "\n\n");
    }
    return status_reply("01");
  }
  if (cmd == "SS") {
    if (args.size() != 6 || !AllDigits(args)) return status_reply("01");
    const int baud = std::stoi(args);
    if (baud != 19200 && baud != 38400 && baud != 57600 && baud != 115200 && baud != 250000 &&
        baud != 500000 && baud != 750000)
      return status_reply("02");
    if (baud == current_baud_) return status_reply("03");
    current_baud_ = baud;  // USB: accepted, no effect on the link
    return status_reply("00");
  }
  if (cmd == "MD" || cmd == "MS" || cmd == "GD" || cmd == "GS") {
    const bool md = cmd[0] == 'M';
    if (args.size() != (md ? 13u : 10u)) return status_reply("0C");
    const std::string s_start = args.substr(0, 4), s_end = args.substr(4, 4),
                      s_cluster = args.substr(8, 2);
    if (!AllDigits(s_start)) return status_reply("01");
    if (!AllDigits(s_end)) return status_reply("02");
    if (!AllDigits(s_cluster)) return status_reply("03");
    const int start = std::stoi(s_start), end = std::stoi(s_end), cluster = std::stoi(s_cluster);
    if (end > options_.max_step) return status_reply("04");
    if (end < start) return status_reply("05");
    int skip = 0, scans = 0;
    if (md) {
      if (!AllDigits(args.substr(10, 1))) return status_reply("06");
      if (!AllDigits(args.substr(11, 2))) return status_reply("07");
      skip = std::stoi(args.substr(10, 1));
      scans = std::stoi(args.substr(11, 2));
    }
    encoding_ = cmd[1] == 'S' ? 2 : 3;
    start_step_ = start;
    end_step_ = end;
    cluster_ = std::max(1, cluster);
    tag_ = tag;
    if (!md) {
      if (!laser_) return status_reply("10");
      // The last complete scan: its step 0 was at least the scan time before now.
      const double turns = std::floor(
          (static_cast<double>(now - power_on_) - period_us * (end_step_ + 1.0) / options_.ares) /
          period_us);
      SendScan(power_on_ + static_cast<Utime>(turns * period_us), false);
      return;
    }
    status_reply("00");
    laser_ = streaming_ = true;
    skip_ = skip;
    skip_count_ = 0;
    infinite_ = scans == 0;
    remaining_ = scans;
    // The next turn of the motor.
    const double turns = std::ceil(static_cast<double>(now - power_on_) / period_us);
    next_scan_ = power_on_ + static_cast<Utime>(turns * period_us);
    return;
  }
  status_reply("0D");
}

void UrgEmulator::Run() {
  const double period_us = 60.0e6 / options_.scan_rpm;
  bool stalled = false;
  while (!stop_) {
    const Utime now = NowUtime();
    // Periodic faults from the options.
    {
      std::lock_guard<std::mutex> lock(mu_);
      const double t = UtimeToSeconds(now - start_);
      if (!periodic_stall_done_ && options_.stall_for_s > 0 && t >= options_.stall_after_s) {
        periodic_stall_done_ = true;
        stall_until_ = now + SecondsToUtime(options_.stall_for_s);
      }
      if (!periodic_vanish_done_ && options_.vanish_for_s > 0 && t >= options_.vanish_after_s) {
        periodic_vanish_done_ = true;
        vanish_at_ = now;
        back_at_ = now + SecondsToUtime(options_.vanish_for_s);
      }
    }
    Utime vanish_at, back_at, stall_until;
    {
      std::lock_guard<std::mutex> lock(mu_);
      vanish_at = vanish_at_;
      back_at = back_at_;
      stall_until = stall_until_;
    }
    if (vanish_at > 0 && now >= vanish_at) {
      ClosePty();
      ++vanishes_;
      while (!stop_ && NowUtime() < back_at) {
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
      }
      {
        std::lock_guard<std::mutex> lock(mu_);
        vanish_at_ = back_at_ = 0;
      }
      if (stop_) break;
      if (!OpenPty().ok()) break;
      PowerOn(NowUtime());  // a device that comes back has been power-cycled
      continue;
    }
    stalled = now < stall_until;
    // Wait for a command or the next scan.
    const double send_delay_us = period_us * (end_step_ + 1.0) / options_.ares;
    Utime wake = now + 20000;
    if (streaming_) wake = std::min(wake, next_scan_ + static_cast<Utime>(send_delay_us));
    struct pollfd p = {master_, POLLIN, 0};
    const int timeout_ms = static_cast<int>(std::max<Utime>(0, (wake - now) / 1000));
    if (::poll(&p, 1, timeout_ms) > 0 && (p.revents & POLLIN)) {
      char buf[512];
      const ssize_t n = ::read(master_, buf, sizeof(buf));
      if (n > 0) {
        for (ssize_t i = 0; i < n; ++i) {
          const char c = buf[i];
          if (c == '\n' || c == '\r') {
            if (!input_.empty() && !stalled) HandleLine(input_, NowUtime());
            input_.clear();
          } else if (input_.size() < 64) {
            input_.push_back(c);
          }
        }
      }
    }
    if (!streaming_) continue;
    const Utime t = NowUtime();
    while (streaming_ && t >= next_scan_ + static_cast<Utime>(send_delay_us)) {
      const Utime step0 = next_scan_;
      next_scan_ = step0 + static_cast<Utime>(period_us);
      if (stalled) continue;  // a stalled sensor sends nothing
      if (skip_count_++ % (skip_ + 1) != 0) continue;
      if (!infinite_) --remaining_;
      SendScan(step0, true);
      if (!infinite_ && remaining_ <= 0) streaming_ = laser_ = false;
    }
  }
}

}  // namespace fl::urg
