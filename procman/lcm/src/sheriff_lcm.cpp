#include "fusionloc/procman/sheriff_lcm.hpp"

#include <chrono>
#include <random>

#include "fusionloc/common/channels.hpp"

namespace fl::procman {

SheriffNode::SheriffNode(Sheriff* sheriff, LcmInterface* lcm, const ChannelMap& channels,
                         SheriffNodeOptions options, std::ostream* out)
    : sheriff_(sheriff),
      lcm_(lcm),
      orders_channel_(channels(channels::kPmdOrders)),
      options_(options),
      out_(out) {
  sink_ = [this](const bot_procman::orders2_t& o) { PublishPlain(o); };
  lcm_->Subscribe<bot_procman::info2_t>(
      channels(channels::kPmdInfo), [this](const bot_procman::info2_t& msg, const std::string&) {
        sheriff_->HandleStatus(FromLcm(msg), Now());
      });
  if (options_.show_output) {
    lcm_->Subscribe<bot_procman::printf_t>(
        channels(channels::kPmdPrintf),
        [this](const bot_procman::printf_t& msg, const std::string&) {
          std::string name = msg.deputy_name;
          for (size_t i = 0; i < sheriff_->config().commands.size(); ++i) {
            const CommandStatus& r = sheriff_->Reported(i);
            if (msg.sheriff_id != 0 && r.spec.sheriff_id == msg.sheriff_id &&
                sheriff_->config().commands[i].host == msg.deputy_name) {
              name = sheriff_->config().commands[i].path();
            }
          }
          std::string text = msg.text;
          if (!text.empty() && text.back() == '\n') text.pop_back();
          size_t start = 0;
          while (start <= text.size()) {
            size_t end = text.find('\n', start);
            if (end == std::string::npos) end = text.size();
            *out_ << "[" << name << "] " << text.substr(start, end - start) << "\n";
            start = end + 1;
          }
          out_->flush();
        });
  }
  reply_channel_ = channels(kCtlReplyChannel);
  lcm_->Subscribe<bot_procman::printf_t>(
      channels(channels::kPmdSheriffCtl),
      [this](const bot_procman::printf_t& msg, const std::string&) {
        if (ctl_verifier_) {
          ++plain_ctl_refused_;
          *out_ << "refused an unsigned order from " << msg.deputy_name << ": " << msg.text
                << " (this sheriff takes only signed ones)\n";
          Reply(msg.deputy_name,
                "refused: this sheriff signs its orders and takes only signed ones; run "
                "fl-procman-ctl with --key FILE (the sheriff's key)");
          return;
        }
        *out_ << "order from " << msg.deputy_name << ": " << msg.text << "\n";
        Reply(msg.deputy_name, Execute(msg.text));
      });
  lcm_->Subscribe<fusionloc::procman_signed_orders_t>(
      channels(channels::kPmdSheriffCtlSigned),
      [this](const fusionloc::procman_signed_orders_t& env, const std::string&) {
        if (!ctl_verifier_) {
          Reply(env.sheriff_id,
                "refused: this sheriff has no key (started without --key or with --insecure); "
                "send the order unsigned (fl-procman-ctl --insecure)");
          return;
        }
        std::vector<uint8_t> payload;
        const OrderVerifier::Verdict v = ctl_verifier_->Verify(env, WallClockUs(), &payload);
        bot_procman::printf_t msg;
        if (v != OrderVerifier::Verdict::kOk ||
            msg.decode(payload.data(), 0, static_cast<int>(payload.size())) !=
                static_cast<int>(payload.size())) {
          const std::string why = v != OrderVerifier::Verdict::kOk
                                      ? std::string(OrderVerifier::Name(v)) + " (" +
                                            ctl_verifier_->last_detail() + ")"
                                      : "the signed payload is not a bot_procman.printf_t";
          *out_ << "refused a signed order from " << env.sheriff_id << ": " << why << "\n";
          Reply(env.sheriff_id, "refused: " + why);
          return;
        }
        *out_ << "order from " << msg.deputy_name << " (signed, key " << env.key_id
              << "): " << msg.text << "\n";
        Reply(msg.deputy_name, Execute(msg.text));
      });
  bot_procman::discovery_t d;
  d.utime = WallClockUs();
  d.host = "sheriff";
  std::random_device rd;
  d.nonce = static_cast<int64_t>((static_cast<uint64_t>(rd()) << 32) ^ rd());
  lcm_->Publish(channels(channels::kPmdDiscover), d);
}

double SheriffNode::Now() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

void SheriffNode::PublishPlain(const bot_procman::orders2_t& orders) {
  lcm_->Publish(orders_channel_, orders);
}

void SheriffNode::RequireSignedCtl(std::vector<Key> keys) {
  ctl_verifier_ = std::make_unique<OrderVerifier>(std::move(keys), OrderVerifier::Options());
}

void SheriffNode::Reply(const std::string& client, const std::string& text) {
  bot_procman::printf_t reply;
  reply.utime = WallClockUs();
  reply.deputy_name = client;
  reply.sheriff_id = 0;
  reply.text = text;
  lcm_->Publish(reply_channel_, reply);
}

std::string SheriffNode::Execute(const std::string& line) {
  return sheriff_->Execute(line, &quit_);
}

void SheriffNode::Poll() {
  const double now = Now();
  sheriff_->StepScripts(now);
  for (const Orders& o : sheriff_->DueOrders(now, WallClockUs())) sink_(ToLcm(o));
  for (const std::string& e : sheriff_->TakeEvents()) *out_ << e << "\n";
  out_->flush();
}

}  // namespace fl::procman
