#include "fusionloc/fusion/fusion_lcm.hpp"

#include <atomic>
#include <chrono>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/common/message_checks.hpp"
#include "fusionloc/common/robot_description_lcm.hpp"
#include "fusionloc/common/state_buffer.hpp"
#include "fusionloc/common/yaml_options.hpp"
#include "fusionloc/fused_pose_t.hpp"
#include "fusionloc/maps/map_export.hpp"
#include "fusionloc/status_t.hpp"

namespace fl::fusion {
namespace {

// Time stamps beyond ±kMaxStampUs (2^61 us, about 73000 years) cannot come from a clock: refused
// at the door, so that the fusion's differences of two time stamps never overflow int64.
bool PlausibleUtime(Utime t) { return t > -kMaxStampUs && t < kMaxStampUs; }
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
  cli->AddFlag("journal", &journal,
               "live: record every input in this LCM log, and when started again within "
               "--journal-max-age-s (a respawn after a crash) replay it first and go on with the "
               "same graph and map");
  cli->AddFlag("journal-max-age-s", &journal_max_age_s, "[s] oldest journal that is replayed");
  cli->AddFlag("journal-snapshot-s", &journal_snapshot_s,
               "[s] of data time between journal snapshots (the saved state, then the inputs "
               "since: the journal and a respawn's replay stay bounded); 0 = never");
  cli->AddCheck([this] {
    return journal_max_age_s >= 0.0 && journal_snapshot_s >= 0.0 &&
                   std::isfinite(journal_max_age_s) && std::isfinite(journal_snapshot_s)
               ? std::string()
               : std::string("--journal-max-age-s and --journal-snapshot-s must be >= 0");
  });
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
  Handle<bot_core::pose_t>(ch_rbpf_pose_, [this](const bot_core::pose_t& m) { OnLaserPose(m); });
  for (const char* ch : {channels::kRbpfFactors, channels::kVoFactors}) {
    const std::string channel = channels(ch);
    Handle<fusionloc::relative_pose_factor_t>(
        channel,
        [this, channel](const fusionloc::relative_pose_factor_t& m) { OnFactor(m, channel); });
  }
  Handle<fusionloc::wheel_odometry_t>(
      ch_odometry_, [this](const fusionloc::wheel_odometry_t& m) { OnOdometry(m); });
  Handle<fusionloc::point_cloud_t>(ch_points_,
                                   [this](const fusionloc::point_cloud_t& m) { OnPoints(m); });
  Handle<bot_core::rigid_transform_t>(ch_camera_to_base_,
                                      [this](const bot_core::rigid_transform_t& m) {
                                        T_base_camera_ = TransformFromLcm(m);
                                        have_camera_to_base_ = true;
                                      });
  status_.SetState(fusionloc::status_t::LEVEL_STARTING, "waiting for " + ch_rbpf_pose_);
  if (!async_ && lcm->replaying()) FL_LOG(INFO) << "replaying a log: full solves inline";
  RestoreFromJournal();
}

template <class Msg>
void FusionNode::Handle(const std::string& channel, std::function<void(const Msg&)> handler) {
  journal_handlers_[channel] = [handler](const void* data, int size) {
    Msg msg;
    if (msg.decode(data, 0, size) != size) return false;
    handler(msg);
    return true;
  };
  // Estimates and odometry carry their own stamps: a byte-identical repeat is a duplicate.
  const auto duplicates = std::is_same_v<Msg, bot_core::rigid_transform_t>
                              ? LcmInterface::Duplicates::kDeliver
                              : LcmInterface::Duplicates::kDrop;
  lcm_->Subscribe<Msg>(
      channel,
      [this, handler](const Msg& m, const std::string& ch) {
        handler(m);
        if (journal_writer_) {
          const int size = m.getEncodedSize();
          encode_buffer_.resize(static_cast<size_t>(size));
          m.encode(encode_buffer_.data(), 0, size);
          Record(ch, encode_buffer_.data(), size);
        }
      },
      duplicates);
}

void FusionNode::RestoreFromJournal() {
  const std::string& path = node_options_.journal;
  if (path.empty() || lcm_->replaying()) return;
  try {
    retired_file_ = std::make_shared<RetiredSpillFile>(path + ".retired");
    fusion_ = NewGraph();
  } catch (const std::exception& ex) {
    FL_LOG(ERROR) << ex.what() << "; the retired trajectory stays in memory (it grows by "
                  << "2.3 MB an hour at 10 Hz)";
    retired_file_.reset();
  }
  std::error_code ec;
  std::vector<LcmLogEvent> events;
  if (std::filesystem::exists(path, ec)) {
    const auto age =
        std::filesystem::file_time_type::clock::now() - std::filesystem::last_write_time(path, ec);
    const double age_s = std::chrono::duration<double>(age).count();
    if (ec || age_s > node_options_.journal_max_age_s) {
      FL_LOG(INFO) << "journal " << path << " is " << static_cast<int>(age_s)
                   << " s old (limit --journal-max-age-s " << node_options_.journal_max_age_s
                   << "): starting a new graph";
    } else {
      try {
        LcmLogReader reader(path);
        LcmLogEvent e;
        while (reader.Next(&e)) events.push_back(std::move(e));
        if (!reader.ProblemSummary().empty()) {
          FL_LOG(WARN) << "journal " << path << ": " << reader.ProblemSummary() << "; the "
                       << events.size() << " whole inputs before it are used";
        }
      } catch (const std::exception& ex) {
        FL_LOG(WARN) << "journal " << path << " unreadable (" << ex.what()
                     << "): starting a new graph";
        events.clear();
      }
    }
  }
  // The journal is written anew (its valid events first, so that a damaged tail is not kept
  // in the middle of it) and renamed into place before anything is appended.
  const std::string fresh = path + ".new";
  try {
    journal_writer_ = std::make_unique<LcmLogWriter>(fresh, /*atomic=*/false);
    for (const LcmLogEvent& e : events) {
      journal_writer_->Write(e.channel, e.data.data(), static_cast<int>(e.data.size()), e.utime);
    }
    journal_writer_->Flush();
    if (std::rename(fresh.c_str(), path.c_str()) != 0) {
      throw std::runtime_error("cannot rename " + fresh + " to " + path);
    }
  } catch (const std::exception& ex) {
    FL_LOG(ERROR) << "journal " << path << ": " << ex.what()
                  << "; going on without one (a respawn will start a new graph)";
    journal_writer_.reset();
  }
  if (events.empty()) return;
  const auto t0 = std::chrono::steady_clock::now();
  size_t first_input = 0;
  std::string from_snapshot;
  if (events.front().channel == kJournalSnapshotChannel) {
    try {
      LoadState(events.front().data);
      first_input = 1;
      from_snapshot = "a snapshot of " + std::to_string(fusion_.num_nodes()) + " nodes and " +
                      std::to_string(fusion_.num_retired_nodes()) + " retired (" +
                      std::to_string(fusion_.retired_trajectory().spilled()) + " of them in " +
                      path + ".retired), then ";
    } catch (const std::exception& ex) {
      FL_LOG(WARN) << "journal " << path << ": its snapshot cannot be used (" << ex.what()
                   << "): starting a new graph";
      Reset();
      return;
    }
  }
  restoring_ = true;
  int64_t used = 0;
  for (size_t k = first_input; k < events.size(); ++k) {
    const LcmLogEvent& e = events[k];
    const auto it = journal_handlers_.find(e.channel);
    if (it != journal_handlers_.end() && it->second(e.data.data(), static_cast<int>(e.data.size())))
      ++used;
  }
  restoring_ = false;
  if (fusion_.num_nodes() == 0) return;
  const SolveSummary full = fusion_.FullSolve();
  last_full_ = full;
  restored_ = true;
  restored_until_ = last_utime_;
  last_snapshot_utime_ = last_utime_;
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  FL_LOG(INFO) << "restored from the journal " << path << ": " << from_snapshot << used
               << " inputs, "
               << fusion_.num_nodes() << " nodes, " << fusion_.num_factors() << " factors, "
               << map_.num_keyframes() << " map keyframes, in " << static_cast<int>(ms)
               << " ms; going on with the same graph (" << full.ToString() << ")";
  restored_inputs_ = used;
  status_.Set("restored_inputs", static_cast<double>(used));
}

void FusionNode::Record(const std::string& channel, const void* data, int size) {
  try {
    journal_writer_->Write(channel, data, size, lcm_->Now());
    journal_writer_->Flush();
  } catch (const std::exception& e) {
    journal_warning_.Warn(std::string(e.what()) + "; the journal stops here");
    journal_writer_.reset();
  }
}

namespace {
constexpr char kNodeStateMagic[] = "FLFUSNOD";
constexpr uint32_t kNodeStateVersion = 1;
}  // namespace

std::vector<uint8_t> FusionNode::SaveState(std::vector<uint8_t> buffer) const {
  StateWriter w(std::move(buffer));
  w.Begin(kNodeStateMagic, kNodeStateVersion);
  w.Put(ConfigText());
  w.Put(last_utime_);
  w.Put(last_trajectory_utime_);
  w.Put(Eigen::Matrix4d(T_base_camera_.matrix()));
  w.Put(static_cast<uint8_t>(have_camera_to_base_));
  fusion_.SaveState(&w);
  map_.SaveState(&w);
  return w.Release();
}

void FusionNode::LoadState(const std::vector<uint8_t>& bytes) {
  StateReader r(bytes.data(), bytes.size());
  r.Begin(kNodeStateMagic, kNodeStateVersion);
  if (r.GetString("config") != ConfigText()) {
    throw std::runtime_error("it was made with another configuration (the fusion's YAML)");
  }
  const Utime last_utime = r.Get<int64_t>("last_utime");
  const Utime last_trajectory_utime = r.Get<int64_t>("last_trajectory_utime");
  Eigen::Matrix4d T_base_camera;
  r.Get(&T_base_camera, "T_base_camera");
  if (!T_base_camera.allFinite()) r.Fail("T_base_camera is not finite");
  const bool have_camera_to_base = r.GetBool("have_camera_to_base");
  FactorGraphFusion fusion = NewGraph();
  fusion.LoadState(&r);
  PointMap map(config_.map);
  map.LoadState(&r);
  r.End("fusion node state");
  fusion_ = std::move(fusion);
  map_ = std::move(map);
  last_utime_ = last_utime;
  last_trajectory_utime_ = last_trajectory_utime;
  T_base_camera_.matrix() = T_base_camera;
  have_camera_to_base_ = have_camera_to_base;
}

std::string FusionNode::ConfigText() const {
  YAML::Emitter out;
  YamlWriteArchive archive(&out);
  const_cast<FusionProcessConfig&>(config_).Serialize(&archive);
  return out.c_str();
}

void FusionNode::SnapshotJournal() {
  snapshot_due_ = false;
  const auto t0 = std::chrono::steady_clock::now();
  const std::string& path = node_options_.journal;
  const std::string fresh = path + ".new";
  try {
    // Room for growth first, so that the buffer is seldom reallocated as the state grows.
    if (snapshot_buffer_.capacity() < snapshot_buffer_.size() + snapshot_buffer_.size() / 4) {
      snapshot_buffer_.reserve(snapshot_buffer_.size() + snapshot_buffer_.size() / 2);
    }
    snapshot_buffer_ = SaveState(std::move(snapshot_buffer_));
    const std::vector<uint8_t>& bytes = snapshot_buffer_;
    auto writer = std::make_unique<LcmLogWriter>(fresh, /*atomic=*/false);
    writer->Write(kJournalSnapshotChannel, bytes.data(), static_cast<int>(bytes.size()),
                  lcm_->Now());
    writer->Flush();
    if (std::rename(fresh.c_str(), path.c_str()) != 0) {
      throw std::runtime_error("cannot rename " + fresh + " to " + path + ": " +
                               std::strerror(errno));
    }
    journal_writer_ = std::move(writer);
    const double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    status_.Set("journal_snapshot_mb", static_cast<double>(bytes.size()) / 1e6);
    status_.SetTiming("journal_snapshot_ms", ms);
    FL_LOG(DEBUG) << "journal " << path << ": snapshot of " << bytes.size() << " bytes in "
                  << ms << " ms";
  } catch (const std::exception& e) {
    std::error_code ec;
    std::filesystem::remove(fresh, ec);
    snapshot_warning_.Warn("journal " + path + ": no snapshot (" + e.what() +
                           "); the journal goes on growing with every input");
  }
}

FactorGraphFusion FusionNode::NewGraph() const {
  FactorGraphFusion fusion(config_.graph);
  if (retired_file_) {
    const size_t keep = std::max<size_t>(1, node_options_.retired_in_memory);
    fusion.SpillRetiredTrajectory(retired_file_, keep,
                                  std::min(keep, RetiredTrajectory::kDefaultSpillBatch));
  }
  return fusion;
}

void FusionNode::Reset() {
  fusion_ = NewGraph();
  map_ = PointMap(config_.map);
  last_utime_ = 0;
  last_trajectory_utime_ = 0;
  last_full_ = SolveSummary();
  if (journal_writer_) {
    try {
      journal_writer_ = std::make_unique<LcmLogWriter>(node_options_.journal, /*atomic=*/false);
    } catch (const std::exception& e) {
      FL_LOG(ERROR) << e.what() << "; going on without a journal";
      journal_writer_.reset();
    }
  }
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
  if (snapshot_due_ && journal_writer_ && !job_future_.valid()) SnapshotJournal();
}

void FusionNode::Finish() {
  if (job_future_.valid()) {
    job_future_.wait();
    FinishFullSolve();
  }
  if (fusion_.num_nodes() > 0) {
    const SolveSummary s = fusion_.FullSolve();
    FL_LOG(INFO) << "final " << s.ToString();
    PublishTrajectory(last_utime_, /*whole=*/true);
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
  status_.CountIn(ch_rbpf_pose_, m.utime);
  if (!PlausibleUtime(m.utime)) {
    status_.CountDropped(ch_rbpf_pose_ + ": utime " + std::to_string(m.utime) + " out of range");
    return;
  }
  const auto t0 = std::chrono::steady_clock::now();
  if (restored_ && !restoring_) {
    restored_ = false;
    if (m.utime + SecondsToUtime(5.0) < restored_until_) {
      FL_LOG(WARN) << "the first live " << ch_rbpf_pose_ << " (utime " << m.utime
                   << ") is older than the journal's newest node (utime " << restored_until_
                   << "): the journal is of another run; starting a new graph";
      Reset();
    }
  }
  const Utime arrival = lcm_->last_message_utime();
  if (!restoring_) {
    const Status jump = laser_clock_.Check(ch_rbpf_pose_, m.utime, arrival);
    if (!jump.ok()) {
      status_.CountDropped(jump.message());
      clock_warning_.Warn(jump.message());
      return;
    }
  }
  const Eigen::Isometry3d T = IsometryFromArrays(m.pos, m.orientation);
  // The laser back at the stamp of a node the odometry placed in its outage: that node takes
  // this RBPF pose (its FUSED_POSE is out already).
  const bool newest = fusion_.num_nodes() > 0 && m.utime == fusion_.newest_node_utime();
  const bool in_outage = fusion_.newest_node_from_odometry();
  auto log_back = [&] {
    if (in_outage && !fusion_.newest_node_from_odometry() && !restoring_) {
      FL_LOG(INFO) << ch_rbpf_pose_ << " is back: laser nodes again";
    }
  };
  if (fusion_.TakeOverOdometryNode(m.utime, Pose2::FromIsometry3(T))) {
    if (!restoring_ && newest) laser_clock_.Accept(m.utime, arrival);
    log_back();
    if (newest) AfterNewNode(m.utime, t0, kNoPose);
    return;
  }
  if (fusion_.num_nodes() > 0 && m.utime <= fusion_.newest_node_utime()) {
    // Late (the network delayed or reordered it): placed by its stamp, no node.
    TrajectoryPoint late;
    const Status placed = fusion_.PlaceLateLaserPose(m.utime, Pose2::FromIsometry3(T), &late);
    if (!placed.ok()) {
      status_.CountDropped(placed.message());
      return;
    }
    status_.Set("late_laser_poses_placed",
                static_cast<double>(fusion_.counters().late_laser_poses_placed));
    if (!restoring_) PublishPose(late);
    return;
  }
  const Status s = fusion_.AddLaserPose(m.utime, Pose2::FromIsometry3(T));
  if (!s.ok()) {
    status_.CountDropped(s.message());
    return;
  }
  if (!restoring_) laser_clock_.Accept(m.utime, arrival);
  log_back();
  AfterNewNode(m.utime, t0, m.utime);
}

void FusionNode::AfterNewNode(Utime utime, std::chrono::steady_clock::time_point t0,
                              Utime publish_from) {
  last_utime_ = utime;
  if (restoring_) return;  // one full solve at the end of the journal
  const SolveSummary u = fusion_.Update();
  if (publish_from == utime) {
    PublishPose();
  } else if (publish_from < utime) {
    for (const TrajectoryPoint& p : fusion_.Trajectory(publish_from)) PublishPose(p);
  }
  if (fusion_.full_solve_requested() && !job_future_.valid()) StartFullSolve();
  if (UtimeToSeconds(utime - last_trajectory_utime_) >= config_.trajectory_period_s) {
    PublishTrajectory(utime);
  }
  if (journal_writer_ && node_options_.journal_snapshot_s > 0.0) {
    if (last_snapshot_utime_ == 0 || utime < last_snapshot_utime_) last_snapshot_utime_ = utime;
    if (UtimeToSeconds(utime - last_snapshot_utime_) >= node_options_.journal_snapshot_s) {
      last_snapshot_utime_ = utime;
      snapshot_due_ = true;  // at the next Poll(), after this message is in the journal
    }
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
  status_.Set("odometry_nodes", static_cast<double>(fusion_.counters().odometry_nodes));
  status_.Set("map_keyframes", map_.num_keyframes());
  status_.Set("map_keyframes_merged", static_cast<double>(map_.merged_keyframes()));
  status_.Set("map_points", static_cast<double>(map_.stored_points()));
  status_.Set("map_nodes", fusion_.num_map_nodes());
  status_.Set("retired_nodes", static_cast<double>(fusion_.num_retired_nodes()));
  if (retired_file_) {
    const RetiredTrajectory& retired = fusion_.retired_trajectory();
    status_.Set("retired_in_memory", static_cast<double>(retired.in_memory()));
    status_.Set("retired_spilled", static_cast<double>(retired.spilled()));
    if (!retired.spill_error().empty()) spill_warning_.Warn(retired.spill_error());
  }
  status_.Set("reanchored_factors", static_cast<double>(fusion_.counters().reanchored_factors));
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
  status_.CountIn(ch_odometry_, m.utime);
  if (!PlausibleUtime(m.utime)) {
    status_.CountDropped(ch_odometry_ + ": utime " + std::to_string(m.utime) + " out of range");
    return;
  }
  const auto t0 = std::chrono::steady_clock::now();
  const int64_t odometry_nodes = fusion_.counters().odometry_nodes;
  const Utime newest_before = fusion_.newest_node_utime();
  const bool in_outage = fusion_.newest_node_from_odometry();
  const Status s = fusion_.AddOdometry(m.utime, Pose2(m.x, m.y, m.theta));
  if (!s.ok()) {
    status_.CountDropped(s.message());
    return;
  }
  // The laser is silent: the odometry placed nodes up to its stamp (FactorGraphFusion, LASER
  // OUTAGE).
  if (fusion_.counters().odometry_nodes > odometry_nodes) {
    if (!in_outage && !restoring_) {
      outage_warning_.Warn("no " + ch_rbpf_pose_ + " for " +
                           FormatDouble(config_.graph.odometry_nodes_after_s) +
                           " s of odometry: fused poses from the wheel odometry (and the VO) "
                           "until the laser is back");
    }
    // Every new node's pose: the first of an outage fill the time it took to notice it.
    AfterNewNode(fusion_.newest_node_utime(), t0, newest_before + 1);
  }
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
  // Keyframes of the frozen past in a region already mapped merge (bounded memory).
  map_.MergeFinalKeyframes([this](Utime t, Pose2* p) { return fusion_.PoseAt(t, p); },
                           fusion_.final_until());
}

void FusionNode::PublishPose() {
  TrajectoryPoint p;
  if (fusion_.Latest(&p)) PublishPose(p);
}

void FusionNode::PublishPose(const TrajectoryPoint& p) {
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
}

void FusionNode::PublishTrajectory(Utime utime, bool whole) {
  Utime from = 0;
  const Utime final_until = fusion_.final_until();
  const Utime overlap = SecondsToUtime(config_.trajectory_overlap_s);
  if (!whole && config_.trajectory_overlap_s > 0.0 && final_until > overlap) {
    from = final_until - overlap;
  }
  lcm_->Publish(ch_trajectory_, TrajectoryToLcm(fusion_.Trajectory(from), utime), utime);
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
    map_save_failure_.clear();
  } catch (const std::exception& e) {
    map_save_failure_ = "could not save the 3D map to " + out + ".*: " + e.what();
    FL_LOG(ERROR) << map_save_failure_;
  }
}

}  // namespace fl::fusion
