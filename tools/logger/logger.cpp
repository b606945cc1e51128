#include "logger.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <regex>
#include <stdexcept>
#include <thread>

namespace fl::logger {
namespace {

namespace fs = std::filesystem;

// The size of one event in the log: header (sync word, number, time, two lengths), channel,
// data.
constexpr int64_t kEventHeaderBytes = 28;

std::string FormatSize(double bytes) {
  char text[64];
  if (bytes < 1e6) {
    std::snprintf(text, sizeof(text), "%.1f kB", bytes / 1e3);
  } else {
    std::snprintf(text, sizeof(text), "%.1f MB", bytes / 1e6);
  }
  return text;
}

bool Exists(const std::string& path) {
  std::error_code ec;
  return fs::exists(fs::symlink_status(path, ec));
}

}  // namespace

std::string LoggerOptions::Check() const {
  if (flush_interval_ms < 0) return "--flush-interval-ms must be >= 0";
  if (!(progress_interval_s >= 0)) return "--progress-interval-s must be >= 0 (0: no progress)";
  if (!(lcm_failure_timeout_s > 0)) return "the LCM failure timeout must be > 0";
  if (channel_regex.empty()) return "--channel must not be empty ('.*' records every channel)";
  try {
    std::regex check(channel_regex);
  } catch (const std::regex_error& e) {
    return "--channel '" + channel_regex + "' is not a valid regular expression (" + e.what() + ")";
  }
  return "";
}

std::string Logger::PrepareOutput(const LoggerOptions& options) {
  const std::string error =
      options.output.empty() ? "no OUTPUT (the log to write) given" : options.Check();
  if (!error.empty()) throw std::invalid_argument(error);
  const std::string partial = options.output + ".partial";
  if (!options.force) {
    if (Exists(options.output)) {
      throw std::runtime_error("'" + options.output +
                               "' exists; not overwriting it: choose another name, move it "
                               "away, or use --force");
    }
    if (Exists(partial)) {
      throw std::runtime_error("'" + partial +
                               "' exists: an unfinished recording (a logger stopped by a kill "
                               "or a write error); keep it (rename it) or use --force to "
                               "overwrite it");
    }
  } else if (Exists(options.output)) {
    // Deleted now, not when the new log is renamed over it: should this recording fail, an
    // old log must not be left in its place and taken for it.
    std::error_code ec;
    if (!fs::remove(options.output, ec) || ec) {
      throw std::runtime_error("cannot remove '" + options.output + "' (--force): " + ec.message());
    }
    FL_LOG(INFO) << "--force: removed the old '" << options.output << "'";
  }
  return partial;
}

Logger::Logger(LcmInterface* lcm, LoggerOptions options)
    : lcm_(lcm),
      options_(std::move(options)),
      partial_(PrepareOutput(options_)),
      writer_(options_.output, /*atomic=*/true),
      start_(Clock::now()),
      last_progress_(start_) {
  lcm_->SubscribeRaw(options_.channel_regex,
                     [this](const std::string& channel, const void* data, int size, Utime utime) {
                       OnMessage(channel, data, size, utime);
                     });
}

void Logger::OnMessage(const std::string& channel, const void* data, int size, Utime utime) {
  // Called from inside LCM's C code: nothing may be thrown through it.
  if (!write_error_.empty()) return;
  try {
    writer_.Write(channel, data, size, utime);
  } catch (const std::exception& e) {
    write_error_ = e.what();
    return;
  }
  ++events_;
  bytes_ += kEventHeaderBytes + static_cast<int64_t>(channel.size()) + size;
  unflushed_ = true;
}

void Logger::FailWrite(const std::string& what) {
  try {
    writer_.Close();  // throws after a failed write; keeps the partial file, renames nothing
  } catch (const std::exception&) {
  }
  std::error_code ec;
  const auto on_disk = fs::file_size(partial_, ec);
  throw std::runtime_error(
      what + "; the recording stopped after " + std::to_string(events_) + " events (" +
      std::to_string(bytes_) + " bytes); '" + partial_ + "'" +
      (ec ? "" : " (" + std::to_string(on_disk) + " bytes)") +
      " holds the events written until then (the last one may be cut short) and was NOT "
      "renamed to '" +
      options_.output + "'");
}

void Logger::Progress(Clock::time_point now) {
  if (options_.progress_interval_s <= 0) return;
  const double since = std::chrono::duration<double>(now - last_progress_).count();
  if (since < options_.progress_interval_s) return;
  const double total_s = std::chrono::duration<double>(now - start_).count();
  char rates[160];
  std::snprintf(rates, sizeof(rates), "%.1f events/s, %.2f MB/s",
                static_cast<double>(events_ - progress_events_) / since,
                static_cast<double>(bytes_ - progress_bytes_) / since / 1e6);
  FL_LOG(INFO) << partial_ << ": " << events_ << " events, " << FormatSize(bytes_) << " in "
               << std::lround(total_s) << " s; last " << std::lround(since) << " s: " << rates;
  last_progress_ = now;
  progress_events_ = events_;
  progress_bytes_ = bytes_;
}

LoggerReport Logger::Run(const std::function<bool()>& stop) {
  LoggerReport report;
  const auto flush_interval = std::chrono::milliseconds(options_.flush_interval_ms);
  // How long LCM may wait for a message: short enough to flush on time and to see stop().
  const int timeout_ms =
      options_.flush_interval_ms > 0 ? std::clamp(options_.flush_interval_ms, 10, 100) : 100;
  Clock::time_point last_flush = Clock::now();
  Clock::time_point failing_since{};
  bool failing = false;
  while (!stop()) {
    const int handled = lcm_->HandleSubscriptions(timeout_ms);
    if (!write_error_.empty()) FailWrite(write_error_);
    const Clock::time_point now = Clock::now();
    if (handled < 0) {
      if (lcm_->replaying()) {
        report.input_ended = true;
        break;
      }
      if (stop()) break;  // the signal that stops us also interrupts LCM's wait
      // Live LCM failed to receive: tolerated for a moment, then an error.
      if (!failing) failing_since = now;
      failing = true;
      const double failing_s = std::chrono::duration<double>(now - failing_since).count();
      if (failing_s > options_.lcm_failure_timeout_s) {
        try {
          writer_.Close();
        } catch (const std::exception& e) {
          FailWrite(e.what());
        }
        throw std::runtime_error("LCM on '" + lcm_->url() + "' keeps failing to receive (for " +
                                 std::to_string(std::lround(failing_s)) + " s); stopped. '" +
                                 options_.output + "' holds the " + std::to_string(events_) +
                                 " events recorded until then");
      }
      lcm_warning_.Warn("LCM on '" + lcm_->url() + "' failed to receive; retrying");
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    } else {
      failing = false;
    }
    if (unflushed_ && now - last_flush >= flush_interval) {
      try {
        writer_.Flush();
      } catch (const std::exception& e) {
        FailWrite(e.what());
      }
      unflushed_ = false;
      last_flush = now;
    }
    Progress(now);
  }
  try {
    writer_.Close();
  } catch (const std::exception& e) {
    FailWrite(e.what());
  }
  report.events = events_;
  report.bytes = bytes_;
  report.wall_s = std::chrono::duration<double>(Clock::now() - start_).count();
  return report;
}

}  // namespace fl::logger
