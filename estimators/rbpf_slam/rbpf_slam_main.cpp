// fl-rbpf-slam: the laser RBPF-SLAM process. A thin LCM adapter around fl::rbpf::RbpfSlam.
//
// In:  LASER (bot_core.planar_lidar_t), ODOMETRY (fusionloc.wheel_odometry_t, interpolated at
//      each scan's time), STEREO_CALIBRATION (fusionloc.stereo_calibration_t: T_base_laser, read
//      before the first scan; identity if never received).
// Out: RBPF_POSE (bot_core.pose_t, every scan), RBPF_FACTORS (fusionloc.relative_pose_factor_t,
//      ICP factors between laser keyframes in the base frame, information in the x, y, yaw
//      rows/cols 0, 1, 5), RBPF_TRAJECTORY (fusionloc.trajectory_t, keyframe poses whenever the
//      pose graph changes and at the end), RBPF_MAP (fusionloc.occupancy_grid_t, every
//      --map-period-s of data time and at the end), STATUS_FL_RBPF_SLAM.
#include <algorithm>
#include <cmath>
#include <deque>
#include <filesystem>
#include <iostream>
#include <variant>

#include "bot_core/planar_lidar_t.hpp"
#include "bot_core/pose_t.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/command_line.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/common/status_reporter.hpp"
#include "fusionloc/common/stream_merger.hpp"
#include "fusionloc/common/yaml_options.hpp"
#include "fusionloc/occupancy_grid_t.hpp"
#include "fusionloc/rbpf_slam/odometry_buffer.hpp"
#include "fusionloc/rbpf_slam/rbpf_slam.hpp"
#include "fusionloc/relative_pose_factor_t.hpp"
#include "fusionloc/status_t.hpp"
#include "fusionloc/stereo_calibration_t.hpp"
#include "fusionloc/trajectory_t.hpp"
#include "fusionloc/wheel_odometry_t.hpp"

namespace {

using Input = std::variant<fl::rbpf::LaserScan, fl::Pose2>;

bot_core::pose_t ToPoseMsg(fl::Utime utime, const fl::Pose2& p) {
  bot_core::pose_t m{};
  m.utime = utime;
  double trans[3], quat[4];
  fl::IsometryToArrays(p.ToIsometry3(), trans, quat);
  for (int i = 0; i < 3; ++i) m.pos[i] = trans[i];
  for (int i = 0; i < 4; ++i) m.orientation[i] = quat[i];
  return m;
}

fusionloc::relative_pose_factor_t ToFactorMsg(const fl::rbpf::KeyframeFactor& f) {
  fusionloc::relative_pose_factor_t m{};
  m.utime_i = f.utime_i;
  m.utime_j = f.utime_j;
  double trans[3], quat[4];
  fl::IsometryToArrays(f.T_i_j.ToIsometry3(), trans, quat);
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

fusionloc::trajectory_t ToTrajectoryMsg(fl::Utime utime, const std::vector<fl::rbpf::StampedPose2>& poses) {
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

fusionloc::occupancy_grid_t ToGridMsg(fl::Utime utime, const fl::rbpf::TiledGrid& g) {
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

}  // namespace

int main(int argc, char** argv) {
  fl::CommandLine cli("fl-rbpf-slam",
                      "Laser RBPF-SLAM (GMapping-style particle filter with a scan-matching "
                      "proposal and likelihood-field weights, refined by ICP keyframe factors and "
                      "a Ceres pose graph with loop closures). Subscribes LASER, ODOMETRY and "
                      "STEREO_CALIBRATION (for T_base_laser); publishes RBPF_POSE, RBPF_FACTORS, "
                      "RBPF_TRAJECTORY, RBPF_MAP and STATUS_FL_RBPF_SLAM.");
  std::string config;
  std::string url = fl::kDefaultLcmUrl;
  double map_period_s = 5.0;
  double merge_latency_s = 0.3;
  bool no_odometry = false;
  bool print_config = false;
  cli.AddFlag("config", &config, "options YAML (e.g. config/rbpf_slam.yaml); empty: built-in defaults");
  cli.AddFlag("lcm-url", &url, "LCM URL: udpm://..., memq://, or log:IN.lcmlog,OUT.lcmlog to replay a log at full speed");
  cli.AddFlag("map-period-s", &map_period_s, "publish RBPF_MAP every this many seconds of data time (0: only at the end)");
  cli.AddFlag("merge-latency-s", &merge_latency_s, "how long a scan may wait for odometry at or after its time");
  cli.AddFlag("no-odometry", &no_odometry, "run without wheel odometry (scan matching from the last pose)");
  cli.AddFlag("print-config", &print_config, "print the effective options as YAML and exit");
  if (!cli.Parse(argc, argv)) return cli.exit_code();
  fl::SetLogProcessName("fl-rbpf-slam");

  fl::rbpf::RbpfSlamOptions options;
  try {
    if (!config.empty()) options = fl::LoadYamlFile<fl::rbpf::RbpfSlamOptions>(config);
  } catch (const std::exception& e) {
    std::cerr << "fl-rbpf-slam: " << e.what() << "\n";
    return 2;
  }
  if (print_config) {
    std::cout << fl::SaveYamlString(options);
    return 0;
  }
  if (!(map_period_s >= 0.0) || !(merge_latency_s > 0.0)) {
    std::cerr << "fl-rbpf-slam: --map-period-s must be >= 0 and --merge-latency-s > 0\n";
    return 2;
  }
  std::unique_ptr<fl::LcmInterface> lcm;
  try {
    lcm = fl::MakeLcm(url);
  } catch (const std::exception& e) {
    std::cerr << "fl-rbpf-slam: " << e.what() << "\n";
    return 2;
  }
  fl::InstallShutdownHandlers();
  fl::rbpf::RbpfSlam slam(options);
  fl::rbpf::OdometryBuffer odom_buffer;
  fl::StatusReporter status(lcm.get(), "FL_RBPF_SLAM");
  fl::StreamMerger<Input> merger(fl::SecondsToUtime(merge_latency_s));
  const int laser_stream = merger.AddStream(fl::channels::kLaser);
  const int odom_stream = no_odometry ? -1 : merger.AddStream(fl::channels::kOdometry);
  fl::RateLimitedWarning warn;
  bool have_calibration = false;
  bool started = false;
  fl::Utime last_map_utime = 0, last_utime = 0;

  lcm->Subscribe<fusionloc::stereo_calibration_t>(
      fl::channels::kStereoCalibration, [&](const fusionloc::stereo_calibration_t& m, const std::string&) {
        const fl::Pose2 T = fl::Pose2::FromIsometry3(
            fl::IsometryFromArrays(m.T_base_laser.trans, m.T_base_laser.quat));
        if (started) {
          if (!have_calibration) warn.Warn("STEREO_CALIBRATION arrived after the first scan; T_base_laser ignored (identity used)");
          return;
        }
        const fl::Status s = slam.SetBaseLaser(T);
        if (!s.ok()) {
          warn.Warn("STEREO_CALIBRATION: " + s.message());
          return;
        }
        if (!have_calibration) FL_LOG(INFO) << "T_base_laser from STEREO_CALIBRATION: x " << T.x << " y " << T.y << " yaw " << T.theta;
        have_calibration = true;
      });
  lcm->Subscribe<bot_core::planar_lidar_t>(fl::channels::kLaser, [&](const bot_core::planar_lidar_t& m, const std::string&) {
    status.CountIn();
    fl::rbpf::LaserScan s;
    s.utime = m.utime;
    s.ranges = m.ranges;
    s.rad0 = m.rad0;
    s.radstep = m.radstep;
    const fl::Status st = merger.Push(laser_stream, m.utime, Input(std::move(s)));
    if (!st.ok()) {
      status.CountDropped(st.message());
      warn.Warn(st.message());
    }
  });
  if (!no_odometry) {
    lcm->Subscribe<fusionloc::wheel_odometry_t>(fl::channels::kOdometry, [&](const fusionloc::wheel_odometry_t& m, const std::string&) {
      const fl::Status st = merger.Push(odom_stream, m.utime, Input(fl::Pose2(m.x, m.y, m.theta)));
      if (!st.ok()) warn.Warn(st.message());
    });
  }

  auto publish_graph = [&](fl::Utime utime) {
    lcm->Publish(fl::channels::kRbpfTrajectory, ToTrajectoryMsg(utime, slam.KeyframePoses()), utime);
  };
  // Scans wait here until odometry at or after their time has been buffered (the merger
  // releases a scan once the odometry stream has *sent* a later sample, which may still be
  // queued behind it).
  std::deque<fl::rbpf::LaserScan> pending;
  auto run_scan = [&](const fl::rbpf::LaserScan& scan) {
    fl::Pose2 odom;
    if (!no_odometry) {
      const fl::Status st = odom_buffer.Lookup(scan.utime, &odom);
      if (!st.ok()) {
        status.CountDropped("LASER: " + st.message());
        warn.Warn("LASER scan dropped: " + st.message());
        return;
      }
    } else {
      odom = slam.stats().scans == 0 ? fl::Pose2() : slam.CurrentPose();
    }
    const fl::Utime t0 = fl::MonotonicUtime();
    fl::rbpf::ScanResult r;
    const fl::Status st = slam.AddScan(scan, odom, &r);
    status.AddItemTime((fl::MonotonicUtime() - t0) * 1e-3);
    if (!st.ok()) {
      status.CountDropped("LASER: " + st.message());
      warn.Warn(st.message());
      return;
    }
    started = true;
    last_utime = scan.utime;
    lcm->Publish(fl::channels::kRbpfPose, ToPoseMsg(scan.utime, r.T_world_base), scan.utime);
    status.CountOut();
    for (const auto& f : r.factors) lcm->Publish(fl::channels::kRbpfFactors, ToFactorMsg(f), scan.utime);
    if (r.graph_changed) publish_graph(scan.utime);
    if (r.odometry_jump) warn.Warn("odometry jump at utime " + std::to_string(scan.utime) + " flagged; step not trusted");
    if (map_period_s > 0 && scan.utime - last_map_utime >= fl::SecondsToUtime(map_period_s)) {
      lcm->Publish(fl::channels::kRbpfMap, ToGridMsg(scan.utime, slam.BestMap()), scan.utime);
      last_map_utime = scan.utime;
    }
    const auto& s = slam.stats();
    status.Set("particles", slam.num_particles());
    status.Set("neff", r.neff);
    status.Set("keyframes", static_cast<double>(s.keyframes));
    status.Set("loop_closures", static_cast<double>(s.loop_closures));
    status.Set("divergences", static_cast<double>(s.divergences));
    status.Set("recoveries", static_cast<double>(s.recoveries));
    status.Set("skipped_fast_turn", static_cast<double>(s.skipped_fast_turn));
    status.Set("odometry_jumps", static_cast<double>(s.odometry_jumps));
    status.Set("invalid_beams", static_cast<double>(s.invalid_beams));
    status.SetState(fusionloc::status_t::LEVEL_OK, "running");
  };
  const fl::Utime max_wait_us = fl::SecondsToUtime(merge_latency_s);
  auto process = [&](bool flush) {
    fl::StreamMerger<Input>::Item item;
    fl::Utime newest = 0;
    while (merger.Pop(&item)) {
      newest = std::max(newest, item.utime);
      if (const fl::Pose2* odom = std::get_if<fl::Pose2>(&item.value)) {
        const fl::Status st = odom_buffer.Add(item.utime, *odom);
        if (!st.ok()) warn.Warn("ODOMETRY: " + st.message());
      } else {
        pending.push_back(std::move(std::get<fl::rbpf::LaserScan>(item.value)));
      }
      while (!pending.empty() &&
             (no_odometry || (!odom_buffer.empty() && odom_buffer.newest() >= pending.front().utime) ||
              newest - pending.front().utime > max_wait_us)) {
        run_scan(pending.front());
        pending.pop_front();
      }
    }
    if (flush) {
      for (const auto& scan : pending) run_scan(scan);
      pending.clear();
    }
  };

  status.SetState(fusionloc::status_t::LEVEL_STARTING, "waiting for LASER");
  while (!fl::ShutdownRequested()) {
    const int rc = lcm->HandleSubscriptions(100);
    process(false);
    status.Tick();
    if (rc < 0) break;  // end of the replayed log
  }
  merger.Flush();
  process(true);
  slam.Finish();
  if (started) {
    publish_graph(last_utime);
    lcm->Publish(fl::channels::kRbpfMap, ToGridMsg(last_utime, slam.BestMap()), last_utime);
  }
  const auto& s = slam.stats();
  FL_LOG(INFO) << "scans " << s.scans << ", processed " << s.processed << ", keyframes " << s.keyframes
               << ", loop closures " << s.loop_closures << " (of " << s.loop_candidates
               << " candidates), divergences caught " << s.divergences
               << ", lost-track recoveries " << s.recoveries
               << ", scans held back in fast turns " << s.skipped_fast_turn
               << ", dropped (time) " << s.dropped_time_backwards
               << ", rejected " << s.rejected_bad_scan << ", odometry jumps " << s.odometry_jumps;
  status.Tick(true);
  return 0;
}
