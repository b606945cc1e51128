// Numeric sanity of decoded input messages at the process edge. LcmInterface::Subscribe runs
// BadField(msg) on every message of a type listed here before any handler sees it: a message
// with a real field that is NaN, infinite or beyond ±kMaxFieldMagnitude is dropped, counted
// (LcmInterface::invalid_values(), status key lcm_invalid_values) and reported with a
// rate-limited warning naming the channel and the field. A sender that writes such a value is
// broken, whether or not the receiving process reads that field.
//
// Exempt: a laser's per-beam ranges and intensities (planar_lidar_t, laser_scan_3d_t), where
// ±inf and NaN mean "no return" (REP 117); the consumers leave such beams out and count them.
// Integer fields (stamps, sizes) are the consumers' to judge (clock-jump guards, image checks),
// but for a static transform's stamp, which its consumers do not use: one that is negative or
// beyond kMaxStampUs cannot come from a clock, and drops the message here.
#pragma once

#include <cstdint>
#include <string>

#include "bot_core/planar_lidar_t.hpp"
#include "bot_core/pose_t.hpp"
#include "bot_core/rigid_transform_t.hpp"
#include "fusionloc/fused_pose_t.hpp"
#include "fusionloc/point_cloud_t.hpp"
#include "fusionloc/relative_pose_factor_t.hpp"
#include "fusionloc/stereo_calibration_t.hpp"
#include "fusionloc/trajectory_t.hpp"
#include "fusionloc/wheel_odometry_t.hpp"

namespace fl {

// No quantity these messages carry, in SI units, comes near it (1e15 m is 0.1 light-year);
// the fault benchmark's "out of any range" value is 1e30.
constexpr double kMaxFieldMagnitude = 1e15;
// [us] about 73000 years: no clock stamps beyond it (the fusion refuses such stamps too).
constexpr int64_t kMaxStampUs = int64_t{1} << 61;

// The first bad real field of `msg` as "name = value" (e.g. "pos[2] = nan"); "" if none.
std::string BadField(const bot_core::planar_lidar_t& msg);  // rad0, radstep
std::string BadField(const bot_core::pose_t& msg);
std::string BadField(const bot_core::rigid_transform_t& msg);  // also utime (static: unused)
std::string BadField(const fusionloc::wheel_odometry_t& msg);
std::string BadField(const fusionloc::stereo_calibration_t& msg);
std::string BadField(const fusionloc::relative_pose_factor_t& msg);
std::string BadField(const fusionloc::point_cloud_t& msg);
std::string BadField(const fusionloc::fused_pose_t& msg);
std::string BadField(const fusionloc::trajectory_t& msg);

}  // namespace fl
