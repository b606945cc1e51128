// libbot2's procman `.cfg` format, as bot-procman-sheriff reads it:
//
//   # a comment
//   cmd "logger" { exec = "lcm-logger --force ${RUN_DIR}/run.lcmlog"; host = "compute"; }
//   group "estimators" {
//     cmd "rbpf_slam" {
//       exec = "${BIN}/fl-rbpf-slam";
//       host = "compute";            # or: deputy = "compute";
//       auto_respawn = "true";       # "true" | "false" (default false)
//       stop_signal = 15;            # integer >= 1 (default 2, SIGINT, as libbot2)
//       stop_time_allowed = 5;       # [s] integer >= 1 (default 7, as libbot2)
//     }
//     group "vision" { cmd "stereo_vo" { ... } }   # nested: "estimators/vision"
//   }
//   script "bringup" {
//     start cmd "logger" wait "running";
//     wait ms 1000;
//     start group "estimators";
//     stop group "estimators/vision" wait "stopped";
//     restart cmd "estimators/rbpf_slam";
//     start everything;
//     wait cmd "logger" status "running";
//     run_script "other";
//   }
//
// A command is referenced by its name ("rbpf_slam", if unique) or its path with the groups
// ("estimators/rbpf_slam"); a group by its path. Errors throw fl::ConfigError with
// FILE:LINE:COLUMN and what was expected.
#pragma once

#include <string>
#include <vector>

namespace fl::procman {

struct CommandConfig {
  std::string name;           // the cmd's name (the exec string if the cmd has none, as libbot2)
  std::string group;          // group path, "" | "g" | "g/sub"
  std::string exec;           // the command line (split by SplitShellWords when started)
  std::string host;           // the deputy that runs it
  bool auto_respawn = false;  // restart it when it exits
  int stop_signal = 2;        // [signal number] first sent to stop it (SIGINT)
  double stop_time_allowed_s = 7;  // [s] after stop_signal, before SIGKILL
  int line = 0;                    // where it is defined
  std::string path() const { return group.empty() ? name : group + "/" + name; }
};

enum class ActionKind { kStart, kStop, kRestart, kWaitMs, kWaitStatus, kRunScript };
enum class TargetKind { kEverything, kCmd, kGroup };

struct ScriptAction {
  ActionKind kind = ActionKind::kStart;
  TargetKind target = TargetKind::kEverything;
  std::string ident;        // cmd or group reference, or the script of run_script
  std::string wait_status;  // "" | "running" | "stopped"
  int wait_ms = 0;          // [ms] for wait ms N
  int line = 0;
};

struct ScriptConfig {
  std::string name;
  std::vector<ScriptAction> actions;
  int line = 0;
};

struct ProcmanConfig {
  std::string file;
  std::vector<CommandConfig> commands;  // in file order
  std::vector<std::string> groups;      // every group path
  std::vector<ScriptConfig> scripts;

  const ScriptConfig* FindScript(const std::string& name) const;
  // Indices of the commands that `ident` names: a command (by path, or by name when that
  // is unique), or a group path (its commands and its subgroups'). Empty when nothing matches;
  // *ambiguous is set when a bare name matches several commands.
  std::vector<size_t> Resolve(TargetKind kind, const std::string& ident,
                              bool* ambiguous = nullptr) const;
};

// Parses `text` (`file` names it in errors). Throws fl::ConfigError.
ProcmanConfig ParseProcmanConfig(const std::string& text, const std::string& file);
// Reads and parses a file. Throws fl::ConfigError (also when it cannot be read).
ProcmanConfig LoadProcmanConfig(const std::string& path);

}  // namespace fl::procman
