// The LCM side of the process manager: libbot2's bot_procman messages <-> the pure types of
// deputy.hpp, and DeputyNode, the deputy on LCM (orders in, status, output and discovery out).
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <string>

#include "fusionloc/common/channel_map.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/status_reporter.hpp"
#include "fusionloc/procman/bot_procman_types.hpp"
#include "fusionloc/procman/deputy.hpp"
#include "fusionloc/procman/order_auth.hpp"

namespace fl::procman {

Orders FromLcm(const bot_procman::orders2_t& msg);
bot_procman::orders2_t ToLcm(const Orders& orders);
// The extra per-command fields (state, starts, respawns, peak memory, CPU time, error, log)
// travel in command2_t's options, the host's extra keys in info2_t's options; libbot2's tools
// ignore them.
bot_procman::info2_t ToLcm(const HostStatus& status);
HostStatus FromLcm(const bot_procman::info2_t& msg);

int64_t WallClockUs();

struct DeputyNodeOptions {
  std::string program = "fl-procman-deputy";  // its STATUS_<PROGRAM> channel
  double status_period_s = 1.0;               // [s] PMD_INFO2 this often (libbot2: 1 Hz)
  // Act on plain PMD_ORDERS2 (libbot2's unsigned orders). When false they are refused,
  // counted and logged ("unsigned").
  bool accept_unsigned = true;
  // Subscribe to orders on LCM at all (false: the in-process deputy of a lone-ranger sheriff,
  // which takes its sheriff's orders directly through HandleOrders).
  bool subscribe_orders = true;
};

// Counts of orders the deputy did not act on, by reason (also in its status options).
struct RefusedOrders {
  int64_t other_host = 0;  // for another deputy (normal on a shared network; not logged)
  std::map<std::string, int64_t> by_reason;  // every refusal that is logged
};

class DeputyNode {
 public:
  DeputyNode(Deputy* deputy, LcmInterface* lcm, const ChannelMap& channels,
             DeputyNodeOptions options = DeputyNodeOptions());
  ~DeputyNode();  // unhooks the deputy's output
  DeputyNode(const DeputyNode&) = delete;
  DeputyNode& operator=(const DeputyNode&) = delete;
  // Polls the deputy and publishes its status when due. Call often (~10 ms).
  void Poll();
  const RefusedOrders& refused() const { return refused_; }
  int64_t orders_applied() const { return applied_; }
  // Orders decoded from any source (plain, or a verified envelope).
  void HandleOrders(const Orders& orders, const std::string& source);
  // Extra status keys (set by whoever decides the order policy).
  void SetStatusOption(const std::string& key, const std::string& value) {
    options_extra_[key] = value;
  }
  // Acts on signed orders (PMD_ORDERS2_SIGNED) that `verifier` accepts; refusals are counted
  // by verdict and logged (rate-limited) with the reason.
  void EnableSignedOrders(std::unique_ptr<OrderVerifier> verifier, const ChannelMap& channels);
  // Logs and counts an order not acted on; `kind` is its counter (unsigned, stale, bad_mac,
  // unknown_key, replayed, malformed), `reason` the log line.
  void Refuse(const std::string& kind, const std::string& reason);
  void PublishStatus();
  StatusReporter& status() { return status_; }

 private:
  void Printf(int32_t sheriff_id, const std::string& text);

  Deputy* deputy_;
  LcmInterface* lcm_;
  std::string info_channel_, printf_channel_, discover_channel_;
  DeputyNodeOptions options_;
  RefusedOrders refused_;
  int64_t applied_ = 0;
  std::map<std::string, std::string> options_extra_;
  int64_t next_status_us_ = 0;
  int64_t last_status_us_ = 0;
  uint64_t published_changes_ = 0;
  int64_t nonce_ = 0;
  StatusReporter status_;
  std::unique_ptr<OrderVerifier> verifier_;
  std::map<std::string, RateLimitedWarning> refusal_log_;
};

}  // namespace fl::procman
