// The sheriff on LCM: deputies' status (PMD_INFO2) and output (PMD_PRINTF) in, orders out
// (PMD_ORDERS2, or through a signer), and text orders from fl-procman-ctl on PMD_SHERIFF_CTL
// (a bot_procman.printf_t: deputy_name = the client's id, text = the order line), answered on
// PMD_SHERIFF_CTL_REPLY with the same id. A sheriff that signs its orders (RequireSignedCtl)
// takes ctl orders only signed with the procman key, on PMD_SHERIFF_CTL_SIGNED (the envelope
// of the deputies' orders around the encoded printf_t), and refuses plain ones: otherwise
// anyone on the LCM network could have it sign whatever they asked for.
#pragma once

#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <string>

#include "fusionloc/common/channel_map.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/procman/order_auth.hpp"
#include "fusionloc/procman/procman_lcm.hpp"
#include "fusionloc/procman/sheriff.hpp"

namespace fl::procman {

constexpr const char* kCtlReplyChannel = "PMD_SHERIFF_CTL_REPLY";

struct SheriffNodeOptions {
  bool show_output = false;  // print the commands' output (PMD_PRINTF) with their names
};

class SheriffNode {
 public:
  // Sends orders: publishes them plain on PMD_ORDERS2 by default.
  using OrdersSink = std::function<void(const bot_procman::orders2_t&)>;

  SheriffNode(Sheriff* sheriff, LcmInterface* lcm, const ChannelMap& channels,
              SheriffNodeOptions options, std::ostream* out);
  void set_orders_sink(OrdersSink sink) { sink_ = std::move(sink); }
  const OrdersSink& orders_sink() const { return sink_; }
  // Sends due orders, advances scripts, prints events. Call often.
  void Poll();
  // A text order from the terminal (or fl-procman-ctl); returns the reply.
  std::string Execute(const std::string& line);
  bool quit_requested() const { return quit_; }
  // Publishes orders plainly (the default sink).
  void PublishPlain(const bot_procman::orders2_t& orders);
  // From now on only ctl orders signed with one of `keys` are obeyed (see the file comment).
  void RequireSignedCtl(std::vector<Key> keys);
  // Ctl envelopes refused per verdict, and plain ctl orders refused (RequireSignedCtl).
  const OrderVerifier* ctl_verifier() const { return ctl_verifier_.get(); }
  int64_t plain_ctl_refused() const { return plain_ctl_refused_; }

 private:
  double Now() const;
  void Reply(const std::string& client, const std::string& text);
  Sheriff* sheriff_;
  LcmInterface* lcm_;
  std::string orders_channel_;
  SheriffNodeOptions options_;
  std::ostream* out_;
  OrdersSink sink_;
  bool quit_ = false;
  std::string reply_channel_;
  std::unique_ptr<OrderVerifier> ctl_verifier_;
  int64_t plain_ctl_refused_ = 0;
};

}  // namespace fl::procman
