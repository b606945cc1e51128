#include "fusionloc/rbpf_slam/localizer_lcm.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "bot_core/rigid_transform_t.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/number_format.hpp"
#include "fusionloc/common/program.hpp"
#include "fusionloc/common/robot_description_lcm.hpp"
#include "fusionloc/status_t.hpp"
#include "fusionloc/wheel_odometry_t.hpp"

namespace fl::rbpf {

// ---- conversions ----
OccupancyMap OccupancyMapFromLcm(const fusionloc::occupancy_grid_t& g) {
  if (g.width <= 0 || g.height <= 0) {
    throw std::invalid_argument("occupancy grid has size " + std::to_string(g.width) + " x " +
                                std::to_string(g.height) + " cells; both must be > 0");
  }
  const int64_t n = static_cast<int64_t>(g.width) * g.height;
  if (g.num_cells != n || static_cast<int64_t>(g.cells.size()) != n) {
    throw std::invalid_argument(
        "occupancy grid is inconsistent: width*height = " + std::to_string(n) +
        " but num_cells = " + std::to_string(g.num_cells) + " and " +
        std::to_string(g.cells.size()) + " cells");
  }
  if (!(g.resolution > 0) || !std::isfinite(g.resolution) || !std::isfinite(g.origin_x) ||
      !std::isfinite(g.origin_y)) {
    throw std::invalid_argument("occupancy grid resolution must be > 0 and its origin finite");
  }
  OccupancyMap m;
  m.resolution = g.resolution;
  m.origin_x = g.origin_x;
  m.origin_y = g.origin_y;
  m.width = g.width;
  m.height = g.height;
  m.cells = g.cells;
  for (size_t i = 0; i < m.cells.size(); ++i) {
    if (m.cells[i] < -1 || m.cells[i] > 100) {
      throw std::invalid_argument("occupancy grid cell " + std::to_string(i) + " is " +
                                  std::to_string(m.cells[i]) + "; cells must be -1 or 0..100");
    }
  }
  return m;
}

fusionloc::occupancy_grid_t OccupancyMapToLcm(Utime utime, const OccupancyMap& map) {
  fusionloc::occupancy_grid_t g{};
  g.utime = utime;
  g.resolution = map.resolution;
  g.origin_x = map.origin_x;
  g.origin_y = map.origin_y;
  g.width = map.width;
  g.height = map.height;
  g.num_cells = map.width * map.height;
  g.cells = map.cells;
  return g;
}

bool PoseFromLcm(const bot_core::pose_t& m, Pose2* T) {
  const Eigen::Isometry3d iso = IsometryFromArrays(m.pos, m.orientation);
  *T = Pose2::FromIsometry3(iso);
  return std::isfinite(T->x) && std::isfinite(T->y) && std::isfinite(T->theta);
}

// ---- the node ----
namespace {
constexpr double kMaxOdometryM = 1e6;     // [m] as RbpfSlamNode
constexpr double kMaxMountOffsetM = 100;  // [m]
bool PlausiblePose(const Pose2& p, double max_xy) {
  return std::abs(p.x) <= max_xy && std::abs(p.y) <= max_xy && std::isfinite(p.theta);
}
std::string PoseText(const Pose2& p) {
  return "(" + FormatDouble(std::round(p.x * 1000) / 1000) + ", " +
         FormatDouble(std::round(p.y * 1000) / 1000) + ", " +
         FormatDouble(std::round(p.theta * 1000) / 1000) + " rad)";
}
}  // namespace

std::vector<ChannelSpec> LocalizerNode::Inputs() {
  return {{channels::kLaser, "bot_core.planar_lidar_t", "laser scans (required)"},
          {channels::kOdometry, "fusionloc.wheel_odometry_t",
           "wheel odometry, interpolated at each scan (required)"},
          {channels::kLaserToBase, "bot_core.rigid_transform_t",
           "T_base_laser, the robot description's mounting, read before the first scan "
           "(identity if absent, with a warning)"},
          {channels::kInitialPose, "bot_core.pose_t",
           "T_map_base: the robot's pose in the map (spread: initial_sigma_xy / "
           "initial_sigma_theta); without one, global initialisation"}};
}

std::vector<ChannelSpec> LocalizerNode::Outputs() {
  return {{channels::kRbpfPose, "bot_core.pose_t", "T_map_base at every scan"},
          {channels::kRbpfFactors, "fusionloc.relative_pose_factor_t",
           "relative poses between localized keyframes (base frame; information in x, y, yaw)"},
          {channels::kRbpfMap, "fusionloc.occupancy_grid_t",
           "the loaded map, at the first scan, every --map-period-s and at the end"}};
}

LocalizerNode::LocalizerNode(const LocalizerOptions& options,
                             const RbpfSlamNodeOptions& node_options, const OccupancyMap& map,
                             const std::string& map_name, LcmInterface* lcm,
                             const ChannelMap& channels)
    : node_options_(node_options),
      lcm_(lcm),
      ch_laser_(channels(channels::kLaser)),
      ch_odometry_(channels(channels::kOdometry)),
      ch_laser_to_base_(channels(channels::kLaserToBase)),
      ch_initial_pose_(channels(channels::kInitialPose)),
      ch_pose_(channels(channels::kRbpfPose)),
      ch_factors_(channels(channels::kRbpfFactors)),
      ch_map_(channels(channels::kRbpfMap)),
      map_name_(map_name),
      map_(map),
      localizer_(options, map),
      sync_(node_options.merge_latency_s, true),
      status_(lcm, kProgram),
      mounting_wait_(node_options.mounting_wait_s) {
  if (node_options.scan_trajectory) {
    throw UsageError(
        "--scan-trajectory cannot be used with --localize: the localizer publishes its pose on "
        "RBPF_POSE at every scan; record that");
  }
  if (node_options.no_odometry) {
    throw UsageError(
        "--no-odometry cannot be used with --localize: the localizer runs its filter on the "
        "odometry's motion; publish ODOMETRY");
  }
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
  lcm_->Subscribe<bot_core::pose_t>(
      ch_initial_pose_,
      [this](const bot_core::pose_t& m, const std::string&) { OnInitialPose(m); });
  lcm_->Subscribe<bot_core::planar_lidar_t>(
      ch_laser_,
      [this](const bot_core::planar_lidar_t& m, const std::string&) {
        status_.CountIn(ch_laser_, m.utime);
        const Status st = sync_.PushScan(ScanFromLcm(m), lcm_->last_message_utime());
        if (!st.ok()) {
          status_.CountDropped(st.message());
          warn_.Warn(st.message());
        }
      },
      LcmInterface::Duplicates::kDrop);
  lcm_->Subscribe<fusionloc::wheel_odometry_t>(
      ch_odometry_,
      [this](const fusionloc::wheel_odometry_t& m, const std::string&) {
        status_.CountIn(ch_odometry_, m.utime);
        if (!PlausiblePose(Pose2(m.x, m.y, m.theta), kMaxOdometryM)) {
          status_.CountDropped(ch_odometry_ + ": x, y, theta not finite or beyond " +
                               std::to_string(kMaxOdometryM) + " m; dropped");
          return;
        }
        const Status st =
            sync_.PushOdometry(m.utime, Pose2(m.x, m.y, m.theta), lcm_->last_message_utime());
        if (!st.ok()) {
          status_.CountDropped(st.message());
          warn_.Warn(st.message());
        }
      },
      LcmInterface::Duplicates::kDrop);
  status_.Set("state", static_cast<double>(LocalizerState::kWaiting));
  status_.SetState(fusionloc::status_t::LEVEL_STARTING,
                   "map " + map_name_ + " loaded; waiting for " + ch_laser_);
}

std::vector<std::string> LocalizerNode::RequiredInputs() const { return {ch_laser_, ch_odometry_}; }

void LocalizerNode::OnLaserToBase(const Pose2& T) {
  if (started_) {
    if (!have_laser_to_base_) {
      warn_.Warn(ch_laser_to_base_ +
                 " arrived after the first scan; T_base_laser ignored (identity used)");
    }
    return;
  }
  const Status s = localizer_.SetBaseLaser(T);
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

void LocalizerNode::OnInitialPose(const bot_core::pose_t& m) {
  status_.CountIn();
  Pose2 T;
  if (!PoseFromLcm(m, &T)) {
    status_.CountDropped(ch_initial_pose_ + ": pose not finite; ignored");
    warn_.Warn(ch_initial_pose_ + ": pose not finite; ignored");
    return;
  }
  const Status s = localizer_.SetInitialPose(T);
  if (!s.ok()) {
    status_.CountDropped(ch_initial_pose_ + ": " + s.message());
    warn_.Warn(ch_initial_pose_ + ": " + s.message());
    return;
  }
  have_initial_pose_ = true;
  initial_pose_ = T;
  FL_LOG(INFO) << ch_initial_pose_ << ": " << PoseText(T) << " (applied at the next scan)";
}

void LocalizerNode::Poll() { ProcessReady(false); }

void LocalizerNode::ProcessReady(bool flush) {
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

void LocalizerNode::RunScan(const LaserScan& scan, const Pose2* odom, const Status& lookup) {
  if (!odom) {
    status_.CountDropped("LASER: " + lookup.message());
    warn_.Warn("LASER scan dropped: " + lookup.message());
    return;
  }
  const Utime t0 = MonotonicUtime();
  LocalizationResult r;
  const Status st = localizer_.AddScan(scan, *odom, &r);
  status_.AddItemTime(static_cast<double>(MonotonicUtime() - t0) * 1e-3);
  if (!st.ok()) {
    status_.CountDropped("LASER: " + st.message());
    warn_.Warn(st.message());
    return;
  }
  if (!started_) {
    if (!have_laser_to_base_) {
      warn_.Warn("no " + ch_laser_to_base_ +
                 " before the first scan: the laser is taken to be at the base origin (identity "
                 "T_base_laser). Publish the robot description (fl-robot-description --robot "
                 "config/robot/<robot>.yaml) if it is mounted elsewhere");
    }
  }
  if (!started_ || (node_options_.map_period_s > 0 &&
                    scan.utime - last_map_utime_ >= SecondsToUtime(node_options_.map_period_s))) {
    lcm_->Publish(ch_map_, OccupancyMapToLcm(scan.utime, map_), scan.utime);
    last_map_utime_ = scan.utime;
  }
  started_ = true;
  last_utime_ = scan.utime;
  lcm_->Publish(ch_pose_, PoseToLcm(scan.utime, r.T_map_base), scan.utime);
  status_.CountOut();
  for (const auto& f : r.factors) lcm_->Publish(ch_factors_, FactorToLcm(f), scan.utime);
  if (r.odometry_jump) {
    warn_.Warn("odometry jump at utime " + std::to_string(scan.utime) +
               " flagged; step not trusted");
  }
  UpdateStatus(r);
}

void LocalizerNode::UpdateStatus(const LocalizationResult& r) {
  const LocalizerOptions& o = localizer_.options();
  const auto& s = localizer_.stats();
  const std::string why = "the scans did not fit the map (mean log-likelihood per beam " +
                          FormatDouble(std::round(r.fit * 100) / 100) + " < lost_log_likelihood " +
                          FormatDouble(o.lost_log_likelihood) + " for " +
                          std::to_string(o.lost_updates) + " filter updates)";
  const std::string next = o.relocalize ? "; relocalizing over the whole map"
                                        : "; not relocalizing (relocalize: false): publish "
                                          "INITIAL_POSE";
  if (r.initial_pose_rejected) {
    last_event_ = "initial pose " + PoseText(initial_pose_) + " rejected at utime " +
                  std::to_string(last_utime_) + ": " + why + next;
    FL_LOG(WARN) << last_event_;
  } else if (r.lost) {
    last_event_ = "lost at utime " + std::to_string(last_utime_) + " (kidnapped?): " + why + next;
    FL_LOG(WARN) << last_event_;
  } else if (r.relocalization_refused) {
    last_event_ = "poor fit at utime " + std::to_string(last_utime_) + ": " + why +
                  ", but no place on the map fits better (best " +
                  FormatDouble(std::round(r.search_fit * 100) / 100) + "): staying";
    FL_LOG(WARN) << last_event_;
  } else if (r.initialized_from_pose) {
    last_event_.clear();
  }
  status_.Set("state", static_cast<double>(r.state));
  status_.Set("particles", r.particles);
  status_.Set("neff", r.neff);
  if (r.processed) {
    status_.Set("fit", r.fit);
    last_fit_ = r.fit;
  }
  status_.Set("bad_updates", r.bad_updates);
  status_.Set("initial_poses", static_cast<double>(s.initial_poses));
  status_.Set("initial_pose_rejections", static_cast<double>(s.initial_pose_rejections));
  status_.Set("lost_detections", static_cast<double>(s.lost_detections));
  status_.Set("global_initializations", static_cast<double>(s.global_initializations));
  status_.Set("relocalizations_refused", static_cast<double>(s.relocalizations_refused));
  status_.Set("factors", static_cast<double>(s.factors));
  status_.Set("sigma_xy", std::sqrt(std::max(0.0, r.covariance(0, 0) + r.covariance(1, 1))));
  status_.Set("sigma_theta", std::sqrt(std::max(0.0, r.covariance(2, 2))));
  switch (r.state) {
    case LocalizerState::kLocalized:
      if (r.bad_updates > 0 || r.relocalization_refused) {
        // Still where it was, but the scans do not fit the map well there right now.
        status_.SetState(fusionloc::status_t::LEVEL_WARN,
                         "localized on " + map_name_ + ", but the last " +
                             std::to_string(std::max(r.bad_updates, 1)) +
                             " filter update(s) fit poorly (fit " +
                             FormatDouble(std::round(last_fit_ * 100) / 100) +
                             " < lost_log_likelihood " + FormatDouble(o.lost_log_likelihood) + ")" +
                             (last_event_.empty() ? std::string() : "; " + last_event_));
      } else {
        status_.SetState(
            fusionloc::status_t::LEVEL_OK,
            "localized on " + map_name_ +
                (last_event_.empty() ? std::string() : " (earlier: " + last_event_ + ")"));
      }
      break;
    case LocalizerState::kConverging:
      status_.SetState(fusionloc::status_t::LEVEL_WARN,
                       last_event_.empty()
                           ? std::string(s.global_initializations > 0 && !have_initial_pose_
                                             ? "converging: global initialisation (no "
                                               "INITIAL_POSE)"
                                             : "converging from the initial pose")
                           : "converging: " + last_event_);
      break;
    case LocalizerState::kLost:
      status_.SetState(fusionloc::status_t::LEVEL_ERROR,
                       last_event_.empty() ? std::string("lost") : last_event_);
      break;
    case LocalizerState::kWaiting:
      status_.SetState(fusionloc::status_t::LEVEL_STARTING, "waiting for a scan to run on");
      break;
  }
}

void LocalizerNode::Finish() {
  ProcessReady(true);
  if (started_) lcm_->Publish(ch_map_, OccupancyMapToLcm(last_utime_, map_), last_utime_);
}

std::string LocalizerNode::Summary() const {
  const auto& s = localizer_.stats();
  return "localization on " + map_name_ + ": scans " + std::to_string(s.scans) +
         ", filter updates " + std::to_string(s.processed) + " (bad fits " +
         std::to_string(s.bad_updates) + "), final state " +
         LocalizerStateName(localizer_.state()) + ", particles " +
         std::to_string(localizer_.num_particles()) + " (max " +
         std::to_string(s.max_particles_used) + "), initial poses " +
         std::to_string(s.initial_poses) + " (rejected " +
         std::to_string(s.initial_pose_rejections) + "), lost " +
         std::to_string(s.lost_detections) + ", global initialisations " +
         std::to_string(s.global_initializations) + " (searches that found no better place " +
         std::to_string(s.relocalizations_refused) + "), factors " + std::to_string(s.factors) +
         ", dropped (time) " + std::to_string(s.dropped_time_backwards) + ", rejected " +
         std::to_string(s.rejected_bad_scan) + ", odometry jumps " +
         std::to_string(s.odometry_jumps);
}

}  // namespace fl::rbpf
