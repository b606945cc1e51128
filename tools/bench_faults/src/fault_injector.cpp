#include "fusionloc/bench_faults/fault_injector.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "fusionloc/bench_faults/message_faults.hpp"

namespace fl::bench_faults {
namespace {

constexpr size_t kCorruptionsKept = 1000;  // all of a bench run (a few hundred)

bool Fraction(double f) { return f >= 0.0 && f <= 1.0; }

}  // namespace

Status FaultOptions::Validate() const {
  if (!Fraction(drop_fraction)) return Status::Error("drop_fraction must be in [0, 1]");
  if (!Fraction(duplicate_fraction)) return Status::Error("duplicate_fraction must be in [0, 1]");
  if (!Fraction(delay_fraction)) return Status::Error("delay_fraction must be in [0, 1]");
  if (!Fraction(corrupt_fraction)) return Status::Error("corrupt_fraction must be in [0, 1]");
  if (!(max_delay_s >= 0.0) || (delay_fraction > 0.0 && !(max_delay_s > 0.0))) {
    return Status::Error("max_delay_s must be >= 0, and > 0 when delay_fraction > 0");
  }
  if (!std::isfinite(jump_offset_s) || !(jump_start_s >= 0.0) || !(jump_duration_s >= 0.0)) {
    return Status::Error("jump_offset_s must be finite, jump_start_s and jump_duration_s >= 0");
  }
  if (!(outage_start_s >= 0.0) || !(outage_duration_s >= 0.0) ||
      !std::isfinite(outage_start_s + outage_duration_s)) {
    return Status::Error("outage_start_s and outage_duration_s must be finite and >= 0");
  }
  try {
    std::regex r(channels);
  } catch (const std::regex_error& e) {
    return Status::Error("channels '" + channels + "' is not a valid regex: " + e.what());
  }
  return Status::Ok();
}

bool FaultOptions::any() const {
  return drop_fraction > 0 || duplicate_fraction > 0 || delay_fraction > 0 ||
         corrupt_fraction > 0 || (jump_offset_s != 0 && jump_duration_s > 0) ||
         outage_duration_s > 0;
}

FaultInjector::FaultInjector(FaultOptions options) : options_(std::move(options)) {
  const Status s = options_.Validate();
  if (!s.ok()) throw std::invalid_argument("fault options: " + s.message());
  channels_ = std::regex(options_.channels);
  rng_.seed(options_.seed);
}

bool FaultInjector::Uniform(double fraction) {
  if (fraction <= 0.0) return false;
  return std::uniform_real_distribution<double>(0.0, 1.0)(rng_) < fraction;
}

bool FaultInjector::StampSeconds(const std::vector<uint8_t>& data, double* t) {
  int64_t utime = 0;
  if (!MessageUtime(data, &utime)) return false;
  if (!have_t0_) {
    have_t0_ = true;
    t0_us_ = utime;
  }
  *t = 1e-6 * (static_cast<double>(utime) - static_cast<double>(t0_us_));
  return true;
}

void FaultInjector::Enqueue(double due_s, FaultEvent event) {
  Held h{due_s, order_++, std::move(event)};
  auto at = std::upper_bound(queue_.begin(), queue_.end(), h, [](const Held& a, const Held& b) {
    return a.due_s < b.due_s || (a.due_s == b.due_s && a.order < b.order);
  });
  queue_.insert(at, std::move(h));
}

void FaultInjector::Push(const std::string& channel, const std::vector<uint8_t>& data,
                         double now_s) {
  ++counts_.in;
  FaultEvent event{channel, data};
  if (!std::regex_match(channel, channels_)) {
    Enqueue(now_s, std::move(event));
    return;
  }
  // Every draw is made for every message, so that one fault's choices do not depend on
  // whether another fault is on (the drop run and the drop+delay run lose the same messages).
  const bool drop = Uniform(options_.drop_fraction);
  const bool duplicate = Uniform(options_.duplicate_fraction);
  const bool delay = Uniform(options_.delay_fraction);
  const double delay_s =
      std::uniform_real_distribution<double>(0.0, std::max(options_.max_delay_s, 1e-9))(rng_);
  const bool corrupt = Uniform(options_.corrupt_fraction);
  double t = 0.0;  // [s] of its stamp after the first one
  const bool stamped =
      (options_.outage_duration_s > 0.0 ||
       (options_.jump_offset_s != 0.0 && options_.jump_duration_s > 0.0)) &&
      StampSeconds(event.data, &t);
  const bool silenced = stamped && options_.outage_duration_s > 0.0 &&
                        t >= options_.outage_start_s &&
                        t < options_.outage_start_s + options_.outage_duration_s;
  if (drop || silenced) {
    ++counts_.dropped;
    ++counts_.dropped_per_channel[channel];
    if (silenced) ++counts_.silenced;
    return;
  }
  if (stamped && options_.jump_offset_s != 0.0 && options_.jump_duration_s > 0.0 &&
      t >= options_.jump_start_s && t < options_.jump_start_s + options_.jump_duration_s &&
      ShiftMessageTime(&event.data, std::llround(options_.jump_offset_s * 1e6))) {
    ++counts_.shifted;
  }
  if (corrupt) {
    std::string what;
    if (CorruptMessageField(&event.data, &rng_, &what)) {
      ++counts_.corrupted;
      ++counts_.corrupted_per_channel[channel];
      if (counts_.corruptions.size() < kCorruptionsKept) {
        counts_.corruptions.push_back(channel + ": " + what);
      }
    }
  }
  const double due = delay ? now_s + delay_s : now_s;
  if (delay) ++counts_.delayed;
  if (duplicate) {
    ++counts_.duplicated;
    Enqueue(due, event);
  }
  Enqueue(due, std::move(event));
}

bool FaultInjector::Pop(double now_s, FaultEvent* out) {
  if (queue_.empty() || (!flushing_ && queue_.front().due_s > now_s)) return false;
  *out = std::move(queue_.front().event);
  queue_.pop_front();
  ++counts_.out;
  return true;
}

void FaultInjector::Flush() { flushing_ = true; }

}  // namespace fl::bench_faults
