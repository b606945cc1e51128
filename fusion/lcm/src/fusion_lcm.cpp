#include "fusionloc/fusion/fusion_lcm.hpp"

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "fusionloc/common/robot_description_lcm.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/common/number_format.hpp"
#include "fusionloc/fused_pose_t.hpp"
#include "fusionloc/maps/map_export.hpp"
#include "fusionloc/status_t.hpp"

namespace fl::fusion {
namespace {

// Time stamps beyond ±2^61 us (about 73000 years) cannot come from a clock: refused at the
// door, so that the fusion's differences of two time stamps never overflow int64.
constexpr Utime kMaxUtime = Utime{1} << 61;
bool PlausibleUtime(Utime t) { return t > -kMaxUtime && t < kMaxUtime; }
std::atomic<bool> g_save_map_requested{false};
}  // namespace

bool FactorFromLcm(const fusionloc::relative_pose_factor_t& m, RelativePoseFactor* f,
                   std::string* error) {
  const int8_t laser = fusionloc::relative_pose_factor_t::SOURCE_LASER;
  const int8_t vision = fusionloc::relative_pose_factor_t::SOURCE_VISION;
  const int8_t wheel = fusionloc::relative_pose_factor_t::SOURCE_WHEEL_ODOMETRY;
  if (m.source == laser) {
    f->source = FactorSource::kLaser;
  } else if (m.source == vision) {
    f->source = FactorSource::kVision;
  } else if (m.source == wheel) {
    f->source = FactorSource::kWheelOdometry;
  } else {
    *error = "relative_pose_factor_t with unknown source " + std::to_string(m.source);
    return false;
  }
  const double qn = std::sqrt(m.quat[0] * m.quat[0] + m.quat[1] * m.quat[1] +
                              m.quat[2] * m.quat[2] + m.quat[3] * m.quat[3]);
  if (!(std::fabs(qn - 1.0) < 1e-3)) {
    *error = "relative_pose_factor_t quaternion has norm " + std::to_string(qn) +
             " (must be a unit quaternion w, x, y, z)";
    return false;
  }
  f->utime_i = m.utime_i;
  f->utime_j = m.utime_j;
  f->T_i_j = IsometryFromArrays(m.trans, m.quat);
  for (int k = 0; k < 36; ++k) f->information(k / 6, k % 6) = m.information[k];
  f->is_loop_closure = m.is_loop_closure;
  return true;
}

fusionloc::trajectory_t TrajectoryToLcm(const std::vector<TrajectoryPoint>& traj, Utime utime) {
  fusionloc::trajectory_t msg;
  msg.utime = utime;
  msg.num_poses = static_cast<int32_t>(traj.size());
  for (const auto& p : traj) {
    msg.utimes.push_back(p.utime);
    msg.x.push_back(p.T_map_base.x);
    msg.y.push_back(p.T_map_base.y);
    msg.z.push_back(0.0);
    msg.theta.push_back(p.T_map_base.theta);
  }
  return msg;
}

void FusionNodeOptions::AddFlags(CommandLine* cli) {
  cli->AddFlag("map-out", &map_out,
               "prefix of the saved 3D map: PREFIX.pcd and PREFIX_top.png ('' = don't save)");
  cli->AddFlag("sync-full-solve", &sync_full_solve,
               "run full solves inline (always the case when replaying a log)");
  cli->AddFlag("state-file", &state_file,
               "live: keep the map frame's offset from the RBPF's world in this file, and go on "
               "from it when started again within --state-max-age-s (a respawn after a crash)");
  cli->AddFlag("state-max-age-s", &state_max_age_s, "[s] oldest state file that is used");
}

std::vector<ChannelSpec> FusionNode::Inputs() {
  return {{channels::kRbpfPose, "bot_core.pose_t", "laser-rate nodes of the graph (required)"},
          {channels::kRbpfFactors, "fusionloc.relative_pose_factor_t", "laser keyframe factors"},
          {channels::kVoFactors, "fusionloc.relative_pose_factor_t", "visual keyframe factors"},
          {channels::kOdometry, "fusionloc.wheel_odometry_t", "wheel odometry between nodes"},
          {channels::kVoPoints, "fusionloc.point_cloud_t", "keyframe points for the 3D map"},
          {channels::kCameraToBase, "bot_core.rigid_transform_t",
           "T_base_camera (robot description) for the keyframe points"}};
}

std::vector<ChannelSpec> FusionNode::Outputs() {
  return {{channels::kFusedPose, "fusionloc.fused_pose_t", "T_map_base at the laser rate"},
          {channels::kFusedTrajectory, "fusionloc.trajectory_t",
           "the fused trajectory, when it changes"},
          {channels::kFusedMap, "fusionloc.point_cloud_t",
           "the 3D map (map frame), at the end and on SIGUSR1"}};
}

void FusionNode::RequestMapSave() { g_save_map_requested = true; }

FusionNode::FusionNode(const FusionProcessConfig& config, const FusionNodeOptions& node_options,
                       LcmInterface* lcm, const ChannelMap& channels)
    : config_(config),
      node_options_(node_options),
      lcm_(lcm),
      async_(!(node_options.sync_full_solve || lcm->replaying())),
      with_time_(!lcm->replaying()),
      ch_rbpf_pose_(channels(channels::kRbpfPose)),
      ch_odometry_(channels(channels::kOdometry)),
      ch_points_(channels(channels::kVoPoints)),
      ch_camera_to_base_(channels(channels::kCameraToBase)),
      ch_pose_(channels(channels::kFusedPose)),
      ch_trajectory_(channels(channels::kFusedTrajectory)),
      ch_map_(channels(channels::kFusedMap)),
      fusion_(config.graph),
      map_(config.map),
      status_(lcm, kProgram) {
  lcm_->Subscribe<bot_core::pose_t>(
      ch_rbpf_pose_, [this](const bot_core::pose_t& m, const std::string&) { OnLaserPose(m); });
  for (const char* ch : {channels::kRbpfFactors, channels::kVoFactors}) {
    lcm_->Subscribe<fusionloc::relative_pose_factor_t>(
        channels(ch), [this](const fusionloc::relative_pose_factor_t& m, const std::string& c) {
          OnFactor(m, c);
        });
  }
  lcm_->Subscribe<fusionloc::wheel_odometry_t>(
      ch_odometry_,
      [this](const fusionloc::wheel_odometry_t& m, const std::string&) { OnOdometry(m); });
  lcm_->Subscribe<fusionloc::point_cloud_t>(
      ch_points_, [this](const fusionloc::point_cloud_t& m, const std::string&) { OnPoints(m); });
  lcm_->Subscribe<bot_core::rigid_transform_t>(
      ch_camera_to_base_, [this](const bot_core::rigid_transform_t& m, const std::string&) {
        T_base_camera_ = TransformFromLcm(m);
        have_camera_to_base_ = true;
      });
  status_.SetState(fusionloc::status_t::LEVEL_STARTING, "waiting for " + ch_rbpf_pose_);
  LoadState();
  if (!async_ && lcm->replaying()) FL_LOG(INFO) << "replaying a log: full solves inline";
}

FusionNode::~FusionNode() {
  if (job_future_.valid()) job_future_.wait();
}

void FusionNode::Poll() {
  if (job_future_.valid() &&
      job_future_.wait_for(std::chrono::seconds(0)) == std::future_status::ready) {
    FinishFullSolve();
  }
  if (g_save_map_requested.exchange(false)) SaveMap();
}

void FusionNode::Finish() {
  if (job_future_.valid()) {
    job_future_.wait();
    FinishFullSolve();
  }
  if (fusion_.num_nodes() > 0) {
    const SolveSummary s = fusion_.FullSolve();
    FL_LOG(INFO) << "final " << s.ToString();
    PublishTrajectory(last_utime_);
  }
  SaveMap();
  status_.SetState(fusionloc::status_t::LEVEL_OK,
                   "finished: " + fusion_.last_summary().ToString(with_time_));
}

std::string FusionNode::Summary() const {
  const auto& c = fusion_.counters();
  return std::to_string(fusion_.num_nodes()) + " nodes, " + std::to_string(fusion_.num_factors()) +
         " factors, " + std::to_string(c.full_solves) + " full solves, " +
         std::to_string(c.rejected_total()) + " inputs rejected, " +
         std::to_string(fusion_.num_pending_factors()) + " factors still waiting for a laser node";
}

void FusionNode::OnLaserPose(const bot_core::pose_t& m) {
  status_.CountIn();
  if (!PlausibleUtime(m.utime)) {
    status_.CountDropped(ch_rbpf_pose_ + ": utime " + std::to_string(m.utime) + " out of range");
    return;
  }
  const auto t0 = std::chrono::steady_clock::now();
  const Eigen::Isometry3d T = IsometryFromArrays(m.pos, m.orientation);
  last_rbpf_pose_ = Pose2::FromIsometry3(T);
  last_rbpf_utime_ = m.utime;
  const Status s = fusion_.AddLaserPose(m.utime, T_map_rbpf_ * last_rbpf_pose_);
  if (!s.ok()) {
    status_.CountDropped(s.message());
    return;
  }
  last_utime_ = m.utime;
  const SolveSummary u = fusion_.Update();
  PublishPose();
  if (fusion_.full_solve_requested() && !job_future_.valid()) StartFullSolve();
  if (UtimeToSeconds(m.utime - last_trajectory_utime_) >= config_.trajectory_period_s) {
    PublishTrajectory(m.utime);
  }
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  status_.AddItemTime(ms);
  status_.SetTiming("update_ms", u.time_ms);
  status_.Set("nodes", fusion_.num_nodes());
  status_.Set("factors", fusion_.num_factors());
  status_.Set("pending_factors", fusion_.num_pending_factors());
  status_.Set("rejected", static_cast<double>(fusion_.counters().rejected_total()));
  status_.Set("full_solves", static_cast<double>(fusion_.counters().full_solves));
  status_.Set("odometry_factors", static_cast<double>(fusion_.counters().odometry_factors));
  status_.Set("odometry_gaps", static_cast<double>(fusion_.counters().odometry_gaps));
  status_.Set("chain_factors", static_cast<double>(fusion_.counters().chain_factors));
  status_.Set("map_keyframes", map_.num_keyframes());
  if (u.ran) {
    status_.SetState(fusionloc::status_t::LEVEL_OK,
                     u.ToString(with_time_) +
                         (last_full_.ran ? "; last " + last_full_.ToString(with_time_) : ""));
  }
}

void FusionNode::OnFactor(const fusionloc::relative_pose_factor_t& m, const std::string& channel) {
  status_.CountIn();
  if (!PlausibleUtime(m.utime_i) || !PlausibleUtime(m.utime_j)) {
    status_.CountDropped(channel + ": utime_i/utime_j out of range");
    return;
  }
  RelativePoseFactor f;
  std::string error;
  if (!FactorFromLcm(m, &f, &error)) {
    status_.CountDropped(channel + ": " + error);
    bad_factor_warning_.Warn(channel + ": " + error + "; dropped");
    return;
  }
  const Status s = fusion_.AddFactor(f);
  if (!s.ok()) status_.CountDropped(channel + ": " + s.message());
}

void FusionNode::OnOdometry(const fusionloc::wheel_odometry_t& m) {
  status_.CountIn();
  if (!PlausibleUtime(m.utime)) {
    status_.CountDropped(ch_odometry_ + ": utime " + std::to_string(m.utime) + " out of range");
    return;
  }
  const Status s = fusion_.AddOdometry(m.utime, Pose2(m.x, m.y, m.theta));
  if (!s.ok()) status_.CountDropped(s.message());
}

void FusionNode::OnPoints(const fusionloc::point_cloud_t& m) {
  status_.CountIn();
  if (!PlausibleUtime(m.utime)) {
    status_.CountDropped(ch_points_ + ": utime " + std::to_string(m.utime) + " out of range");
    return;
  }
  std::vector<Eigen::Vector3f> points;
  try {
    points = maps::PointsFromMessage(m);
  } catch (const std::exception& e) {
    status_.CountDropped(ch_points_ + ": " + e.what());
    return;
  }
  Eigen::Isometry3f T_base_frame = Eigen::Isometry3f::Identity();
  if (m.frame == "camera") {
    if (!have_camera_to_base_) {
      status_.CountDropped(ch_points_ + " in the camera frame before any " + ch_camera_to_base_ +
                           " (T_base_camera unknown); keyframe dropped");
      return;
    }
    T_base_frame = T_base_camera_.cast<float>();
  } else if (m.frame != "base") {
    status_.CountDropped(ch_points_ + " frame '" + m.frame +
                         "' unsupported; keyframe points must be in 'camera' or 'base'");
    return;
  }
  for (auto& p : points) p = T_base_frame * p;
  const Status s = map_.AddKeyframe(m.utime, points);
  if (!s.ok()) status_.CountDropped(s.message());
}

void FusionNode::PublishPose() {
  TrajectoryPoint p;
  if (!fusion_.Latest(&p)) return;
  fusionloc::fused_pose_t msg;
  msg.utime = p.utime;
  msg.x = p.T_map_base.x;
  msg.y = p.T_map_base.y;
  msg.theta = p.T_map_base.theta;
  const Eigen::Matrix3d& c = fusion_.latest_covariance();
  for (int k = 0; k < 9; ++k) msg.covariance[k] = c(k / 3, k % 3);
  msg.num_nodes = fusion_.num_nodes();
  msg.num_factors = fusion_.num_factors();
  lcm_->Publish(ch_pose_, msg, p.utime);
  status_.CountOut();
  SaveState(p.utime, p.T_map_base);
}

std::string FormatFusionState(Utime utime, const Pose2& T_map_rbpf) {
  std::ostringstream out;
  out << "fusionloc-fusion-state 1\nutime " << utime << "\nT_map_rbpf "
      << FormatDouble(T_map_rbpf.x) << " " << FormatDouble(T_map_rbpf.y) << " "
      << FormatDouble(T_map_rbpf.theta) << "\n";
  return out.str();
}

bool ParseFusionState(const std::string& text, Utime* utime, Pose2* T_map_rbpf,
                      std::string* error) {
  std::istringstream in(text);
  std::string magic, key_utime, key_T;
  int version = 0;
  double x = 0, y = 0, theta = 0;
  if (!(in >> magic >> version) || magic != "fusionloc-fusion-state" || version != 1) {
    *error = "not a fusion state file (expected 'fusionloc-fusion-state 1' first)";
    return false;
  }
  if (!(in >> key_utime >> *utime) || key_utime != "utime" || !(in >> key_T >> x >> y >> theta) ||
      key_T != "T_map_rbpf" || !std::isfinite(x) || !std::isfinite(y) || !std::isfinite(theta)) {
    *error = "malformed: expected 'utime U' and 'T_map_rbpf X Y THETA' with finite numbers";
    return false;
  }
  *T_map_rbpf = Pose2(x, y, WrapAngle(theta));
  return true;
}

void FusionNode::LoadState() {
  const std::string& path = node_options_.state_file;
  if (path.empty() || lcm_->replaying()) return;
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return;  // a first start
  const auto age =
      std::filesystem::file_time_type::clock::now() - std::filesystem::last_write_time(path, ec);
  const double age_s = std::chrono::duration<double>(age).count();
  if (ec || age_s > node_options_.state_max_age_s) {
    FL_LOG(INFO) << "state file " << path << " is " << static_cast<int>(age_s)
                 << " s old (limit --state-max-age-s " << node_options_.state_max_age_s
                 << "): starting a new map frame";
    return;
  }
  std::ifstream in(path);
  std::ostringstream text;
  text << in.rdbuf();
  Utime utime = 0;
  Pose2 T;
  std::string error;
  if (!ParseFusionState(text.str(), &utime, &T, &error)) {
    FL_LOG(WARN) << "state file " << path << ": " << error << "; starting a new map frame";
    return;
  }
  T_map_rbpf_ = T;
  FL_LOG(INFO) << "going on in the map frame of " << path << " (" << age_s << " s old, utime "
               << utime << "): T_map_rbpf x " << T.x << " y " << T.y << " theta " << T.theta;
  status_.Set("resumed_from_state", 1.0);
}

void FusionNode::SaveState(Utime utime, const Pose2& T_map_base) {
  const std::string& path = node_options_.state_file;
  if (path.empty() || lcm_->replaying() || utime != last_rbpf_utime_) return;
  if (last_state_utime_ != 0 && UtimeToSeconds(utime - last_state_utime_) < 0.5) return;
  last_state_utime_ = utime;
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp, std::ios::trunc);
    out << FormatFusionState(utime, T_map_base * last_rbpf_pose_.inverse());
    if (!out) {
      state_warning_.Warn("cannot write the state file " + tmp + " (check the folder)");
      return;
    }
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    state_warning_.Warn("cannot rename " + tmp + " to " + path);
  }
}

void FusionNode::PublishTrajectory(Utime utime) {
  lcm_->Publish(ch_trajectory_, TrajectoryToLcm(fusion_.Trajectory(), utime), utime);
  status_.CountOut();
  last_trajectory_utime_ = utime;
}

void FusionNode::StartFullSolve() {
  if (!async_) {
    last_full_ = fusion_.FullSolve();
    PublishTrajectory(last_utime_);
    return;
  }
  job_ = fusion_.PrepareFullSolve();
  FullSolveJob* job = job_.get();
  job_future_ = std::async(std::launch::async, [job] { job->Run(); });
}

void FusionNode::FinishFullSolve() {
  job_future_.get();
  fusion_.ApplyFullSolve(*job_);
  last_full_ = job_->summary();
  job_.reset();
  FL_LOG(INFO) << last_full_.ToString();
  PublishTrajectory(last_utime_);
}

void FusionNode::SaveMap() {
  int skipped = 0;
  const std::vector<Eigen::Vector3f> points =
      map_.Build([this](Utime t, Pose2* p) { return fusion_.PoseAt(t, p); }, &skipped);
  if (skipped > 0) {
    FL_LOG(WARN) << skipped << " map keyframes lie outside the fused trajectory's time span "
                 << "and were left out";
  }
  if (points.empty()) {
    FL_LOG(INFO) << "3D map is empty (" << map_.num_keyframes() << " keyframes on " << ch_points_
                 << "); nothing saved";
    return;
  }
  fusionloc::point_cloud_t msg;
  msg.utime = last_utime_;
  msg.frame = "map";
  msg.num_points = static_cast<int32_t>(points.size());
  for (const auto& p : points) msg.points.push_back({p.x(), p.y(), p.z()});
  msg.num_intensities = 0;
  lcm_->Publish(ch_map_, msg, last_utime_);
  const std::string& out = node_options_.map_out;
  if (out.empty()) return;
  try {
    const std::filesystem::path parent = std::filesystem::path(out).parent_path();
    if (!parent.empty()) std::filesystem::create_directories(parent);
    maps::SavePointCloudPcd(points, {}, out + ".pcd");
    maps::SavePointCloudTopView(points, out + "_top.png", config_.map_png_resolution_m);
    FL_LOG(INFO) << "saved " << points.size() << " map points to " << out << ".pcd and " << out
                 << "_top.png";
  } catch (const std::exception& e) {
    FL_LOG(ERROR) << "could not save the 3D map to " << out << ".*: " << e.what();
  }
}

}  // namespace fl::fusion
