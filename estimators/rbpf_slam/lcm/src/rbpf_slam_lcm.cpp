#include "fusionloc/rbpf_slam/rbpf_slam_lcm.hpp"

#include <algorithm>
#include <cmath>

#include "fusionloc/common/robot_description_lcm.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/number_format.hpp"
#include "fusionloc/common/geometry.hpp"
#include "fusionloc/status_t.hpp"
#include "bot_core/rigid_transform_t.hpp"
#include "fusionloc/wheel_odometry_t.hpp"

namespace fl::rbpf {

// ---- conversions ----
namespace {
constexpr double kMaxOdometryM = 1e6;     // [m] 1000 km from the odometry origin
constexpr double kMaxMountOffsetM = 100;  // [m] a sensor mounted on the robot
bool PlausiblePose(const Pose2& p, double max_xy) {
  return std::abs(p.x) <= max_xy && std::abs(p.y) <= max_xy && std::isfinite(p.theta);
}
}  // namespace

LaserScan ScanFromLcm(const bot_core::planar_lidar_t& m) {
  LaserScan s;
  s.utime = m.utime;
  s.ranges = m.ranges;
  s.rad0 = m.rad0;
  s.radstep = m.radstep;
  return s;
}

bot_core::pose_t PoseToLcm(Utime utime, const Pose2& p) {
  bot_core::pose_t m{};
  m.utime = utime;
  double trans[3], quat[4];
  IsometryToArrays(p.ToIsometry3(), trans, quat);
  for (int i = 0; i < 3; ++i) m.pos[i] = trans[i];
  for (int i = 0; i < 4; ++i) m.orientation[i] = quat[i];
  return m;
}

fusionloc::relative_pose_factor_t FactorToLcm(const KeyframeFactor& f) {
  fusionloc::relative_pose_factor_t m{};
  m.utime_i = f.utime_i;
  m.utime_j = f.utime_j;
  double trans[3], quat[4];
  IsometryToArrays(f.T_i_j.ToIsometry3(), trans, quat);
  for (int i = 0; i < 3; ++i) m.trans[i] = trans[i];
  for (int i = 0; i < 4; ++i) m.quat[i] = quat[i];
  const int idx[3] = {0, 1, 5};  // x, y, yaw rows/cols of the 6x6 information
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) m.information[idx[r] * 6 + idx[c]] = f.information(r, c);
  }
  m.source = fusionloc::relative_pose_factor_t::SOURCE_LASER;
  m.is_loop_closure = f.is_loop_closure;
  m.keyframe_id_i = f.keyframe_i;
  m.keyframe_id_j = f.keyframe_j;
  return m;
}

fusionloc::trajectory_t TrajectoryToLcm(Utime utime, const std::vector<StampedPose2>& poses) {
  fusionloc::trajectory_t m{};
  m.utime = utime;
  m.num_poses = static_cast<int32_t>(poses.size());
  for (const auto& p : poses) {
    m.utimes.push_back(p.utime);
    m.x.push_back(p.T_world_base.x);
    m.y.push_back(p.T_world_base.y);
    m.z.push_back(0.0);
    m.theta.push_back(p.T_world_base.theta);
  }
  return m;
}

fusionloc::occupancy_grid_t GridToLcm(Utime utime, const TiledGrid& g) {
  fusionloc::occupancy_grid_t m{};
  m.utime = utime;
  m.resolution = g.resolution();
  int x0, y0, x1, y1;
  if (!g.Bounds(&x0, &y0, &x1, &y1)) return m;
  m.width = x1 - x0;
  m.height = y1 - y0;
  m.origin_x = x0 * g.resolution();
  m.origin_y = y0 * g.resolution();
  m.num_cells = m.width * m.height;
  m.cells.resize(static_cast<size_t>(m.num_cells));
  for (int y = y0; y < y1; ++y) {
    for (int x = x0; x < x1; ++x) {
      const float l = g.LogOdds(x, y);
      int8_t v = -1;
      if (l != 0.0f) v = static_cast<int8_t>(std::lround(100.0 / (1.0 + std::exp(-l))));
      m.cells[static_cast<size_t>(y - y0) * m.width + (x - x0)] = v;
    }
  }
  return m;
}

// ---- scan/odometry synchronisation ----
ScanOdometrySync::ScanOdometrySync(double merge_latency_s, bool use_odometry)
    : use_odometry_(use_odometry),
      max_wait_us_(SecondsToUtime(merge_latency_s)),
      merger_(SecondsToUtime(merge_latency_s)) {
  laser_stream_ = merger_.AddStream(channels::kLaser);
  if (use_odometry_) odom_stream_ = merger_.AddStream(channels::kOdometry);
}

Status ScanOdometrySync::PushScan(LaserScan scan, Utime arrival) {
  const Utime t = scan.utime;
  return merger_.Push(laser_stream_, t, Input(std::move(scan)), arrival);
}

Status ScanOdometrySync::PushOdometry(Utime utime, const Pose2& odom, Utime arrival) {
  if (!use_odometry_) return Status::Ok();
  return merger_.Push(odom_stream_, utime, Input(odom), arrival);
}

void ScanOdometrySync::Process(bool flush, const OnScan& on_scan,
                               const std::function<void(const std::string&)>& warn) {
  if (flush) merger_.Flush();
  auto hand_on = [&](const LaserScan& scan) {
    if (!use_odometry_) {
      on_scan(scan, nullptr, Status::Ok());
      return;
    }
    Pose2 odom;
    const Status st = odom_buffer_.Lookup(scan.utime, &odom);
    on_scan(scan, st.ok() ? &odom : nullptr, st);
  };
  // Scans wait in pending_ until odometry at or after their time has been buffered (the merger
  // releases a scan once the odometry stream has *sent* a later sample, which may still be
  // queued behind it).
  StreamMerger<Input>::Item item;
  Utime newest = 0;
  while (merger_.Pop(&item)) {
    newest = std::max(newest, item.utime);
    if (const Pose2* odom = std::get_if<Pose2>(&item.value)) {
      const Status st = odom_buffer_.Add(item.utime, *odom);
      if (!st.ok()) warn("ODOMETRY: " + st.message());
    } else {
      pending_.push_back(std::move(std::get<LaserScan>(item.value)));
    }
    while (!pending_.empty() &&
           (!use_odometry_ ||
            (!odom_buffer_.empty() && odom_buffer_.newest() >= pending_.front().utime) ||
            newest - pending_.front().utime > max_wait_us_)) {
      const LaserScan scan = std::move(pending_.front());
      pending_.pop_front();
      hand_on(scan);
    }
  }
  if (flush) {
    while (!pending_.empty()) {
      const LaserScan scan = std::move(pending_.front());
      pending_.pop_front();
      hand_on(scan);
    }
  }
}

// ---- the node ----
MountingWait::Outcome MountingWait::Offer(bool waiting, const LaserScan& scan, const Pose2* odom,
                                          const Status& lookup,
                                          const ScanOdometrySync::OnScan& run) {
  if (waiting && wait_s_ > 0.0 &&
      (held_.empty() ||
       UtimeDifference(held_.front().scan.utime, scan.utime) < SecondsToUtime(wait_s_))) {
    held_.push_back({scan, odom != nullptr, odom ? *odom : Pose2(), lookup});
    return held_.size() == 1 ? Outcome::kHeldFirst : Outcome::kHeld;
  }
  Release(run);
  run(scan, odom, lookup);
  return Outcome::kRun;
}

void MountingWait::Release(const ScanOdometrySync::OnScan& run) {
  std::vector<HeldScan> held;
  held.swap(held_);
  for (const HeldScan& h : held) run(h.scan, h.has_odom ? &h.odom : nullptr, h.lookup);
}

void RbpfSlamNodeOptions::AddFlags(CommandLine* cli) {
  cli->AddFlag("map-period-s", &map_period_s,
               "publish RBPF_MAP every this many seconds of data time (0: only at the end)");
  cli->AddFlag("merge-latency-s", &merge_latency_s,
               "how long a scan may wait for odometry at or after its time [s]");
  cli->AddFlag("no-odometry", &no_odometry,
               "run without wheel odometry (scan matching from the last pose)");
  cli->AddFlag("mounting-wait-s", &mounting_wait_s,
               "[s] of scan time the first scans wait for LASER_TO_BASE before the laser is "
               "taken to be at the base origin (0: no wait)");
  cli->AddFlag("scan-trajectory", &scan_trajectory,
               "keep every scan's pose and publish them all (smoothed) on RBPF_TRAJECTORY at the "
               "end, for scoring a log replay (64 bytes per scan in memory; off: keyframe poses)");
  cli->AddCheck([this] { return Check(); });
}

std::string RbpfSlamNodeOptions::Check() const {
  if (!(map_period_s >= 0.0)) return "--map-period-s must be >= 0";
  if (!(merge_latency_s > 0.0)) return "--merge-latency-s must be > 0";
  if (!(mounting_wait_s >= 0.0)) return "--mounting-wait-s must be >= 0";
  return "";
}

std::vector<ChannelSpec> RbpfSlamNode::Inputs() {
  return {{channels::kLaser, "bot_core.planar_lidar_t", "laser scans (required)"},
          {channels::kOdometry, "fusionloc.wheel_odometry_t",
           "wheel odometry, interpolated at each scan (required unless --no-odometry)"},
          {channels::kLaserToBase, "bot_core.rigid_transform_t",
           "T_base_laser, the robot description's mounting, read before the first scan "
           "(identity if absent, with a warning)"}};
}

std::vector<ChannelSpec> RbpfSlamNode::Outputs() {
  return {{channels::kRbpfPose, "bot_core.pose_t", "T_world_base at every scan"},
          {channels::kRbpfFactors, "fusionloc.relative_pose_factor_t",
           "ICP keyframe factors (base frame; information in x, y, yaw)"},
          {channels::kRbpfTrajectory, "fusionloc.trajectory_t",
           "keyframe poses, when the pose graph changes and at the end"},
          {channels::kRbpfMap, "fusionloc.occupancy_grid_t",
           "occupancy grid, every --map-period-s and at the end"}};
}

RbpfSlamNode::RbpfSlamNode(const RbpfSlamOptions& options, const RbpfSlamNodeOptions& node_options,
                           LcmInterface* lcm, const ChannelMap& channels)
    : node_options_(node_options),
      lcm_(lcm),
      ch_laser_(channels(channels::kLaser)),
      ch_odometry_(channels(channels::kOdometry)),
      ch_laser_to_base_(channels(channels::kLaserToBase)),
      ch_pose_(channels(channels::kRbpfPose)),
      ch_factors_(channels(channels::kRbpfFactors)),
      ch_trajectory_(channels(channels::kRbpfTrajectory)),
      ch_map_(channels(channels::kRbpfMap)),
      slam_(options),
      sync_(node_options.merge_latency_s, !node_options.no_odometry),
      status_(lcm, kProgram),
      mounting_wait_(node_options.mounting_wait_s) {
  slam_.SetKeepScanPath(node_options.scan_trajectory);
  lcm_->Subscribe<bot_core::rigid_transform_t>(
      ch_laser_to_base_, [this](const bot_core::rigid_transform_t& m, const std::string&) {
        const Pose2 T = Pose2::FromIsometry3(TransformFromLcm(m));
        if (!PlausiblePose(T, kMaxMountOffsetM)) {
          status_.CountDropped(ch_laser_to_base_ + ": T_base_laser not finite or more than " +
                               std::to_string(kMaxMountOffsetM) + " m away; ignored");
          return;
        }
        OnLaserToBase(T);
      });
  lcm_->Subscribe<bot_core::planar_lidar_t>(
      ch_laser_, [this](const bot_core::planar_lidar_t& m, const std::string&) { OnLaser(m); },
      LcmInterface::Duplicates::kDrop);
  if (!node_options_.no_odometry) {
    lcm_->Subscribe<fusionloc::wheel_odometry_t>(
        ch_odometry_, [this](const fusionloc::wheel_odometry_t& m, const std::string&) {
          status_.CountIn(ch_odometry_, m.utime);
          // Odometry further than kMaxOdometryM from its origin is corrupt: poses that far
          // have no grid cell (the map's cell indices are ints).
          if (!PlausiblePose(Pose2(m.x, m.y, m.theta), kMaxOdometryM)) {
            status_.CountDropped(ch_odometry_ + ": x, y, theta not finite or beyond " +
                                 std::to_string(kMaxOdometryM) + " m; dropped");
            return;
          }
          const Status st = sync_.PushOdometry(m.utime, Pose2(m.x, m.y, m.theta),
                                               lcm_->last_message_utime());
          if (!st.ok()) {
            status_.CountDropped(st.message());
            warn_.Warn(st.message());
          }
        },
        LcmInterface::Duplicates::kDrop);
  }
  status_.SetState(fusionloc::status_t::LEVEL_STARTING, "waiting for " + ch_laser_);
}

std::vector<std::string> RbpfSlamNode::RequiredInputs() const {
  if (node_options_.no_odometry) return {ch_laser_};
  return {ch_laser_, ch_odometry_};
}

void RbpfSlamNode::OnLaserToBase(const Pose2& T) {
  if (started_) {
    if (!have_laser_to_base_) {
      warn_.Warn(ch_laser_to_base_ +
                 " arrived after the first scan; T_base_laser ignored (identity used)");
    }
    return;
  }
  const Status s = slam_.SetBaseLaser(T);
  if (!s.ok()) {
    warn_.Warn(ch_laser_to_base_ + ": " + s.message());
    return;
  }
  if (!have_laser_to_base_) {
    FL_LOG(INFO) << "T_base_laser from " << ch_laser_to_base_ << ": x " << T.x << " y " << T.y
                 << " yaw " << T.theta;
  }
  have_laser_to_base_ = true;
  mounting_wait_.Release([this](const LaserScan& scan, const Pose2* odom, const Status& lookup) {
    RunScan(scan, odom, lookup);
  });
}

void RbpfSlamNode::OnLaser(const bot_core::planar_lidar_t& m) {
  status_.CountIn(ch_laser_, m.utime);
  if (started_ && !node_options_.no_odometry && sync_.Late(m.utime)) {
    PlaceLateScan(ScanFromLcm(m));
    return;
  }
  const Status st = sync_.PushScan(ScanFromLcm(m), lcm_->last_message_utime());
  if (!st.ok()) {
    status_.CountDropped(st.message());
    warn_.Warn(st.message());
  }
}

void RbpfSlamNode::PlaceLateScan(const LaserScan& scan) {
  Pose2 odom, T_world_base;
  Status st = sync_.LookupOdometry(scan.utime, &odom);
  if (!st.ok()) {
    st = Status::Error("scan at utime " + std::to_string(scan.utime) +
                       " arrived late and has no odometry to place it by: " + st.message() +
                       "; dropped");
  } else {
    st = slam_.PlaceLateScan(scan, odom, &T_world_base);
  }
  if (!st.ok()) {
    status_.CountDropped("LASER: " + st.message());
    warn_.Warn("LASER: " + st.message());
    return;
  }
  lcm_->Publish(ch_pose_, PoseToLcm(scan.utime, T_world_base), scan.utime);
  status_.CountOut();
  status_.Set("late_scans_placed", static_cast<double>(slam_.stats().late_scans_placed));
}

void RbpfSlamNode::Poll() { ProcessReady(false); }

void RbpfSlamNode::ProcessReady(bool flush) {
  const auto run = [this](const LaserScan& scan, const Pose2* odom, const Status& lookup) {
    RunScan(scan, odom, lookup);
  };
  sync_.Process(
      flush,
      [&](const LaserScan& scan, const Pose2* odom, const Status& lookup) {
        if (mounting_wait_.Offer(!started_ && !have_laser_to_base_, scan, odom, lookup, run) ==
            MountingWait::Outcome::kHeldFirst) {
          status_.SetState(fusionloc::status_t::LEVEL_STARTING,
                           "waiting up to " + FormatDouble(node_options_.mounting_wait_s) +
                               " s for " + ch_laser_to_base_);
        }
      },
      [this](const std::string& w) { warn_.Warn(w); });
  if (flush) mounting_wait_.Release(run);
}

void RbpfSlamNode::RunScan(const LaserScan& scan, const Pose2* odom_in, const Status& lookup) {
  Pose2 odom;
  if (!node_options_.no_odometry) {
    if (!odom_in) {
      status_.CountDropped("LASER: " + lookup.message());
      warn_.Warn("LASER scan dropped: " + lookup.message());
      return;
    }
    odom = *odom_in;
  } else {
    odom = slam_.stats().scans == 0 ? Pose2() : slam_.CurrentPose();
  }
  const Utime t0 = MonotonicUtime();
  ScanResult r;
  // The pose goes out as soon as the filter has it; the keyframe stage (ICP factors, loop
  // closures, the pose graph) runs after, so that it never delays what the robot steers by. A
  // correction it makes shows in the next scan's pose.
  const Status st = slam_.AddScan(scan, odom, &r, /*defer_keyframe=*/true);
  if (!st.ok()) {
    status_.AddItemTime(static_cast<double>(MonotonicUtime() - t0) * 1e-3);
    status_.CountDropped("LASER: " + st.message());
    warn_.Warn(st.message());
    return;
  }
  if (!started_ && !have_laser_to_base_) {
    warn_.Warn("no " + ch_laser_to_base_ +
               " before the first scan: the laser is taken to be at the base origin (identity "
               "T_base_laser). Publish the robot description (fl-robot-description --robot "
               "config/robot/<robot>.yaml) if it is mounted elsewhere");
  }
  started_ = true;
  last_utime_ = scan.utime;
  lcm_->Publish(ch_pose_, PoseToLcm(scan.utime, r.T_world_base), scan.utime);
  status_.CountOut();
  slam_.FinishScan(&r);
  status_.AddItemTime(static_cast<double>(MonotonicUtime() - t0) * 1e-3);
  for (const auto& f : r.factors) lcm_->Publish(ch_factors_, FactorToLcm(f), scan.utime);
  if (r.graph_changed) PublishGraph(scan.utime);
  if (r.odometry_jump) {
    warn_.Warn("odometry jump at utime " + std::to_string(scan.utime) +
               " flagged; step not trusted");
  }
  if (node_options_.map_period_s > 0 &&
      scan.utime - last_map_utime_ >= SecondsToUtime(node_options_.map_period_s)) {
    lcm_->Publish(ch_map_, GridToLcm(scan.utime, slam_.BestMap()), scan.utime);
    last_map_utime_ = scan.utime;
  }
  const auto& s = slam_.stats();
  status_.Set("particles", slam_.num_particles());
  status_.Set("neff", r.neff);
  status_.Set("keyframes", static_cast<double>(s.keyframes));
  status_.Set("loop_closures", static_cast<double>(s.loop_closures));
  status_.Set("keyframe_reuses", static_cast<double>(s.keyframe_reuses));
  status_.Set("keyframes_bounded", static_cast<double>(s.keyframes_bounded));
  status_.Set("map_rebuilds", static_cast<double>(s.map_rebuilds));
  status_.Set("divergences", static_cast<double>(s.divergences));
  status_.Set("recoveries", static_cast<double>(s.recoveries));
  status_.Set("skipped_fast_turn", static_cast<double>(s.skipped_fast_turn));
  status_.Set("scans_refined", static_cast<double>(s.scans_refined));
  status_.Set("turn_scans_placed", static_cast<double>(s.turn_scans_placed));
  status_.Set("late_scans_placed", static_cast<double>(s.late_scans_placed));
  status_.Set("noisy_factors", static_cast<double>(s.noisy_factors));
  status_.Set("odometry_jumps", static_cast<double>(s.odometry_jumps));
  status_.Set("invalid_beams", static_cast<double>(s.invalid_beams));
  status_.Set("map_integrations_refused", static_cast<double>(s.map_integrations_refused));
  status_.SetState(fusionloc::status_t::LEVEL_OK, "running");
}

void RbpfSlamNode::PublishGraph(Utime utime) {
  lcm_->Publish(ch_trajectory_, TrajectoryToLcm(utime, slam_.KeyframePoses()), utime);
}

void RbpfSlamNode::PublishFinalTrajectory(Utime utime) {
  // With --scan-trajectory every scan's smoothed pose, else the keyframes (Trajectory() is
  // KeyframePoses() when the scan path is not kept).
  lcm_->Publish(ch_trajectory_, TrajectoryToLcm(utime, slam_.Trajectory()), utime);
}

void RbpfSlamNode::Finish() {
  ProcessReady(true);
  slam_.Finish();
  if (started_) {
    PublishFinalTrajectory(last_utime_);
    lcm_->Publish(ch_map_, GridToLcm(last_utime_, slam_.BestMap()), last_utime_);
  }
}

std::string RbpfSlamNode::Summary() const {
  const auto& s = slam_.stats();
  return "scans " + std::to_string(s.scans) + ", processed " + std::to_string(s.processed) +
         ", keyframes " + std::to_string(s.keyframes) + " (reused on revisits " +
         std::to_string(s.keyframe_reuses) + ", in full places unverified " +
         std::to_string(s.keyframes_bounded) + ")" + ", loop closures " +
         std::to_string(s.loop_closures) + " (of " + std::to_string(s.loop_candidates) +
         " candidates), divergences caught " + std::to_string(s.divergences) +
         ", lost-track recoveries " + std::to_string(s.recoveries) +
         ", scans held back in fast turns " + std::to_string(s.skipped_fast_turn) +
         " (placed by the turn search " + std::to_string(s.turn_scans_placed) + " of " +
         std::to_string(s.turn_searches) + " searched)" + ", late scans placed by their stamp " +
         std::to_string(s.late_scans_placed) +
         ", dropped (time) " + std::to_string(s.dropped_time_backwards) + ", rejected " +
         std::to_string(s.rejected_bad_scan) + ", odometry jumps " +
         std::to_string(s.odometry_jumps) + ", map integrations refused (beyond grid.max_size_m) " +
         std::to_string(s.map_integrations_refused);
}

}  // namespace fl::rbpf
