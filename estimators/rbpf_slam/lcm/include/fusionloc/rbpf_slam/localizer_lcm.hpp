// The localizer's LCM adapter (target fl_rbpf_slam_lcm): LocalizerNode, which
// `fl-rbpf-slam --localize MAP.yaml` runs instead of RbpfSlamNode (localizer.hpp holds the
// method). It reads and writes the SLAM's channels, so the fusion and the tools need no change.
//
// In:  LASER, ODOMETRY, LASER_TO_BASE (as RbpfSlamNode: the same ScanOdometrySync and
//      mounting wait), INITIAL_POSE (bot_core.pose_t: T_map_base, the robot's pose in the map;
//      its spread is the options' initial_sigma_xy / initial_sigma_theta, since pose_t has no
//      covariance). Applied at the next scan; one may come at any time to re-initialise.
// Out: RBPF_POSE (bot_core.pose_t, every scan, map frame), RBPF_FACTORS
//      (fusionloc.relative_pose_factor_t between consecutive localized keyframes, SOURCE_LASER,
//      information in rows/cols 0, 1, 5), RBPF_MAP (the loaded map as
//      fusionloc.occupancy_grid_t, at the first scan, every --map-period-s of data time and at
//      the end), STATUS_FL_RBPF_SLAM:
//      level OK while localized (WARN while its last updates fit poorly), WARN while
//      converging (after an initial pose, a global initialisation, a rejected initial pose or
//      a loss: the message says which and why),
//      ERROR when lost without relocalizing; keys state (0 waiting, 1 converging,
//      2 localized, 3 lost), particles, neff, fit, bad_updates, initial_poses,
//      initial_pose_rejections, lost_detections, global_initializations,
//      relocalizations_refused, factors, sigma_xy, sigma_theta (the pose cluster's spread).
#pragma once

#include <string>
#include <vector>

#include "bot_core/pose_t.hpp"
#include "fusionloc/common/channel_map.hpp"
#include "fusionloc/common/lcm_process.hpp"
#include "fusionloc/occupancy_grid_t.hpp"
#include "fusionloc/rbpf_slam/localizer.hpp"
#include "fusionloc/rbpf_slam/rbpf_slam_lcm.hpp"

namespace fl::rbpf {

// ---- conversions ----
// The map of a grid message (validated: sizes consistent, resolution > 0, origin finite, cells
// in -1..100; throws std::invalid_argument naming what is wrong otherwise).
OccupancyMap OccupancyMapFromLcm(const fusionloc::occupancy_grid_t& grid);
fusionloc::occupancy_grid_t OccupancyMapToLcm(Utime utime, const OccupancyMap& map);
// T_map_base of a pose message (projected on the plane); false if not finite.
bool PoseFromLcm(const bot_core::pose_t& msg, Pose2* T_map_base);

// ---- the node ----
class LocalizerNode : public LcmNode {
 public:
  static constexpr const char* kProgram = "fl-rbpf-slam";  // the same process and STATUS channel
  static std::vector<ChannelSpec> Inputs();
  static std::vector<ChannelSpec> Outputs();

  // `map_name` (the file it came from) is only for messages. Throws std::invalid_argument for
  // bad options or a map without obstacles, UsageError for --no-odometry (the filter runs on
  // odometry motion).
  LocalizerNode(const LocalizerOptions& options, const RbpfSlamNodeOptions& node_options,
                const OccupancyMap& map, const std::string& map_name, LcmInterface* lcm,
                const ChannelMap& channels);

  StatusReporter& status() override { return status_; }
  std::vector<std::string> RequiredInputs() const override;
  void Poll() override;
  void Finish() override;
  std::string Summary() const override;

  const MonteCarloLocalizer& localizer() const { return localizer_; }

 private:
  void OnLaserToBase(const Pose2& T_base_laser);
  void OnInitialPose(const bot_core::pose_t& msg);
  void ProcessReady(bool flush);
  void RunScan(const LaserScan& scan, const Pose2* odom, const Status& lookup);
  void UpdateStatus(const LocalizationResult& r);

  RbpfSlamNodeOptions node_options_;
  LcmInterface* lcm_;
  std::string ch_laser_, ch_odometry_, ch_laser_to_base_, ch_initial_pose_, ch_pose_, ch_factors_,
      ch_map_;
  std::string map_name_;
  OccupancyMap map_;
  MonteCarloLocalizer localizer_;
  ScanOdometrySync sync_;
  StatusReporter status_;
  RateLimitedWarning warn_;
  bool have_laser_to_base_ = false;
  bool started_ = false;
  MountingWait mounting_wait_;  // first scans waiting for LASER_TO_BASE
  Utime last_utime_ = 0, last_map_utime_ = 0;
  std::string last_event_;  // the last rejection / loss, kept in the status message
  double last_fit_ = 0.0;   // the last filter update's fit
  bool have_initial_pose_ = false;
  Pose2 initial_pose_;  // the last INITIAL_POSE accepted (for the messages)
};

}  // namespace fl::rbpf
