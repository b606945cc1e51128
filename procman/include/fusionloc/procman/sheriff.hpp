// The sheriff's logic without LCM (the adapter is procman/lcm/sheriff_lcm.hpp): the desired
// state of every command of a .cfg, orders for each deputy, the deputies' reported state,
// scripts, and text orders (start|stop|restart NAME|GROUP|everything, run SCRIPT, status,
// quit).
//
// libbot2's model: the sheriff keeps no state the deputies do not have. Starting a command
// bumps its desired_runid, stopping sets force_quit; each deputy gets its full desired state
// in every order (about once a second, and at once after a change). A new sheriff adopts
// what the deputies already run: before its first orders to a host (when that host's status
// arrives, or after adopt_wait_s without one) it takes each matching command's sheriff_id
// and run id from the deputy, so nothing is restarted.
#pragma once

#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "fusionloc/common/status.hpp"
#include "fusionloc/procman/deputy.hpp"
#include "fusionloc/procman/procman_config.hpp"

namespace fl::procman {

struct SheriffOptions {
  std::string name = "fl-procman-sheriff";  // sheriff_name in the orders
  double adopt_wait_s = 1.5;    // [s] wait this long for a deputy's status before ordering it
  double order_period_s = 1.0;  // [s] orders repeated this often (libbot2: 1 s)
  bool observer = false;        // only watch: never send orders
  Status Validate() const;
};

// What the sheriff shows for a command.
enum class ShownState { kUnknown, kStopped, kStarting, kRunning, kRespawning, kStopping };
const char* ToString(ShownState state);

class Sheriff {
 public:
  // Throws std::invalid_argument for invalid options.
  Sheriff(ProcmanConfig config, SheriffOptions options);

  const ProcmanConfig& config() const { return config_; }

  // A deputy's status (PMD_INFO2). now_s: any monotonic clock [s].
  void HandleStatus(const HostStatus& status, double now_s);
  // The orders due now, one per host (empty for an observer).
  std::vector<Orders> DueOrders(double now_s, int64_t now_us);

  // start / stop / restart of commands (indices into config().commands). Observer: refused.
  void Start(const std::vector<size_t>& cmds);
  void Stop(const std::vector<size_t>& cmds);
  void Restart(const std::vector<size_t>& cmds);

  // One text order; returns the reply (the status table for "status"); *quit set by "quit".
  std::string Execute(const std::string& line, bool* quit);

  // Queues a script (after the running one). False (and *error) if there is no such script.
  bool RunScript(const std::string& name, std::string* error);
  // Advances the running script as far as its waits allow.
  void StepScripts(double now_s);
  bool ScriptRunning() const { return !frames_.empty() || !queued_.empty(); }

  ShownState State(size_t cmd) const;
  // True when the command counts as "running" / "stopped" for a script's wait.
  bool IsRunning(size_t cmd) const;
  bool IsStopped(size_t cmd) const;
  // The deputy's last report of a command (default-constructed before any).
  const CommandStatus& Reported(size_t cmd) const { return cmds_[cmd].reported; }
  bool HostSeen(const std::string& host) const {
    auto it = hosts_.find(host);
    return it != hosts_.end() && it->second.reported;
  }
  std::set<std::string> Hosts() const;

  // The live table: host, command, state, pid, run, starts, respawns, last exit, CPU, memory;
  // then a line per host: load, memory, order security, refused orders.
  std::string StatusTable() const;
  // The process table for a report: starts, restarts, last exit, CPU time, peak memory.
  std::string ReportTable() const;
  // Lines of what happened (script steps, orders), taken once.
  std::vector<std::string> TakeEvents();

 private:
  struct Cmd {
    int32_t sheriff_id = 0;  // 0 until adopted or assigned
    int32_t desired_runid = 0;
    bool force_quit = false;
    bool seen = false;  // its deputy reported it
    CommandStatus reported;
  };
  struct HostState {
    bool reported = false;  // its deputy's status arrived
    HostStatus last;        // its last status (host fields and options)
    bool ordered = false;   // orders sent (adoption is over)
    double last_orders_s = -1e9;
  };
  struct Frame {
    const ScriptConfig* script = nullptr;
    size_t next = 0;
    double wait_until_s = -1.0;     // wait ms
    std::vector<size_t> wait_cmds;  // wait status
    std::string wait_status;
  };
  void Event(const std::string& line);
  void Assign(const std::string& host);
  std::vector<size_t> ResolveText(const std::string& ident, std::string* error) const;
  bool Satisfied(const Frame& f) const;

  ProcmanConfig config_;
  SheriffOptions options_;
  std::vector<Cmd> cmds_;
  std::map<std::string, HostState> hosts_;
  std::set<std::string> dirty_;  // hosts whose orders changed
  double start_s_ = -1.0;
  std::vector<Frame> frames_;
  std::vector<std::string> queued_;
  std::vector<std::string> events_;
};

}  // namespace fl::procman
