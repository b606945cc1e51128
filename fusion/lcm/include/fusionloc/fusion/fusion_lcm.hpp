// The fusion's LCM adapter (target fl_fusion_lcm; the fusion library has no LCM): message
// conversions and FusionNode, which fl-fusion and fl-replay run.
//
// In:  RBPF_POSE (laser-rate nodes), RBPF_FACTORS and VO_FACTORS (between-factors), ODOMETRY,
//      VO_POINTS (keyframe points for the 3D map), CAMERA_TO_BASE (T_base_camera).
// Out: FUSED_POSE (at the laser rate), FUSED_TRAJECTORY (when it changes), FUSED_MAP (on exit
//      and on request), STATUS_FL_FUSION.
// Live, the full solve (loop closure / periodic) runs on a worker thread while fused poses
// keep flowing; replaying a log it runs inline, so that the output is reproducible.
#pragma once

#include <Eigen/Geometry>
#include <chrono>
#include <functional>
#include <future>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "bot_core/pose_t.hpp"
#include "bot_core/rigid_transform_t.hpp"
#include "fusionloc/common/clock_jump_guard.hpp"
#include "fusionloc/common/lcm_process.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/fusion/fusion_config.hpp"
#include "fusionloc/point_cloud_t.hpp"
#include "fusionloc/relative_pose_factor_t.hpp"
#include "fusionloc/trajectory_t.hpp"
#include "fusionloc/wheel_odometry_t.hpp"

namespace fl::fusion {

// ---- conversions ----
// The factor of a message; false with `error` for an unknown source or a non-unit quaternion.
bool FactorFromLcm(const fusionloc::relative_pose_factor_t& msg, RelativePoseFactor* factor,
                   std::string* error);
fusionloc::trajectory_t TrajectoryToLcm(const std::vector<TrajectoryPoint>& trajectory,
                                        Utime utime);

// ---- the node ----
struct FusionNodeOptions {
  std::string map_out = "out/fusion/map";  // prefix of the saved map: .pcd and _top.png ("": none)
  bool sync_full_solve = false;            // full solves inline (always so replaying a log)
  // Live only: the journal, an LCM log of every input the fusion has taken (its channels,
  // re-encoded, flushed to the kernel message by message, so a kill -9 loses nothing). A
  // fusion started again (respawned after a crash) with a journal younger than
  // journal_max_age_s replays it through the same handlers without publishing, solves the
  // whole graph once, and goes on with the graph, the map frame and the 3D map it had. A
  // journal that is older, unreadable, or whose data time lies ahead of the live data (another
  // run) is set aside and a new graph is started. Its size: the last snapshot
  // (journal_snapshot_s) and the inputs since, about 0.4 MB per minute with stereo at 2 Hz.
  // Beside it, JOURNAL.retired holds the retired trajectory older than its newest 10 minutes
  // (retired_trajectory.hpp: 64 bytes a scan, 2.3 MB an hour at 10 Hz, read back only for old
  // times), so that memory and snapshots stay bounded over days. "" = none (the whole retired
  // trajectory stays in memory).
  std::string journal;
  double journal_max_age_s = 30.0;  // [s] wall-clock age of a usable journal
  // [s] of data time between journal snapshots: the journal is rewritten as the fusion's saved
  // state (graph, retired trajectory, 3D map; channel kJournalSnapshotChannel) followed by the
  // inputs taken since, so that its size and a respawn's replay are bounded by the state and
  // this period instead of growing with the run. 0 = never (every input since the start).
  double journal_snapshot_s = 120.0;
  // Retired poses kept in memory when JOURNAL.retired is used (the newest; the rest are spilled
  // min(this, 1000) at a time).
  size_t retired_in_memory = RetiredTrajectory::kDefaultKeepInMemory;

  void AddFlags(CommandLine* cli);
};

class FusionNode : public LcmNode {
 public:
  static constexpr const char* kProgram = "fl-fusion";
  // The journal's first event, when it holds a snapshot (FusionNodeOptions::journal_snapshot_s);
  // never published on the bus.
  static constexpr const char* kJournalSnapshotChannel = "FL_FUSION_JOURNAL_SNAPSHOT";
  static std::vector<ChannelSpec> Inputs();
  static std::vector<ChannelSpec> Outputs();
  // Asks every FusionNode to save its map at its next Poll() (async-signal-safe: SIGUSR1).
  static void RequestMapSave();

  FusionNode(const FusionProcessConfig& config, const FusionNodeOptions& node_options,
             LcmInterface* lcm, const ChannelMap& channels);
  ~FusionNode() override;

  StatusReporter& status() override { return status_; }
  std::vector<std::string> RequiredInputs() const override { return {ch_rbpf_pose_}; }
  void Poll() override;
  void Finish() override;
  std::string Summary() const override;
  // The last map save's error ("" if it succeeded or none was asked for).
  std::string Failure() const override { return map_save_failure_; }
  // The graph (read-only: what a journal restore brought back, for benchmarks and tests).
  const FactorGraphFusion& fusion() const { return fusion_; }
  int64_t restored_inputs() const { return restored_inputs_; }  // journal inputs replayed

 private:
  void OnLaserPose(const bot_core::pose_t& m);
  void OnFactor(const fusionloc::relative_pose_factor_t& m, const std::string& channel);
  void OnOdometry(const fusionloc::wheel_odometry_t& m);
  // After new nodes (laser or odometry), the newest at `utime`: update, publish the FUSED_POSE of
  // every node from publish_from on (kNoPose: none), the trajectory and the journal snapshot
  // when due, the status. t0: when their message came in.
  static constexpr Utime kNoPose = INT64_MAX;
  void AfterNewNode(Utime utime, std::chrono::steady_clock::time_point t0, Utime publish_from);
  void OnPoints(const fusionloc::point_cloud_t& m);
  void PublishPose();  // the newest node's
  // FUSED_POSE of p with the newest node's covariance (a late pose's own is not computed).
  void PublishPose(const TrajectoryPoint& p);
  // The latest part of the trajectory (FusionConfig::trajectory_overlap_s), or all of it.
  void PublishTrajectory(Utime utime, bool whole = false);
  void StartFullSolve();
  void FinishFullSolve();
  void SaveMap();
  // Subscribes `handler` to `channel` live, and registers it for the journal's replay.
  template <class Msg>
  void Handle(const std::string& channel, std::function<void(const Msg&)> handler);
  // The journal (FusionNodeOptions::journal): replays an existing one, then opens it for
  // appending; Record() appends one input.
  void RestoreFromJournal();
  void Record(const std::string& channel, const void* data, int size);
  // The node's state (its config, its own fields, the graph and the map) as snapshot bytes,
  // written into `buffer` (its capacity reused), and back (throws StateError, or
  // std::runtime_error for another config).
  std::vector<uint8_t> SaveState(std::vector<uint8_t> buffer) const;
  void LoadState(const std::vector<uint8_t>& bytes);
  // Rewrites the journal as a snapshot (SaveState) followed by the inputs from now on; on a
  // failure (a full disk) the journal goes on as it was, with an error logged.
  void SnapshotJournal();
  std::string ConfigText() const;  // the configuration as YAML (a snapshot must match it)
  // A graph with this node's options and retired-trajectory file.
  FactorGraphFusion NewGraph() const;
  // A new graph and map (a journal of another run).
  void Reset();

  FusionProcessConfig config_;
  FusionNodeOptions node_options_;
  LcmInterface* lcm_;
  bool async_;
  bool with_time_;  // wall-clock times in what is published (live only)
  std::string map_save_failure_;
  ClockJumpGuard laser_clock_;  // RBPF_POSE stamps against their arrival
  RateLimitedWarning clock_warning_;
  std::string ch_rbpf_pose_, ch_odometry_, ch_points_, ch_camera_to_base_, ch_pose_, ch_trajectory_,
      ch_map_;
  FactorGraphFusion fusion_;
  PointMap map_;
  StatusReporter status_;
  Eigen::Isometry3d T_base_camera_ = Eigen::Isometry3d::Identity();
  bool have_camera_to_base_ = false;
  std::unique_ptr<FullSolveJob> job_;
  std::future<void> job_future_;
  SolveSummary last_full_;
  Utime last_utime_ = 0;
  Utime last_trajectory_utime_ = 0;
  RateLimitedWarning bad_factor_warning_;
  RateLimitedWarning outage_warning_;
  // Journal replay: decoders of the input channels; true while replaying (nothing published,
  // no incremental updates: one full solve at the end).
  std::map<std::string, std::function<bool(const void* data, int size)>> journal_handlers_;
  std::unique_ptr<LcmLogWriter> journal_writer_;
  RateLimitedWarning journal_warning_;  // the journal cannot be written
  // JOURNAL.retired (FusionNodeOptions::journal), bound to every graph this node makes.
  std::shared_ptr<RetiredSpillFile> retired_file_;
  RateLimitedWarning spill_warning_;  // the retired trajectory cannot be spilled
  bool restoring_ = false;
  bool restored_ = false;     // the graph came from a journal, no live pose yet
  Utime restored_until_ = 0;  // data time of the journal's newest node
  int64_t restored_inputs_ = 0;
  Utime last_snapshot_utime_ = 0;  // data time of the last journal snapshot (or its start)
  bool snapshot_due_ = false;      // taken at the next Poll() without a full solve running
  RateLimitedWarning snapshot_warning_;  // a snapshot could not be written
  std::vector<uint8_t> snapshot_buffer_;  // reused by every snapshot (see StateWriter)
  std::vector<uint8_t> encode_buffer_;
};

}  // namespace fl::fusion
