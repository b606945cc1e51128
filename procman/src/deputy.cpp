#include "fusionloc/procman/deputy.hpp"

#include <fcntl.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <thread>

#include "fusionloc/common/log.hpp"
#include "fusionloc/procman/shell_words.hpp"

namespace fl::procman {

const char* ToString(CommandState state) {
  switch (state) {
    case CommandState::kStopped:
      return "stopped";
    case CommandState::kRunning:
      return "running";
    case CommandState::kRespawnWait:
      return "respawning";
    case CommandState::kStopping:
      return "stopping";
  }
  return "?";
}

Status DeputyOptions::Validate() const {
  if (max_order_age_s <= 0) return Status::Error("max_order_age_s must be > 0");
  if (min_respawn_delay_s <= 0 || max_respawn_delay_s < min_respawn_delay_s) {
    return Status::Error("respawn delays: need 0 < min_respawn_delay_s <= max_respawn_delay_s");
  }
  if (log_dir.empty()) return Status::Error("log_dir is empty");
  return Status::Ok();
}

namespace {

std::string HostName() {
  char buf[256] = {0};
  if (gethostname(buf, sizeof(buf) - 1) != 0 || buf[0] == '\0') return "localhost";
  return buf;
}

// A command name as a file name.
std::string FileName(const std::string& name) {
  std::string out;
  for (char c : name)
    out +=
        (std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' || c == '.') ? c : '_';
  return out.empty() ? "cmd" : out;
}

}  // namespace

Deputy::Deputy(DeputyOptions options, OutputFn output)
    : options_(std::move(options)), output_(std::move(output)) {
  if (options_.name.empty()) options_.name = HostName();
  const Status s = options_.Validate();
  if (!s.ok()) throw std::invalid_argument("deputy options: " + s.message());
  std::error_code ec;
  std::filesystem::create_directories(options_.log_dir, ec);
  if (ec) {
    throw std::invalid_argument("cannot create the log folder '" + options_.log_dir +
                                "': " + ec.message());
  }
  if (options_.orphan_guard) {
    std::string error;
    if (!guard_.Start(&error)) throw std::runtime_error("cannot start the orphan guard: " + error);
  }
  last_host_ = ReadHostUsage();
}

Deputy::~Deputy() { StopAll(); }

double Deputy::Now() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

void Deputy::Say(const std::string& text) {
  FL_LOG(INFO) << text;
  if (output_) output_(0, text + "\n");
}

Deputy::Command* Deputy::Find(int32_t sheriff_id) {
  for (auto& c : cmds_) {
    if (c->status.spec.sheriff_id == sheriff_id) return c.get();
  }
  return nullptr;
}

OrdersVerdict Deputy::HandleOrders(const Orders& orders, int64_t now_us) {
  if (orders.host != options_.name) return OrdersVerdict::kOtherHost;
  const double age_s = static_cast<double>(now_us - orders.utime_us) * 1e-6;
  if (age_s > options_.max_order_age_s || age_s < -options_.max_order_age_s) {
    return OrdersVerdict::kStale;
  }
  std::vector<Command*> seen;
  for (const CommandOrder& o : orders.cmds) {
    Command* c = Find(o.spec.sheriff_id);
    if (c == nullptr) {
      cmds_.push_back(std::make_unique<Command>());
      c = cmds_.back().get();
      c->status.spec = o.spec;
      c->backoff_s = options_.min_respawn_delay_s;
    }
    seen.push_back(c);
    c->remove_when_stopped = false;
    if (!(c->status.spec == o.spec)) c->status.spec = o.spec;  // takes effect at the next start
    CommandStatus& st = c->status;
    if (o.force_quit) {
      c->start_when_stopped = false;
      if (st.state == CommandState::kRunning) BeginStop(c);
      if (st.state == CommandState::kRespawnWait) st.state = CommandState::kStopped;
    } else if (o.desired_runid != st.actual_runid) {
      if (st.state == CommandState::kRunning || st.state == CommandState::kStopping) {
        if (!c->start_when_stopped || c->pending_runid != o.desired_runid) {
          c->start_when_stopped = true;
          c->pending_runid = o.desired_runid;
          if (st.state == CommandState::kRunning) BeginStop(c);
        }
      } else {
        c->backoff_s = options_.min_respawn_delay_s;
        Start(c, o.desired_runid);
      }
    }
  }
  for (auto& c : cmds_) {
    if (std::find(seen.begin(), seen.end(), c.get()) != seen.end()) continue;
    c->remove_when_stopped = true;
    c->start_when_stopped = false;
    if (c->status.state == CommandState::kRunning) BeginStop(c.get());
  }
  cmds_.erase(std::remove_if(cmds_.begin(), cmds_.end(),
                             [](const std::unique_ptr<Command>& c) {
                               return c->remove_when_stopped &&
                                      (c->status.state == CommandState::kStopped ||
                                       c->status.state == CommandState::kRespawnWait);
                             }),
              cmds_.end());
  return OrdersVerdict::kApplied;
}

void Deputy::Start(Command* c, int32_t runid) {
  CommandStatus& st = c->status;
  st.actual_runid = runid;
  st.error.clear();
  std::vector<std::string> argv;
  std::string error;
  if (!SplitShellWords(st.spec.exec, options_.vars, &argv, &error)) {
    st.error = "exec \"" + st.spec.exec + "\": " + error;
    st.state = CommandState::kStopped;
    Say(st.spec.name + ": " + st.error);
    return;
  }
  st.log_path = options_.log_dir + "/" + FileName(st.spec.name) + ".log";
  if (c->log_fd < 0) {
    c->log_fd = open(st.log_path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  }
  SpawnOptions spawn;
  spawn.capture_output = true;
  const SpawnResult r = SpawnProcess(argv, spawn);
  if (r.pid < 0) {
    st.error = r.error;
    st.state = CommandState::kStopped;
    Say(st.spec.name + ": " + r.error);
    return;
  }
  if (options_.orphan_guard) guard_.Watch(r.pid);
  st.pid = r.pid;
  st.state = CommandState::kRunning;
  ++changes_;
  ++st.starts;
  c->output_fd = r.output_fd;
  c->started_at_s = Now();
  c->killed = false;
  c->ticks_before_this_run = static_cast<uint64_t>(st.cpu_time_s * ClockTicksPerSecond());
  c->last_cpu_ticks = 0;
  Say("started " + st.spec.name + " (pid " + std::to_string(r.pid) + ", run " +
      std::to_string(runid) + ")");
}

void Deputy::BeginStop(Command* c) {
  CommandStatus& st = c->status;
  if (st.pid <= 0) return;
  kill(-st.pid, st.spec.stop_signal);
  st.state = CommandState::kStopping;
  ++changes_;
  c->stop_deadline_s = Now() + st.spec.stop_time_allowed_s;
}

void Deputy::DrainOutput(Command* c) {
  if (c->output_fd < 0) return;
  char buf[4096];
  for (int k = 0; k < 16; ++k) {
    const ssize_t n = read(c->output_fd, buf, sizeof(buf));
    if (n > 0) {
      if (c->log_fd >= 0) (void)!write(c->log_fd, buf, static_cast<size_t>(n));
      if (output_) output_(c->status.spec.sheriff_id, std::string(buf, static_cast<size_t>(n)));
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    if (n == 0) {  // every writer is gone
      close(c->output_fd);
      c->output_fd = -1;
    }
    return;
  }
}

void Deputy::OnExit(Command* c, int ws) {
  CommandStatus& st = c->status;
  DrainOutput(c);
  if (c->output_fd >= 0) {
    close(c->output_fd);
    c->output_fd = -1;
  }
  kill(-st.pid, SIGKILL);  // what it left behind in its group goes with it
  if (options_.orphan_guard) guard_.Unwatch(st.pid);
  const int64_t peak = ReadPeakRss(st.pid);  // 0: already gone
  st.peak_rss_bytes = std::max(st.peak_rss_bytes, peak);
  st.pid = 0;
  ++changes_;
  st.exit_status = ws;
  st.exited = true;
  st.rss_bytes = 0;
  st.vsize_bytes = 0;
  st.cpu_usage = 0.0;
  const double ran_s = Now() - c->started_at_s;
  const bool was_stopping = st.state == CommandState::kStopping;
  Say(st.spec.name + " ended (" + DescribeWaitStatus(ws) + ") after " +
      std::to_string(static_cast<int>(ran_s * 1000)) + " ms");
  if (c->start_when_stopped) {
    c->start_when_stopped = false;
    c->backoff_s = options_.min_respawn_delay_s;
    Start(c, c->pending_runid);
    return;
  }
  if (!was_stopping && !c->remove_when_stopped && st.spec.auto_respawn) {
    if (ran_s >= options_.max_respawn_delay_s) c->backoff_s = options_.min_respawn_delay_s;
    st.state = CommandState::kRespawnWait;
    c->respawn_at_s = Now() + c->backoff_s;
    c->backoff_s = std::min(c->backoff_s * 2.0, options_.max_respawn_delay_s);
    return;
  }
  st.state = CommandState::kStopped;
}

void Deputy::Poll() {
  const double now = Now();
  for (auto& cp : cmds_) {
    Command* c = cp.get();
    CommandStatus& st = c->status;
    DrainOutput(c);
    if (st.pid > 0) {
      int ws = 0;
      rusage ru{};
      const pid_t r = wait4(st.pid, &ws, WNOHANG, &ru);
      if (r == st.pid) {
        // The exact totals of the run (it and the children it waited for).
        const double run_cpu_s =
            static_cast<double>(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
            1e-6 * static_cast<double>(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
        st.cpu_time_s = std::max(
            st.cpu_time_s,
            static_cast<double>(c->ticks_before_this_run) / ClockTicksPerSecond() + run_cpu_s);
        st.peak_rss_bytes =
            std::max<int64_t>(st.peak_rss_bytes, static_cast<int64_t>(ru.ru_maxrss) * 1024);
        OnExit(c, ws);
        continue;
      }
    }
    if (st.state == CommandState::kStopping && !c->killed && now >= c->stop_deadline_s) {
      Say(st.spec.name + " did not stop within " +
          std::to_string(static_cast<int>(st.spec.stop_time_allowed_s)) + " s of signal " +
          std::to_string(st.spec.stop_signal) + "; SIGKILL");
      kill(-st.pid, SIGKILL);
      c->killed = true;
    }
    if (st.state == CommandState::kRespawnWait && now >= c->respawn_at_s) {
      ++st.respawns;
      Start(c, st.actual_runid);
    }
  }
  cmds_.erase(std::remove_if(cmds_.begin(), cmds_.end(),
                             [](const std::unique_ptr<Command>& c) {
                               return c->remove_when_stopped &&
                                      c->status.state != CommandState::kRunning &&
                                      c->status.state != CommandState::kStopping;
                             }),
              cmds_.end());
}

HostStatus Deputy::MeasureStatus(int64_t now_us) {
  const double now = Now();
  const double dt = last_measure_s_ < 0 ? 0.0 : now - last_measure_s_;
  last_measure_s_ = now;
  std::vector<pid_t> groups;
  for (auto& c : cmds_) {
    if (c->status.pid > 0) groups.push_back(c->status.pid);
  }
  const std::map<pid_t, GroupUsage> usage = ReadGroupUsage(groups);
  const double hz = ClockTicksPerSecond();
  HostStatus h;
  h.utime_us = now_us;
  h.host = options_.name;
  for (auto& c : cmds_) {
    CommandStatus& st = c->status;
    if (st.pid > 0) {
      const GroupUsage& u = usage.at(st.pid);
      const uint64_t ticks = std::max(u.cpu_ticks, c->last_cpu_ticks);
      st.cpu_usage = dt > 0 ? static_cast<double>(ticks - c->last_cpu_ticks) / hz / dt : 0.0;
      c->last_cpu_ticks = ticks;
      st.cpu_time_s = static_cast<double>(c->ticks_before_this_run + ticks) / hz;
      st.rss_bytes = u.rss_bytes;
      st.vsize_bytes = u.vsize_bytes;
      st.peak_rss_bytes = std::max({st.peak_rss_bytes, u.rss_bytes, ReadPeakRss(st.pid)});
    }
    h.cmds.push_back(st);
  }
  const HostUsage host = ReadHostUsage();
  if (host.total_ticks > last_host_.total_ticks) {
    h.cpu_load = static_cast<double>(host.busy_ticks - last_host_.busy_ticks) /
                 static_cast<double>(host.total_ticks - last_host_.total_ticks);
  }
  last_host_ = host;
  h.mem_total_bytes = host.mem_total_bytes;
  h.mem_free_bytes = host.mem_available_bytes;
  h.swap_total_bytes = host.swap_total_bytes;
  h.swap_free_bytes = host.swap_free_bytes;
  return h;
}

std::vector<CommandStatus> Deputy::Commands() const {
  std::vector<CommandStatus> out;
  for (const auto& c : cmds_) out.push_back(c->status);
  return out;
}

bool Deputy::AnyRunning() const {
  for (const auto& c : cmds_) {
    if (c->status.pid > 0) return true;
  }
  return false;
}

void Deputy::StopAll() {
  for (auto& c : cmds_) {
    c->start_when_stopped = false;
    c->remove_when_stopped = false;
    if (c->status.state == CommandState::kRunning) BeginStop(c.get());
    if (c->status.state == CommandState::kRespawnWait) c->status.state = CommandState::kStopped;
  }
  while (AnyRunning()) {
    Poll();
    if (AnyRunning()) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  for (auto& c : cmds_) {
    if (c->log_fd >= 0) close(c->log_fd);
    c->log_fd = -1;
  }
}

}  // namespace fl::procman
