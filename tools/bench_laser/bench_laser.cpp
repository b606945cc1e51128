// fl-bench-laser: the laser RBPF-SLAM (fl::rbpf::RbpfSlam) on the CARMEN logs.
//
// Every input goes through the real data path: the CARMEN log is converted to an LCM log by
// fl::importers::ConvertCarmen (corrected logs get the importer's seeded synthetic odometry
// noise and a GROUND_TRUTH channel), the LASER / ODOMETRY messages of that LCM log are decoded,
// odometry is interpolated at each scan's time and fed with the scan to RbpfSlam::AddScan
// (only AddScan is timed). The final trajectory (pose graph keyframes + the filter's motion
// since them) is compared with GROUND_TRUTH: ATE RMSE after SE(2) alignment, RPE over
// consecutive scan pairs. The raw mit-csail.clf is compared with csail-corrected.log.gz, whose
// scans get the raw log's time stamps by matching ranges (CarmenOptions::timestamps_from).
// Consistency of the published keyframe factors: chi2 = eᵀ Ω e of each factor's error e against
// the reference relative pose (x, y, yaw); about 3 (median 2.37) when the information is
// calibrated. With --sim-worlds the simulated worlds of fl::sim (config/sim_<world>.yaml,
// laser and wheel odometry only, camera off) are run the same way against their ground truth.
// With --peers a peer laser SLAM runs side by side on each raw CARMEN log (MRPT's rbpf-slam,
// peers/mrpt_rbpf.hpp) and is scored by the same code; the comparison (ours, the peer, peer over
// ours) is its own table, recorded in its own section (bench:laser-peers).
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <limits>
#include <optional>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "bot_core/planar_lidar_t.hpp"
#include "bot_core/pose_t.hpp"
#include "fusionloc/common/robot_description_lcm.hpp"
#include "fusionloc/bench/bench.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/program.hpp"
#include "fusionloc/common/yaml_options.hpp"
#include "fusionloc/eval/metrics.hpp"
#include "fusionloc/importers/carmen.hpp"
#include "fusionloc/common/odometry_buffer.hpp"
#include "fusionloc/rbpf_slam/rbpf_slam.hpp"
#include "fusionloc/sim/simulator.hpp"
#include "fusionloc/wheel_odometry_t.hpp"
#include "peers/mrpt_rbpf.hpp"
#include "reference_refit.hpp"

namespace fs = std::filesystem;

namespace {

struct Input {
  std::string name;
  std::string log;         // CARMEN log to run
  std::string reference;   // CARMEN log whose GROUND_TRUTH is the reference ("" = log itself)
  std::string sim_config;  // a simulated world's options (config/sim_<world>.yaml) instead of a log
  std::string relations;   // Kuemmerle et al. relations for the log (NAME.relations), "" = none
};

struct LogData {
  std::vector<fl::rbpf::LaserScan> scans;
  fl::OdometryBuffer odom{std::numeric_limits<int64_t>::max() / 4, 5 * fl::kUtimePerSecond};
  fl::eval::Trajectory ground_truth;
  fl::Pose2 T_base_laser;  // LASER_TO_BASE (identity for the CARMEN importer's logs)
};

template <class Msg>
bool Decode(const fl::LcmLogEvent& ev, Msg* msg) {
  return msg->decode(ev.data.data(), 0, static_cast<int>(ev.data.size())) >= 0;
}

LogData ReadLcm(const std::string& path) {
  LogData d;
  fl::LcmLogReader reader(path);
  fl::LcmLogEvent ev;
  while (reader.Next(&ev)) {
    if (ev.channel == fl::channels::kLaser) {
      bot_core::planar_lidar_t m{};
      if (!Decode(ev, &m)) continue;
      fl::rbpf::LaserScan s;
      s.utime = m.utime;
      s.ranges = m.ranges;
      s.rad0 = m.rad0;
      s.radstep = m.radstep;
      d.scans.push_back(std::move(s));
    } else if (ev.channel == fl::channels::kOdometry) {
      fusionloc::wheel_odometry_t m{};
      if (!Decode(ev, &m)) continue;
      (void)d.odom.Add(m.utime, fl::Pose2(m.x, m.y, m.theta));  // repeated stamps: first wins
    } else if (ev.channel == fl::channels::kGroundTruth) {
      bot_core::pose_t m{};
      if (!Decode(ev, &m)) continue;
      fl::eval::StampedPose p;
      p.utime = m.utime;
      p.T_world_base = fl::IsometryFromArrays(m.pos, m.orientation);
      if (!d.ground_truth.empty() && p.utime <= d.ground_truth.back().utime) continue;
      d.ground_truth.push_back(p);
    }
  }
  return d;
}

// Map (grey), reference (green) and estimate (red) in the map frame.
void WritePng(const fl::rbpf::TiledGrid& map, const fl::eval::Trajectory& est,
              const fl::eval::Trajectory& ref_in_map, const std::string& path) {
  int x0, y0, x1, y1;
  if (!map.Bounds(&x0, &y0, &x1, &y1)) return;
  const int w = x1 - x0, h = y1 - y0;
  cv::Mat img(h, w, CV_8UC3, cv::Scalar(200, 200, 200));
  for (int y = y0; y < y1; ++y) {
    for (int x = x0; x < x1; ++x) {
      const float l = map.LogOdds(x, y);
      if (l == 0.0f) continue;
      const double p = 1.0 - 1.0 / (1.0 + std::exp(l));
      const uint8_t v = static_cast<uint8_t>(255.0 * (1.0 - p));
      img.at<cv::Vec3b>(y1 - 1 - y, x - x0) = cv::Vec3b(v, v, v);
    }
  }
  const double res = map.resolution();
  auto px = [&](const Eigen::Vector3d& p) {
    return cv::Point(static_cast<int>(p.x() / res) - x0, y1 - 1 - static_cast<int>(p.y() / res));
  };
  for (size_t i = 1; i < ref_in_map.size(); ++i) {
    cv::line(img, px(ref_in_map[i - 1].T_world_base.translation()),
             px(ref_in_map[i].T_world_base.translation()), cv::Scalar(0, 160, 0), 2);
  }
  for (size_t i = 1; i < est.size(); ++i) {
    cv::line(img, px(est[i - 1].T_world_base.translation()), px(est[i].T_world_base.translation()),
             cv::Scalar(0, 0, 220), 1);
  }
  fs::create_directories(fs::path(path).parent_path());
  cv::imwrite(path, img);
}

std::string Metres(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.3f", v);
  return buf;
}

// Reference pose nearest in time to t (within max_dt), or false.
bool ReferenceAt(const fl::eval::Trajectory& ref, fl::Utime t, fl::Utime max_dt, fl::Pose2* out) {
  auto it =
      std::lower_bound(ref.begin(), ref.end(), t,
                       [](const fl::eval::StampedPose& p, fl::Utime u) { return p.utime < u; });
  const fl::eval::StampedPose* best = nullptr;
  if (it != ref.end()) best = &*it;
  if (it != ref.begin() && (!best || t - std::prev(it)->utime < best->utime - t))
    best = &*std::prev(it);
  if (!best || std::abs(best->utime - t) > max_dt) return false;
  *out = fl::Pose2::FromIsometry3(best->T_world_base);
  return true;
}

// chi2 = eᵀ Ω e of a factor against the reference relative pose T_i_j_reference.
double FactorChi2(const fl::rbpf::KeyframeFactor& f, const fl::Pose2& T_i_j_reference) {
  const fl::Pose2& t = T_i_j_reference;
  const Eigen::Vector3d e(f.T_i_j.x - t.x, f.T_i_j.y - t.y, fl::WrapAngle(f.T_i_j.theta - t.theta));
  return e.dot(f.information * e);
}

// A factor's translation projected on the reference's, T_i_j_reference (both in frame i), and
// the reference's length, for reference motions of at least 0.1 m; false otherwise. Summed over a
// run, their ratio says whether the factors measure the motion short or long (a scale bias).
bool FactorAlongTrack(const fl::rbpf::KeyframeFactor& f, const fl::Pose2& T_i_j_reference,
                      double* projected_m, double* reference_m) {
  const fl::Pose2& t = T_i_j_reference;
  const double length = std::hypot(t.x, t.y);
  if (length < 0.1) return false;
  *projected_m = (f.T_i_j.x * t.x + f.T_i_j.y * t.y) / length;
  *reference_m = length;
  return true;
}

// The reference refit (reference_refit.hpp) of a log's scans that have odometry and a reference
// pose; odometry noise from `noise` (corrected logs: the model that generated it) or, without
// it, the filter's motion model. Empty if fewer than 2 scans qualify.
fl::eval::Trajectory Refit(const LogData& d, const fl::rbpf::RbpfSlamOptions& o,
                           const fl::importers::CarmenNoiseModel* noise, fl::Utime max_dt,
                           const fl::rbpf::RefitOptions& ro, int* icp_edges) {
  std::vector<fl::rbpf::RefitScan> scans;
  for (const fl::rbpf::LaserScan& scan : d.scans) {
    fl::rbpf::RefitScan s;
    if (!ReferenceAt(d.ground_truth, scan.utime, max_dt, &s.T_world_base_reference) ||
        !d.odom.Lookup(scan.utime, &s.T_odom_base).ok())
      continue;
    if (!scans.empty() && scan.utime <= scans.back().scan.utime) continue;
    s.scan = scan;
    scans.push_back(std::move(s));
  }
  if (scans.size() < 2) return {};
  fl::rbpf::RefitOdometrySigma sigma = fl::rbpf::RefitOdometrySigma::FromMotion(o.motion);
  if (noise) {
    sigma.trans_per_m = noise->a1;
    sigma.trans_per_rad = noise->a2;
    sigma.rot_per_rad = noise->a3;
    sigma.rot_per_m = noise->a4;
    sigma.min_sigma_xy = noise->min_sigma_xy;
    sigma.min_sigma_rad = noise->min_sigma_theta;
  }
  const fl::rbpf::RefitResult r = fl::rbpf::RefitReference(scans, d.T_base_laser, o, sigma, ro);
  *icp_edges = r.icp_edges;
  fl::eval::Trajectory out;
  for (size_t k = 0; k < scans.size(); ++k)
    out.push_back({scans[k].scan.utime, r.T_world_base[k].ToIsometry3()});
  return out;
}

// The importer's odometry noise model with every sigma multiplied by `scale`.
fl::importers::CarmenNoiseModel ScaledNoise(double scale) {
  fl::importers::CarmenNoiseModel n;
  n.a1 *= scale;
  n.a2 *= scale;
  n.a3 *= scale;
  n.a4 *= scale;
  n.min_sigma_xy *= scale;
  n.min_sigma_theta *= scale;
  return n;
}

// The Kuemmerle et al. 2009 relation columns of a final trajectory (a pose for every scan) and,
// if given, an online pose stream: one place for our runs and the peers'.
void AddRelationColumns(const fl::eval::Trajectory& final_trajectory,
                        const fl::eval::Trajectory* online,
                        const std::vector<fl::eval::Relation>& relations, fl::Utime max_dt,
                        fl::bench::Run* run) {
  const fl::eval::RelationResult fr =
      fl::eval::ComputeRelationError(final_trajectory, relations, max_dt);
  run->Add("relation_trans_mean_m", fr.trans_m.mean)
      .Add("relation_trans_std_m", fr.trans_m.std)
      .Add("relation_rot_mean_deg", fr.rot_deg.mean)
      .Add("relation_rot_std_deg", fr.rot_deg.std)
      .Add("relations_used", static_cast<double>(fr.used))
      .Add("relations_total", static_cast<double>(relations.size()));
  if (online) {
    const fl::eval::RelationResult onr = fl::eval::ComputeRelationError(*online, relations, max_dt);
    run->Add("online_relation_trans_mean_m", onr.trans_m.mean)
        .Add("online_relation_rot_mean_deg", onr.rot_deg.mean);
  }
}

// The columns of the peers' table (bench:laser-peers), in this order, for ours and each peer.
const std::vector<std::string>& PeerColumns() {
  static const std::vector<std::string> keys = {
      "relation_trans_mean_m", "relation_trans_std_m", "relation_rot_mean_deg",
      "relation_rot_std_deg", "relations_used", "online_relation_trans_mean_m",
      "online_relation_rot_mean_deg", "ate_rmse_m", "ate_rmse_deg", "rpe_trans_m",
      "ms_per_item_mean", "ms_per_item_p95", "ms_per_processed_mean", "items", "processed",
      "peak_rss_mb"};
  return keys;
}
// Of these, the ones whose ratio peer / ours is reported.
const std::vector<std::string>& PeerRatioColumns() {
  static const std::vector<std::string> keys = {
      "relation_trans_mean_m", "relation_trans_std_m", "relation_rot_mean_deg",
      "relation_rot_std_deg", "online_relation_trans_mean_m", "online_relation_rot_mean_deg",
      "ate_rmse_m", "ms_per_item_mean", "ms_per_processed_mean", "peak_rss_mb"};
  return keys;
}

bool HasMetric(const fl::bench::Run& r, const std::string& key) {
  for (const auto& [k, v] : r.metrics)
    if (k == key) return true;
  return false;
}

// `r` reduced to the peers' columns (those it has), under `name`.
fl::bench::Run PeerRow(const fl::bench::Run& r, const std::string& name) {
  fl::bench::Run out;
  out.name = name;
  out.input = r.input;
  for (const std::string& key : PeerColumns())
    if (HasMetric(r, key)) out.Add(key, r.Get(key));
  return out;
}

// Peer over ours for the ratio columns both have (-1 where ours is 0).
fl::bench::Run RatioRow(const fl::bench::Run& peer, const fl::bench::Run& ours,
                        const std::string& name) {
  fl::bench::Run out;
  out.name = name;
  out.input = peer.input;
  for (const std::string& key : PeerRatioColumns()) {
    if (!HasMetric(peer, key) || !HasMetric(ours, key)) continue;
    const double o = ours.Get(key);
    out.Add(key, o != 0.0 ? peer.Get(key) / o : -1.0);
  }
  return out;
}

// An executable: `name` itself if it has a '/', else the first match on PATH ("" if none).
std::string FindProgram(const std::string& name) {
  if (name.find('/') != std::string::npos) return access(name.c_str(), X_OK) == 0 ? name : "";
  const char* path = std::getenv("PATH");
  std::string p = path ? path : "";
  for (size_t a = 0, b; a <= p.size(); a = b + 1) {
    b = p.find(':', a);
    if (b == std::string::npos) b = p.size();
    const std::string candidate = p.substr(a, b - a) + "/" + name;
    if (b > a && access(candidate.c_str(), X_OK) == 0) return candidate;
  }
  return "";
}

// Laser scans, odometry and ground truth of a simulated world (camera off).
LogData SimulateWorld(fl::sim::SimOptions so) {
  so.camera.enabled = false;
  fl::sim::Simulator sim(so);
  LogData d;
  fl::sim::SimFrame f;
  bool have_mounting = false;
  while (sim.Step(&f)) {
    if (f.laser_to_base && !have_mounting) {  // as fl-rbpf-slam reads LASER_TO_BASE
      have_mounting = true;
      d.T_base_laser = fl::Pose2::FromIsometry3(
          fl::TransformFromLcm(*f.laser_to_base));
    }
    d.ground_truth.push_back({f.utime, f.T_world_base.ToIsometry3()});
    (void)d.odom.Add(f.utime, f.T_odom_base);
    if (f.laser) {
      fl::rbpf::LaserScan s;
      s.utime = f.laser->utime;
      s.ranges = f.laser->ranges;
      s.rad0 = f.laser->rad0;
      s.radstep = f.laser->radstep;
      d.scans.push_back(std::move(s));
    }
  }
  return d;
}

}  // namespace

int main(int argc, char** argv) {
  fl::Program program(
      "fl-bench-laser",
      "Runs the laser RBPF-SLAM on the CARMEN logs of DATA/laser (raw mit-csail.clf "
      "against csail-corrected.log.gz; every *-corrected log with the importer's "
      "seeded synthetic odometry noise against its own poses; any other CARMEN log "
      "(.clf, .log, .log.gz) likewise) and reports ATE (SE(2)-aligned), RPE over "
      "consecutive scans, ms per scan (AddScan only, one core) and peak memory, "
      "and writes a PNG of each map with both trajectories.");
  fl::CommandLine& cli = program.cli();
  fl::bench::CommonArgs args;
  fl::bench::AddCommonFlags(&cli, &args, "laser");
  std::string config;
  std::string only;
  std::string png_dir = "out/bench/laser";
  int particles = 0;
  std::string seeds_text = "1,2,3,4,5,6";
  cli.AddFlag("config", &config,
              "RBPF options YAML (default: built-in defaults = config/rbpf_slam.yaml)");
  cli.AddFlag("only", &only,
              "run only the logs whose file name, and the simulated worlds whose run name "
              "(sim-<world>), contain this text");
  cli.AddFlag("particles", &particles, "override the particle count (0 = from the options)");
  cli.AddFlag("seeds", &seeds_text,
              "comma-separated run seeds: run s uses seed s for the synthetic odometry noise of "
              "corrected logs and the filter seed (options) + 7*(s-1); with several seeds each "
              "input also gets a '<name> mean' row averaging its runs");
  cli.AddFlag("png-dir", &png_dir, "folder for the map PNGs");
  std::string sim_worlds = "paper,corridor";
  std::string config_dir = "config";
  cli.AddFlag("sim-worlds", &sim_worlds,
              "also run these simulated worlds, comma-separated (options from "
              "CONFIG_DIR/sim_<world>.yaml, laser + odometry only, the world's own seed; the run "
              "seeds vary the filter), named sim-<world>; empty = none");
  cli.AddFlag("config-dir", &config_dir, "folder with sim_<world>.yaml (for --sim-worlds)");
  double sim_duration_s = 0.0;
  cli.AddFlag("sim-duration-s", &sim_duration_s,
              "simulate this long instead of the world's own duration_s (0 = its own): the "
              "simulator loops its route, so a long run shows whether the graph stays bounded "
              "and the estimate steady; such a run is recorded in its own section "
              "(bench:laser-long), not the laser one");
  double noise_scale = 1.0;
  cli.AddFlag("odometry-noise", &noise_scale,
              "scale of the synthetic odometry noise of corrected logs (all of the importer's "
              "noise sigmas are multiplied by it; 0 = the reference's own motion as odometry, "
              "to see what the scans alone pull away from the reference)");
  bool refit = true;
  cli.AddFlag("refit", &refit,
              "also solve the data's own MAP problem (odometry + ICP edges to the previous and "
              "nearby earlier scans) starting at the reference and report the ATE of its optimum "
              "against the reference as refit_ate_m: how far the measurements, read through the "
              "estimator's models, pull away from the reference (reference_refit.hpp)");
  fl::rbpf::RefitOptions refit_options;
  cli.AddFlag("refit-pairs", &refit_options.max_pairs,
              "--refit: ICP edges from each scan to at most this many nearest earlier scans "
              "within 4 m (besides the previous scan)");
  bool dump = false;
  cli.AddFlag("dump", &dump,
              "also write the estimate (final and online) and reference trajectories (TUM) next to "
              "the PNGs");
  bool peers = false;
  cli.AddFlag("peers", &peers,
              "also run the peer laser SLAM side by side on each raw CARMEN log (mit-csail.clf): "
              "MRPT's rbpf-slam (Debian mrpt-apps) with --peers-config, its input written by "
              "fl-mrpt-rawlog from the same CARMEN reader, its most likely particle's path scored "
              "like ours; prints and records a table of ours, the peer and peer/ours "
              "(bench:laser-peers, JSON NAME-peers.json). `./fusionloc bench laser --peers` "
              "installs MRPT and builds fl-mrpt-rawlog");
  std::string peers_config = "config/peers/mrpt_rbpf_slam.ini";
  cli.AddFlag("peers-config", &peers_config, "--peers: MRPT's rbpf-slam ini");
  std::string peers_rawlog_tool;
  cli.AddFlag("peers-rawlog-tool", &peers_rawlog_tool,
              "--peers: the rawlog writer (default: fl-mrpt-rawlog beside this program)");
  std::string peers_rbpf_slam = "rbpf-slam";
  cli.AddFlag("peers-rbpf-slam", &peers_rbpf_slam, "--peers: MRPT's rbpf-slam program");
  cli.AddEpilog(
      "\nRecording (--record FILE.md): the laser section of FILE.md is rewritten with this "
      "run's table; with --peers the comparison goes to its own section (bench:laser-peers); "
      "with --only the laser section is left alone (a table of some logs would replace the "
      "full one; the JSON is still written); with --sim-duration-s the run goes to its own "
      "section (bench:laser-long).\n"
      "\nLong run (the recorded one): ./fusionloc bench laser --only sim-paper --sim-worlds paper "
      "--sim-duration-s 10800 --seeds 1,2,3\n");
  if (!program.Parse(argc, argv)) return program.exit_code();
  // The whole simulated run is held in memory (about 190 MB per simulated hour of `paper`).
  constexpr double kMaxSimDurationS = 24 * 3600.0;
  if (!(sim_duration_s >= 0.0 && sim_duration_s <= kMaxSimDurationS)) {
    std::cerr << "fl-bench-laser: --sim-duration-s " << sim_duration_s
              << ": must be 0 (the world's own duration) or a time in seconds up to "
              << kMaxSimDurationS << " (24 hours: the run is held in memory, about 190 MB per "
              << "simulated hour)\n";
    return 2;
  }
  if (peers) {
    if (peers_rawlog_tool.empty()) {
      std::error_code e;
      const fs::path self = fs::read_symlink("/proc/self/exe", e);
      peers_rawlog_tool = (e ? fs::path(argv[0]).parent_path() : self.parent_path()).string() +
                          "/fl-mrpt-rawlog";
    }
    if (!fs::is_regular_file(peers_config)) {
      std::cerr << "fl-bench-laser: --peers-config " << peers_config
                << " not found; run from the repository's root or pass --peers-config FILE\n";
      return 2;
    }
    if (FindProgram(peers_rawlog_tool).empty()) {
      std::cerr << "fl-bench-laser: --peers: " << peers_rawlog_tool
                << " is not there: it is built only when CMake finds MRPT; "
                   "`./fusionloc bench laser --peers` installs libmrpt-obs-dev and mrpt-apps "
                   "and builds it (or pass --peers-rawlog-tool)\n";
      return 2;
    }
    const std::string found = FindProgram(peers_rbpf_slam);
    if (found.empty()) {
      std::cerr << "fl-bench-laser: --peers: MRPT's " << peers_rbpf_slam
                << " not found; install Debian's mrpt-apps (`./fusionloc bench laser --peers` "
                   "does) or pass --peers-rbpf-slam PROGRAM\n";
      return 2;
    }
    peers_rbpf_slam = found;
  }
  if (const fl::Status s = refit_options.Validate(); !s.ok()) {
    std::cerr << "fl-bench-laser: --refit-pairs: " << s.message() << "\n";
    return 2;
  }

  fl::rbpf::RbpfSlamOptions options;
  try {
    if (!config.empty()) options = fl::LoadYamlFile<fl::rbpf::RbpfSlamOptions>(config);
  } catch (const std::exception& e) {
    std::cerr << "fl-bench-laser: " << e.what() << "\n";
    return 2;
  }
  if (particles > 0) options.particles = particles;
  if (!std::isfinite(noise_scale) || noise_scale < 0.0) {
    std::cerr << "fl-bench-laser: --odometry-noise=" << noise_scale
              << ": expected a finite scale >= 0 (1 = the importer's noise model, 0 = none)\n";
    return 2;
  }
  const fl::importers::CarmenNoiseModel noise = ScaledNoise(noise_scale);
  std::vector<uint64_t> seeds;
  for (size_t a = 0, b; a < seeds_text.size(); a = b + 1) {
    b = seeds_text.find(',', a);
    if (b == std::string::npos) b = seeds_text.size();
    const std::string t = seeds_text.substr(a, b - a);
    if (t.empty() || t.find_first_not_of("0123456789") != std::string::npos || t.size() > 9 ||
        std::stoul(t) == 0) {
      std::cerr << "fl-bench-laser: --seeds=" << seeds_text
                << ": expected positive integers separated by commas, e.g. --seeds=1,2,3\n";
      return 2;
    }
    seeds.push_back(std::stoul(t));
  }
  if (seeds.empty()) {
    std::cerr << "fl-bench-laser: --seeds is empty; e.g. --seeds=1\n";
    return 2;
  }

  // Inputs: DATA/laser and (if different) the shared data folder's laser logs.
  std::vector<Input> inputs;
  const fs::path dir = fs::path(args.data_dir) / "laser";
  std::vector<fs::path> files;
  std::error_code ec;
  for (fs::directory_iterator it(fs::is_directory(dir) ? dir : fs::path(args.data_dir), ec), end;
       !ec && it != end; it.increment(ec)) {
    const std::string n = it->path().filename().string();
    if (n.size() > 4 && (n.rfind(".clf") == n.size() - 4 || n.find(".log") != std::string::npos)) {
      files.push_back(it->path());
    }
  }
  std::sort(files.begin(), files.end());
  for (const fs::path& f : files) {
    std::string n = f.filename().string();
    if (!only.empty() && n.find(only) == std::string::npos) continue;
    Input in;
    in.log = f.string();
    in.name = n.substr(0, n.find('.'));
    const fs::path relations = f.parent_path() / (in.name + ".relations");
    if (fs::exists(relations)) in.relations = relations.string();
    if (n == "mit-csail.clf") {
      const fs::path ref = f.parent_path() / "csail-corrected.log.gz";
      if (!fs::exists(ref)) {
        std::cerr << "fl-bench-laser: skipping " << f << ": its reference " << ref
                  << " is missing\n";
        continue;
      }
      in.reference = ref.string();
      in.name = "mit-csail-raw";
    }
    inputs.push_back(in);
  }
  for (size_t a = 0, b; a < sim_worlds.size(); a = b + 1) {
    b = sim_worlds.find(',', a);
    if (b == std::string::npos) b = sim_worlds.size();
    if (b == a) continue;
    Input in;
    in.name = "sim-" + sim_worlds.substr(a, b - a);
    if (!only.empty() && in.name.find(only) == std::string::npos) continue;
    in.sim_config = config_dir + "/sim_" + sim_worlds.substr(a, b - a) + ".yaml";
    in.log = in.sim_config;
    if (!fs::exists(in.sim_config)) {
      std::cerr << "fl-bench-laser: --sim-worlds: " << in.sim_config
                << " not found; run from the repository's root, pass --config-dir DIR, or "
                   "--sim-worlds= to run no simulated world\n";
      return 2;
    }
    inputs.push_back(in);
  }
  if (sim_duration_s > 0.0 &&
      std::none_of(inputs.begin(), inputs.end(),
                   [](const Input& in) { return !in.sim_config.empty(); })) {
    std::cerr << "fl-bench-laser: --sim-duration-s applies to simulated worlds and none is "
                 "selected; pass --sim-worlds WORLD (and --only sim-WORLD to leave the logs out)\n";
    return 2;
  }
  if (inputs.empty()) {
    std::cerr << "fl-bench-laser: no CARMEN logs (.clf, .log, .log.gz) in " << dir
              << (only.empty() ? "" : " matching --only " + only) << "; pass --data DIR\n";
    return 2;
  }

  // A long simulated run has its own table: it would replace the full run's.
  fl::bench::Report report(sim_duration_s > 0.0 ? "laser-long" : "laser");
  fl::bench::Report peer_report("laser-peers");
  const std::string tmp =
      (fs::temp_directory_path() / ("fl_bench_laser_" + std::to_string(getpid()))).string();
  fs::create_directories(tmp);
  int failures = 0;
  const fl::Utime max_dt = 20000;  // [us] estimate-reference (and run-run) time association
  for (const Input& in : inputs) {
    std::vector<fl::bench::Run> seed_runs;
    std::vector<fl::eval::Trajectory> seed_trajectories;  // for the run-to-run spread
    fl::eval::Trajectory reference;                       // the same for every seed
    std::vector<fl::eval::Relation> relations;            // read at the first seed
    // A simulated world's data: the run seeds vary the filter, not the world, so it is simulated
    // once (at the first seed) and every run starts from a copy.
    std::optional<LogData> simulated;
    for (const uint64_t seed : seeds) {
      const std::string run_name =
          seeds.size() > 1 ? in.name + "/s" + std::to_string(seed) : in.name;
      try {
        fl::rbpf::RbpfSlamOptions run_options = options;
        run_options.seed = options.seed + 7 * static_cast<int>(seed - 1);
        LogData data;
        if (!in.sim_config.empty()) {
          if (!simulated) {
            fl::sim::SimOptions so = fl::LoadYamlFile<fl::sim::SimOptions>(in.sim_config);
            if (sim_duration_s > 0.0) so.duration_s = sim_duration_s;
            simulated = SimulateWorld(so);
          }
          data = *simulated;
        } else {
          fl::importers::CarmenOptions co;
          co.seed = seed;
          co.noise = noise;
          const std::string lcm_log = tmp + "/" + in.name + ".lcmlog";
          if (!in.reference.empty()) co.noisy_odometry = "false";
          // csail-corrected.log.gz printed its time stamps with 6 significant digits: take them
          // from the raw log of the same run when it is there (matched by ranges).
          const fs::path raw_csail = fs::path(in.log).parent_path() / "mit-csail.clf";
          if (fs::path(in.log).filename() == "csail-corrected.log.gz" && fs::exists(raw_csail)) {
            co.timestamps_from = raw_csail.string();
          }
          fl::importers::ConvertCarmen(co, in.log, lcm_log);
          data = ReadLcm(lcm_log);
          if (!in.reference.empty()) {
            fl::importers::CarmenOptions ro;
            ro.noisy_odometry = "true";
            ro.timestamps_from = in.log;
            const std::string ref_log = tmp + "/" + in.name + ".ref.lcmlog";
            fl::importers::ConvertCarmen(ro, in.reference, ref_log);
            data.ground_truth = ReadLcm(ref_log).ground_truth;
          }
        }
        if (data.ground_truth.size() < 3)
          throw std::runtime_error("fewer than 3 ground-truth poses");

        fl::rbpf::RbpfSlam slam(run_options);
        if (const fl::Status s = slam.SetBaseLaser(data.T_base_laser); !s.ok())
          throw std::runtime_error(s.message());
        std::vector<double> ms_processed, ms_all, chi2_seq, chi2_loop;
        double along_factor_m = 0.0, along_reference_m = 0.0;  // sequential factors
        int64_t skipped = 0;
        fl::eval::Trajectory online;  // the pose of each scan as AddScan gave it (RBPF_POSE)
        fl::eval::Trajectory odometry;  // the odometry at each scan: what the SLAM starts from
        fl::bench::Progress progress("[bench laser] " + run_name,
                                     static_cast<int64_t>(data.scans.size()));
        for (size_t i = 0; i < data.scans.size(); ++i) {
          fl::Pose2 odom;
          if (!data.odom.Lookup(data.scans[i].utime, &odom).ok()) {
            ++skipped;
            continue;
          }
          fl::rbpf::ScanResult r;
          const auto t0 = std::chrono::steady_clock::now();
          const fl::Status s = slam.AddScan(data.scans[i], odom, &r);
          const double ms =
              std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                  .count();
          if (!s.ok()) {  // e.g. a stamp that goes back (intel-corrected: 940.54 after 940.654)
            ++skipped;
            continue;
          }
          odometry.push_back({data.scans[i].utime, odom.ToIsometry3()});
          ms_all.push_back(ms);
          online.push_back({data.scans[i].utime, r.T_world_base.ToIsometry3()});
          for (const fl::rbpf::KeyframeFactor& f : r.factors) {
            fl::Pose2 a, b;
            if (!ReferenceAt(data.ground_truth, f.utime_i, max_dt, &a) ||
                !ReferenceAt(data.ground_truth, f.utime_j, max_dt, &b)) {
              continue;
            }
            const fl::Pose2 T_i_j_reference = a.between(b);
            (f.is_loop_closure ? chi2_loop : chi2_seq).push_back(FactorChi2(f, T_i_j_reference));
            double projected = 0.0, length = 0.0;
            if (!f.is_loop_closure && FactorAlongTrack(f, T_i_j_reference, &projected, &length)) {
              along_factor_m += projected;
              along_reference_m += length;
            }
          }
          if (r.processed) ms_processed.push_back(ms);
          progress.Update(static_cast<int64_t>(i + 1));
        }
        const auto t0 = std::chrono::steady_clock::now();
        slam.Finish();
        const double finish_ms =
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                .count();
        progress.Finish();

        fl::eval::Trajectory est;
        for (const auto& p : slam.Trajectory())
          est.push_back({p.utime, p.T_world_base.ToIsometry3()});
        const fl::eval::AteResult ate =
            fl::eval::ComputeAte(est, data.ground_truth, fl::eval::Alignment::kSE2, max_dt);
        const fl::eval::AteResult odometry_ate =
            fl::eval::ComputeAte(odometry, data.ground_truth, fl::eval::Alignment::kSE2, max_dt);
        const fl::eval::RpeResult rpe =
            fl::eval::ComputeRpe(est, data.ground_truth, 1, fl::eval::DeltaUnit::kFrames, max_dt);
        const fl::bench::Stats sp = fl::bench::ComputeStats(ms_processed);
        const fl::bench::Stats sa = fl::bench::ComputeStats(ms_all);
        fl::bench::Run run;
        run.name = run_name;
        run.input = in.log;
        const auto& st = slam.stats();
        run.Add("ate_rmse_m", ate.trans_m.rmse)
            .Add("ate_rmse_deg", ate.rot_deg.rmse)
            .Add("odometry_ate_rmse_m", odometry_ate.trans_m.rmse)
            .Add("ate_over_odometry",
                 odometry_ate.trans_m.rmse > 0.0 ? ate.trans_m.rmse / odometry_ate.trans_m.rmse
                                                 : -1.0)
            .Add("rpe_trans_m", rpe.trans_m.mean)
            .Add("rpe_rot_deg", rpe.rot_deg.mean)
            .Add("ms_per_item_mean", sa.mean)
            .Add("ms_per_item_p95", sa.p95)
            .Add("ms_per_processed_mean", sp.mean)
            .Add("ms_per_processed_p95", sp.p95)
            .Add("finish_ms", finish_ms)
            .Add("items", static_cast<double>(ms_all.size()))
            .Add("processed", static_cast<double>(st.processed))
            .Add("matched_pairs", static_cast<double>(ate.trans_m.count))
            .Add("keyframes", static_cast<double>(st.keyframes))
            .Add("keyframe_reuses", static_cast<double>(st.keyframe_reuses))
            .Add("keyframes_bounded", static_cast<double>(st.keyframes_bounded))
            .Add("loop_candidates", static_cast<double>(st.loop_candidates))
            .Add("loop_closures", static_cast<double>(st.loop_closures))
            .Add("loop_searches", static_cast<double>(st.loop_searches))
            .Add("searches_skipped", static_cast<double>(st.loop_searches_skipped))
            .Add("loop_rejections", static_cast<double>(st.loop_rejections))
            .Add("optimizations", static_cast<double>(st.optimizations))
            .Add("match_evals",
                 static_cast<double>(st.matcher_evaluations) /
                     std::max<double>(1.0, static_cast<double>(st.processed * options.particles)))
            .Add("map_rebuilds", static_cast<double>(st.map_rebuilds))
            .Add("rebuilds_continued", static_cast<double>(st.map_rebuilds_continued))
            .Add("divergences", static_cast<double>(st.divergences))
            .Add("degenerate_kept", static_cast<double>(st.degenerate_kept))
            .Add("recoveries", static_cast<double>(st.recoveries))
            .Add("skipped_fast_turn", static_cast<double>(st.skipped_fast_turn))
            .Add("scans_refined_pct", 100.0 * static_cast<double>(st.scans_refined) /
                                          std::max<double>(1.0, static_cast<double>(st.scans)))
            .Add("turn_placed_pct", 100.0 * static_cast<double>(st.turn_scans_placed) /
                                        std::max<double>(1.0, static_cast<double>(st.scans)))
            .Add("resamples", static_cast<double>(st.resamples))
            .Add("degenerate_pct",
                 100.0 * static_cast<double>(st.degenerate_matches) /
                     std::max<double>(1.0, static_cast<double>(st.processed * options.particles)))
            .Add("dropped", static_cast<double>(skipped))
            .Add("factors", static_cast<double>(chi2_seq.size()))
            .Add("noisy_factors", static_cast<double>(st.noisy_factors))
            .Add("factor_chi2_median",
                 chi2_seq.empty() ? -1.0 : fl::bench::ComputeStats(chi2_seq).median)
            .Add("factor_chi2_p95", chi2_seq.empty() ? -1.0 : fl::bench::ComputeStats(chi2_seq).p95)
            .Add("factor_length_ratio",
                 along_reference_m > 0.0 ? along_factor_m / along_reference_m : -1.0)
            .Add("loop_factors", static_cast<double>(chi2_loop.size()))
            .Add("loop_chi2_median",
                 chi2_loop.empty() ? -1.0 : fl::bench::ComputeStats(chi2_loop).median)
            .Add("peak_rss_mb", fl::bench::PeakRssMb());
        if (!in.relations.empty()) {
          // Kuemmerle et al. 2009: the final trajectory (a pose for every scan) and the online
          // pose against the log's hand-checked relations.
          if (relations.empty()) relations = fl::eval::ReadRelations(in.relations);
          AddRelationColumns(est, &online, relations, max_dt, &run);
        }
        if (refit && in.sim_config.empty()) {
          int refit_edges = 0;
          const fl::eval::Trajectory fitted =
              Refit(data, run_options, in.reference.empty() ? &noise : nullptr, max_dt,
                    refit_options, &refit_edges);
          if (!fitted.empty()) {
            const fl::eval::AteResult fa =
                fl::eval::ComputeAte(fitted, data.ground_truth, fl::eval::Alignment::kSE2, max_dt);
            run.Add("refit_ate_m", fa.trans_m.rmse)
                .Add("refit_icp_edges", static_cast<double>(refit_edges));
          }
        }
        const std::string file_stem =
            seeds.size() > 1 ? in.name + "-s" + std::to_string(seed) : in.name;
        const std::string png = png_dir + "/" + file_stem + ".png";
        fl::eval::Trajectory ref_in_map;
        const Eigen::Isometry3d T_est_ref = ate.T_ref_est.inverse();
        for (const auto& p : ate.ref_matched)
          ref_in_map.push_back({p.utime, T_est_ref * p.T_world_base});
        WritePng(slam.BestMap(), est, ref_in_map, png);
        if (dump) {
          fl::eval::WriteTrajectoryTum(est, png_dir + "/" + file_stem + ".est.tum");
          fl::eval::WriteTrajectoryTum(online, png_dir + "/" + file_stem + ".online.tum");
          fl::eval::WriteTrajectoryTum(data.ground_truth, png_dir + "/" + file_stem + ".ref.tum");
        }
        run.note =
            "png " + png + "; particles " + std::to_string(options.particles) +
            "; factor_chi2 = e^T Omega e of the sequential ICP factors against the reference "
            "(calibrated: median ~2.4), loop_chi2 the same for loop closures" +
            "; factor_length_ratio = the sequential factors' translations projected on the " +
            "reference's, summed, over the reference's summed length (< 1: they measure the " +
            "motion short)" + "; ICP factors failed " + std::to_string(st.icp_failures) +
            "; ms_per_item = every scan, ms_per_processed = scans the filter ran on" +
            (refit ? "; refit_ate_m = ATE of the data's own optimum (odometry + ICP edges) solved "
                     "from the reference (reference_refit.hpp)"
                   : "");
        seed_runs.push_back(run);
        seed_trajectories.push_back(est);
        if (reference.empty()) reference = data.ground_truth;
        report.AddRun(run);
      } catch (const std::exception& e) {
        std::cerr << "fl-bench-laser: " << run_name << ": " << e.what() << "\n";
        ++failures;
      }
    }
    if (seed_runs.size() > 1) {
      // Mean over the seeds (the filter's accuracy varies from seed to seed; one seed can mislead).
      fl::bench::Run mean;
      mean.name = in.name + " mean";
      mean.input = in.log;
      for (const auto& [key, value] : seed_runs.front().metrics) {
        double sum = 0.0;
        for (const fl::bench::Run& r : seed_runs) sum += r.Get(key);
        mean.Add(key, sum / static_cast<double>(seed_runs.size()));
      }
      std::string per_seed;
      std::vector<double> ates;
      for (const fl::bench::Run& r : seed_runs) {
        ates.push_back(r.Get("ate_rmse_m"));
        per_seed += (per_seed.empty() ? "" : ", ") + Metres(ates.back());
      }
      // The spread is heavy-tailed (most seeds agree, one may lock onto a wrong match): the
      // median is the typical run, the mean includes the bad ones.
      std::sort(ates.begin(), ates.end());
      const size_t n = ates.size();
      const double median = n % 2 ? ates[n / 2] : 0.5 * (ates[n / 2 - 1] + ates[n / 2]);
      // Reference-free repeatability: how far the seeds' trajectories are from each other.
      const fl::eval::RunSpreadResult spread =
          fl::eval::ComputeRunSpread(seed_trajectories, fl::eval::Alignment::kSE2, max_dt);
      mean.Add("run_spread_m", spread.mean_m);
      // The error the runs share: ATE of their average trajectory (scatter averaged out).
      const fl::eval::Trajectory average =
          fl::eval::AverageRuns(seed_trajectories, fl::eval::Alignment::kSE2, max_dt);
      mean.Add(
          "shared_ate_m",
          fl::eval::ComputeAte(average, reference, fl::eval::Alignment::kSE2, max_dt).trans_m.rmse);
      // > 1: the runs' average is smaller than the reference (p_ref ≈ s R p_est + t).
      mean.Add("shared_scale",
               fl::eval::ComputeAte(average, reference, fl::eval::Alignment::kSim3, max_dt).scale);
      mean.note = "mean of " + std::to_string(seed_runs.size()) + " runs (seeds " + seeds_text +
                  "); ATE per seed " + per_seed + " m, median " + Metres(median) + " m, worst " +
                  Metres(ates.back()) + " m; run_spread_m = ATE of one run against another " +
                  "(SE(2)-aligned, mean of " + std::to_string(spread.pairs) +
                  (spread.pairs == 1 ? " pair, " : " pairs, ") + Metres(spread.min_m) + "-" +
                  Metres(spread.max_m) + " m): the runs' own scatter, without the reference" +
                  "; shared_ate_m = ATE of the runs' average trajectory (each aligned onto the " +
                  "first): the part of the error all runs share; shared_scale = the scale that " +
                  "maps that average onto the reference (Sim(3) alignment; > 1: the estimate " +
                  "is smaller)";
      report.AddRun(mean);
    }
    // The peer on a raw CARMEN log (its own odometry: corrected logs get our seeded synthetic
    // noise, which the peer's reader does not see), once: its seed is in its ini.
    if (peers && in.sim_config.empty() && !seed_runs.empty() &&
        !fl::importers::IsCorrectedCarmenLog(fl::importers::CarmenOptions{}, in.log)) {
      const fl::bench::Run ours = seed_runs.size() > 1 ? report.runs().back() : seed_runs.front();
      const std::string peer_name = in.name + "/mrpt-rbpf";
      try {
        fl::peers::MrptRbpfOptions po;
        po.ini = peers_config;
        po.rawlog_tool = peers_rawlog_tool;
        po.rbpf_slam = peers_rbpf_slam;
        po.work_dir = tmp + "/" + in.name + "-mrpt";
        po.label = "[bench laser] " + peer_name;
        const fl::peers::MrptRbpfRun pr = fl::peers::RunMrptRbpf(po, in.log);
        const fl::eval::Trajectory& est = pr.final_trajectory;
        const fl::eval::AteResult ate =
            fl::eval::ComputeAte(est, reference, fl::eval::Alignment::kSE2, max_dt);
        const fl::eval::RpeResult rpe =
            fl::eval::ComputeRpe(est, reference, 1, fl::eval::DeltaUnit::kFrames, max_dt);
        std::vector<double> ms_filter;
        for (size_t i = 0; i < pr.steps.size(); ++i)
          if (pr.steps[i].filter) ms_filter.push_back(pr.ms_per_step[i]);
        const fl::bench::Stats sa = fl::bench::ComputeStats(pr.ms_per_step);
        const fl::bench::Stats sp = fl::bench::ComputeStats(ms_filter);
        fl::bench::Run run;
        run.name = peer_name;
        run.input = in.log;
        run.Add("ate_rmse_m", ate.trans_m.rmse)
            .Add("ate_rmse_deg", ate.rot_deg.rmse)
            .Add("rpe_trans_m", rpe.trans_m.mean)
            .Add("rpe_rot_deg", rpe.rot_deg.mean)
            .Add("ms_per_item_mean", sa.mean)
            .Add("ms_per_item_p95", sa.p95)
            .Add("ms_per_processed_mean", sp.mean)
            .Add("ms_per_processed_p95", sp.p95)
            .Add("items", static_cast<double>(pr.steps.size()))
            .Add("processed", static_cast<double>(pr.filter_steps))
            .Add("inserted", static_cast<double>(pr.inserted_steps))
            .Add("peak_rss_mb", pr.peak_rss_mb)
            .Add("cpu_s", pr.cpu_s)
            .Add("wall_s", pr.wall_s);
        if (!relations.empty()) AddRelationColumns(est, &pr.online, relations, max_dt, &run);
        // Its map beside ours, and (--dump) its trajectory in the evaluator's TUM format.
        for (fs::directory_iterator it(pr.output_dir, ec), end; !ec && it != end;
             it.increment(ec)) {
          const std::string f = it->path().filename().string();
          if (f.rfind("finalMap", 0) == 0 && it->path().extension() == ".png") {
            fs::create_directories(png_dir);
            fs::copy_file(it->path(), png_dir + "/" + in.name + "-mrpt.png",
                          fs::copy_options::overwrite_existing, ec);
            break;
          }
        }
        if (dump) fl::eval::WriteTrajectoryTum(est, png_dir + "/" + in.name + "-mrpt.est.tum");
        char cpu[160];
        std::snprintf(cpu, sizeof(cpu),
                      "%.1f s CPU, %.1f s wall for the whole process (%.1f ms CPU per scan)",
                      pr.cpu_s, pr.wall_s,
                      1e3 * pr.cpu_s / std::max<double>(1.0, static_cast<double>(pr.steps.size())));
        run.note = "MRPT rbpf-slam (" + peers_config +
                   "): final trajectory = its most likely particle's path, a pose for every "
                   "scan (between its filter updates: the last path pose and the odometry since), "
                   "online = its particles' weighted mean at each step; ms_per_item = wall time "
                   "of each step's processActionObservation (its log_times.txt), as ours is of "
                   "AddScan; processed = steps with a filter update; peak_rss_mb = the rbpf-slam "
                   "process's ru_maxrss (ours: this process's VmHWM); " + std::string(cpu);
        peer_report.AddRun(PeerRow(ours, ours.name));
        fl::bench::Run peer_row = PeerRow(run, run.name);
        peer_row.note = run.note;
        peer_report.AddRun(peer_row);
        fl::bench::Run ratio = RatioRow(run, ours, in.name + " mrpt-rbpf/ours");
        ratio.note = "peer over ours (" + ours.name + "): > 1 = the peer's error, time or memory "
                     "is larger";
        peer_report.AddRun(ratio);
      } catch (const std::exception& e) {
        std::cerr << "fl-bench-laser: " << peer_name << ": " << e.what() << "\n";
        ++failures;
      }
    }
  }
  if (!std::getenv("FL_BENCH_KEEP_TMP")) fs::remove_all(tmp, ec);
  fl::bench::CommonArgs laser_args = args;
  if (!only.empty() && !laser_args.record.empty() && sim_duration_s <= 0.0) {
    laser_args.record.clear();
    std::cerr << "fl-bench-laser: --only " << only << ": not recording the laser section of "
              << args.record << " (it holds the full run; this one covers some logs; the JSON "
              << "is written)" << (peers ? "; the peers' table is recorded in its own section" : "")
              << "\n";
  }
  fl::bench::Publish(report, laser_args);
  if (peers) {
    fl::bench::CommonArgs peer_args = args;
    if (!peer_args.json.empty()) {
      const fs::path j(peer_args.json);
      peer_args.json = (j.parent_path() / (j.stem().string() + "-peers" + j.extension().string()))
                           .string();
    }
    if (peer_report.runs().empty()) {
      std::cerr << "fl-bench-laser: --peers: no raw CARMEN log ran (the peer runs on raw logs "
                   "such as mit-csail.clf)\n";
      ++failures;
    } else {
      std::cout << "\n";
      fl::bench::Publish(peer_report, peer_args);
    }
  }
  return failures == 0 ? 0 : 1;
}
