#include "fusionloc/urg/clock_sync.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

namespace fl::urg {

namespace {
// Arrivals after TM before the drift filter starts (the stamps use the TM line until then).
constexpr int kMinLatencyScans = 10;
}  // namespace

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
  if (latency_scans < 10) return Status::Error("clock.latency_scans must be >= 10");
  if (!(min_span_s > 0)) return Status::Error("clock.min_span_s must be > 0");
  if (!(outlier_ms > 0)) return Status::Error("clock.outlier_ms must be > 0");
  return Status::Ok();
}

void ClockSync::Reset() { *this = ClockSync(options_); }

void ClockSync::AddTmSample(int64_t sensor_ms, Utime host_before, Utime host_after) {
  const double mid_us = 0.5 * (static_cast<double>(host_before) + static_cast<double>(host_after));
  const double rtt_ms = static_cast<double>(host_after - host_before) * 1e-3;
  // The request with the shortest round trip bounds the reading's time best (as NTP does).
  // The timer counts whole milliseconds: the reading was taken, on average, half a
  // millisecond after the tick it shows.
  if (tm_count_ == 0 || rtt_ms < tm_rtt_ms_) {
    tm_rtt_ms_ = rtt_ms;
    tm_best_ms_ = static_cast<double>(sensor_ms);
    tm_best_us_ = mid_us - 500.0;
  }
  ++tm_count_;
}

bool ClockSync::FinishTm() {
  if (tm_count_ == 0) return false;
  sensor_ref_ms_ = tm_best_ms_;
  host_ref_us_ = tm_best_us_;
  us_per_ms_ = 1000.0;
  synced_ = true;
  have_tm_ = true;
  first_.clear();
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
    have_tm_ = false;
  }
  if (have_tm_ && static_cast<int>(first_.size()) < options_.latency_scans) {
    // The first scans after TM, the least delayed of which give the latency against the TM
    // anchor (recomputed with the rate as it becomes known: a skew does not leak into it).
    const double d = arrival - static_cast<double>(ToHost(s));
    if (first_.empty() || d < min_delay_us_) min_delay_us_ = d;
    if (d > min_delay_us_ + options_.outlier_ms * 1000.0) return;
    first_.push_back({s, arrival});
    window_.push_back({s, arrival});
    if (static_cast<int>(first_.size()) >= kMinLatencyScans) Fit();
    return;
  }
  if (window_.size() >= 2 &&
      (arrival - static_cast<double>(ToHost(s))) * 1e-3 - latency_ms_ > options_.outlier_ms) {
    return;  // a read delayed by the host, not the sensor's clock
  }
  window_.push_back({s, arrival});
  while (static_cast<int>(window_.size()) > options_.window) window_.pop_front();
  Fit();
}

void ClockSync::Fit() {
  // Arrival delays are one-sided (a read is late, never early), so the line is fit to the
  // lower envelope: a least-squares fit, then up to four times again through the samples at or
  // below the line's median residual (keeping at least 4). A loaded host delays many reads; the
  // least delayed still sit on the envelope.
  std::vector<const Sample*> used;
  used.reserve(window_.size());
  for (const Sample& x : window_) used.push_back(&x);
  if (used.size() < 2) return;
  double ms = 0, mh = 0, rate = us_per_ms_;
  std::vector<double> r;
  for (int iter = 0;; ++iter) {
    const double n = static_cast<double>(used.size());
    ms = mh = 0;
    for (const Sample* x : used) {
      ms += x->sensor_ms;
      mh += x->host_us;
    }
    ms /= n;
    mh /= n;
    double sxx = 0, sxy = 0;
    for (const Sample* x : used) {
      sxx += (x->sensor_ms - ms) * (x->sensor_ms - ms);
      sxy += (x->sensor_ms - ms) * (x->host_us - mh);
    }
    const double span_s = (window_.back().sensor_ms - window_.front().sensor_ms) * 1e-3;
    // Before the span allows a rate, keep the rate and move only the offset.
    if (span_s >= options_.min_span_s && sxx > 0) rate = sxy / sxx;
    r.clear();
    for (const Sample* x : used) r.push_back(x->host_us - (mh + rate * (x->sensor_ms - ms)));
    if (iter == 4 || used.size() < 8) break;
    std::vector<double> sorted = r;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const double median = sorted[sorted.size() / 2];
    std::vector<const Sample*> lower;
    for (size_t k = 0; k < used.size(); ++k) {
      if (r[k] <= median) lower.push_back(used[k]);
    }
    used.swap(lower);
  }
  // The latency: the least delayed of the first scans against the TM anchor, at this rate.
  if (have_tm_ && !first_.empty()) {
    double lat =
        first_.front().host_us - (tm_best_us_ + rate * (first_.front().sensor_ms - tm_best_ms_));
    for (const Sample& x : first_) {
      lat = std::min(lat, x.host_us - (tm_best_us_ + rate * (x.sensor_ms - tm_best_ms_)));
    }
    latency_ms_ = lat * 1e-3;
  } else {
    latency_ms_ = 0.0;
  }
  sensor_ref_ms_ = ms;
  host_ref_us_ = mh - latency_ms_ * 1000.0;
  us_per_ms_ = rate;
  // Residual: every arrival of the window about the clock line (read delays and misfit).
  double ss = 0;
  for (const Sample& x : window_) {
    const double e = x.host_us - (mh + rate * (x.sensor_ms - ms));
    ss += e * e;
  }
  residual_ms_ = std::sqrt(ss / static_cast<double>(window_.size())) * 1e-3;
}

}  // namespace fl::urg
