#include "fusionloc/common/status_reporter.hpp"

#include <cctype>

#include "fusionloc/common/channels.hpp"
#include "fusionloc/status_t.hpp"

namespace fl {

std::string StatusChannel(const std::string& program) {
  std::string channel = channels::kStatusPrefix;
  for (char c : program) {
    channel +=
        std::isalnum(static_cast<unsigned char>(c)) ? static_cast<char>(std::toupper(c)) : '_';
  }
  return channel;
}

StatusReporter::StatusReporter(LcmInterface* lcm, std::string process, double period_s)
    : lcm_(lcm),
      process_(std::move(process)),
      channel_(StatusChannel(process_)),
      period_s_(period_s) {}

void StatusReporter::CountDropped(const std::string& reason) {
  ++dropped_;
  level_ = fusionloc::status_t::LEVEL_WARN;
  message_ = reason;
}

void StatusReporter::CountIn(const std::string& channel, Utime utime) {
  ++in_;
  gaps_.Add(channel, utime);
}

void StatusReporter::AddItemTime(double ms) {
  item_ms_sum_ += ms;
  ++item_count_;
}

void StatusReporter::SetTiming(const std::string& key, double ms) {
  if (!lcm_->replaying()) values_[key] = ms;
}

void StatusReporter::SetState(int level, const std::string& message) {
  if (level == fusionloc::status_t::LEVEL_ERROR && level_ != level) error_pending_ = true;
  level_ = level;
  message_ = message;
}

void StatusReporter::Tick(bool force) {
  const Utime now = lcm_->Now();
  if (!force && !error_pending_ && now >= last_publish_ &&
      UtimeToSeconds(now - last_publish_) < period_s_) {
    return;
  }
  last_publish_ = now;
  error_pending_ = false;
  fusionloc::status_t st;
  st.utime = now;
  st.process = process_;
  st.level = static_cast<int8_t>(level_);
  st.message = message_;
  st.messages_in = in_;
  st.messages_out = out_;
  st.messages_dropped = dropped_;
  st.cpu_ms_per_item = item_count_ > 0 && !lcm_->replaying() ? item_ms_sum_ / item_count_ : 0.0;
  item_ms_sum_ = 0.0;
  item_count_ = 0;
  for (const auto& [channel, n] : gaps_.all_gaps()) {
    values_["gaps_" + channel] = static_cast<double>(n);
    values_["missing_" + channel] = static_cast<double>(gaps_.missing(channel));
  }
  // What the LCM interface itself refused (only when something was: most runs have none).
  if (lcm_->duplicates_dropped() > 0) {
    values_["lcm_duplicates_dropped"] = static_cast<double>(lcm_->duplicates_dropped());
  }
  if (lcm_->invalid_values() > 0) {
    values_["lcm_invalid_values"] = static_cast<double>(lcm_->invalid_values());
  }
  if (lcm_->decode_errors() > 0) {
    values_["lcm_decode_errors"] = static_cast<double>(lcm_->decode_errors());
  }
  st.num_keys = static_cast<int32_t>(values_.size());
  for (const auto& kv : values_) {
    st.keys.push_back(kv.first);
    st.values.push_back(kv.second);
  }
  lcm_->Publish(channel_, st, now);
}

}  // namespace fl
