// CARMEN laser logs (.clf / .log, optionally gzip-compressed) into LCM logs.
//
// Input lines (one message per line, '#' starts a comment):
//   FLASER n r_1..r_n x y theta odom_x odom_y odom_theta ipc_timestamp hostname logger_timestamp
//   ROBOTLASER1 laser_type start_angle fov angular_resolution max_range accuracy remission_mode
//     n r_1..r_n m e_1..e_m laser_x laser_y laser_theta robot_x robot_y robot_theta laser_tv
//     laser_rv forward_safety_dist side_safety_dist turn_axis ipc_timestamp hostname
//     logger_timestamp
//   ODOM x y theta tv rv accel ipc_timestamp hostname logger_timestamp
// Ranges in metres, poses in metres/radians, timestamps in seconds. Every other message type
// (PARAM, SYNC, NEFF, RLASER, RAWLASER*, ...) is skipped and counted per type. A log with
// both FLASER and ROBOTLASER1 lines is an error (the same scans would be converted twice).
//
// Output channels (fusionloc/common/channels.hpp):
//   LASER         bot_core.planar_lidar_t, one per FLASER / ROBOTLASER1 line (ROBOTLASER1
//                 gives start_angle and angular_resolution itself). CARMEN's FLASER convention:
//                 the beams cover the 180 degree field of view counter-clockwise starting at the
//                 robot's right, so rad0 = -pi/2; the beam spacing is CARMEN's (see
//                 CarmenBeamStep): 0.5 deg for 361/360 beams, 1 deg for 181/180 beams,
//                 0.25 deg for 401/400 beams, else fov/(n-1).
//   ODOMETRY      fusionloc.wheel_odometry_t, one per FLASER line (its odometry fields) and one
//                 per ODOM line, in file order. For corrected logs: synthetic noisy odometry.
//   GROUND_TRUTH  bot_core.pose_t, corrected logs: the FLASER line's (corrected) pose; raw logs
//                 with ground_truth_from: the matched corrected scans' poses.
// Times: utime = round(ipc_timestamp * 1e6) (or logger_timestamp, see CarmenOptions).
#pragma once

#include <cmath>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/status.hpp"
#include "fusionloc/common/time.hpp"
#include "fusionloc/importers/convert_summary.hpp"

namespace fl::importers {

// The odometry-noise model for corrected logs (documented in docs/IMPORTERS.md).
// For consecutive corrected poses P_{k-1}, P_k the true motion u = P_{k-1}^-1 * P_k = (dx, dy,
// dtheta) in the previous base frame, d = |(dx, dy)|. The odometry reports
//   dx' = (1 + scale_error) * dx + N(0, sigma_xy^2)
//   dy' = (1 + scale_error) * dy + N(0, sigma_xy^2)
//   dtheta' = dtheta + yaw_bias * d + N(0, sigma_theta^2)
//   sigma_xy    = max(min_sigma_xy,    a1 * d + a2 * |dtheta|)
//   sigma_theta = max(min_sigma_theta, a3 * |dtheta| + a4 * d)
// and the noisy odometry pose integrates O_k = O_{k-1} * (dx', dy', dtheta'), O_0 = P_0.
// A step with no motion at all (d == 0 and dtheta == 0: the robot stood still) gets no noise,
// like real wheel odometry. The normal samples come from std::mt19937_64(seed) through a
// Box-Muller transform written here, so the output is the same on every platform.
struct CarmenNoiseModel {
  double a1 = 0.05;                 // [m/m] translation noise per metre travelled
  double a2 = 0.01;                 // [m/rad] translation noise per radian turned
  double a3 = 0.05;                 // [rad/rad] heading noise per radian turned
  double a4 = 0.01;                 // [rad/m] heading noise per metre travelled
  double min_sigma_xy = 0.001;      // [m] floor of sigma_xy for a moving step
  double min_sigma_theta = 0.0005;  // [rad] floor of sigma_theta for a moving step
  double scale_error = 0.0;         // [-] systematic translation scale error (0.01 = 1% long)
  double yaw_bias = 0.0;            // [rad/m] systematic heading drift per metre travelled

  template <class A>
  void Serialize(A* a) {
    a->Visit("a1", &a1);
    a->Visit("a2", &a2);
    a->Visit("a3", &a3);
    a->Visit("a4", &a4);
    a->Visit("min_sigma_xy", &min_sigma_xy);
    a->Visit("min_sigma_theta", &min_sigma_theta);
    a->Visit("scale_error", &scale_error);
    a->Visit("yaw_bias", &yaw_bias);
  }
  Status Validate() const;
};

struct CarmenOptions {
  // "auto": corrected logs (file name contains "corrected", any case) get synthetic noisy
  // odometry and their poses go to GROUND_TRUTH; raw logs keep their own odometry.
  // "true": treat the log as corrected. "false": treat it as raw.
  std::string noisy_odometry = "auto";
  uint64_t seed = 1;       // [-] seed of the odometry noise (same seed, same output)
  CarmenNoiseModel noise;  // noise model for corrected logs
  // Which CARMEN time stamp becomes utime: "ipc" (ipc_timestamp, the time the message was
  // published; absolute Unix time in live CARMEN logs) or "logger" (logger_timestamp, the
  // time the logger wrote it, often relative to the logger's start).
  std::string timestamp = "ipc";
  // Optional: a raw CARMEN log of the same run whose scans are a superset of this log's
  // (e.g. mit-csail.clf for csail-corrected.log.gz, whose time stamps were printed with only 6
  // significant digits). Each scan is matched, in order, to the raw scan with identical ranges
  // (within range_match_tolerance) and takes that scan's time stamp. A scan without a match is
  // an error.
  std::string timestamps_from;
  // Optional, for a raw log: a corrected log of the same run whose scans are a subset of this
  // log's (e.g. csail-corrected.log.gz for mit-csail.clf). Each of its scans is matched, in
  // order, to the raw scan with identical ranges, and its corrected pose is written to
  // GROUND_TRUTH with that raw scan's utime (so only the matched scans have a reference). A
  // corrected scan without a match is an error. Not with timestamps_from.
  std::string ground_truth_from;
  double range_match_tolerance = 0.006;  // [m] max per-beam difference for a match
  double fov_deg = 180.0;                // [deg] field of view of FLASER scans (CARMEN: 180)
  // Scans whose time stamp repeats the one before (a log printed with too few digits, such as
  // csail-corrected.log.gz: 406 scans, 2 distinct stamps 10^4 s apart), when timestamps_from
  // is not given:
  // "keep": kept as they are (warned; an evaluation keeps one pose per stamp).
  // "by_order": every scan is stamped by its place in the file, the first scan's stamp plus
  //   index * by_order_interval_s, so that scans, odometry and ground truth pair up by order
  //   (warned: the time is synthetic, only the order is the log's).
  // "auto": by_order when more than a quarter of the scans repeat a stamp, else keep.
  std::string repeated_stamps = "auto";
  double by_order_interval_s = 1.0;  // [s] scan spacing of by_order (corrected logs keep
                                     // about one scan per metre or per 0.5 rad of travel)

  template <class A>
  void Serialize(A* a) {
    a->Visit("noisy_odometry", &noisy_odometry);
    a->Visit("seed", &seed);
    a->Visit("noise", &noise);
    a->Visit("timestamp", &timestamp);
    a->Visit("timestamps_from", &timestamps_from);
    a->Visit("ground_truth_from", &ground_truth_from);
    a->Visit("range_match_tolerance", &range_match_tolerance);
    a->Visit("fov_deg", &fov_deg);
    a->Visit("repeated_stamps", &repeated_stamps);
    a->Visit("by_order_interval_s", &by_order_interval_s);
  }
  Status Validate() const;
};

struct CarmenScan {
  Utime utime = 0;                 // [us] from the chosen time stamp
  std::vector<float> ranges;       // [m]
  float rad0 = 0.0f;               // [rad] angle of the first beam (CCW from the robot's x axis)
  float radstep = 0.0f;            // [rad] angle between beams
  std::vector<float> intensities;  // ROBOTLASER1 remission values (empty for FLASER)
  // FLASER: the line's x y theta (the laser pose; the corrected pose in corrected logs) and
  // odom_x odom_y odom_theta. ROBOTLASER1: laser_pose and robot_pose.
  Pose2 pose;
  Pose2 odom;
  double ipc_timestamp = 0.0;     // [s] as printed
  double logger_timestamp = 0.0;  // [s] as printed
  int64_t line = 0;               // 1-based line number in the file
};

struct CarmenOdom {
  Utime utime = 0;     // [us]
  Pose2 pose;          // odometry pose x y theta
  double tv = 0.0;     // [m/s] translational velocity
  double rv = 0.0;     // [rad/s] rotational velocity
  double accel = 0.0;  // [m/s^2]
  int64_t line = 0;
};

// One parsed log. `order` interleaves scans and ODOM records in file order.
struct CarmenLog {
  std::string path;
  std::vector<CarmenScan> scans;
  std::vector<CarmenOdom> odom;
  struct Entry {
    bool is_scan;
    size_t index;  // into scans or odom
  };
  std::vector<Entry> order;
  std::map<std::string, int64_t> skipped_types;  // message type -> lines skipped
  int64_t lines = 0;                             // lines read (including comments)
  int64_t dropped_last_line = 0;  // the last line's number if it was incomplete and dropped
};

// CARMEN's beam spacing for an n-beam FLASER covering fov (radians): 0.5 deg for 361/360
// beams, 1 deg for 181/180, 0.25 deg for 401/400 (the "minus one" counts drop the last beam
// of the full sweep), otherwise fov / (n - 1).
double CarmenBeamStep(int n, double fov_rad);

// Reads a CARMEN log (.gz is decompressed). `timestamp` is "ipc" or "logger". Throws
// std::runtime_error "FILE:LINE: what is wrong (fix)" on a malformed FLASER or ODOM line, a
// missing or unreadable file, or a log without any FLASER line. Lines of every other type
// are skipped and counted, never an error. The last line alone, if incomplete (no newline at
// its end, or fewer fields than its type needs: a log cut short while written), is dropped
// with a warning naming FILE:LINE (dropped_last_line). Numbers
// may be subnormal (9.53173e-312); inf and nan are errors.
CarmenLog ReadCarmenLog(const std::string& path, const std::string& timestamp = "ipc",
                        double fov_deg = 180.0);

// True if `noisy_odometry` says this file is a corrected log (see CarmenOptions).
bool IsCorrectedCarmenLog(const CarmenOptions& options, const std::string& path);

// The noisy odometry poses, one per scan, for a corrected log (see CarmenNoiseModel).
std::vector<Pose2> SynthesizeNoisyOdometry(const CarmenNoiseModel& noise, uint64_t seed,
                                           const std::vector<Pose2>& corrected_poses);

// How an odometry compares with a reference trajectory, in the terms of CarmenNoiseModel.
// Per step k the odometry increment o = O_{k-1}^-1 O_k is compared with the reference
// increment u = P_{k-1}^-1 P_k = (dx, dy, dθ), d = |(dx, dy)|, error e = o - u (angle wrapped).
//   translation steps (|dθ| < 0.1 rad, d > 0.05 m): a1 = sqrt(Σ ½(ex² + ey²) / Σ d²),
//     a4 = sqrt(Σ eθ² / Σ d²), scale_error = Σ ex / Σ d, yaw_bias = Σ eθ / Σ d;
//   rotation steps (d < 0.1 m, |dθ| > 0.1 rad): a3 = sqrt(Σ eθ² / Σ dθ²),
//     a2 = sqrt(Σ ½(ex² + ey²) / Σ dθ²).
// The reference's own error is included, so these are upper bounds for the odometry.
struct OdometryErrorFit {
  int translation_steps = 0;
  int rotation_steps = 0;
  double a1 = NAN, a2 = NAN, a3 = NAN, a4 = NAN;  // NaN when no step of the kind
  double scale_error = NAN, yaw_bias = NAN;
  std::string ToString() const;
};
OdometryErrorFit FitOdometryError(const std::vector<Pose2>& odometry,
                                  const std::vector<Pose2>& reference);

// For each scan of `subset`, the index of the scan of `superset` with the same ranges (each
// beam within `tolerance`), searched forward in order. Throws naming the first unmatched
// scan's FILE:LINE, followed by `hint`.
std::vector<size_t> MatchScansByRanges(const CarmenLog& superset, const CarmenLog& subset,
                                       double tolerance, const std::string& hint);

// Replaces each scan's utime with the utime of the matching scan in `raw` (see
// CarmenOptions::timestamps_from). Throws naming the first unmatched scan's line.
void RecoverTimestampsByRanges(const CarmenLog& raw, double tolerance, CarmenLog* log);

// The number of scans whose utime equals the scan before's.
int64_t CountRepeatedStamps(const CarmenLog& log);

// CarmenOptions::repeated_stamps = by_order: scan k gets the first scan's utime plus
// k * interval_s. ODOM lines are left alone (a corrected log ignores them).
void StampScansByOrder(double interval_s, CarmenLog* log);

// Converts `in` to the LCM log `out_log` (written to out_log.partial, renamed when complete;
// on any error nothing is left at out_log and the exception is rethrown).
ConvertSummary ConvertCarmen(const CarmenOptions& options, const std::string& in,
                             const std::string& out_log);

}  // namespace fl::importers
