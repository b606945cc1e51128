// What the viewer shows, kept without LCM: the latest grid, scan, poses, trajectories, clouds,
// process reports and channel rates, and the frames that bring a browser up to date.
//
// The process feeds it (ViewerNode, viewer/lcm/) and asks, every 100 ms, for the frames of
// what changed (TakeChanges); a browser that connects gets Snapshot(). Only what changed goes
// out, thinned: the grid when its cells changed, at most every grid_period_s; the scan at most
// every scan_period_s; trails as their new poses (TrailDecimator); whole trajectories thinned
// (DecimateTrajectory); clouds voxel-thinned (VoxelSet), the VO cloud as its new voxels only.
#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/status.hpp"
#include "fusionloc/common/time.hpp"
#include "fusionloc/viewer/decimate.hpp"
#include "fusionloc/viewer/frame.hpp"

namespace fl::viewer {

struct SceneOptions {
  double grid_period_s = 1.0;             // [s] at most one grid to the browser per period
  double scan_period_s = 0.1;             // [s] at most one scan per period (the latest)
  double trail_period_s = 0.1;            // [s] of data time between two trail poses, at least
  double trail_min_distance_m = 0.02;     // [m] a trail pose needs this much motion ...
  double trail_min_turn_rad = 0.02;       // [rad] ... or this much turn since the last one
  double trajectory_min_distance_m = 0.05;  // [m] of path between poses of a sent trajectory
  double cloud_voxel_m = 0.1;             // [m] voxel of the clouds sent to the browser
  double cloud_period_s = 1.0;            // [s] at most one cloud update per period
  int max_trail_poses = 20000;            // poses kept per trail (the oldest half goes first)
  int max_cloud_points = 300000;          // voxels kept per cloud (then new points are ignored)
  double rates_window_s = 2.0;            // [s] of data time over which channel rates are taken
  double status_period_s = 1.0;           // [s] between process table / rates updates

  template <class A>
  void Serialize(A* a) {
    a->Visit("grid_period_s", &grid_period_s);
    a->Visit("scan_period_s", &scan_period_s);
    a->Visit("trail_period_s", &trail_period_s);
    a->Visit("trail_min_distance_m", &trail_min_distance_m);
    a->Visit("trail_min_turn_rad", &trail_min_turn_rad);
    a->Visit("trajectory_min_distance_m", &trajectory_min_distance_m);
    a->Visit("cloud_voxel_m", &cloud_voxel_m);
    a->Visit("cloud_period_s", &cloud_period_s);
    a->Visit("max_trail_poses", &max_trail_poses);
    a->Visit("max_cloud_points", &max_cloud_points);
    a->Visit("rates_window_s", &rates_window_s);
    a->Visit("status_period_s", &status_period_s);
  }
  Status Validate() const;
};

struct GridView {
  Utime utime = 0;
  double resolution = 0;  // [m]
  int width = 0, height = 0;
  double origin_x = 0, origin_y = 0;  // [m] corner of cell (0, 0)
  std::vector<int8_t> cells;          // [%] 0..100, -1 unknown; row-major, row 0 at origin_y
};

struct ScanView {
  Utime utime = 0;
  std::vector<float> ranges;  // [m] <= 0 or non-finite: no return
  double rad0 = 0, radstep = 0;
};

struct ProcessView {
  std::string channel;  // STATUS_FL_RBPF_SLAM
  std::string process;  // fl-rbpf-slam
  Utime utime = 0;
  int level = 0;  // fusionloc.status_t LEVEL_*
  std::string message;
  int64_t messages_in = 0, messages_out = 0, messages_dropped = 0;
  double cpu_ms_per_item = 0;
  std::vector<std::pair<std::string, double>> values;
};

struct DeputyCommandView {
  std::string name, group, exec;
  int pid = 0, runid = 0, exit_code = 0;
  float cpu = 0;  // [fraction of a core]
  int64_t rss_bytes = 0;
};

struct DeputyView {
  std::string host;
  Utime utime = 0;
  float cpu_load = 0;
  int64_t mem_total_bytes = 0, mem_free_bytes = 0;
  std::vector<DeputyCommandView> commands;
};

// The viewer's own traffic, shown on the page.
struct ViewerStats {
  int clients = 0;
  int64_t frames_sent = 0, frames_dropped = 0, bytes_sent = 0;
};

class Scene {
 public:
  // Pose sources, by their default channel names: the robot is drawn at the first of these
  // that has a recent pose (FUSED_POSE, then RBPF_POSE, VO_POSE, ODOMETRY, GROUND_TRUTH).
  static const std::vector<std::string>& PoseSources();

  explicit Scene(const SceneOptions& options);

  void SetGrid(GridView grid);
  void SetScan(ScanView scan);
  // The laser's mounting on the base (LASER_TO_BASE), for placing scans.
  void SetLaserToBase(const Pose2& T_base_laser);
  // The left camera's mounting (CAMERA_TO_BASE), for placing VO keyframe points.
  void SetCameraToBase(const Eigen::Isometry3d& T_base_camera);
  // A pose of `source` (one of PoseSources()).
  void AddPose(const std::string& source, const ViewPose& pose);
  // A trajectory message (RBPF_TRAJECTORY, FUSED_TRAJECTORY): its poses replace those from
  // its first time on (a message may carry only the latest part, trajectory_t.lcm).
  void SetTrajectory(const std::string& source, Utime utime, const std::vector<ViewPose>& poses);
  // A whole cloud in the map frame (FUSED_MAP), replacing the previous one.
  void SetCloud(const std::string& source, Utime utime, const float* xyz, size_t n);
  // A VO keyframe's points in the camera frame: placed with the robot's current pose and the
  // camera mounting, added to the VO_POINTS cloud.
  void AddKeyframePoints(Utime utime, const float* xyz_camera, size_t n);
  void SetProcess(ProcessView process);
  void SetDeputy(DeputyView deputy);
  // Every message the process sees, for the channel rates ([us] on the message clock).
  void CountMessage(const std::string& channel, Utime utime, size_t bytes);
  void SetViewerStats(const ViewerStats& stats) { viewer_stats_ = stats; }

  // The frames of what changed since the last call; `now_s` is a monotonic clock [s] for the
  // rate limits.
  std::vector<Frame> TakeChanges(double now_s);
  // Everything, for a browser that has just connected (or after a seek in a log): the state
  // as TakeChanges last sent it, so call it right after TakeChanges.
  std::vector<Frame> Snapshot() const;
  // Forgets everything (a seek backwards in a log).
  void Reset();

  // For tests and the status line.
  bool has_grid() const { return !grid_.cells.empty(); }
  size_t trail_size(const std::string& source) const;
  size_t cloud_size(const std::string& source) const;
  int64_t frames_made() const { return frames_made_; }
  // The latest data time seen in any message.
  Utime clock() const { return clock_; }

 private:
  struct Trail {
    TrailDecimator decimator;
    std::vector<ViewPose> poses;  // kept (thinned) poses
    size_t sent = 0;              // how many of `poses` TakeChanges has sent
    bool restart = false;         // the trail was cut (time went back or capped): send whole
    ViewPose last;                // the latest pose, kept or not (the arrow)
    bool have_last = false, last_sent = true;
  };
  struct Cloud {
    explicit Cloud(double voxel) : voxels(voxel) {}
    VoxelSet voxels;
    std::vector<float> points;
    size_t sent = 0;
    bool whole = false;  // replaced: send all of it
    Utime utime = 0;
  };
  struct Rate {
    std::deque<Utime> recent;
    int64_t count = 0;
    int64_t bytes = 0;
  };

  Frame GridFrame() const;
  Frame ScanFrame() const;
  Frame TrailFrame(const std::string& source, const Trail& t, size_t from, bool replace) const;
  Frame PoseFrame() const;
  Frame TrajectoryFrame(const std::string& source) const;
  Frame CloudFrame(const std::string& source, const Cloud& c, size_t from, size_t to,
                   bool replace) const;
  Frame ProcessesFrame() const;
  Frame RatesFrame() const;
  Trail& TrailOf(const std::string& source);
  Cloud& CloudOf(const std::string& source);
  // The pose the robot is drawn at (and its source), false if none yet.
  bool RobotPose(ViewPose* pose, std::string* source) const;

  SceneOptions options_;
  GridView grid_;
  bool grid_changed_ = false;
  double grid_sent_s_ = -1e9;
  ScanView scan_;
  bool scan_changed_ = false;
  double scan_sent_s_ = -1e9;
  Pose2 T_base_laser_;
  Eigen::Isometry3d T_base_camera_ = Eigen::Isometry3d::Identity();
  std::map<std::string, Trail> trails_;
  std::map<std::string, std::vector<ViewPose>> trajectories_;
  std::map<std::string, bool> trajectory_changed_;
  std::map<std::string, Cloud> clouds_;
  double cloud_sent_s_ = -1e9;
  std::map<std::string, ProcessView> processes_;
  std::map<std::string, DeputyView> deputies_;
  bool processes_changed_ = false;
  std::map<std::string, Rate> rates_;
  double status_sent_s_ = -1e9;
  ViewerStats viewer_stats_;
  Utime clock_ = 0;
  int64_t frames_made_ = 0;
};

}  // namespace fl::viewer
