#include "fusionloc/procman/sheriff.hpp"

#include <sys/wait.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <iomanip>
#include <sstream>
#include <stdexcept>

#include "fusionloc/procman/process.hpp"

namespace fl::procman {

const char* ToString(ShownState state) {
  switch (state) {
    case ShownState::kUnknown:
      return "unknown";
    case ShownState::kStopped:
      return "stopped";
    case ShownState::kStarting:
      return "starting";
    case ShownState::kRunning:
      return "running";
    case ShownState::kRespawning:
      return "respawning";
    case ShownState::kStopping:
      return "stopping";
  }
  return "?";
}

Status SheriffOptions::Validate() const {
  if (adopt_wait_s < 0) return Status::Error("adopt_wait_s must be >= 0");
  if (order_period_s <= 0) return Status::Error("order_period_s must be > 0");
  if (name.empty()) return Status::Error("the sheriff needs a name");
  return Status::Ok();
}

Sheriff::Sheriff(ProcmanConfig config, SheriffOptions options)
    : config_(std::move(config)), options_(std::move(options)), cmds_(config_.commands.size()) {
  const Status s = options_.Validate();
  if (!s.ok()) throw std::invalid_argument("sheriff options: " + s.message());
}

std::set<std::string> Sheriff::Hosts() const {
  std::set<std::string> h;
  for (const CommandConfig& c : config_.commands) h.insert(c.host);
  return h;
}

void Sheriff::Event(const std::string& line) { events_.push_back(line); }

std::vector<std::string> Sheriff::TakeEvents() {
  std::vector<std::string> out;
  out.swap(events_);
  return out;
}

void Sheriff::HandleStatus(const HostStatus& status, double /*now_s*/) {
  HostState& host = hosts_[status.host];
  host.reported = true;
  if (status.mem_total_bytes > 0) {  // a full status (not the lone ranger's quick one)
    host.last = status;
    host.last.cmds.clear();
  }
  for (size_t i = 0; i < cmds_.size(); ++i) {
    if (config_.commands[i].host == status.host) cmds_[i].seen = false;
  }
  for (const CommandStatus& r : status.cmds) {
    const std::string path = r.spec.group.empty() ? r.spec.name : r.spec.group + "/" + r.spec.name;
    for (size_t i = 0; i < cmds_.size(); ++i) {
      const CommandConfig& c = config_.commands[i];
      Cmd& m = cmds_[i];
      if (c.host != status.host) continue;
      if (!host.ordered && m.sheriff_id == 0 && c.path() == path) {
        // Adopt what this deputy runs: its id and run id, so that nothing restarts.
        m.sheriff_id = r.spec.sheriff_id;
        m.desired_runid = r.actual_runid;
        m.force_quit = false;
        Event("adopted " + c.path() + " on " + c.host + " (" + ToString(r.state) +
              (r.pid > 0 ? ", pid " + std::to_string(r.pid) : std::string()) + ")");
      }
      if (m.sheriff_id != 0 && m.sheriff_id == r.spec.sheriff_id) {
        m.seen = true;
        m.reported = r;
      }
    }
  }
}

void Sheriff::Assign(const std::string& host) {
  int32_t next = 0;
  for (const Cmd& m : cmds_) next = std::max(next, m.sheriff_id);
  for (size_t i = 0; i < cmds_.size(); ++i) {
    if (config_.commands[i].host == host && cmds_[i].sheriff_id == 0) cmds_[i].sheriff_id = ++next;
  }
}

std::vector<Orders> Sheriff::DueOrders(double now_s, int64_t now_us) {
  if (start_s_ < 0) start_s_ = now_s;
  std::vector<Orders> out;
  if (options_.observer) return out;
  for (const std::string& host : Hosts()) {
    HostState& h = hosts_[host];
    if (!h.ordered) {
      const bool seen = h.reported;
      if (!seen && now_s - start_s_ < options_.adopt_wait_s) continue;
      Assign(host);
      h.ordered = true;
      dirty_.insert(host);
      if (!seen) Event("no status from deputy '" + host + "' yet; ordering it anyway");
    }
    if (dirty_.count(host) == 0 && now_s - h.last_orders_s < options_.order_period_s) continue;
    dirty_.erase(host);
    h.last_orders_s = now_s;
    Orders o;
    o.utime_us = now_us;
    o.host = host;
    o.sheriff_name = options_.name;
    for (size_t i = 0; i < cmds_.size(); ++i) {
      const CommandConfig& c = config_.commands[i];
      if (c.host != host) continue;
      CommandOrder co;
      co.spec.sheriff_id = cmds_[i].sheriff_id;
      co.spec.name = c.name;
      co.spec.group = c.group;
      co.spec.exec = c.exec;
      co.spec.auto_respawn = c.auto_respawn;
      co.spec.stop_signal = c.stop_signal;
      co.spec.stop_time_allowed_s = c.stop_time_allowed_s;
      co.desired_runid = cmds_[i].desired_runid;
      co.force_quit = cmds_[i].force_quit;
      o.cmds.push_back(co);
    }
    out.push_back(o);
  }
  return out;
}

void Sheriff::Start(const std::vector<size_t>& cmds) {
  for (size_t i : cmds) {
    Cmd& m = cmds_[i];
    if (IsRunning(i) || State(i) == ShownState::kStarting) continue;
    m.desired_runid = std::max(m.desired_runid, m.reported.actual_runid) + 1;
    m.force_quit = false;
    dirty_.insert(config_.commands[i].host);
  }
}

void Sheriff::Stop(const std::vector<size_t>& cmds) {
  for (size_t i : cmds) {
    cmds_[i].force_quit = true;
    dirty_.insert(config_.commands[i].host);
  }
}

void Sheriff::Restart(const std::vector<size_t>& cmds) {
  for (size_t i : cmds) {
    Cmd& m = cmds_[i];
    m.desired_runid = std::max(m.desired_runid, m.reported.actual_runid) + 1;
    m.force_quit = false;
    dirty_.insert(config_.commands[i].host);
  }
}

bool Sheriff::IsRunning(size_t i) const {
  const Cmd& m = cmds_[i];
  return m.seen && !m.force_quit && m.reported.pid > 0 &&
         m.reported.actual_runid == m.desired_runid;
}

bool Sheriff::IsStopped(size_t i) const {
  const Cmd& m = cmds_[i];
  return m.seen && m.reported.pid == 0 && m.reported.state != CommandState::kRespawnWait &&
         (m.force_quit || m.reported.actual_runid == m.desired_runid);
}

ShownState Sheriff::State(size_t i) const {
  const Cmd& m = cmds_[i];
  if (!m.seen) return ShownState::kUnknown;
  if (m.force_quit) return m.reported.pid > 0 ? ShownState::kStopping : ShownState::kStopped;
  if (m.reported.actual_runid != m.desired_runid) return ShownState::kStarting;
  if (m.reported.pid > 0) return ShownState::kRunning;
  if (m.reported.state == CommandState::kRespawnWait) return ShownState::kRespawning;
  return ShownState::kStopped;
}

std::vector<size_t> Sheriff::ResolveText(const std::string& ident, std::string* error) const {
  if (ident == "everything") return config_.Resolve(TargetKind::kEverything, "");
  bool ambiguous = false;
  std::vector<size_t> r = config_.Resolve(TargetKind::kCmd, ident, &ambiguous);
  if (r.empty() && !ambiguous) r = config_.Resolve(TargetKind::kGroup, ident);
  if (r.empty()) {
    *error = ambiguous ? "'" + ident + "' names several commands: write its group/name"
                       : "no command or group '" + ident + "' in " + config_.file;
  }
  return r;
}

std::string Sheriff::Execute(const std::string& line, bool* quit) {
  std::istringstream in(line);
  std::vector<std::string> w;
  for (std::string s; in >> s;) w.push_back(s);
  if (w.empty()) return "";
  const std::string& verb = w[0];
  const std::string kUsage =
      "orders: start|stop|restart NAME|GROUP|everything, run SCRIPT, status, quit";
  if (verb == "status" && w.size() == 1) return StatusTable();
  if (verb == "quit" && w.size() == 1) {
    *quit = true;
    return "quitting (the deputies keep running their commands)";
  }
  if (verb == "help" && w.size() == 1) return kUsage;
  if (verb == "run" && w.size() == 2) {
    std::string error;
    if (options_.observer) return "error: an observer sends no orders";
    if (!RunScript(w[1], &error)) return "error: " + error;
    return "running script " + w[1];
  }
  if ((verb == "start" || verb == "stop" || verb == "restart") && w.size() == 2) {
    if (options_.observer) return "error: an observer sends no orders";
    std::string error;
    const std::vector<size_t> targets = ResolveText(w[1], &error);
    if (targets.empty()) return "error: " + error;
    for (const std::string& h : Hosts()) {
      if (!hosts_[h].ordered) return "error: still looking for the deputies; try again in a second";
    }
    if (verb == "start") Start(targets);
    if (verb == "stop") Stop(targets);
    if (verb == "restart") Restart(targets);
    std::string names;
    for (size_t i : targets) names += (names.empty() ? "" : ", ") + config_.commands[i].path();
    return verb + ": " + names;
  }
  return "error: cannot read '" + line + "'; " + kUsage;
}

bool Sheriff::RunScript(const std::string& name, std::string* error) {
  if (config_.FindScript(name) == nullptr) {
    std::string known;
    for (const ScriptConfig& s : config_.scripts) known += (known.empty() ? "" : ", ") + s.name;
    *error = "no script '" + name + "' in " + config_.file +
             (known.empty() ? " (it has none)" : " (it has: " + known + ")");
    return false;
  }
  queued_.push_back(name);
  return true;
}

bool Sheriff::Satisfied(const Frame& f) const {
  if (!f.wait_status.empty()) {
    for (size_t i : f.wait_cmds) {
      if (f.wait_status == "running" ? !IsRunning(i) : !IsStopped(i)) return false;
    }
  }
  return true;
}

void Sheriff::StepScripts(double now_s) {
  if (options_.observer) return;
  for (const std::string& h : Hosts()) {
    if (!hosts_[h].ordered) return;  // adoption first
  }
  for (int guard = 0; guard < 10000; ++guard) {
    if (frames_.empty()) {
      if (queued_.empty()) return;
      frames_.emplace_back();
      frames_.back().script = config_.FindScript(queued_.front());
      queued_.erase(queued_.begin());
      Event("script " + frames_.back().script->name + ": started");
    }
    Frame& f = frames_.back();
    if (f.wait_until_s >= 0 && now_s < f.wait_until_s) return;
    f.wait_until_s = -1;
    if (!Satisfied(f)) return;
    f.wait_status.clear();
    f.wait_cmds.clear();
    if (f.next >= f.script->actions.size()) {
      Event("script " + f.script->name + ": done");
      frames_.pop_back();
      continue;
    }
    const ScriptAction& a = f.script->actions[f.next++];
    const std::string who = a.target == TargetKind::kEverything
                                ? "everything"
                                : (a.target == TargetKind::kCmd ? "cmd " : "group ") + a.ident;
    switch (a.kind) {
      case ActionKind::kStart:
      case ActionKind::kStop:
      case ActionKind::kRestart: {
        const std::vector<size_t> t = config_.Resolve(a.target, a.ident);
        const char* verb = a.kind == ActionKind::kStart  ? "start"
                           : a.kind == ActionKind::kStop ? "stop"
                                                         : "restart";
        if (a.kind == ActionKind::kStart) Start(t);
        if (a.kind == ActionKind::kStop) Stop(t);
        if (a.kind == ActionKind::kRestart) Restart(t);
        Event("script " + f.script->name + ": " + verb + " " + who +
              (a.wait_status.empty() ? "" : ", wait until " + a.wait_status));
        f.wait_cmds = t;
        f.wait_status = a.wait_status;
        break;
      }
      case ActionKind::kWaitMs:
        f.wait_until_s = now_s + a.wait_ms * 1e-3;
        break;
      case ActionKind::kWaitStatus:
        f.wait_cmds = config_.Resolve(a.target, a.ident);
        f.wait_status = a.wait_status;
        Event("script " + f.script->name + ": wait until " + who + " is " + a.wait_status);
        break;
      case ActionKind::kRunScript: {
        Event("script " + f.script->name + ": run_script " + a.ident);
        const ScriptConfig* sub = config_.FindScript(a.ident);
        frames_.emplace_back();  // invalidates f
        frames_.back().script = sub;
        break;
      }
    }
  }
}

namespace {

std::string ExitText(const CommandStatus& r) {
  if (!r.exited) return "-";
  if (WIFEXITED(r.exit_status)) return std::to_string(WEXITSTATUS(r.exit_status));
  if (WIFSIGNALED(r.exit_status)) return std::string("SIG") + sigabbrev_np(WTERMSIG(r.exit_status));
  return "?";
}

std::string Mb(int64_t bytes) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.1f", static_cast<double>(bytes) / (1024.0 * 1024.0));
  return buf;
}

}  // namespace

std::string Sheriff::StatusTable() const {
  std::ostringstream o;
  o << std::left << std::setw(10) << "host" << std::setw(24) << "command" << std::setw(11)
    << "state" << std::right << std::setw(8) << "pid" << std::setw(5) << "run" << std::setw(7)
    << "starts" << std::setw(9) << "respawns" << std::setw(8) << "exit" << std::setw(7) << "cpu%"
    << std::setw(9) << "rss_MB"
    << "\n";
  for (size_t i = 0; i < cmds_.size(); ++i) {
    const CommandConfig& c = config_.commands[i];
    const CommandStatus& r = cmds_[i].reported;
    char cpu[16];
    std::snprintf(cpu, sizeof(cpu), "%.0f", r.cpu_usage * 100.0);
    o << std::left << std::setw(10) << c.host << std::setw(24) << c.path() << std::setw(11)
      << ToString(State(i)) << std::right << std::setw(8)
      << (r.pid > 0 ? std::to_string(r.pid) : "-") << std::setw(5) << r.actual_runid << std::setw(7)
      << r.starts << std::setw(9) << r.respawns << std::setw(8) << ExitText(r) << std::setw(7)
      << cpu << std::setw(9) << Mb(r.rss_bytes);
    if (!r.error.empty()) o << "  (" << r.error << ")";
    o << "\n";
  }
  for (const std::string& host : Hosts()) {
    auto it = hosts_.find(host);
    if (it == hosts_.end() || !it->second.reported) {
      o << "host " << host << ": no status from its deputy\n";
      continue;
    }
    const HostStatus& h = it->second.last;
    if (h.mem_total_bytes <= 0) continue;
    char line[160];
    std::snprintf(line, sizeof(line), "host %s: load %.0f%%, memory %.1f of %.1f GB free",
                  host.c_str(), h.cpu_load * 100.0, h.mem_free_bytes / 1e9,
                  h.mem_total_bytes / 1e9);
    o << line;
    auto opt = [&](const char* k) {
      auto f = h.options.find(k);
      return f == h.options.end() ? std::string() : f->second;
    };
    if (!opt("security").empty()) o << "; " << opt("security");
    if (!opt("refused_orders").empty() && opt("refused_orders") != "0") {
      o << "; refused orders " << opt("refused_orders");
    }
    o << "\n";
  }
  return o.str();
}

std::string Sheriff::ReportTable() const {
  std::ostringstream o;
  o << std::left << std::setw(24) << "command" << std::setw(10) << "host" << std::right
    << std::setw(7) << "starts" << std::setw(9) << "restarts" << std::setw(10) << "last exit"
    << std::setw(10) << "cpu_s" << std::setw(13) << "peak_rss_MB"
    << "\n";
  for (size_t i = 0; i < cmds_.size(); ++i) {
    const CommandConfig& c = config_.commands[i];
    const CommandStatus& r = cmds_[i].reported;
    char cpu[16];
    std::snprintf(cpu, sizeof(cpu), "%.1f", r.cpu_time_s);
    o << std::left << std::setw(24) << c.path() << std::setw(10) << c.host << std::right
      << std::setw(7) << r.starts << std::setw(9) << std::max(0, r.starts - 1) << std::setw(10)
      << ExitText(r) << std::setw(10) << cpu << std::setw(13) << Mb(r.peak_rss_bytes);
    if (!r.error.empty()) o << "  (" << r.error << ")";
    o << "\n";
  }
  return o.str();
}

}  // namespace fl::procman
