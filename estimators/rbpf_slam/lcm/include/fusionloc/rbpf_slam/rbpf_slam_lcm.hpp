// The RBPF-SLAM's LCM adapter (target fl_rbpf_slam_lcm; the core library has no LCM):
// message conversions, the scan/odometry synchronisation, and RbpfSlamNode, which fl-rbpf-slam
// and fl-replay run.
//
// In:  LASER (bot_core.planar_lidar_t), ODOMETRY (fusionloc.wheel_odometry_t, interpolated at
//      each scan's time), LASER_TO_BASE (bot_core.rigid_transform_t: T_base_laser, the robot
//      description's mounting, read before the first scan; identity, with a warning, if not).
// Out: RBPF_POSE (bot_core.pose_t, every scan), RBPF_FACTORS (fusionloc.relative_pose_factor_t,
//      ICP factors between laser keyframes in the base frame, information in the x, y, yaw
//      rows/cols 0, 1, 5), RBPF_TRAJECTORY (fusionloc.trajectory_t, keyframe poses whenever the
//      pose graph changes and at the end), RBPF_MAP (fusionloc.occupancy_grid_t, every
//      map_period_s of data time and at the end), STATUS_FL_RBPF_SLAM.
#pragma once

#include <deque>
#include <functional>
#include <string>
#include <variant>
#include <vector>

#include "bot_core/planar_lidar_t.hpp"
#include "bot_core/pose_t.hpp"
#include "fusionloc/common/channel_map.hpp"
#include "fusionloc/common/command_line.hpp"
#include "fusionloc/common/lcm_process.hpp"
#include "fusionloc/common/stream_merger.hpp"
#include "fusionloc/occupancy_grid_t.hpp"
#include "fusionloc/common/odometry_buffer.hpp"
#include "fusionloc/rbpf_slam/rbpf_slam.hpp"
#include "fusionloc/relative_pose_factor_t.hpp"
#include "fusionloc/trajectory_t.hpp"

namespace fl::rbpf {

// ---- conversions ----
LaserScan ScanFromLcm(const bot_core::planar_lidar_t& msg);
bot_core::pose_t PoseToLcm(Utime utime, const Pose2& T_world_base);
// Information goes to the x, y, yaw rows/cols (0, 1, 5) of the 6x6; SOURCE_LASER.
fusionloc::relative_pose_factor_t FactorToLcm(const KeyframeFactor& factor);
fusionloc::trajectory_t TrajectoryToLcm(Utime utime, const std::vector<StampedPose2>& poses);
// Cells in percent (100 / (1 + e^-logodds)), -1 where unknown; empty grid if nothing observed.
fusionloc::occupancy_grid_t GridToLcm(Utime utime, const TiledGrid& grid);

// ---- scan/odometry synchronisation ----
// Puts LASER and ODOMETRY in time order (StreamMerger with `merge_latency_s`) and hands each
// scan on once odometry at or after its time has been buffered (or it has waited
// `merge_latency_s` of data time), with the odometry interpolated at the scan's time.
class ScanOdometrySync {
 public:
  // `odom` is null when running without odometry; `lookup` says why there is none otherwise.
  using OnScan =
      std::function<void(const LaserScan& scan, const Pose2* odom, const Status& lookup)>;

  ScanOdometrySync(double merge_latency_s, bool use_odometry);

  // Errors (time going backwards, too late, a clock jumped ahead of the other stream's) are
  // returned and the message dropped. `arrival` [us]: the message's receive time (log time in
  // replay), for StreamMerger's clock-jump check; kNoArrival skips it.
  static constexpr Utime kNoArrival = StreamMerger<int>::kNoArrival;
  Status PushScan(LaserScan scan, Utime arrival = kNoArrival);
  Status PushOdometry(Utime utime, const Pose2& odom, Utime arrival = kNoArrival);
  // Hands on every scan that is ready; with flush, every scan still waiting too. Odometry the
  // buffer refuses is reported through `warn`.
  void Process(bool flush, const OnScan& on_scan,
               const std::function<void(const std::string&)>& warn);
  size_t waiting() const { return pending_.size(); }
  // Whether a scan at utime is late: data after its time was handed on already (PushScan would
  // refuse it); the node places such a scan by its stamp (RbpfSlam::PlaceLateScan).
  bool Late(Utime utime) const { return utime < merger_.released_utime(); }
  // The buffered odometry at utime (a late scan's).
  Status LookupOdometry(Utime utime, Pose2* odom) const { return odom_buffer_.Lookup(utime, odom); }

 private:
  using Input = std::variant<LaserScan, Pose2>;
  bool use_odometry_;
  Utime max_wait_us_;
  StreamMerger<Input> merger_;
  int laser_stream_ = -1, odom_stream_ = -1;
  fl::OdometryBuffer odom_buffer_;
  std::deque<LaserScan> pending_;
};

// ---- the wait for the laser's mounting ----
// Holds the first scans (with their odometry) until LASER_TO_BASE arrives or `wait_s` of scan
// time has passed since the first one held, then hands them on in order before the scan that
// ended the wait. Shared by the SLAM and the localizer nodes.
class MountingWait {
 public:
  explicit MountingWait(double wait_s) : wait_s_(wait_s) {}

  enum class Outcome {
    kHeldFirst,  // the scan was held and started the wait (the caller reports it)
    kHeld,       // the scan was held
    kRun,        // the held scans, then this one, went to `run`
  };
  // `waiting`: no mounting known and nothing run yet (the caller's state). While waiting and
  // within `wait_s` of the first held scan, the scan is held; otherwise it goes to `run`
  // after every held scan. wait_s <= 0 never holds.
  Outcome Offer(bool waiting, const LaserScan& scan, const Pose2* odom, const Status& lookup,
                const ScanOdometrySync::OnScan& run);
  // Hands every held scan to `run` (the mounting arrived, or the log ended).
  void Release(const ScanOdometrySync::OnScan& run);
  size_t held() const { return held_.size(); }

 private:
  struct HeldScan {
    LaserScan scan;
    bool has_odom = false;
    Pose2 odom;
    Status lookup;
  };
  double wait_s_;
  std::vector<HeldScan> held_;
};

// ---- the node ----
struct RbpfSlamNodeOptions {
  double map_period_s = 5.0;     // [s] of data time between RBPF_MAP messages (0: only at the end)
  double merge_latency_s = 0.3;  // [s] how long a scan may wait for odometry at or after its time
  bool no_odometry = false;      // scan matching from the last pose, without ODOMETRY
  // [s] of scan time the first scans wait for LASER_TO_BASE (its publishers send it every
  // second, so a process started or respawned mid-run gets it within one period); then the
  // laser is taken to be at the base origin, with a warning. 0: no wait.
  double mounting_wait_s = 2.0;
  // Keep every scan's pose (RbpfSlam::SetKeepScanPath) and publish them all on RBPF_TRAJECTORY
  // at the end (a log replay to score); off, a long run's memory stays flat and the final
  // RBPF_TRAJECTORY holds the keyframes.
  bool scan_trajectory = false;

  void AddFlags(CommandLine* cli);
  std::string Check() const;  // "" or the usage error
};

class RbpfSlamNode : public LcmNode {
 public:
  static constexpr const char* kProgram = "fl-rbpf-slam";
  static std::vector<ChannelSpec> Inputs();
  static std::vector<ChannelSpec> Outputs();

  RbpfSlamNode(const RbpfSlamOptions& options, const RbpfSlamNodeOptions& node_options,
               LcmInterface* lcm, const ChannelMap& channels);

  StatusReporter& status() override { return status_; }
  std::vector<std::string> RequiredInputs() const override;
  void Poll() override;
  void Finish() override;
  std::string Summary() const override;

 private:
  void OnLaserToBase(const Pose2& T_base_laser);
  void OnLaser(const bot_core::planar_lidar_t& msg);
  // A scan delivered after data past its time was processed (delayed or reordered beyond the
  // merge window): placed by its stamp (RbpfSlam::PlaceLateScan), its RBPF_POSE published late.
  void PlaceLateScan(const LaserScan& scan);
  // Runs every scan the synchronisation hands on (with flush: every scan still waiting too).
  void ProcessReady(bool flush);
  void RunScan(const LaserScan& scan, const Pose2* odom, const Status& lookup);
  void PublishGraph(Utime utime);            // the keyframe poses
  void PublishFinalTrajectory(Utime utime);  // at the end: every scan's, if kept

  RbpfSlamNodeOptions node_options_;
  LcmInterface* lcm_;
  std::string ch_laser_, ch_odometry_, ch_laser_to_base_, ch_pose_, ch_factors_, ch_trajectory_,
      ch_map_;
  RbpfSlam slam_;
  ScanOdometrySync sync_;
  StatusReporter status_;
  RateLimitedWarning warn_;
  bool have_laser_to_base_ = false;
  bool started_ = false;
  MountingWait mounting_wait_;  // first scans waiting for LASER_TO_BASE
  Utime last_map_utime_ = 0, last_utime_ = 0;
};

}  // namespace fl::rbpf
