// Supervisor: starts the processes of a launch file, restarts them by their policy, and stops
// them all cleanly (SIGTERM, then SIGKILL after stop_timeout_s, in reverse launch order so
// that e.g. a logger listed first records until the end).
//
// Each process runs in its own process group with stdin from /dev/null and stdout+stderr
// appended to <log_dir>/<name>.log. A program that cannot be executed (missing, not
// executable) is reported with the exec error, not as an anonymous exit code 127.
//
// The run ends when a process with on_exit: stop_all exits (after end_grace_s the others are
// stopped; the run succeeds if that exit was clean), when a required process fails for good
// (restarts exhausted; the run fails naming it and its log), when every process has ended,
// or on SIGINT/SIGTERM to the supervisor (fl::ShutdownRequested) or Stop().
#pragma once

#include <sys/types.h>

#include <atomic>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "fusionloc/procman/launch.hpp"

namespace fl::procman {

enum class ProcessState { kWaiting, kRunning, kBackoff, kExited, kFailed, kStopped };
const char* ToString(ProcessState state);

struct ProcessStatus {
  std::string name;
  ProcessState state = ProcessState::kWaiting;
  pid_t pid = -1;
  int starts = 0;          // successful execs
  int restarts = 0;        // starts after the first
  int exit_code = -1;      // of the last exit (-1: none yet, or killed by a signal)
  int exit_signal = 0;     // signal that ended the last run (0: none)
  std::string error;       // exec failure or why it was given up
  double uptime_s = 0.0;   // [s] summed over all runs
  std::string log_path;
};

struct SupervisorOptions {
  std::string log_dir = ".";                 // created if missing
  std::map<std::string, std::string> vars;   // ${NAME} values for the commands
  double poll_period_s = 0.02;               // [s] child-state polling
  double status_period_s = 0.0;              // [s] one status line this often (0: never)
  std::function<void(const std::string&)> print;  // status/event lines (default: stdout)
};

struct RunResult {
  bool ok = false;
  std::string reason;  // one line: why the run ended
};

class Supervisor {
 public:
  // Throws std::invalid_argument if the launch file is invalid or a command cannot be
  // expanded/split (message names the process and the fix).
  Supervisor(const LaunchFile& launch, SupervisorOptions options);
  ~Supervisor();  // stops whatever still runs
  Supervisor(const Supervisor&) = delete;
  Supervisor& operator=(const Supervisor&) = delete;

  RunResult Run();
  void Stop() { stop_requested_ = true; }  // thread-safe; Run() then stops everything

  const std::vector<ProcessStatus>& statuses() const { return status_; }
  // A plain-text table: name, state, starts, restarts, last exit, uptime, log.
  std::string ReportTable() const;

 private:
  struct Proc {
    ProcessSpec spec;
    std::vector<std::string> argv;
    double next_start_s = 0.0;  // [s] since Run() began
    double started_at_s = 0.0;
  };
  double Now() const;
  void Print(const std::string& line) const;
  bool Start(size_t i);
  void Reap();
  void OnExit(size_t i, int wait_status);
  void StopAll();
  bool Active(size_t i) const;

  LaunchFile launch_;
  SupervisorOptions options_;
  std::vector<Proc> procs_;
  std::vector<ProcessStatus> status_;
  std::atomic<bool> stop_requested_{false};
  bool stopping_ = false;
  bool end_requested_ = false;
  double end_at_s_ = 0.0;
  RunResult result_;
  double t0_ = 0.0;
};

}  // namespace fl::procman
