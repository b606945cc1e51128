// Trajectories for evaluation: reading them from text files (TUM, KITTI, plain 2D) and from
// the project's LCM logs, checking them, and associating two of them by time stamp.
//
//   fl::eval::Trajectory est = fl::eval::ReadTrajectoryLcm("run.lcmlog", "FUSED_POSE");
//   fl::eval::Trajectory ref = fl::eval::ReadTrajectoryText("gt.txt");          // format "auto"
//   auto pairs = fl::eval::Associate(est, ref, 10000);                          // 10 ms
//
// Every problem with the input (missing file, unknown format, malformed line, NaN, time going
// backwards, empty trajectory, channel absent or of the wrong type, no overlap) throws
// fl::eval::EvalError with a message naming the file/line or channel and the fix.
//
// Text formats (one pose a line; blank lines and lines starting with '#' are ignored;
// numbers separated by spaces, tabs or commas):
//   "tum"   t x y z qx qy qz qw          t in seconds, quaternion Hamilton (x, y, z, w)
//   "kitti" r00 r01 r02 tx r10 r11 r12 ty r20 r21 r22 tz   row-major 3x4 [R|t], no time:
//           frame i gets utime = i * 100000 (10 Hz), or the i-th time of a times file
//   "2d"    t x y theta                  t in seconds, theta in radians (CCW about z)
//   "auto"  decided by the count of numbers on the first pose line (8, 12 or 4).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "fusionloc/common/time.hpp"

namespace fl::eval {

// One pose of the robot base at a time: T_world_base (p_world = T_world_base * p_base).
struct StampedPose {
  fl::Utime utime = 0;  // [us]
  Eigen::Isometry3d T_world_base = Eigen::Isometry3d::Identity();
};

// Sorted by strictly increasing utime (the readers guarantee it).
using Trajectory = std::vector<StampedPose>;

// Every bad-input error of the evaluation tools; the message says what is wrong and the fix.
class EvalError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Time between KITTI frames when no times file is given: 10 Hz.
constexpr fl::Utime kKittiDefaultFramePeriodUs = 100000;

// Reads a text trajectory. `format`: "tum", "kitti", "2d" or "auto".
Trajectory ReadTrajectoryText(const std::string& path, const std::string& format = "auto");
// Same, for KITTI poses with a times file: one time a line, either seconds ("12.3456") or the
// KITTI raw "YYYY-MM-DD HH:MM:SS.fffffffff" (UTC). Must have one time per pose.
// An empty `kitti_times_path` means 10 Hz frame times. Ignored for other formats.
Trajectory ReadTrajectoryText(const std::string& path, const std::string& format,
                              const std::string& kitti_times_path);

// Reads poses from an LCM log. The channel's type is detected by fingerprint:
//   bot_core.pose_t          a stream of poses (utime = the message's time of validity)
//   fusionloc.fused_pose_t   a stream of planar poses
//   fusionloc.wheel_odometry_t  a stream of integrated odometry poses (odometry baseline)
//   fusionloc.trajectory_t   the LAST message on the channel (the final optimised trajectory)
// Streams are sorted by utime; a repeated utime keeps the latest message (counted, warned).
Trajectory ReadTrajectoryLcm(const std::string& log_path, const std::string& channel);

// True if the file starts with the LCM log sync word.
bool IsLcmLog(const std::string& path);

// Reads `path` as an LCM log (using `channel`) if it is one, else as text in `format`.
Trajectory ReadTrajectory(const std::string& path, const std::string& channel,
                          const std::string& format = "auto",
                          const std::string& kitti_times_path = "");

// Writes TUM text (t x y z qx qy qz qw, t in seconds with microsecond digits).
void WriteTrajectoryTum(const Trajectory& trajectory, const std::string& path);

// Throws EvalError (naming `what`) if empty, non-finite or not strictly increasing in time.
void CheckTrajectory(const Trajectory& trajectory, const std::string& what);

// Pairs (est index, ref index): each est pose with the ref pose nearest in time if within
// `max_dt_us`; one-to-one (a ref pose claimed twice keeps the nearer est pose) and monotone
// (both indices strictly increase). Throws EvalError if either is empty or no pair is found
// (the message gives both time ranges).
std::vector<std::pair<size_t, size_t>> Associate(const Trajectory& est, const Trajectory& ref,
                                                 fl::Utime max_dt_us);

// Sum of distances between consecutive positions [m].
double PathLength(const Trajectory& trajectory);

// Yaw of the rotated x axis [rad] (heading of a ground robot).
double Yaw(const Eigen::Isometry3d& T);

}  // namespace fl::eval
