#include "fusionloc/procman/supervisor.hpp"

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/procman/process.hpp"

namespace fl::procman {

const char* ToString(ProcessState state) {
  switch (state) {
    case ProcessState::kWaiting: return "waiting";
    case ProcessState::kRunning: return "running";
    case ProcessState::kBackoff: return "restarting";
    case ProcessState::kExited: return "exited";
    case ProcessState::kFailed: return "failed";
    case ProcessState::kStopped: return "stopped";
  }
  return "?";
}

Supervisor::Supervisor(const LaunchFile& launch, SupervisorOptions options)
    : launch_(launch), options_(std::move(options)) {
  const Status valid = launch_.Validate();
  if (!valid.ok()) throw std::invalid_argument("launch file '" + launch_.name + "': " + valid.message());
  std::error_code ec;
  std::filesystem::create_directories(options_.log_dir, ec);
  if (ec) {
    throw std::invalid_argument("cannot create log folder '" + options_.log_dir +
                                "': " + ec.message());
  }
  for (const ProcessSpec& spec : launch_.processes) {
    Proc p;
    p.spec = spec;
    std::string expanded, error;
    if (!ExpandVariables(spec.command, options_.vars, &expanded, &error) ||
        !SplitCommand(expanded, &p.argv, &error)) {
      throw std::invalid_argument("process '" + spec.name + "': " + error);
    }
    p.next_start_s = spec.start_delay_s;
    procs_.push_back(p);
    ProcessStatus s;
    s.name = spec.name;
    s.log_path = (std::filesystem::path(options_.log_dir) / (spec.name + ".log")).string();
    status_.push_back(s);
  }
}

Supervisor::~Supervisor() {
  if (!stopping_) StopAll();
}

double Supervisor::Now() const {
  using Clock = std::chrono::steady_clock;
  return std::chrono::duration<double>(Clock::now().time_since_epoch()).count() - t0_;
}

void Supervisor::Print(const std::string& line) const {
  if (options_.print) {
    options_.print(line);
  } else {
    std::cout << "[procman " << launch_.name << "] " << line << std::endl;
  }
}

bool Supervisor::Active(size_t i) const {
  const ProcessState s = status_[i].state;
  return s == ProcessState::kWaiting || s == ProcessState::kRunning ||
         s == ProcessState::kBackoff;
}

bool Supervisor::Start(size_t i) {
  Proc& p = procs_[i];
  ProcessStatus& st = status_[i];
  SpawnOptions spawn;
  spawn.capture_output = false;
  spawn.output_path = st.log_path;
  const SpawnResult r = SpawnProcess(p.argv, spawn);
  if (r.pid < 0) {
    st.error = r.error;
    return false;
  }
  const pid_t pid = r.pid;
  st.pid = pid;
  st.state = ProcessState::kRunning;
  st.error.clear();
  if (st.starts > 0) ++st.restarts;
  ++st.starts;
  p.started_at_s = Now();
  Print("started " + p.spec.name + " (pid " + std::to_string(pid) + "): " + p.argv[0] +
        (st.restarts > 0 ? ", restart " + std::to_string(st.restarts) : std::string()));
  return true;
}

void Supervisor::OnExit(size_t i, int wait_status) {
  Proc& p = procs_[i];
  ProcessStatus& st = status_[i];
  st.pid = -1;
  st.uptime_s += Now() - p.started_at_s;
  st.exit_code = WIFEXITED(wait_status) ? WEXITSTATUS(wait_status) : -1;
  st.exit_signal = WIFSIGNALED(wait_status) ? WTERMSIG(wait_status) : 0;
  const bool failed = st.exit_code != 0;
  const std::string how = st.exit_signal != 0
                              ? std::string("killed by signal ") + strsignal(st.exit_signal)
                              : "exit code " + std::to_string(st.exit_code);
  if (stopping_) {
    st.state = ProcessState::kStopped;
    return;
  }
  Print(p.spec.name + " ended (" + how + ")" +
        (failed ? "; its output: " + st.log_path : std::string()));
  if (p.spec.on_exit == "stop_all") {
    st.state = failed ? ProcessState::kFailed : ProcessState::kExited;
    if (!end_requested_) {
      end_requested_ = true;
      end_at_s_ = Now() + launch_.end_grace_s;
      result_.ok = !failed;
      result_.reason = p.spec.name + " ended (" + how + "), which ends the run";
    }
    return;
  }
  const bool wants_restart =
      p.spec.restart == "always" || (p.spec.restart == "on_failure" && failed);
  if (wants_restart && st.restarts < p.spec.max_restarts && !end_requested_) {
    st.state = ProcessState::kBackoff;
    p.next_start_s = Now() + p.spec.restart_delay_s;
    return;
  }
  st.state = failed ? ProcessState::kFailed : ProcessState::kExited;
  if (failed && p.spec.required && !end_requested_) {
    st.error = "gave up after " + std::to_string(st.restarts) + " restarts";
    end_requested_ = true;
    end_at_s_ = Now();
    result_.ok = false;
    result_.reason = "required process " + p.spec.name + " failed (" + how + ") after " +
                     std::to_string(st.restarts) + " restarts; see " + st.log_path;
  }
}

void Supervisor::Reap() {
  for (;;) {
    int ws = 0;
    const pid_t pid = waitpid(-1, &ws, WNOHANG);
    if (pid <= 0) return;
    for (size_t i = 0; i < procs_.size(); ++i) {
      if (status_[i].pid == pid) OnExit(i, ws);
    }
  }
}

void Supervisor::StopAll() {
  stopping_ = true;
  for (size_t k = procs_.size(); k-- > 0;) {
    ProcessStatus& st = status_[k];
    if (st.state == ProcessState::kWaiting || st.state == ProcessState::kBackoff) {
      st.state = ProcessState::kStopped;
    }
    if (st.pid <= 0) continue;
    kill(-st.pid, SIGTERM);
    const double deadline = Now() + launch_.stop_timeout_s;
    while (st.pid > 0 && Now() < deadline) {
      Reap();
      if (st.pid > 0) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    if (st.pid > 0) {
      Print(st.name + " did not stop within " + std::to_string(launch_.stop_timeout_s) +
            " s of SIGTERM; SIGKILL");
      kill(-st.pid, SIGKILL);
      int ws = 0;
      waitpid(st.pid, &ws, 0);
      OnExit(k, ws);
    }
  }
}

RunResult Supervisor::Run() {
  t0_ = 0.0;
  t0_ = Now();
  result_ = RunResult();
  double next_status = options_.status_period_s;
  for (;;) {
    Reap();
    if (stop_requested_ || ShutdownRequested()) {
      if (!end_requested_) {
        result_.ok = true;
        result_.reason = "stop requested";
      }
      break;
    }
    if (end_requested_ && Now() >= end_at_s_) break;
    bool any_active = false;
    for (size_t i = 0; i < procs_.size(); ++i) {
      ProcessStatus& st = status_[i];
      if ((st.state == ProcessState::kWaiting || st.state == ProcessState::kBackoff) &&
          !end_requested_ && Now() >= procs_[i].next_start_s) {
        if (!Start(i)) {
          st.state = ProcessState::kFailed;
          Print(st.name + ": " + st.error);
          if (procs_[i].spec.required && !end_requested_) {
            end_requested_ = true;
            end_at_s_ = Now();
            result_.ok = false;
            result_.reason = "required process " + st.name + ": " + st.error;
          }
        }
      }
      any_active = any_active || Active(i);
    }
    if (!any_active) {
      if (!end_requested_) {
        result_.ok = true;
        result_.reason = "every process has ended";
      }
      break;
    }
    if (options_.status_period_s > 0.0 && Now() >= next_status) {
      next_status += options_.status_period_s;
      std::ostringstream line;
      line << std::fixed << std::setprecision(0) << Now() << " s:";
      for (const ProcessStatus& s : status_) {
        line << " " << s.name << "=" << ToString(s.state);
        if (s.restarts > 0) line << "(" << s.restarts << " restarts)";
      }
      Print(line.str());
    }
    std::this_thread::sleep_for(std::chrono::duration<double>(options_.poll_period_s));
  }
  StopAll();
  return result_;
}

std::string Supervisor::ReportTable() const {
  std::ostringstream o;
  o << std::left << std::setw(14) << "process" << std::setw(11) << "state" << std::right
    << std::setw(7) << "starts" << std::setw(9) << "restarts" << std::setw(11) << "last exit"
    << std::setw(10) << "uptime_s" << "  log\n";
  for (const ProcessStatus& s : status_) {
    std::string exit = "-";
    if (s.exit_signal != 0) {
      exit = std::string("SIG") + sigabbrev_np(s.exit_signal);
    } else if (s.exit_code >= 0) {
      exit = std::to_string(s.exit_code);
    }
    o << std::left << std::setw(14) << s.name << std::setw(11) << ToString(s.state) << std::right
      << std::setw(7) << s.starts << std::setw(9) << s.restarts << std::setw(11) << exit
      << std::setw(10) << std::fixed << std::setprecision(1) << s.uptime_s << "  " << s.log_path;
    if (!s.error.empty()) o << "  (" << s.error << ")";
    o << "\n";
  }
  return o.str();
}

}  // namespace fl::procman
