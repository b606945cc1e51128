// fl-bench-sim: the MSIF comparison on the simulated worlds `paper` and `corridor`:
// RBPF-SLAM alone, stereo VO alone and their fusion by fl::fusion::FactorGraphFusion, each
// against the simulator's ground truth (ATE after SE(2) alignment, position and heading), beside
// the wheel odometry's own ATE (run <world>_odometry, and ate_over_odometry on the others).
//
// The data path is the simulator's messages (fl::sim::Simulator::Step), decoded as the
// processes do; the estimators run with the built-in default options, the same as
// `./fusionloc bench laser` and `./fusionloc bench stereo` (the mountings are taken from
// the simulator's LASER_TO_BASE and CAMERA_TO_BASE, as the processes do). The fusion gets
// exactly what fl-fusion gets on LCM: the RBPF pose of every scan (nodes), the RBPF keyframe
// factors and the VO keyframe factors; it is updated after every scan (the timed "incremental
// update") and fully solved when it asks (loop closure, period) and at the end.
// Outputs per world: a Fig. 6-style PNG of x, y, heading error over time for the four.
// With --laser-aided-runs (default) each world runs again with the simulator's 16-line laser
// and the VO in its laser-aided mode: runs <world>_vo_only_lv and <world>_fused_lv.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <chrono>
#include <filesystem>
#include <iostream>
#include <map>
#include <optional>
#include <sstream>

#include "fusionloc/common/robot_description_lcm.hpp"
#include "fusionloc/bench/bench.hpp"
#include "fusionloc/common/program.hpp"
#include "fusionloc/common/yaml_options.hpp"
#include "fusionloc/eval/metrics.hpp"
#include "fusionloc/eval/plot.hpp"
#include "fusionloc/fusion/factor_graph_fusion.hpp"
#include "fusionloc/rbpf_slam/rbpf_slam.hpp"
#include "fusionloc/sim/simulator.hpp"
#include "fusionloc/stereo_vo/stereo_vo.hpp"
#include "fusionloc/stereo_vo/stereo_vo_lcm.hpp"

namespace {

namespace ff = fl::fusion;
using Clock = std::chrono::steady_clock;

struct WorldResult {
  fl::eval::Trajectory truth, rbpf, vo, fused;
  fl::eval::Trajectory odometry;  // the ODOMETRY messages' poses (T_odom_base), as published
  std::vector<double> update_ms, full_solve_ms;
  // Consistency of each estimator's factors with the truth: chi2 = e^T Omega e over
  // (x, y, yaw) (expected about 3 if the information is calibrated).
  std::vector<double> laser_chi2, vo_chi2;
  int64_t scans = 0, vo_frames = 0, vo_factors = 0, laser_factors = 0, rejected = 0;
  // Stereo frames the VO did not track (not tracked, rejected, or a new segment after the first).
  int64_t vo_lost = 0;
  std::map<std::string, int64_t> vo_lost_reasons;  // message -> frames
  // Laser-aided runs: frames given a usable LASER_3D scan, and the mean features with laser depth.
  int64_t vo_laser_frames = 0;
  double vo_laser_depth_sum = 0;
  double wall_s = 0;
};

// The kind of a VO message without its numbers: "not tracked: only 12 closed quadrilaterals
// (need 20) ..." -> "only closed quadrilaterals".
std::string LostReason(const std::string& message) {
  std::string out;
  const size_t colon = message.find(": ");
  for (char c : message.substr(colon == std::string::npos ? 0 : colon + 2)) {
    if (c == '(' || c == ';') break;
    if (std::isdigit(static_cast<unsigned char>(c)) || c == '.') continue;
    if (c == ' ' && (out.empty() || out.back() == ' ')) continue;
    out += c;
  }
  while (!out.empty() && out.back() == ' ') out.pop_back();
  return out;
}

fl::eval::StampedPose Stamp(fl::Utime t, const fl::Pose2& p) { return {t, p.ToIsometry3()}; }

double Chi2(const ff::RelativePoseFactor& f, const std::map<fl::Utime, fl::Pose2>& truth) {
  const auto a = truth.find(f.utime_i), b = truth.find(f.utime_j);
  if (a == truth.end() || b == truth.end()) return -1;
  const fl::Pose2 t = a->second.between(b->second);
  const fl::Pose2 m = fl::Pose2::FromIsometry3(f.T_i_j);
  const Eigen::Vector3d e(m.x - t.x, m.y - t.y, fl::WrapAngle(m.theta - t.theta));
  Eigen::Matrix3d info;
  std::string reason;
  if (!ff::ReduceInformationToPlanar(f.information, &info, &reason)) return -1;
  return e.dot(info * e);
}

ff::RelativePoseFactor LaserFactor(const fl::rbpf::KeyframeFactor& k) {
  ff::RelativePoseFactor f;
  f.utime_i = k.utime_i;
  f.utime_j = k.utime_j;
  f.T_i_j = k.T_i_j.ToIsometry3();
  const int idx[3] = {0, 1, 5};
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) f.information(idx[r], idx[c]) = k.information(r, c);
  f.source = ff::FactorSource::kLaser;
  f.is_loop_closure = k.is_loop_closure;
  return f;
}

// laser_aided: the simulator's multi-line laser on and the VO in its laser-aided mode, given
// each frame's LASER_3D scan through the mountings as fl-stereo-vo --laser-aided does.
WorldResult RunWorld(const fl::sim::SimOptions& sim_options_in,
                     const fl::rbpf::RbpfSlamOptions& rbpf_options_in,
                     const fl::vo::StereoVoOptions& vo_options_in, const ff::FusionOptions& fopts,
                     bool laser_aided) {
  WorldResult out;
  const auto t0 = Clock::now();
  fl::sim::SimOptions sim_options = sim_options_in;
  fl::vo::StereoVoOptions vo_options = vo_options_in;
  sim_options.laser3d.enabled = laser_aided;
  vo_options.laser_depth.enabled = laser_aided;
  fl::sim::Simulator sim(sim_options);
  std::optional<Eigen::Isometry3d> T_base_laser3d;
  std::optional<fusionloc::laser_scan_3d_t> scan_3d;
  ff::FactorGraphFusion fusion(fopts);
  std::optional<fl::rbpf::RbpfSlam> rbpf;
  std::unique_ptr<fl::vo::StereoVo> vo;
  fl::bench::Progress progress(sim_options.world.name, sim.total_frames());
  fl::sim::SimFrame f;
  std::map<fl::Utime, fl::Pose2> truth_by_time;
  int64_t step = 0;
  while (sim.Step(&f)) {
    progress.Update(++step);
    if (f.calibration && !vo) {
      if (!f.camera_to_base) throw std::runtime_error("simulator: no CAMERA_TO_BASE");
      const fl::vo::StereoCalibration cal =
          fl::vo::CalibrationFromLcm(*f.calibration, *f.camera_to_base);
      vo = std::make_unique<fl::vo::StereoVo>(vo_options, cal);
      rbpf.emplace(rbpf_options_in);
      if (f.laser_to_base) {  // as fl-rbpf-slam reads LASER_TO_BASE
        const fl::Status s = rbpf->SetBaseLaser(fl::Pose2::FromIsometry3(
            fl::TransformFromLcm(*f.laser_to_base)));
        if (!s.ok()) throw std::runtime_error(s.message());
      }
    }
    out.truth.push_back(Stamp(f.utime, f.T_world_base));
    truth_by_time[f.utime] = f.T_world_base;
    if (f.odometry) {
      // As fl-fusion does with ODOMETRY (used only when the fusion's use_wheel_odometry is on).
      const fl::Pose2 T_odom_base(f.odometry->x, f.odometry->y, f.odometry->theta);
      out.odometry.push_back(Stamp(f.odometry->utime, T_odom_base));
      if (!fusion.AddOdometry(f.odometry->utime, T_odom_base).ok()) ++out.rejected;
      if (vo) vo->AddOdometry(f.odometry->utime, T_odom_base);  // as fl-stereo-vo does
    }
    if (f.laser && rbpf) {
      fl::rbpf::LaserScan scan;
      scan.utime = f.laser->utime;
      scan.ranges = f.laser->ranges;
      scan.rad0 = f.laser->rad0;
      scan.radstep = f.laser->radstep;
      fl::rbpf::ScanResult r;
      if (rbpf->AddScan(scan, f.T_odom_base, &r).ok()) {
        ++out.scans;
        if (!fusion.AddLaserPose(scan.utime, r.T_world_base).ok()) ++out.rejected;
        for (const auto& k : r.factors) {
          ++out.laser_factors;
          const ff::RelativePoseFactor lf = LaserFactor(k);
          out.laser_chi2.push_back(Chi2(lf, truth_by_time));
          if (!fusion.AddFactor(lf).ok()) ++out.rejected;
        }
      }
    }
    if (f.laser_3d_to_base) T_base_laser3d = fl::TransformFromLcm(*f.laser_3d_to_base);
    if (f.laser_3d) scan_3d = *f.laser_3d;
    if (f.stereo && vo) {
      cv::Mat left, right;
      if (fl::vo::StereoImagesToGray(*f.stereo, &left, &right).ok()) {
        fl::vo::LaserCloud cloud;
        const bool with_scan = laser_aided && scan_3d && T_base_laser3d;
        if (with_scan) {
          int64_t non_finite = 0;
          cloud = fl::vo::LaserCloudFromScan(
              *scan_3d, vo->calibration().T_base_camera.inverse() * *T_base_laser3d, &non_finite);
        }
        const fl::vo::StereoVoResult r =
            vo->AddStereoFrame(f.stereo->utime, left, right, with_scan ? &cloud : nullptr);
        if (laser_aided && r.laser_message.empty()) ++out.vo_laser_frames;
        out.vo_laser_depth_sum += r.stats.laser_depth_cur;
        ++out.vo_frames;
        if (r.state != fl::vo::TrackingState::kTracked && out.vo_frames > 1) {
          ++out.vo_lost;
          ++out.vo_lost_reasons[r.new_segment ? "new segment after a gap" : LostReason(r.message)];
        }
        if (r.pose_valid) {
          out.vo.push_back({r.utime, fl::Pose2::FromIsometry3(r.T_world_base).ToIsometry3()});
        }
        if (r.factor) {
          ff::RelativePoseFactor vf;
          vf.utime_i = r.factor->utime_i;
          vf.utime_j = r.factor->utime_j;
          vf.T_i_j = r.factor->T_i_j;
          vf.information = r.factor->information;
          vf.source = ff::FactorSource::kVision;
          ++out.vo_factors;
          out.vo_chi2.push_back(Chi2(vf, truth_by_time));
          if (!fusion.AddFactor(vf).ok()) ++out.rejected;
        }
      }
    }
    if (f.laser && rbpf && fusion.num_nodes() > 0) {
      // The timed incremental update, as fl-fusion runs it after every laser pose.
      const auto u0 = Clock::now();
      fusion.Update();
      out.update_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - u0).count());
      if (fusion.full_solve_requested()) {
        const ff::SolveSummary s = fusion.FullSolve();
        out.full_solve_ms.push_back(s.time_ms);
      }
    }
  }
  progress.Finish();
  if (rbpf) {
    rbpf->Finish();
    for (const auto& p : rbpf->Trajectory()) out.rbpf.push_back(Stamp(p.utime, p.T_world_base));
  }
  if (fusion.num_nodes() > 0) {
    out.full_solve_ms.push_back(fusion.FullSolve().time_ms);
    for (const auto& p : fusion.Trajectory()) out.fused.push_back(Stamp(p.utime, p.T_map_base));
  }
  out.wall_s = std::chrono::duration<double>(Clock::now() - t0).count();
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  fl::Program program(
      "fl-bench-sim",
      "RBPF-SLAM alone, stereo VO alone and the factor-graph fusion on the simulated worlds "
      "(paper, corridor): ATE position/heading RMSE against ground truth, time per incremental "
      "update, and a PNG of x/y/heading error over time per world (MSIF Fig. 6).");
  fl::CommandLine& cli = program.cli();
  fl::bench::CommonArgs args;
  fl::bench::AddCommonFlags(&cli, &args, "sim");
  std::string worlds = "paper,corridor";
  std::string config_dir = "config";
  std::string fusion_config, rbpf_config, vo_config;
  std::string png_dir = "out/bench";
  double duration_s = 0;
  double camera_rate_hz = 0;
  bool laser_aided_runs = true;
  cli.AddFlag("worlds", &worlds, "comma-separated worlds (config/sim_<world>.yaml)");
  cli.AddFlag("config-dir", &config_dir, "folder with sim_<world>.yaml");
  cli.AddFlag("fusion-config", &fusion_config,
              "fusion YAML (FusionProcessConfig, e.g. config/fusion.yaml); default: built-in");
  cli.AddFlag("rbpf-config", &rbpf_config,
              "RBPF-SLAM options YAML (e.g. config/rbpf_slam.yaml); default: built-in");
  cli.AddFlag("vo-config", &vo_config,
              "stereo VO options YAML (e.g. config/stereo_vo.yaml); default: built-in");
  cli.AddFlag("png-dir", &png_dir, "where to write fusion_<world>_errors.png");
  cli.AddFlag("duration", &duration_s, "override the simulated duration [s] (0: the world's)");
  cli.AddFlag("camera-rate-hz", &camera_rate_hz,
              "override the worlds' stereo camera rate [Hz] (0: the world's, 10 Hz; the paper's "
              "2 Hz with --vo-config config/stereo_vo_2hz.yaml); recorded as a benchmark of its "
              "own, sim-camera-<rate>hz");
  cli.AddFlag("laser-aided-runs", &laser_aided_runs,
              "also run each world with the simulator's 16-line laser and the VO laser-aided "
              "(runs <world>_vo_only_lv and <world>_fused_lv)");
  if (!program.Parse(argc, argv)) return program.exit_code();

  ff::FusionOptions fopts;
  fl::rbpf::RbpfSlamOptions rbpf_options;  // defaults, as bench laser
  fl::vo::StereoVoOptions vo_options;      // defaults, as bench stereo
  try {
    if (!fusion_config.empty()) fopts = fl::LoadYamlFile<ff::FusionOptions>(fusion_config, "graph");
    if (!rbpf_config.empty())
      rbpf_options = fl::LoadYamlFile<fl::rbpf::RbpfSlamOptions>(rbpf_config);
    if (!vo_config.empty()) vo_options = fl::LoadYamlFile<fl::vo::StereoVoOptions>(vo_config);
    for (const fl::Status& s : {rbpf_options.Validate(), vo_options.Validate()}) {
      if (!s.ok()) throw fl::ConfigError("invalid options: " + s.message());
    }
  } catch (const fl::ConfigError& e) {
    std::cerr << "fl-bench-sim: " << e.what() << "\n";
    return 2;
  }

  if (camera_rate_hz < 0 || !std::isfinite(camera_rate_hz)) {
    std::cerr << "fl-bench-sim: --camera-rate-hz must be a rate in Hz > 0 (or 0: the world's)\n";
    return 2;
  }
  std::string bench_name = "sim";
  if (camera_rate_hz > 0) {
    std::ostringstream n;
    n << "sim-camera-" << camera_rate_hz << "hz";
    bench_name = n.str();
  }
  fl::bench::Report report(bench_name);
  std::vector<std::string> names;
  for (size_t a = 0, b; a <= worlds.size(); a = b + 1) {
    b = worlds.find(',', a);
    if (b == std::string::npos) b = worlds.size();
    if (b > a) names.push_back(worlds.substr(a, b - a));
  }
  int failures = 0;
  for (const std::string& world : names) {
    const std::string path = config_dir + "/sim_" + world + ".yaml";
    fl::sim::SimOptions so;
    try {
      so = fl::LoadYamlFile<fl::sim::SimOptions>(path);
    } catch (const fl::ConfigError& e) {
      std::cerr << "fl-bench-sim: " << e.what() << "\n";
      ++failures;
      continue;
    }
    if (duration_s > 0) so.duration_s = duration_s;
    if (camera_rate_hz > 0) so.camera.rate_hz = camera_rate_hz;
    WorldResult r, lv;
    try {
      r = RunWorld(so, rbpf_options, vo_options, fopts, false);
      if (laser_aided_runs) lv = RunWorld(so, rbpf_options, vo_options, fopts, true);
    } catch (const std::exception& e) {
      std::cerr << "fl-bench-sim: " << world << ": " << e.what() << "\n";
      ++failures;
      continue;
    }
    const fl::Utime max_dt = 60000;  // [us] laser/camera times are sim steps: exact matches
    struct Est {
      const char* suffix;
      const fl::eval::Trajectory* traj;
      fl::eval::Color color;
    };
    const Est ests[4] = {{"rbpf_only", &r.rbpf, fl::eval::kPlotBlue},
                         {"vo_only", &r.vo, fl::eval::kPlotOrange},
                         {"fused", &r.fused, fl::eval::kPlotGreen},
                         {"odometry", &r.odometry, fl::eval::kPlotGray}};
    constexpr int kOdometry = 3;
    // Every estimate is read against the wheel odometry it starts from.
    double odometry_rmse = -1.0;
    if (r.odometry.size() >= 3) {
      odometry_rmse =
          fl::eval::ComputeAte(r.odometry, r.truth, fl::eval::Alignment::kSE2, max_dt).trans_m.rmse;
    }
    std::vector<fl::eval::Panel> panels(3);
    panels[0].y_label = "x error [m]";
    panels[1].y_label = "y error [m]";
    panels[2].y_label = "heading error [deg]";
    double rmse[4] = {0, 0, 0, 0};
    for (int e = 0; e < 4; ++e) {
      fl::bench::Run run;
      run.name = world + "_" + ests[e].suffix;
      run.input = path;
      if (ests[e].traj->size() < 3) {
        run.note = "too few poses to evaluate";
        report.AddRun(run);
        ++failures;
        continue;
      }
      const fl::eval::AteResult ate =
          fl::eval::ComputeAte(*ests[e].traj, r.truth, fl::eval::Alignment::kSE2, max_dt);
      rmse[e] = ate.trans_m.rmse;
      run.Add("ate_rmse_m", ate.trans_m.rmse).Add("ate_rmse_deg", ate.rot_deg.rmse);
      if (e != kOdometry) {
        run.Add("ate_over_odometry",
                odometry_rmse > 0.0 ? ate.trans_m.rmse / odometry_rmse : -1.0);
      }
      run.Add("items", static_cast<double>(ate.utimes.size()));
      if (e == 2) {
        const auto st = fl::bench::ComputeStats(r.update_ms);
        run.Add("ms_per_item_median", st.median)
            .Add("ms_per_item_mean", st.mean)
            .Add("ms_per_item_p95", st.p95);
        run.Add("full_solves", static_cast<double>(r.full_solve_ms.size()));
        run.Add("solve_s", fl::bench::ComputeStats(r.full_solve_ms).max / 1000.0);
        run.Add("dropped", static_cast<double>(r.rejected));
      }
      if (e == 0) {
        run.Add("factors", static_cast<double>(r.laser_factors));
        if (!r.laser_chi2.empty())
          run.Add("factor_chi2_median", fl::bench::ComputeStats(r.laser_chi2).median);
      }
      if (e == 1) {
        run.Add("factors", static_cast<double>(r.vo_factors));
        run.Add("lost_frames", static_cast<double>(r.vo_lost));
        std::ostringstream why;
        for (const auto& [reason, n] : r.vo_lost_reasons) why << (why.tellp() > 0 ? "; " : "") << n << "x " << reason;
        if (r.vo_lost > 0) run.note = "lost frames: " + why.str();
        if (!r.vo_chi2.empty())
          run.Add("factor_chi2_median", fl::bench::ComputeStats(r.vo_chi2).median);
      }
      run.Add("peak_rss_mb", fl::bench::PeakRssMb());
      report.AddRun(run);
      const double t_first = fl::UtimeToSeconds(ate.utimes.front());
      std::vector<double> ts;
      for (fl::Utime t : ate.utimes) ts.push_back(fl::UtimeToSeconds(t) - t_first);
      panels[0].curves.push_back({ests[e].suffix, ts, ate.err_x_m, ests[e].color});
      panels[1].curves.push_back({ests[e].suffix, ts, ate.err_y_m, ests[e].color});
      panels[2].curves.push_back({ests[e].suffix, ts, ate.err_yaw_deg, ests[e].color});
    }
    // The laser-aided runs, read against the same odometry and the plain runs.
    if (laser_aided_runs) {
      const fl::eval::Trajectory* lv_traj[2] = {&lv.vo, &lv.fused};
      const char* lv_name[2] = {"_vo_only_lv", "_fused_lv"};
      for (int e = 0; e < 2; ++e) {
        fl::bench::Run run;
        run.name = world + lv_name[e];
        run.input = path;
        if (lv_traj[e]->size() < 3) {
          run.note = "too few poses to evaluate";
          report.AddRun(run);
          ++failures;
          continue;
        }
        const fl::eval::AteResult ate =
            fl::eval::ComputeAte(*lv_traj[e], lv.truth, fl::eval::Alignment::kSE2, max_dt);
        const double plain = e == 0 ? rmse[1] : rmse[2];
        run.Add("ate_rmse_m", ate.trans_m.rmse).Add("ate_rmse_deg", ate.rot_deg.rmse);
        run.Add("ate_over_odometry", odometry_rmse > 0.0 ? ate.trans_m.rmse / odometry_rmse : -1.0);
        run.Add("ate_over_plain", plain > 0.0 ? ate.trans_m.rmse / plain : -1.0);
        run.Add("items", static_cast<double>(ate.utimes.size()));
        if (e == 0) {
          run.Add("factors", static_cast<double>(lv.vo_factors));
          run.Add("lost_frames", static_cast<double>(lv.vo_lost));
          run.Add("laser_frames", static_cast<double>(lv.vo_laser_frames));
          run.Add("laser_depth_features_mean",
                  lv.vo_frames > 0 ? lv.vo_laser_depth_sum / static_cast<double>(lv.vo_frames) : 0);
          if (!lv.vo_chi2.empty())
            run.Add("factor_chi2_median", fl::bench::ComputeStats(lv.vo_chi2).median);
          run.note = std::string("laser-aided VO (16-line laser); target <= the plain VO's ATE: ") +
                     (ate.trans_m.rmse <= plain ? "met" : "NOT met");
        } else {
          run.note = std::string("fused with the laser-aided VO; <= the plain fused ATE: ") +
                     (ate.trans_m.rmse <= plain ? "met" : "NOT met");
        }
        run.Add("peak_rss_mb", fl::bench::PeakRssMb());
        report.AddRun(run);
      }
    }
    // Targets on the fused run's note.
    std::ostringstream note;
    const bool below_both = rmse[2] < rmse[0] && rmse[2] < rmse[1];
    note << "fused RMSE below both single-sensor RMSEs: " << (below_both ? "met" : "NOT met");
    if (world == "corridor") {
      note << "; <= 0.5x RBPF-only (" << 0.5 * rmse[0]
           << " m): " << (rmse[2] <= 0.5 * rmse[0] ? "met" : "NOT met");
    }
    const double med = fl::bench::ComputeStats(r.update_ms).median;
    note << "; median update " << med << " ms <= 2 ms: " << (med <= 2.0 ? "met" : "NOT met");
    note << "; " << r.scans << " scans, " << r.vo_frames << " stereo frames, wall " << r.wall_s
         << " s";
    // Annotate the fused run.
    std::vector<fl::bench::Run> runs = report.runs();
    for (auto& run : runs)
      if (run.name == world + "_fused") run.note = note.str();
    report = fl::bench::Report(bench_name);
    for (auto& run : runs) report.AddRun(run);
    try {
      std::filesystem::create_directories(png_dir);
      const std::string png = png_dir + "/sim_" + world + "_errors.png";
      fl::eval::PlotSeries(png, "world " + world + ": error vs ground truth (SE(2)-aligned)",
                           "time [s]", panels);
      std::cout << "plot: " << png << "\n";
    } catch (const std::exception& e) {
      std::cerr << "fl-bench-sim: plot: " << e.what() << "\n";
    }
  }
  try {
    fl::bench::Publish(report, args);
  } catch (const std::exception& e) {
    std::cerr << "fl-bench-sim: " << e.what() << "\n";
    return 1;
  }
  return failures == 0 ? 0 : 1;
}
