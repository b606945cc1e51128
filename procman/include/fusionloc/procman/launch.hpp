// Launch files for fl-procman: which processes make up a run, how to start them and what to
// do when one exits. Parsed with the project's YAML loader (unknown keys are errors).
//
//   name: sim_demo
//   processes:
//     - name: rbpf_slam
//       command: ${BIN}/fl-rbpf-slam --lcm-url=${LCM_URL}
//       restart: on_failure        # never | on_failure | always
//     - name: sim
//       command: ${BIN}/fl-sim --lcm-url=${LCM_URL} --rate 1
//       start_delay_s: 2           # let the subscribers come up first
//       on_exit: stop_all          # the run ends when the simulator's route is done
//
// Commands are split on whitespace (double quotes group words) and run directly with
// execvp, never through a shell. ${NAME} is replaced from the variables given to fl-procman
// (--vars NAME=VALUE), then from the environment; an unknown name is an error naming it.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "fusionloc/common/status.hpp"

namespace fl::procman {

struct ProcessSpec {
  std::string name;                    // unique; [A-Za-z0-9_-]; also the log file name
  std::string command;                 // program and arguments (see the file comment)
  std::string restart = "on_failure";  // never | on_failure (non-zero exit or signal) | always
  int max_restarts = 3;                // restarts before the process is given up
  double restart_delay_s = 1.0;        // [s] wait before a restart
  double start_delay_s = 0.0;          // [s] after the launch starts
  std::string on_exit = "continue";    // continue | stop_all (its exit ends the run)
  bool required = true;                // given up after a failure -> the run stops and fails

  template <class A>
  void Serialize(A* a) {
    a->Visit("name", &name);
    a->Visit("command", &command);
    a->Visit("restart", &restart);
    a->Visit("max_restarts", &max_restarts);
    a->Visit("restart_delay_s", &restart_delay_s);
    a->Visit("start_delay_s", &start_delay_s);
    a->Visit("on_exit", &on_exit);
    a->Visit("required", &required);
  }
  Status Validate() const;
};

struct LaunchFile {
  std::string name = "launch";  // shown in status lines and the report
  double stop_timeout_s = 5.0;  // [s] SIGTERM, then SIGKILL after this long
  double end_grace_s = 3.0;     // [s] after a stop_all exit, before the others are stopped
                                // (estimators finish the queue, the fusion saves its map)
  std::vector<ProcessSpec> processes;

  template <class A>
  void Serialize(A* a) {
    a->Visit("name", &name);
    a->Visit("stop_timeout_s", &stop_timeout_s);
    a->Visit("end_grace_s", &end_grace_s);
    a->Visit("processes", &processes);
  }
  Status Validate() const;
};

// Loads and validates a launch file; throws fl::ConfigError with file:line on bad input.
LaunchFile LoadLaunchFile(const std::string& path);

// Replaces every ${NAME}: from `vars`, then the environment. False (and *error names the
// variable and the fix) if a name is unknown or a ${ is not closed.
bool ExpandVariables(const std::string& text, const std::map<std::string, std::string>& vars,
                     std::string* out, std::string* error);

// Splits a command line on blanks; "double quotes" keep blanks. False on an open quote.
bool SplitCommand(const std::string& command, std::vector<std::string>* argv, std::string* error);

}  // namespace fl::procman
