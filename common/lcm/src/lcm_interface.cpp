#include "fusionloc/common/lcm_interface.hpp"

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <deque>
#include <filesystem>
#include <functional>
#include <lcm/lcm-cpp.hpp>
#include <queue>
#include <regex>
#include <string_view>
#include <stdexcept>

#include "fusionloc/common/program.hpp"

namespace fl {

bool RecentMessages::SeenBefore(const std::string& channel, const void* data, int size) {
  if (size <= 0) return false;
  const uint64_t digest =
      std::hash<std::string_view>()(std::string_view(static_cast<const char*>(data),
                                                     static_cast<size_t>(size))) ^
      (static_cast<uint64_t>(size) * 0x9E3779B97F4A7C15ULL);
  std::vector<uint64_t>& ring = digests_[channel];
  if (std::find(ring.begin(), ring.end(), digest) != ring.end()) return true;
  size_t& next = next_[channel];
  if (ring.size() < kKept) {
    ring.push_back(digest);
  } else {
    ring[next] = digest;
  }
  next = (next + 1) % kKept;
  return false;
}
namespace {

constexpr uint32_t kLogSyncWord = 0xEDA1DA01u;
// Sanity bounds on one event: beyond these a header is taken as corrupt, not as a huge read.
constexpr int32_t kMaxChannelLength = 1024;
constexpr int32_t kMaxEventBytes = 512 * 1024 * 1024;

uint32_t ReadBe32(const uint8_t* p) {
  return (uint32_t(p[0]) << 24) | (uint32_t(p[1]) << 16) | (uint32_t(p[2]) << 8) | uint32_t(p[3]);
}
uint64_t ReadBe64(const uint8_t* p) {
  return (uint64_t(ReadBe32(p)) << 32) | uint64_t(ReadBe32(p + 4));
}
// LCM channel names are printable ASCII.
bool ValidChannelName(const std::string& channel) {
  for (const char c : channel) {
    if (c < 0x20 || c > 0x7e) return false;
  }
  return true;
}

// True if the bytes hold an event header (sync word and sane lengths), i.e. the start of a
// real event that a damaged header's lengths have swallowed.
bool ContainsEventHeader(const std::string& channel, const std::vector<uint8_t>& data) {
  std::vector<uint8_t> body(channel.begin(), channel.end());
  body.insert(body.end(), data.begin(), data.end());
  for (size_t i = 0; i + 28 <= body.size(); ++i) {
    if (body[i] != 0xED || ReadBe32(&body[i]) != kLogSyncWord) continue;
    const int32_t channel_len = static_cast<int32_t>(ReadBe32(&body[i + 20]));
    const int32_t data_len = static_cast<int32_t>(ReadBe32(&body[i + 24]));
    if (channel_len > 0 && channel_len <= kMaxChannelLength && data_len >= 0 &&
        data_len <= kMaxEventBytes) {
      return true;
    }
  }
  return false;
}

void WriteBe32(uint32_t v, uint8_t* p) {
  p[0] = uint8_t(v >> 24);
  p[1] = uint8_t(v >> 16);
  p[2] = uint8_t(v >> 8);
  p[3] = uint8_t(v);
}
void WriteBe64(uint64_t v, uint8_t* p) {
  WriteBe32(uint32_t(v >> 32), p);
  WriteBe32(uint32_t(v), p + 4);
}

// ---- live LCM (udpm://, memq://) ----
class LcmLive final : public LcmInterface {
 public:
  explicit LcmLive(const std::string& url) : url_(url), lcm_(url) {
    if (!lcm_.good()) {
      throw std::runtime_error(
          "cannot open LCM URL '" + url +
          "': check the URL; for udpm:// the host needs a multicast route "
          "(e.g. 'ip route add 224.0.0.0/4 dev lo' and 'ip link set lo multicast on')");
    }
  }

  void PublishRaw(const std::string& channel, const void* data, int size, Utime) override {
    if (lcm_.publish(channel, data, static_cast<unsigned int>(size)) != 0) {
      publish_warning_.Warn("LCM publish failed on channel '" + channel + "' (" +
                            std::to_string(size) +
                            " bytes); is the message larger than the "
                            "transport allows?");
      return;
    }
    CountPublished();
  }

  void SubscribeRaw(const std::string& channel_regex, RawHandler handler) override {
    subscriptions_.push_back(std::make_unique<Subscription>(this, std::move(handler)));
    lcm_.subscribe(channel_regex, &Subscription::OnMessage, subscriptions_.back().get());
  }

  int HandleSubscriptions(int timeout_ms) override {
    const int r = lcm_.handleTimeout(timeout_ms);
    return r < 0 ? -1 : r;  // LCM returns 1 when it handled one message, 0 on timeout
  }

  std::string url() const override { return url_; }

 private:
  struct Subscription {
    Subscription(LcmLive* owner_in, RawHandler h) : owner(owner_in), handler(std::move(h)) {}
    void OnMessage(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
      owner->CountReceived(rbuf->recv_utime);
      handler(channel, rbuf->data, static_cast<int>(rbuf->data_size), rbuf->recv_utime);
    }
    LcmLive* owner;
    RawHandler handler;
  };

  std::string url_;
  lcm::LCM lcm_;
  std::vector<std::unique_ptr<Subscription>> subscriptions_;
  RateLimitedWarning publish_warning_;
};

// ---- log replay: reads one log, writes published messages to another ----
// Published messages are also delivered to this process's own subscribers (as live LCM does),
// before the next input event, so that several nodes in one process (fl-replay) form the same
// pipeline as separate processes. Everything published while handling a message is stamped
// with that message's log time.
class LcmLogReplay final : public LcmInterface {
 public:
  explicit LcmLogReplay(const LogReplayOptions& options, std::string url)
      : url_(std::move(url)), options_(options), reader_(options.in_path) {
    if (!options.out_path.empty()) writer_ = std::make_unique<LcmLogWriter>(options.out_path);
  }
  ~LcmLogReplay() override {
    if (writer_) {
      try {
        writer_->Close();
      } catch (const std::exception& e) {
        FL_LOG(ERROR) << e.what();
      }
    }
  }

  void PublishRaw(const std::string& channel, const void* data, int size, Utime utime) override {
    // Outputs are stamped with the log time of the input being handled, if any, so that the
    // output log lines up with the input log.
    const Utime t = in_dispatch_ ? dispatch_utime_ : utime;
    if (writer_) writer_->Write(channel, data, size, t);
    CountPublished();
    if (!Matching(channel).empty()) {
      Queued q;
      q.channel = channel;
      q.utime = t;
      q.data.assign(static_cast<const uint8_t*>(data), static_cast<const uint8_t*>(data) + size);
      loopback_.push_back(std::move(q));
    }
  }

  void SubscribeRaw(const std::string& channel_regex, RawHandler handler) override {
    subs_.push_back({std::regex(channel_regex, std::regex::extended), std::move(handler)});
    match_cache_.clear();
  }

  int HandleSubscriptions(int) override {
    // Messages published by this process's handlers first, in the order they were published.
    if (!loopback_.empty()) {
      int n = 0;
      while (!loopback_.empty()) {
        Queued q = std::move(loopback_.front());
        loopback_.pop_front();
        Dispatch(q.channel, q.data, q.utime);
        ++n;
      }
      return n;
    }
    LcmLogEvent event;
    if (!NextInput(&event)) return -1;
    if (writer_ && options_.copy_inputs) {
      writer_->Write(event.channel, event.data.data(), static_cast<int>(event.data.size()),
                     event.utime);
    }
    Dispatch(event.channel, event.data, event.utime);
    return 1;
  }

  std::string url() const override { return url_; }
  Utime Now() const override { return in_dispatch_ ? dispatch_utime_ : last_message_utime(); }
  bool replaying() const override { return true; }
  std::map<std::string, int64_t> LogChannelCounts() const override { return counts_; }
  std::string LogProblems() const override { return reader_.ProblemSummary(); }
  bool LogTimeSpan(Utime* first, Utime* last) const override {
    if (counts_.empty()) return false;
    *first = oldest_read_;
    *last = newest_read_;
    return true;
  }
  double LogProgress() const override {
    if (finished_) return 1.0;
    return reader_.file_size() > 0
               ? static_cast<double>(reader_.position()) / static_cast<double>(reader_.file_size())
               : 1.0;
  }

 private:
  struct Sub {
    std::regex regex;
    RawHandler handler;
  };
  struct Queued {
    std::string channel;
    Utime utime = 0;
    std::vector<uint8_t> data;
  };
  struct Pending {
    LcmLogEvent event;
    int64_t order = 0;
  };
  struct Later {
    bool operator()(const Pending& a, const Pending& b) const {
      if (a.event.utime != b.event.utime) return a.event.utime > b.event.utime;
      return a.order > b.order;
    }
  };

  // Indices of the subscriptions whose regex matches `channel` (cached per channel).
  const std::vector<size_t>& Matching(const std::string& channel) {
    auto it = match_cache_.find(channel);
    if (it != match_cache_.end()) return it->second;
    std::vector<size_t> idx;
    for (size_t i = 0; i < subs_.size(); ++i) {
      if (std::regex_match(channel, subs_[i].regex)) idx.push_back(i);
    }
    return match_cache_.emplace(channel, std::move(idx)).first->second;
  }

  void Dispatch(const std::string& channel, const std::vector<uint8_t>& data, Utime utime) {
    CountReceived(utime);
    const bool outer = in_dispatch_;
    const Utime outer_utime = dispatch_utime_;
    in_dispatch_ = true;
    dispatch_utime_ = utime;
    const std::vector<size_t> idx = Matching(channel);  // copy: a handler may subscribe
    for (size_t i : idx) {
      subs_[i].handler(channel, data.data(), static_cast<int>(data.size()), utime);
    }
    in_dispatch_ = outer;
    dispatch_utime_ = outer_utime;
  }

  // The next input event to deliver, in time-stamp order within the reorder window.
  bool NextInput(LcmLogEvent* out) {
    const Utime window = SecondsToUtime(options_.reorder_window_s);
    while (!finished_) {
      if (!pending_.empty() && newest_read_ - pending_.top().event.utime >= window && window > 0) {
        break;
      }
      if (!pending_.empty() && window == 0) break;
      Pending p;
      if (!reader_.Next(&p.event)) {
        finished_ = true;
        const std::string problems = reader_.ProblemSummary();
        if (!problems.empty()) FL_LOG(WARN) << problems;
        break;
      }
      ++counts_[p.event.channel];
      oldest_read_ = std::min(oldest_read_, p.event.utime);
      newest_read_ = std::max(newest_read_, p.event.utime);
      if (options_.drop_channels.count(p.event.channel)) continue;
      p.order = next_order_++;
      pending_.push(std::move(p));
    }
    if (pending_.empty()) return false;
    *out = std::move(const_cast<Pending&>(pending_.top()).event);
    pending_.pop();
    return true;
  }

  std::string url_;
  LogReplayOptions options_;
  LcmLogReader reader_;
  std::unique_ptr<LcmLogWriter> writer_;
  std::vector<Sub> subs_;
  std::map<std::string, std::vector<size_t>> match_cache_;
  std::deque<Queued> loopback_;
  std::priority_queue<Pending, std::vector<Pending>, Later> pending_;
  std::map<std::string, int64_t> counts_;
  int64_t next_order_ = 0;
  Utime oldest_read_ = INT64_MAX;
  Utime newest_read_ = INT64_MIN;
  bool finished_ = false;
  bool in_dispatch_ = false;
  Utime dispatch_utime_ = 0;
};

}  // namespace

std::unique_ptr<LcmInterface> MakeLogReplay(const LogReplayOptions& options) {
  return std::make_unique<LcmLogReplay>(options, "log:" + options.in_path);
}

std::unique_ptr<LcmInterface> MakeLcm(const std::string& url) {
  if (url.rfind("log:", 0) == 0) {
    const std::string spec = url.substr(4);
    const size_t comma = spec.find(',');
    const std::string in = spec.substr(0, comma);
    const std::string out = comma == std::string::npos ? "" : spec.substr(comma + 1);
    if (in.empty()) {
      throw UsageError("LCM URL '" + url + "' names no input log; use log:IN[,OUT]");
    }
    LogReplayOptions options;
    options.in_path = in;
    options.out_path = out;
    return std::make_unique<LcmLogReplay>(options, url);
  }
  if (url.rfind("udpm://", 0) == 0 || url.rfind("memq://", 0) == 0 || url.empty()) {
    return std::make_unique<LcmLive>(url);
  }
  throw UsageError("unsupported LCM URL '" + url +
                   "': use udpm://GROUP:PORT?ttl=0, memq:// or log:IN.lcmlog[,OUT.lcmlog]");
}

// ---------------------------------------------------------------------------------------
LcmLogReader::LcmLogReader(const std::string& path) : path_(path) {
  FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) {
    throw std::runtime_error("cannot open LCM log '" + path + "': " + std::strerror(errno));
  }
  std::fseek(f, 0, SEEK_END);
  file_size_ = std::ftell(f);
  std::fseek(f, 0, SEEK_SET);
  file_ = f;
}

LcmLogReader::~LcmLogReader() {
  if (file_) std::fclose(static_cast<FILE*>(file_));
}

int64_t LcmLogReader::position() const { return std::ftell(static_cast<FILE*>(file_)); }

bool LcmLogReader::Next(LcmLogEvent* event) {
  FILE* f = static_cast<FILE*>(file_);
  uint8_t header[28];
  while (true) {
    const long start = std::ftell(f);
    const size_t got = std::fread(header, 1, sizeof(header), f);
    if (got == 0) {
      EndAtFileEnd(start);
      return false;
    }
    const bool synced = got >= 4 && ReadBe32(header) == kLogSyncWord;
    if (got < sizeof(header) && (synced || damage_start_ < 0)) {
      // The last header is cut short (a killed logger, a full disk).
      EndAtFileEnd(start);
      if (!truncated_) {
        truncated_ = true;
        truncated_at_ = start;
      }
      std::fseek(f, 0, SEEK_END);
      return false;
    }
    auto skip_byte = [&] {  // resynchronise: step one byte forward and look again
      ++corrupt_bytes_;
      if (damage_start_ < 0) damage_start_ = start;
      std::fseek(f, start + 1, SEEK_SET);
    };
    if (!synced || got < sizeof(header)) {
      skip_byte();
      continue;
    }
    const int64_t number = static_cast<int64_t>(ReadBe64(header + 4));
    const int64_t utime = static_cast<int64_t>(ReadBe64(header + 12));
    const int32_t channel_len = static_cast<int32_t>(ReadBe32(header + 20));
    const int32_t data_len = static_cast<int32_t>(ReadBe32(header + 24));
    if (channel_len <= 0 || channel_len > kMaxChannelLength || data_len < 0 ||
        data_len > kMaxEventBytes) {
      skip_byte();
      continue;
    }
    const int64_t event_end = start + 28 + int64_t(channel_len) + data_len;
    if (event_end > file_size_) {
      // Either the last event is cut short or this header's lengths are damaged; look for a
      // valid event further on, and call it a truncation if none follows (EndAtFileEnd).
      if (damage_start_ < 0) overrun_start_ = start;
      skip_byte();
      continue;
    }
    event->event_number = number;
    event->utime = utime;
    event->channel.resize(static_cast<size_t>(channel_len));
    event->data.resize(static_cast<size_t>(data_len));
    if (std::fread(&event->channel[0], 1, channel_len, f) != size_t(channel_len) ||
        (data_len > 0 && std::fread(event->data.data(), 1, data_len, f) != size_t(data_len))) {
      truncated_ = true;
      truncated_at_ = start;
      return false;
    }
    // A valid event ends where the next one starts (or at the end of the file). If it does not,
    // either damage follows it or its lengths are damaged: in the second case the next real
    // event starts inside what this header claims, so a sane header found there rejects it.
    if (file_size_ - event_end >= 4) {
      uint8_t next[4];
      const bool next_synced = std::fread(next, 1, 4, f) == 4 && ReadBe32(next) == kLogSyncWord;
      std::fseek(f, event_end, SEEK_SET);
      if (!next_synced && (!ValidChannelName(event->channel) ||
                           ContainsEventHeader(event->channel, event->data))) {
        skip_byte();
        continue;
      }
    }
    EndDamage(start);
    overrun_start_ = -1;
    return true;
  }
}

void LcmLogReader::EndAtFileEnd(int64_t end) {
  if (damage_start_ >= 0 && damage_start_ == overrun_start_) {
    // No valid event after an event that overran the file: the log is truncated there.
    corrupt_bytes_ -= end - damage_start_;
    truncated_ = true;
    truncated_at_ = damage_start_;
    damage_start_ = -1;
    return;
  }
  EndDamage(end);
}

void LcmLogReader::EndDamage(int64_t end) {
  if (damage_start_ < 0) return;
  ++damage_count_;
  if (damage_.size() < kMaxDamageKept) damage_.push_back(Damage{damage_start_, end - damage_start_});
  damage_start_ = -1;
}

std::string LcmLogReader::ProblemSummary() const {
  std::string s;
  if (damage_count_ > 0) {
    s += "LCM log '" + path_ + "': skipped " + std::to_string(corrupt_bytes_) +
         " corrupt bytes in " + std::to_string(damage_count_) +
         " damaged stretch(es) and resynchronised at the next event; damage at byte offset";
    for (size_t i = 0; i < damage_.size() && i < 5; ++i) {
      s += (i ? ", " : " ") + std::to_string(damage_[i].offset) + " (" +
           std::to_string(damage_[i].bytes) + " bytes)";
    }
    if (damage_count_ > 5) s += ", ...";
  }
  if (truncated_) {
    if (!s.empty()) s += "; ";
    s += "LCM log '" + path_ + "' is truncated at byte offset " + std::to_string(truncated_at_) +
         " of " + std::to_string(file_size_) +
         ": the last event is incomplete and was ignored; every event before it was read";
  }
  return s;
}

// ---------------------------------------------------------------------------------------
LcmLogWriter::LcmLogWriter(const std::string& path, bool atomic)
    : path_(path), write_path_(atomic ? path + ".partial" : path) {
  FILE* f = std::fopen(write_path_.c_str(), "wb");
  if (!f) {
    throw std::runtime_error("cannot write LCM log '" + write_path_ + "': " + std::strerror(errno) +
                             " (does the folder exist and is it writable?)");
  }
  file_ = f;
}

LcmLogWriter::~LcmLogWriter() {
  if (file_) {
    try {
      Close();
    } catch (const std::exception& e) {
      FL_LOG(ERROR) << e.what();
    }
  }
}

namespace {
std::string WriteError(const std::string& path, const std::string& reason) {
  return "write error on LCM log '" + path + "': " + reason + " (disk full?)";
}
constexpr const char* kEarlierError = "an earlier write to it failed";
// Deletes `path` if it is a regular file: a writer pointed at a device (/dev/full) leaves it.
void RemoveRegularFile(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_regular_file(std::filesystem::symlink_status(path, ec))) {
    std::filesystem::remove(path, ec);
  }
}
}  // namespace

void LcmLogWriter::Write(const std::string& channel, const void* data, int size, Utime utime) {
  if (!file_) throw std::runtime_error("LCM log '" + path_ + "' written after Close()");
  FILE* f = static_cast<FILE*>(file_);
  if (std::ferror(f)) throw std::runtime_error(WriteError(write_path_, kEarlierError));
  uint8_t header[28];
  WriteBe32(kLogSyncWord, header);
  WriteBe64(static_cast<uint64_t>(next_event_), header + 4);
  WriteBe64(static_cast<uint64_t>(utime), header + 12);
  WriteBe32(static_cast<uint32_t>(channel.size()), header + 20);
  WriteBe32(static_cast<uint32_t>(size), header + 24);
  if (std::fwrite(header, 1, 28, f) != 28 ||
      std::fwrite(channel.data(), 1, channel.size(), f) != channel.size() ||
      (size > 0 && std::fwrite(data, 1, size_t(size), f) != size_t(size))) {
    const int err = errno;
    throw std::runtime_error(WriteError(write_path_, std::strerror(err)));
  }
  ++next_event_;
}

void LcmLogWriter::Flush() {
  if (!file_) return;
  FILE* f = static_cast<FILE*>(file_);
  if (std::ferror(f)) throw std::runtime_error(WriteError(write_path_, kEarlierError));
  if (std::fflush(f) != 0) {
    const int err = errno;
    throw std::runtime_error(WriteError(write_path_, std::strerror(err)));
  }
}

void LcmLogWriter::Close() {
  if (!file_) return;
  FILE* f = static_cast<FILE*>(file_);
  file_ = nullptr;
  // A failed write leaves the stream's error flag set (and stdio drops the bytes it could
  // not write, so a later flush succeeds): checked so that such a log is never passed off
  // as whole.
  std::string reason = std::ferror(f) ? kEarlierError : "";
  if (std::fflush(f) != 0 && reason.empty()) reason = std::strerror(errno);
  if (std::fclose(f) != 0 && reason.empty()) reason = std::strerror(errno);
  if (!reason.empty()) {
    close_failed_ = true;
    std::string message = "cannot finish LCM log '" + write_path_ + "': " + reason;
    if (write_path_ != path_) {
      message +=
          "; it holds the events written before the error and was not renamed to '" + path_ + "'";
    }
    throw std::runtime_error(message);
  }
  if (write_path_ != path_ && std::rename(write_path_.c_str(), path_.c_str()) != 0) {
    const int err = errno;
    close_failed_ = true;
    throw std::runtime_error("cannot rename '" + write_path_ + "' to '" + path_ +
                             "': " + std::strerror(err));
  }
}

void LcmLogWriter::Abandon() {
  if (file_) {
    std::fclose(static_cast<FILE*>(file_));
    file_ = nullptr;
    RemoveRegularFile(write_path_);
  } else if (close_failed_) {
    RemoveRegularFile(write_path_);
  }
  close_failed_ = false;
}

}  // namespace fl
