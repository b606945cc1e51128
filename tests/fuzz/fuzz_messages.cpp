#include "fuzz_messages.hpp"

namespace fl::fuzz {

void FeedMessages(Input* in, LcmInterface* lcm, const std::vector<std::string>& channels,
                  LcmNode* node) {
  Utime utime = 1000000;
  while (!in->empty()) {
    const std::string& channel = channels[in->Byte() % channels.size()];
    const size_t length = in->U16();
    const std::string_view payload = in->Bytes(length);
    utime += 50000;
    lcm->PublishRaw(channel, payload.data(), static_cast<int>(payload.size()), utime);
    while (lcm->HandleSubscriptions(0) > 0) {
    }
    node->Poll();
  }
  node->Finish();
  while (lcm->HandleSubscriptions(0) > 0) {
  }
}

}  // namespace fl::fuzz
