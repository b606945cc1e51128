// fl-fusion: the fusion process. A thin adapter from LCM messages to FactorGraphFusion's verbs
// and from its estimates to FUSED_POSE / FUSED_TRAJECTORY / FUSED_MAP / STATUS_FL_FUSION.
//
// Inputs: RBPF_POSE (laser-rate nodes), RBPF_FACTORS and VO_FACTORS (between-factors),
// ODOMETRY, VO_POINTS (keyframe points for the 3D map), STEREO_CALIBRATION (T_base_camera).
// The full solve (loop closure / periodic) runs on a worker thread while fused poses keep
// flowing; when replaying a log (log:...) it runs inline so that the output is reproducible.
#include <atomic>
#include <chrono>
#include <csignal>
#include <filesystem>
#include <future>
#include <memory>

#include "bot_core/pose_t.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/command_line.hpp"
#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/common/status_reporter.hpp"
#include "fusionloc/common/yaml_options.hpp"
#include "fusionloc/fused_pose_t.hpp"
#include "fusionloc/fusion/fusion_config.hpp"
#include "fusionloc/maps/map_export.hpp"
#include "fusionloc/point_cloud_t.hpp"
#include "fusionloc/relative_pose_factor_t.hpp"
#include "fusionloc/status_t.hpp"
#include "fusionloc/stereo_calibration_t.hpp"
#include "fusionloc/trajectory_t.hpp"
#include "fusionloc/wheel_odometry_t.hpp"

namespace {

using fl::Pose2;
using fl::Utime;
namespace ff = fl::fusion;

std::atomic<bool> g_save_map_requested{false};
void OnSigusr1(int) { g_save_map_requested = true; }

bool ToFactor(const fusionloc::relative_pose_factor_t& m, ff::RelativePoseFactor* f,
              std::string* error) {
  const int8_t laser = fusionloc::relative_pose_factor_t::SOURCE_LASER;
  const int8_t vision = fusionloc::relative_pose_factor_t::SOURCE_VISION;
  const int8_t wheel = fusionloc::relative_pose_factor_t::SOURCE_WHEEL_ODOMETRY;
  if (m.source == laser) {
    f->source = ff::FactorSource::kLaser;
  } else if (m.source == vision) {
    f->source = ff::FactorSource::kVision;
  } else if (m.source == wheel) {
    f->source = ff::FactorSource::kWheelOdometry;
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
  f->T_i_j = fl::IsometryFromArrays(m.trans, m.quat);
  for (int k = 0; k < 36; ++k) f->information(k / 6, k % 6) = m.information[k];
  f->is_loop_closure = m.is_loop_closure;
  return true;
}

fusionloc::trajectory_t ToTrajectoryMsg(const std::vector<ff::TrajectoryPoint>& traj, Utime now) {
  fusionloc::trajectory_t msg;
  msg.utime = now;
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

class FusionProcess {
 public:
  FusionProcess(const ff::FusionProcessConfig& config, fl::LcmInterface* lcm, bool async,
                std::string map_out)
      : config_(config),
        lcm_(lcm),
        async_(async),
        map_out_(std::move(map_out)),
        fusion_(config.graph),
        map_(config.map),
        status_(lcm, "fl-fusion") {}

  void Subscribe() {
    lcm_->Subscribe<bot_core::pose_t>(
        fl::channels::kRbpfPose,
        [this](const bot_core::pose_t& m, const std::string&) { OnLaserPose(m); });
    for (const char* ch : {fl::channels::kRbpfFactors, fl::channels::kVoFactors}) {
      lcm_->Subscribe<fusionloc::relative_pose_factor_t>(
          ch, [this](const fusionloc::relative_pose_factor_t& m, const std::string& c) {
            OnFactor(m, c);
          });
    }
    lcm_->Subscribe<fusionloc::wheel_odometry_t>(
        fl::channels::kOdometry,
        [this](const fusionloc::wheel_odometry_t& m, const std::string&) { OnOdometry(m); });
    lcm_->Subscribe<fusionloc::point_cloud_t>(
        fl::channels::kVoPoints,
        [this](const fusionloc::point_cloud_t& m, const std::string&) { OnPoints(m); });
    lcm_->Subscribe<fusionloc::stereo_calibration_t>(
        fl::channels::kStereoCalibration,
        [this](const fusionloc::stereo_calibration_t& m, const std::string&) {
          T_base_camera_ = fl::IsometryFromArrays(m.T_base_camera.trans, m.T_base_camera.quat);
          have_calibration_ = true;
        });
    status_.SetState(fusionloc::status_t::LEVEL_STARTING, "waiting for RBPF_POSE");
  }

  // Called often from the main loop: finishes a background full solve, saves on request.
  void Poll() {
    if (job_future_.valid() &&
        job_future_.wait_for(std::chrono::seconds(0)) == std::future_status::ready) {
      FinishFullSolve();
    }
    if (g_save_map_requested.exchange(false)) SaveMap();
    status_.Tick();
  }

  void Finish() {
    if (job_future_.valid()) {
      job_future_.wait();
      FinishFullSolve();
    }
    if (fusion_.num_nodes() > 0) {
      const ff::SolveSummary s = fusion_.FullSolve();
      FL_LOG(INFO) << "final " << s.ToString();
      PublishTrajectory(last_utime_);
    }
    SaveMap();
    status_.SetState(fusionloc::status_t::LEVEL_OK,
                     "finished: " + fusion_.last_summary().ToString());
    status_.Tick(true);
    const auto& c = fusion_.counters();
    FL_LOG(INFO) << fusion_.num_nodes() << " nodes, " << fusion_.num_factors() << " factors, "
                 << c.full_solves << " full solves, " << c.rejected_total() << " inputs rejected, "
                 << fusion_.num_pending_factors() << " factors still waiting for a laser node";
  }

 private:
  void OnLaserPose(const bot_core::pose_t& m) {
    status_.CountIn();
    const auto t0 = std::chrono::steady_clock::now();
    const Eigen::Isometry3d T = fl::IsometryFromArrays(m.pos, m.orientation);
    const fl::Status s = fusion_.AddLaserPose(m.utime, Pose2::FromIsometry3(T));
    if (!s.ok()) {
      status_.CountDropped(s.message());
      return;
    }
    last_utime_ = m.utime;
    const ff::SolveSummary u = fusion_.Update();
    PublishPose();
    if (fusion_.full_solve_requested() && !job_future_.valid()) StartFullSolve();
    if (fl::UtimeToSeconds(m.utime - last_trajectory_utime_) >= config_.trajectory_period_s) {
      PublishTrajectory(m.utime);
    }
    const double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    status_.AddItemTime(ms);
    status_.Set("update_ms", u.time_ms);
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
                       u.ToString() + (last_full_.ran ? "; last " + last_full_.ToString() : ""));
    }
  }

  void OnFactor(const fusionloc::relative_pose_factor_t& m, const std::string& channel) {
    status_.CountIn();
    ff::RelativePoseFactor f;
    std::string error;
    if (!ToFactor(m, &f, &error)) {
      status_.CountDropped(channel + ": " + error);
      bad_factor_warning_.Warn(channel + ": " + error + "; dropped");
      return;
    }
    const fl::Status s = fusion_.AddFactor(f);
    if (!s.ok()) status_.CountDropped(channel + ": " + s.message());
  }

  void OnOdometry(const fusionloc::wheel_odometry_t& m) {
    status_.CountIn();
    const fl::Status s = fusion_.AddOdometry(m.utime, Pose2(m.x, m.y, m.theta));
    if (!s.ok()) status_.CountDropped(s.message());
  }

  void OnPoints(const fusionloc::point_cloud_t& m) {
    status_.CountIn();
    std::vector<Eigen::Vector3f> points;
    try {
      points = fl::maps::PointsFromMessage(m);
    } catch (const std::exception& e) {
      status_.CountDropped(std::string("VO_POINTS: ") + e.what());
      return;
    }
    Eigen::Isometry3f T_base_frame = Eigen::Isometry3f::Identity();
    if (m.frame == "camera") {
      if (!have_calibration_) {
        status_.CountDropped(
            "VO_POINTS in the camera frame before any STEREO_CALIBRATION "
            "(T_base_camera unknown); keyframe dropped");
        return;
      }
      T_base_frame = T_base_camera_.cast<float>();
    } else if (m.frame != "base") {
      status_.CountDropped("VO_POINTS frame '" + m.frame +
                           "' unsupported; keyframe points must be in 'camera' or 'base'");
      return;
    }
    for (auto& p : points) p = T_base_frame * p;
    const fl::Status s = map_.AddKeyframe(m.utime, points);
    if (!s.ok()) status_.CountDropped(s.message());
  }

  void PublishPose() {
    ff::TrajectoryPoint p;
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
    lcm_->Publish(fl::channels::kFusedPose, msg, p.utime);
    status_.CountOut();
  }

  void PublishTrajectory(Utime utime) {
    lcm_->Publish(fl::channels::kFusedTrajectory, ToTrajectoryMsg(fusion_.Trajectory(), utime),
                  utime);
    status_.CountOut();
    last_trajectory_utime_ = utime;
  }

  void StartFullSolve() {
    if (!async_) {
      last_full_ = fusion_.FullSolve();
      PublishTrajectory(last_utime_);
      return;
    }
    job_ = fusion_.PrepareFullSolve();
    ff::FullSolveJob* job = job_.get();
    job_future_ = std::async(std::launch::async, [job] { job->Run(); });
  }

  void FinishFullSolve() {
    job_future_.get();
    fusion_.ApplyFullSolve(*job_);
    last_full_ = job_->summary();
    job_.reset();
    FL_LOG(INFO) << last_full_.ToString();
    PublishTrajectory(last_utime_);
  }

  void SaveMap() {
    int skipped = 0;
    const std::vector<Eigen::Vector3f> points =
        map_.Build([this](Utime t, Pose2* p) { return fusion_.PoseAt(t, p); }, &skipped);
    if (skipped > 0) {
      FL_LOG(WARN) << skipped << " map keyframes lie outside the fused trajectory's time span "
                   << "and were left out";
    }
    if (points.empty()) {
      FL_LOG(INFO) << "3D map is empty (" << map_.num_keyframes()
                   << " keyframes on VO_POINTS); nothing saved";
      return;
    }
    fusionloc::point_cloud_t msg;
    msg.utime = last_utime_;
    msg.frame = "map";
    msg.num_points = static_cast<int32_t>(points.size());
    for (const auto& p : points) msg.points.push_back({p.x(), p.y(), p.z()});
    msg.num_intensities = 0;
    lcm_->Publish(fl::channels::kFusedMap, msg, last_utime_);
    if (map_out_.empty()) return;
    try {
      const std::filesystem::path parent = std::filesystem::path(map_out_).parent_path();
      if (!parent.empty()) std::filesystem::create_directories(parent);
      fl::maps::SavePointCloudPcd(points, {}, map_out_ + ".pcd");
      fl::maps::SavePointCloudTopView(points, map_out_ + "_top.png", config_.map_png_resolution_m);
      FL_LOG(INFO) << "saved " << points.size() << " map points to " << map_out_ << ".pcd and "
                   << map_out_ << "_top.png";
    } catch (const std::exception& e) {
      FL_LOG(ERROR) << "could not save the 3D map to " << map_out_ << ".*: " << e.what();
    }
  }

  ff::FusionProcessConfig config_;
  fl::LcmInterface* lcm_;
  bool async_;
  std::string map_out_;
  ff::FactorGraphFusion fusion_;
  ff::PointMap map_;
  fl::StatusReporter status_;
  Eigen::Isometry3d T_base_camera_ = Eigen::Isometry3d::Identity();
  bool have_calibration_ = false;
  std::unique_ptr<ff::FullSolveJob> job_;
  std::future<void> job_future_;
  ff::SolveSummary last_full_;
  Utime last_utime_ = 0;
  Utime last_trajectory_utime_ = 0;
  fl::RateLimitedWarning bad_factor_warning_;
};

}  // namespace

int main(int argc, char** argv) {
  fl::SetLogProcessName("fl-fusion");
  fl::CommandLine cli(
      "fl-fusion",
      "Fuses the laser RBPF-SLAM, the stereo VO and wheel odometry in a Ceres factor graph "
      "(SE(2) poses at the laser rate, incremental window updates, full solve on loop closure). "
      "Publishes FUSED_POSE at the laser rate, FUSED_TRAJECTORY when it changes, FUSED_MAP and "
      "STATUS_FL_FUSION; saves the 3D map (PCD + PNG top view) on exit and on SIGUSR1.");
  std::string url = fl::kDefaultLcmUrl;
  std::string config_path;
  std::string map_out = "out/fusion/map";
  bool print_config = false;
  bool sync = false;
  std::string log_level = "info";
  cli.AddFlag("lcm-url", &url,
              "LCM URL: udpm://... live, or log:IN.lcmlog,OUT.lcmlog to replay a log");
  cli.AddFlag("config", &config_path, "YAML options (e.g. config/fusion.yaml); default: built-in");
  cli.AddFlag("map-out", &map_out,
              "prefix of the saved 3D map: PREFIX.pcd and PREFIX_top.png ('' = don't save)");
  cli.AddFlag("sync-full-solve", &sync,
              "run full solves inline (always the case when replaying a log)");
  cli.AddFlag("print-config", &print_config, "print the effective configuration and exit");
  cli.AddFlag("log-level", &log_level, "debug, info, warn or error");
  cli.AddEpilog(
      "\nInputs:  RBPF_POSE, RBPF_FACTORS, VO_FACTORS, ODOMETRY, VO_POINTS, STEREO_CALIBRATION\n"
      "Outputs: FUSED_POSE, FUSED_TRAJECTORY, FUSED_MAP, STATUS_FL_FUSION\n"
      "Example: fl-fusion --config config/fusion.yaml --lcm-url log:run.lcmlog,fused.lcmlog\n"
      "         kill -USR1 <pid>   # save the 3D map now\n");
  if (!cli.Parse(argc, argv)) return cli.exit_code();
  fl::LogLevel level;
  if (!fl::ParseLogLevel(log_level, &level)) {
    std::cerr << "fl-fusion: --log-level '" << log_level << "' unknown; use debug, info, warn or "
              << "error\n";
    return 2;
  }
  fl::SetLogLevel(level);
  ff::FusionProcessConfig config;
  try {
    if (!config_path.empty()) config = fl::LoadYamlFile<ff::FusionProcessConfig>(config_path);
  } catch (const fl::ConfigError& e) {
    std::cerr << "fl-fusion: " << e.what() << "\n";
    return 2;
  }
  if (print_config) {
    std::cout << fl::SaveYamlString(config);
    return 0;
  }
  std::unique_ptr<fl::LcmInterface> lcm;
  try {
    lcm = fl::MakeLcm(url);
  } catch (const std::exception& e) {
    std::cerr << "fl-fusion: " << e.what() << "\n";
    return 1;
  }
  const bool replay = url.rfind("log:", 0) == 0;
  fl::InstallShutdownHandlers();
  std::signal(SIGUSR1, OnSigusr1);
  FusionProcess process(config, lcm.get(), /*async=*/!(sync || replay), map_out);
  process.Subscribe();
  FL_LOG(INFO) << "fusing on " << url << (replay ? " (replay: full solves inline)" : "");
  while (!fl::ShutdownRequested()) {
    if (lcm->HandleSubscriptions(100) < 0) break;
    process.Poll();
  }
  process.Finish();
  return 0;
}
