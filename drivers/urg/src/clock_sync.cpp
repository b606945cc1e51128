#include "fusionloc/urg/clock_sync.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

namespace fl::urg {

int64_t TimestampUnwrapper::Unwrap(uint32_t raw_ms) {
  constexpr int64_t kPeriod = int64_t{1} << 24;
  raw_ms &= static_cast<uint32_t>(kPeriod - 1);
  if (!started_) {
    started_ = true;
    last_raw_ = raw_ms;
    last_ = raw_ms;
    return last_;
  }
  int64_t delta = (static_cast<int64_t>(raw_ms) - last_raw_) % kPeriod;
  if (delta < 0) delta += kPeriod;
  if (delta >= kPeriod / 2) delta -= kPeriod;
  last_ += delta;
  last_raw_ = raw_ms;
  return last_;
}

Status ClockSyncOptions::Validate() const {
  if (window < 10) return Status::Error("clock.window must be >= 10 scans");
  if (latency_scans < 1) return Status::Error("clock.latency_scans must be >= 1");
  if (!(min_span_s > 0)) return Status::Error("clock.min_span_s must be > 0");
  if (!(outlier_ms > 0)) return Status::Error("clock.outlier_ms must be > 0");
  return Status::Ok();
}

void ClockSync::Reset() { *this = ClockSync(options_); }

void ClockSync::AddTmSample(int64_t sensor_ms, Utime host_before, Utime host_after) {
  const double mid_us = 0.5 * (static_cast<double>(host_before) + static_cast<double>(host_after));
  if (tm_count_ == 0) tm_first_ms_ = static_cast<double>(sensor_ms);
  // The timer counts whole milliseconds: the reading was taken, on average, half a millisecond
  // after the tick it shows.
  tm_sum_offset_ += mid_us - (static_cast<double>(sensor_ms) + 0.5) * 1000.0;
  tm_rtt_sum_ += static_cast<double>(host_after - host_before) * 1e-3;
  ++tm_count_;
}

bool ClockSync::FinishTm() {
  if (tm_count_ == 0) return false;
  sensor_ref_ms_ = tm_first_ms_;
  host_ref_us_ = tm_sum_offset_ / tm_count_ + tm_first_ms_ * 1000.0;
  us_per_ms_ = 1000.0;
  tm_rtt_ms_ = tm_rtt_sum_ / tm_count_;
  synced_ = true;
  latency_known_ = false;
  window_.clear();
  return true;
}

namespace {
Utime ToHostImpl(double ref_ms, double ref_us, double us_per_ms, double sensor_ms) {
  return static_cast<Utime>(std::llround(ref_us + us_per_ms * (sensor_ms - ref_ms)));
}
}  // namespace

Utime ClockSync::ToHost(double sensor_ms) const {
  return ToHostImpl(sensor_ref_ms_, host_ref_us_, us_per_ms_, sensor_ms);
}

double ClockSync::skew_ppm() const { return (1000.0 / us_per_ms_ - 1.0) * 1e6; }

void ClockSync::AddArrival(int64_t sensor_ms, Utime host_arrival) {
  const double s = static_cast<double>(sensor_ms);
  const double arrival = static_cast<double>(host_arrival);
  if (!synced_) {
    // No TM: the arrivals alone (latency unknown, taken as 0).
    sensor_ref_ms_ = s;
    host_ref_us_ = arrival;
    us_per_ms_ = 1000.0;
    synced_ = true;
    latency_known_ = true;
    latency_ms_ = 0.0;
  }
  if (!latency_known_) {
    // Arrivals are the TM clock plus a latency: collect them until their line (rate and
    // intercept) is known, then the latency is the line's distance from the TM estimate at
    // the TM's own time (so a skew does not leak into it).
    const double d = arrival - static_cast<double>(ToHost(s));
    if (window_.empty() || d < min_delay_us_) min_delay_us_ = d;
    if (d > min_delay_us_ + options_.outlier_ms * 1000.0) return;
    window_.push_back({s, arrival});
    const double span_s = (window_.back().sensor_ms - window_.front().sensor_ms) * 1e-3;
    if (static_cast<int>(window_.size()) < options_.latency_scans || span_s < options_.min_span_s)
      return;
    const double tm_ref_ms = sensor_ref_ms_, tm_ref_us = host_ref_us_;
    Fit();  // the arrivals' own line
    const double line_at_tm = host_ref_us_ + us_per_ms_ * (tm_ref_ms - sensor_ref_ms_);
    latency_ms_ = (line_at_tm - tm_ref_us) * 1e-3;
    for (Sample& x : window_) x.host_us -= latency_ms_ * 1000.0;
    host_ref_us_ -= latency_ms_ * 1000.0;
    latency_known_ = true;
    return;
  }
  const double corrected = arrival - latency_ms_ * 1000.0;
  if (window_.size() >= 2 &&
      (corrected - static_cast<double>(ToHost(s))) * 1e-3 > options_.outlier_ms) {
    return;  // a read delayed by the host, not the sensor's clock
  }
  window_.push_back({s, corrected});
  while (static_cast<int>(window_.size()) > options_.window) window_.pop_front();
  Fit();
}

void ClockSync::Fit() {
  const size_t n = window_.size();
  if (n < 2) return;
  const double span_s = (window_.back().sensor_ms - window_.front().sensor_ms) * 1e-3;
  double ms = 0, mh = 0;
  for (const Sample& x : window_) {
    ms += x.sensor_ms;
    mh += x.host_us;
  }
  ms /= static_cast<double>(n);
  mh /= static_cast<double>(n);
  double sxx = 0, sxy = 0;
  for (const Sample& x : window_) {
    sxx += (x.sensor_ms - ms) * (x.sensor_ms - ms);
    sxy += (x.sensor_ms - ms) * (x.host_us - mh);
  }
  double rate = us_per_ms_;
  if (span_s >= options_.min_span_s && sxx > 0) rate = sxy / sxx;
  // Before the span allows a rate, keep the rate and move only the offset.
  sensor_ref_ms_ = ms;
  host_ref_us_ = mh;
  us_per_ms_ = rate;
  double ss = 0;
  for (const Sample& x : window_) {
    const double r = x.host_us - (mh + rate * (x.sensor_ms - ms));
    ss += r * r;
  }
  residual_ms_ = std::sqrt(ss / static_cast<double>(n)) * 1e-3;
}

}  // namespace fl::urg
