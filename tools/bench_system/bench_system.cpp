// fl-bench-system (./fusionloc bench system): fl-sim, fl-rbpf-slam, fl-stereo-vo and
// fl-fusion as separate processes, started by a procman deputy (fl::procman::Deputy, in this
// process), talking over loopback UDP multicast; the simulator runs in real time at its
// rates with 640x480 stereo at each rate of --stereo-rates. Measured by a subscriber here:
//  - latency [ms] from a LASER message's arrival to the arrival of the FUSED_POSE of the
//    same time stamp (the first fused pose that includes the scan): p50, p99, max; and the
//    part of it until the RBPF-SLAM's RBPF_POSE of that stamp (rbpf_latency_ms_*), so that a
//    tail can be told apart as the laser SLAM's or the fusion's;
//  - messages lost per sensor channel: what the simulator published (its deterministic
//    schedule, checked against the total it reports) minus what arrived here; and the scans
//    that got no fused pose;
//  - CPU [% of one core] over the run and peak resident memory [MB] per process (the deputy's
//    /proc and wait4 figures).
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <regex>
#include <sstream>
#include <thread>

#include "bot_core/planar_lidar_t.hpp"
#include "bot_core/pose_t.hpp"
#include "fusionloc/bench/bench.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/number_format.hpp"
#include "fusionloc/common/program.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/common/yaml_options.hpp"
#include "fusionloc/fused_pose_t.hpp"
#include "fusionloc/sim_pipeline/sim_pipeline.hpp"

namespace {

using fl::bench::NowSeconds;

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

struct Setup {
  std::string bin, config_dir, out_dir, world = "paper";
  double duration_s = 30.0;
  int port = 7650;
};

fl::bench::Run RunOnce(const Setup& s, double stereo_hz) {
  const std::string rate = stereo_hz == std::floor(stereo_hz)
                               ? std::to_string(static_cast<int>(stereo_hz))
                               : fl::FormatDouble(stereo_hz);
  const std::string name = "stereo-" + rate + "hz";
  const std::string dir = s.out_dir + "/" + name;
  std::filesystem::create_directories(dir);
  fl::sim::SimOptions sim = fl::sim::DefaultOptionsForWorld(s.world);
  sim.camera.rate_hz = stereo_hz;
  sim.duration_s = s.duration_s;
  const fl::Status valid = sim.Validate();
  if (!valid.ok()) throw fl::UsageError("simulator options: " + valid.message());
  {
    std::ofstream yaml(dir + "/sim.yaml");
    yaml << fl::SaveYamlString(sim);
  }
  const std::string url =
      "udpm://239.255.76.67:" + std::to_string(s.port) + "?ttl=0&recv_buf_size=16777216";
  auto lcm = fl::MakeLcm(url);
  std::map<std::string, int64_t> received;
  std::map<int64_t, double> laser_at, rbpf_at, fused_at;
  lcm->SubscribeRaw(".*",
                    [&](const std::string& ch, const void*, int, fl::Utime) { ++received[ch]; });
  lcm->Subscribe<bot_core::planar_lidar_t>(
      "LASER", [&](const auto& m, const std::string&) { laser_at.emplace(m.utime, NowSeconds()); });
  lcm->Subscribe<bot_core::pose_t>("RBPF_POSE", [&](const auto& m, const std::string&) {
    rbpf_at.emplace(m.utime, NowSeconds());
  });
  lcm->Subscribe<fusionloc::fused_pose_t>("FUSED_POSE", [&](const auto& m, const std::string&) {
    fused_at.emplace(m.utime, NowSeconds());
  });

  fl::procman::DeputyOptions dopt;
  dopt.name = "bench";
  dopt.log_dir = dir;
  dopt.vars = {{"BIN", s.bin}, {"CONFIG", s.config_dir}, {"URL", url}, {"SIM", dir + "/sim.yaml"}};
  fl::bench::SimPipeline pipeline(
      dopt,
      {{"rbpf_slam", "${BIN}/fl-rbpf-slam --lcm-url=${URL} --config ${CONFIG}/rbpf_slam.yaml"},
       {"stereo_vo", "${BIN}/fl-stereo-vo --lcm-url=${URL} --config ${CONFIG}/stereo_vo.yaml"},
       {"fusion", "${BIN}/fl-fusion --lcm-url=${URL} --config ${CONFIG}/fusion.yaml"},
       {"sim",
        "${BIN}/fl-sim --lcm-url=${URL} --robot ${CONFIG}/robot/sim.yaml --config ${SIM} "
        "--rate 1"}});
  auto spin = [&](double seconds) { pipeline.Spin(lcm.get(), seconds); };
  pipeline.Start(spin);
  const double t0 = NowSeconds();
  fl::bench::Progress progress("bench system " + name, static_cast<int64_t>(s.duration_s));
  double next_measure = NowSeconds() + 1.0;
  while (!pipeline.SimExited() && !fl::ShutdownRequested() &&
         NowSeconds() - t0 < 4 * s.duration_s + 30) {
    spin(0.05);
    if (NowSeconds() >= next_measure) {
      pipeline.Measure();  // peak memory, CPU
      next_measure += 1.0;
      progress.Update(std::min<int64_t>(static_cast<int64_t>(NowSeconds() - t0),
                                        static_cast<int64_t>(s.duration_s)));
    }
  }
  progress.Finish();
  spin(3.0);  // the last scans through the estimators and the fusion
  pipeline.Measure();
  const double wall_s = NowSeconds() - t0;
  pipeline.StopAll();

  fl::bench::Run run;
  run.name = name;
  run.input = "world " + s.world + ", " + fl::FormatDouble(s.duration_s) + " s real time";
  // [ms] from each scan's arrival to the arrival of `out`'s message of the same stamp.
  auto latencies_ms = [&](const std::map<int64_t, double>& out) {
    std::vector<double> ms;
    for (const auto& [utime, at] : laser_at) {
      const auto o = out.find(utime);
      if (o != out.end()) ms.push_back(1e3 * (o->second - at));
    }
    return ms;
  };
  const std::vector<double> latency_ms = latencies_ms(fused_at);
  const std::vector<double> rbpf_latency_ms = latencies_ms(rbpf_at);
  const fl::bench::Stats lat = fl::bench::ComputeStats(latency_ms);
  const fl::bench::Stats rbpf_lat = fl::bench::ComputeStats(rbpf_latency_ms);
  run.Add("latency_ms_p50", lat.median)
      .Add("latency_ms_p99", lat.p99)
      .Add("latency_ms_max", lat.max)
      .Add("rbpf_latency_ms_p50", rbpf_lat.median)
      .Add("rbpf_latency_ms_p99", rbpf_lat.p99);
  const std::map<std::string, int64_t> expected = fl::bench::SimSchedule(sim);
  int64_t total_expected = 0, lost = 0;
  for (const auto& [ch, n] : expected) {
    total_expected += n;
    const int64_t l = n - received[ch];
    lost += std::max<int64_t>(0, l);
    if (ch == "LASER" || ch == "STEREO" || ch == "ODOMETRY")
      run.Add("lost_" + ch, static_cast<double>(l));
  }
  run.Add("scans_without_fused_pose",
          static_cast<double>(expected.at("LASER")) - static_cast<double>(latency_ms.size()));
  for (const auto& c : pipeline.Commands()) {
    run.Add("cpu_pct_" + c.spec.name, 100.0 * c.cpu_time_s / wall_s);
    run.Add("peak_rss_mb_" + c.spec.name, static_cast<double>(c.peak_rss_bytes) / 1048576.0);
  }
  // The schedule counts the steps the simulator says it published.
  std::smatch m;
  const std::string sim_log = ReadFile(dir + "/sim.log");
  std::ostringstream note;
  if (!std::regex_search(sim_log, m, std::regex("published ([0-9]+) steps")) ||
      std::stoll(m[1]) != sim.steps() + 1) {
    note << "the simulator did not report " << sim.steps() + 1 << " steps (see " << dir
         << "/sim.log); ";
  }
  note << (lat.p99 <= 20.0 ? "p99 <= 20 ms: met" : "p99 <= 20 ms: NOT met") << "; "
       << (lost == 0 ? "nothing lost: met"
                     : "nothing lost: NOT met (" + std::to_string(lost) + ")");
  run.note = note.str();
  return run;
}

}  // namespace

int main(int argc, char** argv) {
  fl::Program program(
      "fl-bench-system",
      "The whole pipeline as separate processes under a procman deputy over loopback UDP "
      "multicast, the simulator in real time: latency LASER -> FUSED_POSE (p50, p99), "
      "messages lost per channel, CPU and peak memory per process; once per stereo rate. "
      "Targets: p99 <= 20 ms, nothing lost.");
  fl::bench::CommonArgs common;
  fl::bench::AddCommonFlags(&program.cli(), &common, "system");
  Setup s;
  std::string rates = "2,10";
  char self[4096] = {0};
  if (readlink("/proc/self/exe", self, sizeof(self) - 1) > 0) {
    s.bin = std::filesystem::path(self).parent_path().string();
  }
  s.config_dir = "config";
  s.out_dir = "out/bench/system";
  program.cli().AddFlag("bin", &s.bin, "folder of the fl-* programs");
  program.cli().AddFlag("config-dir", &s.config_dir,
                        "folder of rbpf_slam.yaml, stereo_vo.yaml, fusion.yaml");
  program.cli().AddFlag("out", &s.out_dir, "folder for the processes' logs");
  program.cli().AddFlag("world", &s.world, "simulated world: paper or corridor");
  program.cli().AddFlag("duration", &s.duration_s, "[s] simulated (= wall) time per run");
  program.cli().AddFlag("stereo-rates", &rates,
                        "[Hz] stereo rates, one run each (comma-separated)");
  program.cli().AddFlag("port", &s.port, "UDP port of the benchmark's LCM (loopback, ttl=0)");
  if (!program.Parse(argc, argv)) return program.exit_code();
  return program.Run([&] {
    fl::InstallShutdownHandlers();
    fl::bench::Report report("system");
    std::stringstream in(rates);
    for (std::string r; std::getline(in, r, ',');) {
      if (r.empty()) continue;
      report.AddRun(RunOnce(s, std::stod(r)));
      if (fl::ShutdownRequested()) return fl::kExitFailure;
    }
    fl::bench::Publish(report, common);
    return fl::kExitOk;
  });
}
