#include "fusionloc/procman/procman_lcm.hpp"

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <random>

#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/status_t.hpp"

namespace fl::procman {
namespace {

void SetOptions(const std::map<std::string, std::string>& in, int32_t* n,
                std::vector<std::string>* names, std::vector<std::string>* values) {
  names->clear();
  values->clear();
  for (const auto& [k, v] : in) {
    names->push_back(k);
    values->push_back(v);
  }
  *n = static_cast<int32_t>(names->size());
}

std::map<std::string, std::string> GetOptions(const std::vector<std::string>& names,
                                              const std::vector<std::string>& values) {
  std::map<std::string, std::string> out;
  for (size_t i = 0; i < names.size() && i < values.size(); ++i) out[names[i]] = values[i];
  return out;
}

CommandSpec FromLcm(const bot_procman::command2_t& c, int32_t sheriff_id) {
  CommandSpec s;
  s.sheriff_id = sheriff_id;
  s.name = c.command_name;
  s.group = c.group;
  s.exec = c.exec_str;
  s.auto_respawn = c.auto_respawn;
  s.stop_signal = c.stop_signal > 0 ? c.stop_signal : 2;
  s.stop_time_allowed_s = c.stop_time_allowed > 0 ? c.stop_time_allowed : 7.0;
  return s;
}

bot_procman::command2_t ToLcm(const CommandSpec& s) {
  bot_procman::command2_t c;
  c.exec_str = s.exec;
  c.command_name = s.name;
  c.group = s.group;
  c.auto_respawn = s.auto_respawn;
  c.stop_signal = static_cast<int8_t>(s.stop_signal);
  c.stop_time_allowed = static_cast<float>(s.stop_time_allowed_s);
  c.num_options = 0;
  return c;
}

CommandState StateFromText(const std::string& t) {
  if (t == "running") return CommandState::kRunning;
  if (t == "respawning") return CommandState::kRespawnWait;
  if (t == "stopping") return CommandState::kStopping;
  return CommandState::kStopped;
}

}  // namespace

int64_t WallClockUs() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

Orders FromLcm(const bot_procman::orders2_t& msg) {
  Orders o;
  o.utime_us = msg.utime;
  o.host = msg.host;
  o.sheriff_name = msg.sheriff_name;
  for (const auto& c : msg.cmds) {
    CommandOrder co;
    co.spec = FromLcm(c.cmd, c.sheriff_id);
    co.desired_runid = c.desired_runid;
    co.force_quit = c.force_quit != 0;
    o.cmds.push_back(co);
  }
  return o;
}

bot_procman::orders2_t ToLcm(const Orders& o) {
  bot_procman::orders2_t m;
  m.utime = o.utime_us;
  m.host = o.host;
  m.sheriff_name = o.sheriff_name;
  for (const CommandOrder& c : o.cmds) {
    bot_procman::sheriff_cmd2_t s;
    s.cmd = ToLcm(c.spec);
    s.desired_runid = c.desired_runid;
    s.force_quit = c.force_quit ? 1 : 0;
    s.sheriff_id = c.spec.sheriff_id;
    m.cmds.push_back(s);
  }
  m.ncmds = static_cast<int32_t>(m.cmds.size());
  m.num_options = 0;
  return m;
}

bot_procman::info2_t ToLcm(const HostStatus& h) {
  bot_procman::info2_t m;
  m.utime = h.utime_us;
  m.host = h.host;
  m.cpu_load = static_cast<float>(h.cpu_load);
  m.phys_mem_total_bytes = h.mem_total_bytes;
  m.phys_mem_free_bytes = h.mem_free_bytes;
  m.swap_total_bytes = h.swap_total_bytes;
  m.swap_free_bytes = h.swap_free_bytes;
  for (const CommandStatus& c : h.cmds) {
    bot_procman::deputy_cmd2_t d;
    d.cmd = ToLcm(c.spec);
    std::map<std::string, std::string> extra = {
        {"state", ToString(c.state)},
        {"starts", std::to_string(c.starts)},
        {"respawns", std::to_string(c.respawns)},
        {"peak_rss_bytes", std::to_string(c.peak_rss_bytes)},
        {"cpu_time_s", std::to_string(c.cpu_time_s)},
        {"exited", c.exited ? "1" : "0"}};
    if (!c.error.empty()) extra["error"] = c.error;
    if (!c.log_path.empty()) extra["log"] = c.log_path;
    SetOptions(extra, &d.cmd.num_options, &d.cmd.option_names, &d.cmd.option_values);
    d.pid = c.pid;
    d.actual_runid = c.actual_runid;
    d.exit_code = c.exit_status;
    d.cpu_usage = static_cast<float>(c.cpu_usage);
    d.mem_vsize_bytes = c.vsize_bytes;
    d.mem_rss_bytes = c.rss_bytes;
    d.sheriff_id = c.spec.sheriff_id;
    m.cmds.push_back(d);
  }
  m.ncmds = static_cast<int32_t>(m.cmds.size());
  SetOptions(h.options, &m.num_options, &m.option_names, &m.option_values);
  return m;
}

HostStatus FromLcm(const bot_procman::info2_t& m) {
  HostStatus h;
  h.utime_us = m.utime;
  h.host = m.host;
  h.cpu_load = m.cpu_load;
  h.mem_total_bytes = m.phys_mem_total_bytes;
  h.mem_free_bytes = m.phys_mem_free_bytes;
  h.swap_total_bytes = m.swap_total_bytes;
  h.swap_free_bytes = m.swap_free_bytes;
  for (const auto& d : m.cmds) {
    CommandStatus c;
    c.spec = FromLcm(d.cmd, d.sheriff_id);
    const auto extra = GetOptions(d.cmd.option_names, d.cmd.option_values);
    auto get = [&](const char* k) {
      auto it = extra.find(k);
      return it == extra.end() ? std::string() : it->second;
    };
    // A libbot2 deputy sends no state: running when it has a pid.
    c.state = extra.count("state") ? StateFromText(get("state"))
                                   : (d.pid > 0 ? CommandState::kRunning : CommandState::kStopped);
    c.pid = d.pid;
    c.actual_runid = d.actual_runid;
    c.exit_status = d.exit_code;
    c.exited = get("exited") == "1";
    c.cpu_usage = d.cpu_usage;
    c.vsize_bytes = d.mem_vsize_bytes;
    c.rss_bytes = d.mem_rss_bytes;
    c.starts = std::atoi(get("starts").c_str());
    c.respawns = std::atoi(get("respawns").c_str());
    c.peak_rss_bytes = std::max<int64_t>(std::atoll(get("peak_rss_bytes").c_str()), c.rss_bytes);
    c.cpu_time_s = std::atof(get("cpu_time_s").c_str());
    c.error = get("error");
    c.log_path = get("log");
    h.cmds.push_back(c);
  }
  h.options = GetOptions(m.option_names, m.option_values);
  return h;
}

// ---------------------------------------------------------------------------------------

DeputyNode::DeputyNode(Deputy* deputy, LcmInterface* lcm, const ChannelMap& channels,
                       DeputyNodeOptions options)
    : deputy_(deputy),
      lcm_(lcm),
      info_channel_(channels(channels::kPmdInfo)),
      printf_channel_(channels(channels::kPmdPrintf)),
      discover_channel_(channels(channels::kPmdDiscover)),
      options_(options),
      status_(lcm, options.program) {
  deputy_->set_output([this](int32_t id, const std::string& text) { Printf(id, text); });
  if (options_.subscribe_orders) {
    lcm_->Subscribe<bot_procman::orders2_t>(
        channels(channels::kPmdOrders),
        [this](const bot_procman::orders2_t& msg, const std::string&) {
          if (!options_.accept_unsigned) {
            if (msg.host == deputy_->name()) {
              Refuse("unsigned",
                     "unsigned orders from sheriff '" + msg.sheriff_name +
                         "' on PMD_ORDERS2 (this deputy acts on signed orders only; start it with "
                         "--insecure to accept them)");
            } else {
              ++refused_.other_host;
            }
            return;
          }
          HandleOrders(FromLcm(msg), "PMD_ORDERS2");
        });
  }
  // Someone new (a sheriff starting): tell it what runs here now, not in a second.
  lcm_->Subscribe<bot_procman::discovery_t>(
      discover_channel_, [this](const bot_procman::discovery_t& msg, const std::string&) {
        if (msg.nonce != nonce_) next_status_us_ = 0;
      });
  std::random_device rd;
  nonce_ = static_cast<int64_t>((static_cast<uint64_t>(rd()) << 32) ^ rd());
  bot_procman::discovery_t d;
  d.utime = WallClockUs();
  d.host = deputy_->name();
  d.nonce = nonce_;
  lcm_->Publish(discover_channel_, d);
  SetStatusOption("security", options_.accept_unsigned ? "insecure: acts on unsigned PMD_ORDERS2"
                                                       : "signed orders only");
}

DeputyNode::~DeputyNode() { deputy_->set_output(nullptr); }

void DeputyNode::Printf(int32_t sheriff_id, const std::string& text) {
  bot_procman::printf_t p;
  p.utime = WallClockUs();
  p.deputy_name = deputy_->name();
  p.sheriff_id = sheriff_id;
  p.text = text;
  lcm_->Publish(printf_channel_, p);
}

void DeputyNode::Refuse(const std::string& kind, const std::string& reason) {
  const int64_t n = ++refused_.by_reason[kind];
  status_.CountDropped(reason);
  // Logged (and told on PMD_PRINTF) at most every 5 s per kind: a rogue sender at 1 kHz must
  // not flood the log; the counts in the status are exact.
  auto it = refusal_log_.try_emplace(kind, 5.0).first;
  it->second.Warn("refused orders (" + kind + ", " + std::to_string(n) + " so far): " + reason);
  if (n == 1 || n % 100 == 0) Printf(0, "refused orders (" + kind + "): " + reason + "\n");
}

void DeputyNode::EnableSignedOrders(std::unique_ptr<OrderVerifier> verifier,
                                    const ChannelMap& channels) {
  verifier_ = std::move(verifier);
  lcm_->Subscribe<fusionloc::procman_signed_orders_t>(
      channels(channels::kPmdOrdersSigned),
      [this](const fusionloc::procman_signed_orders_t& env, const std::string&) {
        std::vector<uint8_t> encoded;
        const OrderVerifier::Verdict v = verifier_->Verify(env, WallClockUs(), &encoded);
        if (v != OrderVerifier::Verdict::kOk) {
          static const char* kKinds[] = {"ok",      "malformed", "unknown_key",
                                         "bad_mac", "stale",     "replayed"};
          Refuse(kKinds[static_cast<int>(v)], verifier_->last_detail());
          return;
        }
        bot_procman::orders2_t orders;
        if (orders.decode(encoded.data(), 0, static_cast<int>(encoded.size())) !=
            static_cast<int>(encoded.size())) {
          Refuse("malformed", "a signed envelope from '" + env.sheriff_id +
                                  "' holds no valid bot_procman.orders2_t");
          return;
        }
        HandleOrders(FromLcm(orders), "PMD_ORDERS2_SIGNED");
      });
}

void DeputyNode::HandleOrders(const Orders& orders, const std::string& source) {
  const OrdersVerdict v = deputy_->HandleOrders(orders, WallClockUs());
  if (v == OrdersVerdict::kOtherHost) {
    ++refused_.other_host;
  } else if (v == OrdersVerdict::kStale) {
    Refuse("stale", "stale orders on " + source + " from sheriff '" + orders.sheriff_name +
                        "': " + std::to_string((WallClockUs() - orders.utime_us) / 1000000) +
                        " s old (limit 60 s; are the clocks of the two hosts synchronised?)");
  } else {
    ++applied_;
    status_.CountIn();
  }
}

void DeputyNode::PublishStatus() {
  HostStatus h = deputy_->MeasureStatus(WallClockUs());
  h.options = options_extra_;
  int64_t total = 0;
  for (const auto& [reason, n] : refused_.by_reason) {
    h.options["refused_" + reason] = std::to_string(n);
    total += n;
  }
  h.options["refused_orders"] = std::to_string(total);
  h.options["orders_applied"] = std::to_string(applied_);
  lcm_->Publish(info_channel_, ToLcm(h));
  int running = 0;
  for (const CommandStatus& c : h.cmds) running += c.pid > 0;
  status_.Set("commands", static_cast<double>(h.cmds.size()));
  status_.Set("commands_running", running);
  status_.Set("refused_orders", static_cast<double>(total));
  if (status_.dropped() == 0) {
    const int ok = fusionloc::status_t::LEVEL_OK;
    status_.SetState(ok, h.options["security"]);
  }
  status_.Tick();
}

void DeputyNode::Poll() {
  deputy_->Poll();
  const int64_t now = WallClockUs();
  // At the period, and soon after a start or an exit (at most 20 a second).
  const bool changed = deputy_->changes() != published_changes_ && now - last_status_us_ >= 50000;
  if (now >= next_status_us_ || changed) {
    published_changes_ = deputy_->changes();
    last_status_us_ = now;
    next_status_us_ = now + static_cast<int64_t>(options_.status_period_s * 1e6);
    PublishStatus();
  }
}

}  // namespace fl::procman
