// The deputy's process control, without LCM (the adapter is procman/lcm/deputy_lcm.hpp):
// it runs the commands a sheriff orders on this host, with libbot2's semantics.
//
// Orders are stateless: each one carries the full desired state of this deputy's commands,
// identified by sheriff_id.
//  - orders for another host, or older than max_order_age_s, are ignored;
//  - a command not known yet is added (not started); one missing from the orders is stopped
//    and removed;
//  - force_quit set: the command is stopped (and stays stopped);
//  - else a desired_runid different from the command's actual_runid starts a new run (a
//    running command is stopped first: a restart), which takes that run id.
// A command runs in its own process group; its stdout+stderr are captured, appended to
// LOG_DIR/<name>.log and handed to the output callback (-> PMD_PRINTF). When it exits and
// auto_respawn is set (and it was not stopped), it is started again after a back-off that
// begins at min_respawn_delay_s and doubles up to max_respawn_delay_s (libbot2: 10 ms to
// 1 s), reset once a run has lasted max_respawn_delay_s. Stopping sends stop_signal to the
// group, then SIGKILL after stop_time_allowed. No child outlives the deputy: PDEATHSIG and an
// OrphanGuard (process.hpp).
#pragma once

#include <sys/types.h>

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "fusionloc/common/status.hpp"
#include "fusionloc/procman/process.hpp"

namespace fl::procman {

struct CommandSpec {
  int32_t sheriff_id = 0;            // the sheriff's id of the command
  std::string name;                  // command_name
  std::string group;                 // group path ("" | "g/sub")
  std::string exec;                  // command line (SplitShellWords)
  bool auto_respawn = false;         // restart when it exits
  int stop_signal = 2;               // [signal number] first sent to stop it
  double stop_time_allowed_s = 7.0;  // [s] then SIGKILL
  bool operator==(const CommandSpec& o) const {
    return sheriff_id == o.sheriff_id && name == o.name && group == o.group && exec == o.exec &&
           auto_respawn == o.auto_respawn && stop_signal == o.stop_signal &&
           stop_time_allowed_s == o.stop_time_allowed_s;
  }
};

struct CommandOrder {
  CommandSpec spec;
  int32_t desired_runid = 0;  // [count] differs from actual_runid: start a new run
  bool force_quit = false;    // must not run
};

struct Orders {
  int64_t utime_us = 0;  // [us since the epoch] when sent
  std::string host;      // the deputy they are for
  std::string sheriff_name;
  std::vector<CommandOrder> cmds;
};

enum class CommandState { kStopped, kRunning, kRespawnWait, kStopping };
const char* ToString(CommandState state);

struct CommandStatus {
  CommandSpec spec;
  CommandState state = CommandState::kStopped;
  pid_t pid = 0;               // 0 when not running
  int32_t actual_runid = 0;    // [count] of the current or last run
  int exit_status = 0;         // [waitpid status] of the last exit (0 before any)
  bool exited = false;         // there was an exit
  double cpu_usage = 0.0;      // [fraction of one core] over the last status period
  double cpu_time_s = 0.0;     // [s] user+system, summed over every run
  int64_t vsize_bytes = 0;     // [bytes] now, summed over its process group
  int64_t rss_bytes = 0;       // [bytes] now, summed over its process group
  int64_t peak_rss_bytes = 0;  // [bytes] highest resident size seen, over every run
  int starts = 0;              // [count] runs started (respawns included)
  int respawns = 0;            // [count] automatic restarts (auto_respawn)
  std::string error;           // why it could not be started ("" if fine)
  std::string log_path;        // LOG_DIR/<name>.log
};

struct HostStatus {
  int64_t utime_us = 0;  // [us since the epoch]
  std::string host;
  double cpu_load = 0.0;         // [fraction, 0..1] over the last status period
  int64_t mem_total_bytes = 0;   // [bytes]
  int64_t mem_free_bytes = 0;    // [bytes] available
  int64_t swap_total_bytes = 0;  // [bytes]
  int64_t swap_free_bytes = 0;   // [bytes]
  std::vector<CommandStatus> cmds;
  std::map<std::string, std::string> options;  // extra keys (security, refused orders)
};

enum class OrdersVerdict { kApplied, kOtherHost, kStale };

struct DeputyOptions {
  std::string name;                         // this host's deputy name ("" = the hostname)
  std::string log_dir = "out/procman";      // LOG_DIR for <command>.log (created)
  std::map<std::string, std::string> vars;  // ${NAME} values for exec (then the environment)
  double max_order_age_s = 60.0;            // [s] older orders are ignored (libbot2: 60)
  double min_respawn_delay_s = 0.01;        // [s] first respawn back-off (libbot2: 10 ms)
  double max_respawn_delay_s = 1.0;         // [s] back-off ceiling (libbot2: 1 s)
  bool orphan_guard = true;                 // start the OrphanGuard process
  Status Validate() const;
};

class Deputy {
 public:
  // Output of a command (sheriff_id) or of the deputy itself (0): bytes as read.
  using OutputFn = std::function<void(int32_t sheriff_id, const std::string& text)>;
  // Throws std::invalid_argument for invalid options or a log folder that cannot be made.
  Deputy(DeputyOptions options, OutputFn output);
  ~Deputy();  // stops every command (stop signal, then SIGKILL after its time)
  Deputy(const Deputy&) = delete;
  Deputy& operator=(const Deputy&) = delete;

  const std::string& name() const { return options_.name; }
  void set_output(OutputFn output) { output_ = std::move(output); }

  // Applies orders (see the file comment). now_us: wall clock [us since the epoch].
  OrdersVerdict HandleOrders(const Orders& orders, int64_t now_us);
  // Reaps exits, forwards output, respawns, escalates stops. Call often (every ~10 ms).
  void Poll();
  // Measures CPU and memory and returns the status (CPU over the time since the last call).
  HostStatus MeasureStatus(int64_t now_us);
  // The last status without measuring again (states, pids, run ids are current).
  std::vector<CommandStatus> Commands() const;
  // Stops everything and waits (up to each command's stop_time_allowed, then SIGKILL).
  void StopAll();
  // Counts starts, exits and stops begun: a status is worth sending when it changes.
  uint64_t changes() const { return changes_; }
  // True while some command is running or stopping.
  bool AnyRunning() const;

 private:
  struct Command {
    CommandStatus status;
    bool remove_when_stopped = false;
    bool start_when_stopped = false;
    int32_t pending_runid = 0;
    double stop_deadline_s = 0.0;  // [s] SIGKILL then
    bool killed = false;
    double respawn_at_s = 0.0;
    double backoff_s = 0.0;
    double started_at_s = 0.0;
    int output_fd = -1;
    int log_fd = -1;
    uint64_t last_cpu_ticks = 0;
    uint64_t ticks_before_this_run = 0;
  };
  double Now() const;
  void Say(const std::string& text);
  Command* Find(int32_t sheriff_id);
  void Start(Command* c, int32_t runid);
  void BeginStop(Command* c);
  void OnExit(Command* c, int wait_status);
  void DrainOutput(Command* c);

  DeputyOptions options_;
  OutputFn output_;
  OrphanGuard guard_;
  std::vector<std::unique_ptr<Command>> cmds_;
  HostUsage last_host_;
  double last_measure_s_ = -1.0;
  uint64_t changes_ = 0;
};

}  // namespace fl::procman
