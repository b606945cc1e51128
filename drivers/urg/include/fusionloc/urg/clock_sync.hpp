// Host time for the sensor's 24-bit millisecond clock.
//
//  1. TimestampUnwrapper turns the 24-bit timer (wraps every 2^24 ms = 4.66 h) into a
//     continuous count of milliseconds.
//  2. ClockSync estimates host_time = offset + rate * sensor_time:
//     - from TM1 replies (TM0 / TM1 x n / TM2 before streaming): the reading of the request
//       with the shortest round trip, placed in the middle of it, gives the offset.
//     - then from scan arrivals (the drift filter): arrival = true time + latency + delay. A
//       line through (sensor time, arrival) over a sliding window tracks offset and rate
//       (skew); read delays are one-sided, so it is fit to the lower envelope of the arrivals.
//       The latency (time of the last step, transfer) is the smallest distance of the first
//       scans after TM from the TM anchor at the current rate; stamps are the line minus it.
//     The residual (RMS of the line's misfit) is what the driver reports in its status.
#pragma once

#include <cstdint>
#include <deque>
#include <vector>

#include "fusionloc/common/status.hpp"
#include "fusionloc/common/time.hpp"

namespace fl::urg {

class TimestampUnwrapper {
 public:
  // The continuous time [ms] of a 24-bit reading: the nearest continuation of the previous one
  // (a step back of less than half the period is a step back, not a wrap).
  int64_t Unwrap(uint32_t raw_ms);
  void Reset() { started_ = false; }

 private:
  bool started_ = false;
  uint32_t last_raw_ = 0;
  int64_t last_ = 0;
};

struct ClockSyncOptions {
  int window = 300;          // [scans] drift-filter window (30 s at 10 Hz)
  int latency_scans = 50;    // [scans] the first scans after TM whose least delayed gives the
                             //         arrival latency (>= 10; more: robust to a busy host)
  double min_span_s = 2.0;   // [s] sensor-time span of arrivals before the rate is estimated
  double outlier_ms = 20.0;  // [ms] arrivals later than the fit by more than this are not used
                             //      (a delayed read, not clock drift)

  template <class A>
  void Serialize(A* a) {
    a->Visit("window", &window);
    a->Visit("latency_scans", &latency_scans);
    a->Visit("min_span_s", &min_span_s);
    a->Visit("outlier_ms", &outlier_ms);
  }
  Status Validate() const;
};

class ClockSync {
 public:
  explicit ClockSync(const ClockSyncOptions& options) : options_(options) {}

  // Forgets everything (after a reconnect: the sensor's timer may have been reset).
  void Reset();

  // One TM1 reading: the request was written at host_before, the reply read at host_after.
  void AddTmSample(int64_t sensor_ms, Utime host_before, Utime host_after);
  // The TM burst is over: offset from the TM samples (rate 1 until arrivals say otherwise).
  // False if there was no TM sample.
  bool FinishTm();

  // A scan with sensor time `sensor_ms` was read completely at host time `host_arrival`.
  void AddArrival(int64_t sensor_ms, Utime host_arrival);

  bool synced() const { return synced_; }
  // Host time [us] of a sensor time [ms].
  Utime ToHost(double sensor_ms) const;

  // Sensor clock rate relative to the host's, minus 1 [ppm] (positive: the sensor runs fast).
  double skew_ppm() const;
  // Host - sensor time at the reference [us].
  double offset_us() const { return host_ref_us_ - sensor_ref_ms_ * 1000.0; }
  // RMS of the window's arrivals about the drift filter's line [ms]: read-delay jitter plus
  // misfit (0 before the filter runs).
  double residual_ms() const { return residual_ms_; }
  // Learned latency of a scan arrival after the scan's step-0 time [ms].
  double latency_ms() const { return latency_ms_; }
  // Round trip of the best TM request [ms].
  double tm_round_trip_ms() const { return tm_rtt_ms_; }

 private:
  void Fit();

  ClockSyncOptions options_;
  bool synced_ = false;
  // host_us = host_ref_us_ + us_per_ms_ * (sensor_ms - sensor_ref_ms_)
  double sensor_ref_ms_ = 0.0, host_ref_us_ = 0.0, us_per_ms_ = 1000.0;
  double tm_best_ms_ = 0.0, tm_best_us_ = 0.0;  // the TM reading with the shortest round trip
  int tm_count_ = 0;
  double tm_rtt_ms_ = 0.0;
  double min_delay_us_ = 0.0;  // smallest arrival - TM estimate of the first scans
  bool have_tm_ = false;
  double latency_ms_ = 0.0;
  struct Sample {
    double sensor_ms;
    double host_us;  // arrival
  };
  std::vector<Sample> first_;  // the first latency_scans arrivals after TM
  std::deque<Sample> window_;  // the drift filter's arrivals
  double residual_ms_ = 0.0;
};

}  // namespace fl::urg
