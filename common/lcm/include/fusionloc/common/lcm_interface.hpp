// LCM behind a small interface (after Drake's DrakeLcmInterface), so that
//  - processes run live over UDP multicast (udpm://),
//  - tests run in memory (memq://),
//  - a process can replay an LCM log file and write its outputs to another log at full speed,
// all through the same subscribe/publish/handle code path.
//
//   auto lcm = fl::MakeLcm(url);          // "udpm://...", "memq://", or
//   "log:IN.lcmlog[,OUT.lcmlog]" lcm->Subscribe<bot_core::planar_lidar_t>("LASER", [&](const auto&
//   msg, const auto& ch) {...}); while (!fl::ShutdownRequested() && lcm->HandleSubscriptions(100)
//   >= 0) {}
//
// Typed subscriptions decode each message; a message that fails to decode (wrong type,
// truncated) is counted, reported with a rate-limited warning naming the channel and type,
// and never reaches the handler. So is a decoded message with a NaN, infinite or absurd real
// field (message_checks.hpp: BadField for the input types). A subscription to a data stream
// (Duplicates::kDrop) also drops a message byte-for-byte identical to one of the last few of
// its channel (a duplicate from the network or a relay: sensor data and estimates carry their
// own time stamps, so two real ones never match), counted the same way. Commands and orders keep the default (kDeliver): a
// repeated command is meant, and a replayed order must reach the code that refuses and logs it.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "fusionloc/common/log.hpp"
#include "fusionloc/common/message_checks.hpp"
#include "fusionloc/common/time.hpp"

namespace fl {

// Whether message_checks.hpp has a BadField for Msg.
template <class Msg, class = void>
struct HasBadField : std::false_type {};
template <class Msg>
struct HasBadField<Msg, std::void_t<decltype(BadField(std::declval<const Msg&>()))>>
    : std::true_type {};

// Default live URL: loopback-only multicast (ttl=0) with a receive buffer large enough for
// full-resolution stereo pairs.
constexpr const char* kDefaultLcmUrl = "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=16777216";

// Digests (size and hash of the bytes) of the last kKept messages per channel, for one
// subscription: SeenBefore() says whether a message repeats one of them (and records it).
class RecentMessages {
 public:
  static constexpr size_t kKept = 16;
  bool SeenBefore(const std::string& channel, const void* data, int size);

 private:
  std::map<std::string, std::vector<uint64_t>> digests_;  // ring per channel
  std::map<std::string, size_t> next_;
};

class LcmInterface {
 public:
  using RawHandler =
      std::function<void(const std::string& channel, const void* data, int size, Utime recv_utime)>;

  virtual ~LcmInterface() = default;

  // Publishes encoded bytes. `utime` is the time stamp written to logs (live: ignored by LCM).
  virtual void PublishRaw(const std::string& channel, const void* data, int size, Utime utime) = 0;

  // Subscribes to channels matching `channel_regex` (LCM's anchored POSIX regex; a plain
  // channel name matches itself).
  virtual void SubscribeRaw(const std::string& channel_regex, RawHandler handler) = 0;

  // Waits up to `timeout_ms` and dispatches received messages. Returns the number dispatched
  // (0 on timeout), or -1 when the source is finished (end of a log) or broken.
  virtual int HandleSubscriptions(int timeout_ms) = 0;

  // The URL this instance was made from.
  virtual std::string url() const = 0;

  // Time of the message being (or last) dispatched: log time during replay, receive time live.
  Utime last_message_utime() const { return last_message_utime_; }

  // The clock of this process: wall time live; when replaying a log, the data time of the
  // message being (or last) handled, so that everything published in log mode, STATUS
  // included, carries data time.
  virtual Utime Now() const { return NowUtime(); }
  // True when reading a log (log:...): no wall-clock values should go into what is published.
  virtual bool replaying() const { return false; }
  // Log mode: events read so far per channel (all channels of the log); empty live.
  virtual std::map<std::string, int64_t> LogChannelCounts() const { return {}; }
  // Log mode: problems met reading the log ("" if none): corrupt bytes, truncation.
  virtual std::string LogProblems() const { return ""; }
  // Log mode: the earliest and latest time stamps of the input events read so far; false
  // live or before the first event.
  virtual bool LogTimeSpan(Utime* /*first*/, Utime* /*last*/) const { return false; }
  // Log mode: fraction of the input read, in [0, 1]; -1 live.
  virtual double LogProgress() const { return -1.0; }

  int64_t messages_published() const { return published_; }
  int64_t messages_received() const { return received_; }
  int64_t decode_errors() const { return decode_warning_.count(); }
  int64_t duplicates_dropped() const { return duplicate_warning_.count(); }
  int64_t invalid_values() const { return invalid_warning_.count(); }

  // Encodes and publishes an lcm-gen message. `utime` (the time stamp written to logs)
  // defaults to Now().
  template <class Msg>
  void Publish(const std::string& channel, const Msg& msg, Utime utime = -1) {
    const int size = msg.getEncodedSize();
    buffer_.resize(static_cast<size_t>(size));
    msg.encode(buffer_.data(), 0, size);
    PublishRaw(channel, buffer_.data(), size, utime >= 0 ? utime : Now());
  }

  // Decodes messages of type Msg on `channel_regex` and calls `handler(msg, channel)`.
  enum class Duplicates { kDeliver, kDrop };
  template <class Msg>
  void Subscribe(const std::string& channel_regex,
                 std::function<void(const Msg& msg, const std::string& channel)> handler,
                 Duplicates duplicates = Duplicates::kDeliver) {
    auto recent = duplicates == Duplicates::kDrop ? std::make_shared<RecentMessages>() : nullptr;
    SubscribeRaw(channel_regex, [this, handler, recent](const std::string& channel,
                                                        const void* data, int size, Utime) {
      if (recent && recent->SeenBefore(channel, data, size)) {
        duplicate_warning_.Warn("channel '" + channel +
                                "': a message identical to a recent one (a duplicate from the "
                                "network or a relay) dropped");
        return;
      }
      Msg msg;
      if (msg.decode(data, 0, size) != size) {
        decode_warning_.Warn("channel '" + channel + "': a message of " + std::to_string(size) +
                             " bytes does not decode as " + Msg::getTypeName() +
                             " (wrong type or truncated); check that the sender "
                             "uses the same lcmtypes");
        return;
      }
      if constexpr (HasBadField<Msg>::value) {
        const std::string bad = BadField(msg);
        if (!bad.empty()) {
          invalid_warning_.Warn("channel '" + channel + "': a " + Msg::getTypeName() +
                                " with " + bad + " dropped (the sender is broken)");
          return;
        }
      }
      handler(msg, channel);
    });
  }

 protected:
  void CountPublished() { ++published_; }
  void CountReceived(Utime utime) {
    ++received_;
    last_message_utime_ = utime;
  }

 private:
  std::vector<uint8_t> buffer_;
  RateLimitedWarning decode_warning_;
  RateLimitedWarning duplicate_warning_;
  RateLimitedWarning invalid_warning_;
  int64_t published_ = 0;
  int64_t received_ = 0;
  Utime last_message_utime_ = 0;
};

// Makes an interface from a URL:
//   udpm://...  or memq://         live LCM (lcm::LCM)
//   log:IN[,OUT]                  replay IN (an LCM log file) as fast as handled; messages
//                                 published go to OUT if given (else they are counted and dropped)
//                                 and to this process's own subscribers, as live LCM does.
// Throws fl::UsageError (exit code 2) for a URL that is malformed or of an unknown kind, and
// std::runtime_error naming the cause (exit code 1) if it cannot be opened.
std::unique_ptr<LcmInterface> MakeLcm(const std::string& url = kDefaultLcmUrl);

// Log replay with more control than log:IN,OUT (fl-replay).
struct LogReplayOptions {
  std::string in_path;       // the LCM log to read
  std::string out_path;      // where published messages go ("" = nowhere)
  bool copy_inputs = false;  // also write the delivered input events to out_path
  // Deliver input events in time-stamp order within this window of log time [s] (stable for
  // equal stamps); 0 keeps the log's order.
  double reorder_window_s = 0.0;
  // Input channels neither delivered nor copied (e.g. a recorded run's old estimator outputs,
  // which the replay produces anew). They are still counted in LogChannelCounts().
  std::set<std::string> drop_channels;
};
std::unique_ptr<LcmInterface> MakeLogReplay(const LogReplayOptions& options);

// ---------------------------------------------------------------------------------------
// LCM log files (the format of lcm-logger / lcm-logplayer), read and written directly so that
// truncated or corrupt logs are detected and reported instead of silently cut short.

struct LcmLogEvent {
  int64_t event_number = 0;
  Utime utime = 0;  // [us] time the event was logged
  std::string channel;
  std::vector<uint8_t> data;
};

class LcmLogReader {
 public:
  // Throws std::runtime_error naming the file if it cannot be opened.
  explicit LcmLogReader(const std::string& path);
  ~LcmLogReader();
  LcmLogReader(const LcmLogReader&) = delete;
  LcmLogReader& operator=(const LcmLogReader&) = delete;

  // One stretch of bytes that held no valid event, skipped to resynchronise.
  struct Damage {
    int64_t offset = 0;  // [bytes] from the start of the file
    int64_t bytes = 0;   // [bytes] skipped
  };

  // Reads the next event; false at the end of the file. Corrupt bytes are skipped up to the
  // next valid event and recorded with their byte offset; a truncated final event is recorded
  // and ends the log. An event is valid when its header is sane and the bytes after it are the
  // next event's sync word or the end of the file (a header whose lengths were damaged is not
  // taken for an event that swallows its successors).
  bool Next(LcmLogEvent* event);

  const std::string& path() const { return path_; }
  int64_t corrupt_bytes_skipped() const { return corrupt_bytes_; }
  bool truncated() const { return truncated_; }
  // [bytes] where the incomplete last event starts (-1 if the log is not truncated).
  int64_t truncated_at() const { return truncated_at_; }
  // The damaged stretches found so far, in file order (the first kMaxDamageKept of them).
  const std::vector<Damage>& damage() const { return damage_; }
  int64_t damage_count() const { return damage_count_; }
  static constexpr size_t kMaxDamageKept = 64;
  // A human-readable account of problems found so far, naming byte offsets ("" if none).
  std::string ProblemSummary() const;
  int64_t file_size() const { return file_size_; }
  int64_t position() const;

 private:
  std::string path_;
  void* file_ = nullptr;  // FILE*
  int64_t file_size_ = 0;
  void EndDamage(int64_t end);
  void EndAtFileEnd(int64_t end);
  int64_t corrupt_bytes_ = 0;
  bool truncated_ = false;
  int64_t truncated_at_ = -1;
  int64_t damage_start_ = -1;  // start of the damaged stretch being skipped (-1: none)
  int64_t overrun_start_ = -1;  // start of a header whose event overran the end of the file
  std::vector<Damage> damage_;
  int64_t damage_count_ = 0;
};

class LcmLogWriter {
 public:
  // Writes to `path`. With atomic=true (default) the events go to "path.partial" and the file
  // is renamed to `path` by Close(), so an interrupted run never leaves a log that looks whole.
  explicit LcmLogWriter(const std::string& path, bool atomic = true);
  ~LcmLogWriter();  // closes (and renames) if Close() was not called
  LcmLogWriter(const LcmLogWriter&) = delete;
  LcmLogWriter& operator=(const LcmLogWriter&) = delete;

  // Throws on an I/O error (a short write: ENOSPC, EIO, EFBIG), naming the file and the
  // reason. After one, every Write, Flush and Close throws: a log never goes on past a hole.
  void Write(const std::string& channel, const void* data, int size, Utime utime);
  template <class Msg>
  void Write(const std::string& channel, const Msg& msg, Utime utime) {
    const int size = msg.getEncodedSize();
    buffer_.resize(static_cast<size_t>(size));
    msg.encode(buffer_.data(), 0, size);
    Write(channel, buffer_.data(), size, utime);
  }
  // Hands what was written to the kernel (it survives a kill -9 of this process, not a power
  // loss). Throws on I/O error.
  void Flush();
  // Flushes, closes and (if atomic) renames into place. Throws on an I/O error, now or in an
  // earlier Write or Flush: then nothing is renamed and nothing deleted ("path.partial", or
  // the file itself if not atomic, keeps the events written before the error).
  void Close();
  // Closes and deletes the partial output (use on failure; also after a Close that threw).
  // Deletes a regular file only, never a device the writer was pointed at.
  void Abandon();
  int64_t events_written() const { return next_event_; }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  std::string write_path_;
  void* file_ = nullptr;  // FILE*
  int64_t next_event_ = 0;
  bool close_failed_ = false;  // Close threw: write_path_ is still there for Abandon
  std::vector<uint8_t> buffer_;
};

}  // namespace fl
