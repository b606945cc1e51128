// fl-bench-soak (./fusionloc bench soak --minutes N): the simulated robot through all its
// processes for N minutes, as on the robot (config/procman/sim.cfg: fl-rbpf-slam,
// fl-stereo-vo, fl-fusion with its journal and map, fl-sim in real time looping its route),
// under a procman deputy with auto-respawn, over loopback UDP multicast (ttl=0).
//
// Sampled every --sample-s (60 s): the resident memory of each process (procman's /proc
// figures for its process group), the latency from a LASER message's arrival to the arrival
// of the FUSED_POSE of the same stamp (p99 of that minute), and the sizes the processes
// report in their STATUS: the fusion's graph nodes and factors and map keyframes, the
// RBPF-SLAM's keyframes, the journal's size on disk, each process's heap in use (its STATUS
// heap_mb: the allocator's count, which RSS follows since every process returns its free
// pages once a minute). After the warm-up, the slope of each (least squares) per 10 minutes:
// rss_slope_mb_per_10min per process (flat: |slope| < 1 MB per 10 min) and
// size_slope_per_10min per size (bounded: the graph stops growing once the route
// has been mapped). Messages lost: what the simulator's schedule published minus what arrived
// here. The online FUSED_POSE against GROUND_TRUTH: one SE(2) alignment over the run, the RMS
// error overall and per minute (OUT/fused_ate_per_minute.csv). Every sample also goes to
// OUT/samples.csv. At the end, the journal the run left is restored the way a respawned
// fl-fusion restores it (FusionNode, in this process, on a copy), timed: what a kill -9 at the
// end of the run would cost (run "journal_restore"); and so is the largest journal of the
// per-minute samples, a respawn's worst case (run "journal_restore_largest").
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>

#include "bot_core/planar_lidar_t.hpp"
#include "bot_core/pose_t.hpp"
#include "fusionloc/bench/bench.hpp"
#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/number_format.hpp"
#include "fusionloc/common/program.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/common/status_reporter.hpp"
#include "fusionloc/common/yaml_options.hpp"
#include "fusionloc/eval/metrics.hpp"
#include "fusionloc/fused_pose_t.hpp"
#include "fusionloc/fusion/fusion_lcm.hpp"
#include "fusionloc/sim_pipeline/sim_pipeline.hpp"
#include "fusionloc/status_t.hpp"

namespace {

using fl::bench::NowSeconds;

struct Setup {
  std::string bin, config_dir, out_dir, world = "paper";
  double minutes = 30.0;
  double warmup_minutes = -1.0;  // < 0: min(10, minutes / 3)
  double sample_s = 60.0;
  int64_t seed = 1;
  int port = 7660;
  double journal_snapshot_s = -1.0;  // fl-fusion --journal-snapshot-s (< 0: its default)
};

// A sampled size (status key or file size) and where it comes from.
struct SizeSeries {
  std::string name;     // row name
  std::string channel;  // STATUS_ channel ("" : not from status)
  std::string key;      // status key
};

// The value at the first sample with t >= t_from (NaN if none).
double At(const std::vector<double>& t, const std::vector<double>& y, double t_from) {
  for (size_t i = 0; i < t.size(); ++i) {
    if (t[i] >= t_from) return y[i];
  }
  return std::nan("");
}

// The journal restored as a respawned fl-fusion restores it (FusionNode's constructor, here
// on memq:// and a copy of the file), timed; the run is called `name`.
fl::bench::Run RestoreJournal(const Setup& s, const std::string& journal, const std::string& name,
                              const std::string& what) {
  fl::bench::Run run;
  run.name = name;
  run.input = journal;
  std::error_code ec;
  const auto bytes = std::filesystem::file_size(journal, ec);
  if (ec) {
    run.note = "no journal: " + ec.message();
    return run;
  }
  const std::string copy = journal + ".restore-check";
  std::filesystem::copy_file(journal, copy, std::filesystem::copy_options::overwrite_existing);
  // Its retired trajectory beyond the newest 10 minutes (FusionNodeOptions::journal).
  if (std::filesystem::exists(journal + ".retired", ec)) {
    std::filesystem::copy_file(journal + ".retired", copy + ".retired",
                               std::filesystem::copy_options::overwrite_existing);
  }
  const auto config =
      fl::LoadYamlFile<fl::fusion::FusionProcessConfig>(s.config_dir + "/fusion.yaml");
  fl::fusion::FusionNodeOptions options;
  options.map_out = "";
  options.sync_full_solve = true;
  options.journal = copy;
  options.journal_max_age_s = 1e9;
  auto lcm = fl::MakeLcm("memq://");
  const double t0 = NowSeconds();
  fl::fusion::FusionNode node(config, options, lcm.get(), fl::ChannelMap());
  const double restore_s = NowSeconds() - t0;
  std::filesystem::remove(copy, ec);
  std::filesystem::remove(copy + ".new", ec);
  std::filesystem::remove(copy + ".retired", ec);
  run.Add("journal_mb", static_cast<double>(bytes) / 1048576.0)
      .Add("restore_ms", 1e3 * restore_s)
      .Add("restored_inputs", static_cast<double>(node.restored_inputs()))
      .Add("restored_nodes", node.fusion().num_nodes())
      .Add("restored_retired_nodes", static_cast<double>(node.fusion().num_retired_nodes()))
      .Add("restored_retired_spilled",
           static_cast<double>(node.fusion().retired_trajectory().spilled()));
  run.note = what +
             ", replayed in-process as a respawned fl-fusion does: snapshot (if any), "
             "inputs after it, one full solve";
  return run;
}

int RunSoak(const Setup& s, fl::bench::Report* report) {
  std::filesystem::create_directories(s.out_dir);
  const std::string dir = std::filesystem::absolute(s.out_dir).string();
  fl::sim::SimOptions sim = fl::sim::DefaultOptionsForWorld(s.world);
  sim.duration_s = 60.0 * s.minutes;
  sim.seed = s.seed;
  const fl::Status valid = sim.Validate();
  if (!valid.ok()) throw fl::UsageError("simulator options: " + valid.message());
  {
    std::ofstream yaml(dir + "/sim.yaml");
    yaml << fl::SaveYamlString(sim);
  }
  const double warmup_s =
      60.0 * (s.warmup_minutes >= 0 ? s.warmup_minutes : std::min(10.0, s.minutes / 3.0));
  std::filesystem::remove(dir + "/fusion.journal");
  std::filesystem::remove(dir + "/fusion.journal.retired");

  const std::string url =
      "udpm://239.255.76.67:" + std::to_string(s.port) + "?ttl=0&recv_buf_size=16777216";
  auto lcm = fl::MakeLcm(url);
  std::map<std::string, int64_t> received;
  std::map<int64_t, double> laser_at, fused_at;
  std::map<std::string, std::map<std::string, double>> status;  // channel -> key -> value
  lcm->SubscribeRaw(".*",
                    [&](const std::string& ch, const void*, int, fl::Utime) { ++received[ch]; });
  lcm->Subscribe<bot_core::planar_lidar_t>(
      "LASER", [&](const auto& m, const std::string&) { laser_at.emplace(m.utime, NowSeconds()); });
  fl::eval::Trajectory truth, fused;  // GROUND_TRUTH and the online FUSED_POSE
  lcm->Subscribe<fusionloc::fused_pose_t>("FUSED_POSE", [&](const auto& m, const std::string&) {
    fused_at.emplace(m.utime, NowSeconds());
    if (fused.empty() || m.utime > fused.back().utime) {
      fused.push_back({m.utime, fl::Pose2(m.x, m.y, m.theta).ToIsometry3()});
    }
  });
  lcm->Subscribe<bot_core::pose_t>("GROUND_TRUTH", [&](const auto& m, const std::string&) {
    if (truth.empty() || m.utime > truth.back().utime) {
      truth.push_back({m.utime, fl::IsometryFromArrays(m.pos, m.orientation)});
    }
  });
  lcm->Subscribe<fusionloc::status_t>("STATUS_.*", [&](const auto& m, const std::string& ch) {
    auto& st = status[ch];
    for (int k = 0; k < m.num_keys; ++k) {
      st[m.keys[static_cast<size_t>(k)]] = m.values[static_cast<size_t>(k)];
    }
  });

  fl::procman::DeputyOptions dopt;
  dopt.name = "bench-soak";
  dopt.log_dir = dir;
  dopt.vars = {{"BIN", s.bin}, {"CONFIG", s.config_dir}, {"URL", url}, {"DIR", dir}};
  fl::bench::SimPipeline pipeline(
      dopt,
      {{"rbpf_slam", "${BIN}/fl-rbpf-slam --lcm-url=${URL} --config ${CONFIG}/rbpf_slam.yaml",
        true},
       {"stereo_vo", "${BIN}/fl-stereo-vo --lcm-url=${URL} --config ${CONFIG}/stereo_vo.yaml",
        true},
       {"fusion",
        "${BIN}/fl-fusion --lcm-url=${URL} --config ${CONFIG}/fusion.yaml --map-out ${DIR}/map "
        "--journal ${DIR}/fusion.journal" +
            (s.journal_snapshot_s >= 0.0
                 ? " --journal-snapshot-s " + fl::FormatDouble(s.journal_snapshot_s)
                 : std::string()),
        true},
       {"sim",
        "${BIN}/fl-sim --lcm-url=${URL} --robot ${CONFIG}/robot/sim.yaml --config ${DIR}/sim.yaml "
        "--rate 1",
        false}});
  auto spin = [&](double seconds) { pipeline.Spin(lcm.get(), seconds); };
  pipeline.Start(spin);
  const double t0 = NowSeconds();

  const std::vector<std::string> procs = {"rbpf_slam", "stereo_vo", "fusion", "sim"};
  const std::vector<SizeSeries> sizes = {
      {"fusion_nodes", fl::StatusChannel("fl-fusion"), "nodes"},
      {"fusion_factors", fl::StatusChannel("fl-fusion"), "factors"},
      {"map_keyframes", fl::StatusChannel("fl-fusion"), "map_keyframes"},
      {"map_points", fl::StatusChannel("fl-fusion"), "map_points"},
      {"rbpf_keyframes", fl::StatusChannel("fl-rbpf-slam"), "keyframes"},
      {"journal_snapshot_mb", fl::StatusChannel("fl-fusion"), "journal_snapshot_mb"},
      {"journal_snapshot_ms", fl::StatusChannel("fl-fusion"), "journal_snapshot_ms"},
      {"journal_mb", "", ""},
      {"fusion_heap_mb", fl::StatusChannel("fl-fusion"), "heap_mb"},
      {"retired_in_memory", fl::StatusChannel("fl-fusion"), "retired_in_memory"},
      {"retired_spilled", fl::StatusChannel("fl-fusion"), "retired_spilled"},
      {"rbpf_heap_mb", fl::StatusChannel("fl-rbpf-slam"), "heap_mb"},
      {"stereo_vo_heap_mb", fl::StatusChannel("fl-stereo-vo"), "heap_mb"}};
  std::vector<double> sample_t;                          // [min] since the simulator started
  std::map<std::string, std::vector<double>> rss, size;  // per process [MB] / per size
  std::vector<double> minute_p99;
  std::ofstream csv(dir + "/samples.csv");
  csv << "minute";
  for (const auto& p : procs) csv << ",rss_mb_" << p;
  for (const auto& z : sizes) csv << "," << z.name;
  csv << ",latency_ms_p99\n";
  std::uintmax_t largest_journal_bytes = 0;  // of fusion.journal.largest
  std::filesystem::remove(dir + "/fusion.journal.largest");
  std::filesystem::remove(dir + "/fusion.journal.largest.retired");
  size_t latency_from = 0;  // laser_at is ordered by stamp = arrival order of the simulator
  std::vector<double> all_latency_ms;

  auto take_sample = [&] {
    const fl::procman::HostStatus hs = pipeline.Measure();
    const double t_min = (NowSeconds() - t0) / 60.0;
    sample_t.push_back(t_min);
    csv << fl::FormatDouble(t_min);
    for (const auto& p : procs) {
      double mb = std::nan("");
      for (const auto& c : hs.cmds) {
        if (c.spec.name == p && c.state == fl::procman::CommandState::kRunning) {
          mb = static_cast<double>(c.rss_bytes) / 1048576.0;
        }
      }
      rss[p].push_back(mb);
      csv << "," << fl::FormatDouble(mb);
    }
    for (const auto& z : sizes) {
      double v = std::nan("");
      if (z.channel.empty()) {
        std::error_code ec;
        const auto bytes = std::filesystem::file_size(dir + "/fusion.journal", ec);
        if (!ec) v = static_cast<double>(bytes) / 1048576.0;
        // The largest journal seen (the most inputs after a snapshot) is kept for a restore at
        // the end: a respawn's worst case. Copied while fl-fusion appends to it: its last event
        // may be cut, as after a kill -9 (the restore reads what is whole).
        if (!ec && bytes > largest_journal_bytes) {
          std::filesystem::copy_file(dir + "/fusion.journal", dir + "/fusion.journal.largest",
                                     std::filesystem::copy_options::overwrite_existing, ec);
          // The retired trajectory after it: at least what the snapshot counts.
          if (!ec && std::filesystem::exists(dir + "/fusion.journal.retired", ec)) {
            std::filesystem::copy_file(dir + "/fusion.journal.retired",
                                       dir + "/fusion.journal.largest.retired",
                                       std::filesystem::copy_options::overwrite_existing, ec);
          }
          if (!ec) largest_journal_bytes = bytes;
        }
      } else if (status.count(z.channel) && status[z.channel].count(z.key)) {
        v = status[z.channel][z.key];
      }
      size[z.name].push_back(v);
      csv << "," << fl::FormatDouble(v);
    }
    // Latency of the scans that arrived since the last sample and have their fused pose.
    std::vector<double> lat;
    size_t k = 0;
    for (auto it = laser_at.begin(); it != laser_at.end(); ++it, ++k) {
      if (k < latency_from) continue;
      const auto f = fused_at.find(it->first);
      if (f != fused_at.end()) lat.push_back(1e3 * (f->second - it->second));
    }
    latency_from = laser_at.size();
    const double p99 = lat.empty() ? std::nan("") : fl::bench::ComputeStats(lat).p99;
    minute_p99.push_back(p99);
    all_latency_ms.insert(all_latency_ms.end(), lat.begin(), lat.end());
    csv << "," << fl::FormatDouble(p99) << "\n";
    csv.flush();
  };

  fl::bench::Progress progress("bench soak", static_cast<int64_t>(sim.duration_s), 30.0);
  double next_sample = NowSeconds() + s.sample_s;
  while (!pipeline.SimExited() && !fl::ShutdownRequested() &&
         NowSeconds() - t0 < 2 * sim.duration_s + 60) {
    spin(0.05);
    if (NowSeconds() >= next_sample) {
      take_sample();
      next_sample += s.sample_s;
      progress.Update(std::min<int64_t>(static_cast<int64_t>(NowSeconds() - t0),
                                        static_cast<int64_t>(sim.duration_s)));
    }
  }
  progress.Finish();
  spin(3.0);  // the last scans through the estimators and the fusion
  take_sample();
  const double wall_s = NowSeconds() - t0;
  pipeline.StopAll();
  pipeline.Poll();
  if (fl::ShutdownRequested()) return fl::kExitFailure;
  report->AddRun(
      RestoreJournal(s, dir + "/fusion.journal", "journal_restore", "the journal at the end"));
  report->AddRun(RestoreJournal(s, dir + "/fusion.journal.largest", "journal_restore_largest",
                                "the largest journal of the per-minute samples (the most "
                                "inputs after a snapshot: a respawn's worst case)"));

  const double warm_min = warmup_s / 60.0;
  for (const auto& p : procs) {
    fl::bench::Run run;
    run.name = p;
    run.input = "world " + s.world + ", " + fl::FormatDouble(s.minutes) + " min real time";
    const double slope = 10.0 * fl::bench::LeastSquaresSlope(sample_t, rss[p], warm_min);
    run.Add("rss_mb_warm", At(sample_t, rss[p], warm_min))
        .Add("rss_mb_end", rss[p].empty() ? std::nan("") : rss[p].back())
        .Add("rss_slope_mb_per_10min", slope);
    for (const auto& c : pipeline.Commands()) {
      if (c.spec.name != p) continue;
      run.Add("peak_rss_mb", static_cast<double>(c.peak_rss_bytes) / 1048576.0)
          .Add("cpu_pct", 100.0 * c.cpu_time_s / wall_s)
          .Add("respawns", c.respawns);
    }
    if (p != "sim") {
      run.note = std::isfinite(slope) && std::fabs(slope) < 1.0
                     ? "flat (|slope| < 1 MB per 10 min): met"
                     : "flat (|slope| < 1 MB per 10 min): NOT met";
    }
    report->AddRun(run);
  }
  for (const auto& z : sizes) {
    fl::bench::Run run;
    run.name = z.name;
    run.input = z.channel.empty() ? dir + "/fusion.journal" : z.channel + " " + z.key;
    const std::vector<double>& y = size[z.name];
    run.Add("size_warm", At(sample_t, y, warm_min))
        .Add("size_end", y.empty() ? std::nan("") : y.back())
        .Add("size_slope_per_10min", 10.0 * fl::bench::LeastSquaresSlope(sample_t, y, warm_min));
    report->AddRun(run);
  }
  // Online fused pose against the truth: one SE(2) alignment over the run, then the RMS error
  // per minute of data time (does the estimate degrade as the graph is bounded?).
  double ate = std::nan(""), ate_first = std::nan(""), ate_last = std::nan(""), ate_worst = 0;
  if (fused.size() >= 2 && truth.size() >= 2) {
    const fl::eval::AteResult a =
        fl::eval::ComputeAte(fused, truth, fl::eval::Alignment::kSE2, 20000);
    ate = a.trans_m.rmse;
    std::map<int64_t, std::pair<double, int>> per_minute;  // minute -> (sum of e^2, count)
    for (size_t k = 0; k < a.utimes.size(); ++k) {
      auto& m = per_minute[(a.utimes[k] - a.utimes.front()) / 60000000];
      m.first += a.trans_errors_m[k] * a.trans_errors_m[k];
      ++m.second;
    }
    std::ofstream ate_csv(dir + "/fused_ate_per_minute.csv");
    ate_csv << "minute,fused_ate_m\n";
    for (const auto& [minute, e] : per_minute) {
      const double rms = std::sqrt(e.first / e.second);
      ate_csv << minute << "," << fl::FormatDouble(rms) << "\n";
      if (std::isnan(ate_first)) ate_first = rms;
      ate_last = rms;
      ate_worst = std::max(ate_worst, rms);
    }
  }
  fl::bench::Run run;
  run.name = "pipeline";
  run.input = "world " + s.world + ", seed " + std::to_string(s.seed) + ", " +
              fl::FormatDouble(s.minutes) + " min real time, samples every " +
              fl::FormatDouble(s.sample_s) + " s in " + dir + "/samples.csv";
  const fl::bench::Stats lat = fl::bench::ComputeStats(all_latency_ms);
  double worst = 0.0;
  for (double p : minute_p99) {
    if (std::isfinite(p)) worst = std::max(worst, p);
  }
  const std::map<std::string, int64_t> expected = fl::bench::SimSchedule(sim);
  int64_t lost = 0;
  for (const auto& [ch, n] : expected) lost += std::max<int64_t>(0, n - received[ch]);
  run.Add("latency_ms_p50", lat.median)
      .Add("latency_ms_p99", lat.p99)
      .Add("latency_ms_p99_worst_minute", worst)
      .Add("messages_lost", static_cast<double>(lost))
      .Add("scans_without_fused_pose",
           static_cast<double>(expected.at("LASER")) - static_cast<double>(all_latency_ms.size()))
      .Add("crashes", pipeline.crashes())
      .Add("fused_ate_m", ate)
      .Add("fused_ate_m_first_minute", ate_first)
      .Add("fused_ate_m_last_minute", ate_last)
      .Add("fused_ate_m_worst_minute", ate_worst);
  std::ostringstream note;
  note << "warm-up " << fl::FormatDouble(warm_min) << " min; "
       << (pipeline.crashes() == 0 ? "no crash" : "CRASHES: " + pipeline.crash_note());
  run.note = note.str();
  report->AddRun(run);
  return pipeline.crashes() == 0 ? fl::kExitOk : fl::kExitFailure;
}

}  // namespace

int main(int argc, char** argv) {
  fl::Program program(
      "fl-bench-soak",
      "The simulated robot through all its processes under a procman deputy for --minutes, the "
      "simulator in real time looping its route: resident memory per process and its slope "
      "after the warm-up (rss_slope_mb_per_10min; flat: under 1 MB per 10 min), latency "
      "LASER -> FUSED_POSE p99 per minute, messages lost, and the graph, map and journal sizes "
      "with their slopes. Samples in OUT/samples.csv.");
  fl::bench::CommonArgs common;
  fl::bench::AddCommonFlags(&program.cli(), &common, "soak");
  Setup s;
  char self[4096] = {0};
  if (readlink("/proc/self/exe", self, sizeof(self) - 1) > 0) {
    s.bin = std::filesystem::path(self).parent_path().string();
  }
  s.config_dir = "config";
  s.out_dir = "out/bench/soak";
  program.cli().AddFlag("minutes", &s.minutes, "[min] length of the run (simulated = wall time)");
  program.cli().AddFlag("warmup-minutes", &s.warmup_minutes,
                        "[min] samples before this are left out of the slopes (default: "
                        "min(10, minutes / 3): the fusion's 5-minute active window fills, "
                        "then its first lap retires)");
  program.cli().AddFlag("sample-s", &s.sample_s, "[s] sampling period");
  program.cli().AddFlag("world", &s.world, "simulated world: paper or corridor");
  program.cli().AddFlag("seed", &s.seed, "simulator seed");
  program.cli().AddFlag("bin", &s.bin, "folder of the fl-* programs");
  program.cli().AddFlag("config-dir", &s.config_dir,
                        "folder of rbpf_slam.yaml, stereo_vo.yaml, fusion.yaml, robot/sim.yaml");
  program.cli().AddFlag("out", &s.out_dir, "folder for the processes' logs, journal, map, samples");
  program.cli().AddFlag("port", &s.port, "UDP port of the benchmark's LCM (loopback, ttl=0)");
  program.cli().AddFlag("journal-snapshot-s", &s.journal_snapshot_s,
                        "fl-fusion --journal-snapshot-s for the run (0 = no snapshots: the journal "
                        "holds every input); < 0 = fl-fusion's default");
  if (!program.Parse(argc, argv)) return program.exit_code();
  return program.Run([&] {
    if (!(s.minutes > 0.0 && s.minutes <= 24 * 60)) {
      throw fl::UsageError("--minutes must be in (0, 1440], not " + fl::FormatDouble(s.minutes));
    }
    if (!(s.sample_s >= 1.0 && s.sample_s <= 60.0 * s.minutes)) {
      throw fl::UsageError("--sample-s must be >= 1 s and at most the run's length");
    }
    if (s.warmup_minutes >= s.minutes) {
      throw fl::UsageError("--warmup-minutes must be shorter than --minutes");
    }
    fl::InstallShutdownHandlers();
    fl::bench::Report report("soak");
    const int rc = RunSoak(s, &report);
    if (fl::ShutdownRequested()) return fl::kExitFailure;
    fl::bench::Publish(report, common);
    return rc;
  });
}
