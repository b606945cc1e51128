// fl-bench-faults (./fusionloc bench faults, issue 27): faults injected into the simulated
// robot, through the real processes, each run compared with the undisturbed one.
//
// Topology: three LCM buses on loopback (ttl=0), one port each. fl-sim publishes on the
// sensor bus; fl-rbpf-slam and fl-stereo-vo listen and publish on the estimator bus; fl-fusion
// on the fusion bus. This program relays sensor bus -> estimator bus -> fusion bus, each hop
// through a FaultInjector (drop, duplicate, delay, clock jump, corrupt), and starts the four
// processes under a procman deputy (fl::procman::Deputy, auto-respawn for the estimators and
// the fusion, the fusion with its journal), so that a kill -9 is restarted as on the robot.
// The fusion bus and GROUND_TRUTH are recorded to RUN/run.lcmlog and scored like the demo.
//
// Per run (one JSON run each): crashes (deaths by a signal we did not send, or a non-zero
// exit), fused_ate_m and fused_ate_ratio (over the undisturbed run's), messages_lost (sensor
// and estimator messages that did not reach their consumers' bus), recovery_s, rejected (inputs
// the processes counted as dropped in their STATUS), and the fault's own counts.
// The file faults (damaged logs, full disks) are file_faults.hpp's.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iomanip>
#include <iostream>
#include <map>
#include <memory>
#include <set>
#include <sstream>

#include "bot_core/planar_lidar_t.hpp"
#include "bot_core/pose_t.hpp"
#include "file_faults.hpp"
#include "fusionloc/bench/bench.hpp"
#include "fusionloc/bench_faults/fault_injector.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/number_format.hpp"
#include "fusionloc/common/program.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/eval/metrics.hpp"
#include "fusionloc/eval/trajectory.hpp"
#include "fusionloc/fused_pose_t.hpp"
#include "fusionloc/sim_pipeline/sim_pipeline.hpp"
#include "fusionloc/status_t.hpp"

namespace {

namespace bf = fl::bench_faults;

using fl::bench::WallUs;
double Now() { return fl::bench::NowSeconds(); }

struct Setup {
  std::string bin, config_dir, out_dir, world = "paper";
  double duration_s = 60.0;
  int port = 7670;
  int seed = 1;
  double kill_at = 0.4;  // fraction of the run at which a process is killed
};

// One fault scenario: what the two hops do, and which process is killed.
struct Scenario {
  std::string name;
  std::string description;
  bf::FaultOptions sensors;     // sensor bus -> estimator bus
  bf::FaultOptions estimators;  // estimator bus -> fusion bus
  std::string kill;             // deputy command name to kill -9 ("" = none)
  double window_end_s = -1;     // [s of data] end of a clock-jump window (for recovery_s)
};

constexpr const char* kSensorChannels = "LASER|ODOMETRY|STEREO";
constexpr const char* kInputChannels =
    "LASER|ODOMETRY|STEREO|STEREO_CALIBRATION|LASER_TO_BASE|CAMERA_TO_BASE";
constexpr const char* kEstimatorChannels = "RBPF_POSE|RBPF_FACTORS|VO_POSE|VO_FACTORS|VO_POINTS";

std::vector<Scenario> Scenarios(const Setup& s) {
  std::vector<Scenario> v;
  auto none = [] {
    bf::FaultOptions o;
    o.channels = "$^";
    return o;
  };
  auto add = [&](std::string name, std::string description) -> Scenario& {
    Scenario sc;
    sc.name = std::move(name);
    sc.description = std::move(description);
    sc.sensors = none();
    sc.estimators = none();
    sc.sensors.seed = static_cast<uint64_t>(s.seed);
    sc.estimators.seed = static_cast<uint64_t>(s.seed) + 1000;
    v.push_back(sc);
    return v.back();
  };
  add("undisturbed", "no fault: the reference of every ratio");
  {
    Scenario& sc = add("drop_sensors_10pct",
                       "10 % of LASER, ODOMETRY, STEREO dropped at random "
                       "between the drivers and the estimators");
    sc.sensors.channels = kSensorChannels;
    sc.sensors.drop_fraction = 0.10;
  }
  {
    Scenario& sc = add("drop_estimators_10pct",
                       "10 % of the estimators' messages dropped at "
                       "random between the estimators and the fusion");
    sc.estimators.channels = kEstimatorChannels;
    sc.estimators.drop_fraction = 0.10;
  }
  {
    Scenario& sc = add("duplicate_reorder_late",
                       "on both hops 10 % duplicated and 10 % delayed by up to 1 s (reordered)");
    sc.sensors.channels = kSensorChannels;
    sc.estimators.channels = kEstimatorChannels;
    for (bf::FaultOptions* o : {&sc.sensors, &sc.estimators}) {
      o->duplicate_fraction = 0.10;
      o->delay_fraction = 0.10;
      o->max_delay_s = 1.0;
    }
  }
  const double jump_start = 0.3 * s.duration_s, jump_len = 5.0;
  {
    Scenario& sc = add("clock_backwards_2s", "the laser's clock 2 s behind for 5 s of scans");
    sc.sensors.channels = "LASER";
    sc.sensors.jump_offset_s = -2.0;
    sc.sensors.jump_start_s = jump_start;
    sc.sensors.jump_duration_s = jump_len;
    sc.window_end_s = jump_start + jump_len;
  }
  {
    Scenario& sc = add("clock_forward_60s", "the laser's clock 60 s ahead for 5 s of scans");
    sc.sensors.channels = "LASER";
    sc.sensors.jump_offset_s = 60.0;
    sc.sensors.jump_start_s = jump_start;
    sc.sensors.jump_duration_s = jump_len;
    sc.window_end_s = jump_start + jump_len;
  }
  {
    Scenario& sc = add("laser_outage_10s",
                       "no LASER for 10 s of scans (the laser unplugged), then back: the fusion "
                       "goes on from the wheel odometry and the VO");
    sc.sensors.channels = "LASER";
    sc.sensors.outage_start_s = jump_start;
    sc.sensors.outage_duration_s = 10.0;
  }
  {
    Scenario& sc = add("bad_values",
                       "2 % of every input message (sensors, mountings, "
                       "calibration, estimator outputs) with one numeric field "
                       "NaN, +-inf or out of range");
    sc.sensors.channels = kInputChannels;
    sc.sensors.corrupt_fraction = 0.02;
    sc.estimators.channels = kEstimatorChannels;
    sc.estimators.corrupt_fraction = 0.02;
  }
  for (const char* p : {"rbpf_slam", "stereo_vo", "fusion"}) {
    Scenario& sc =
        add(std::string("kill9_") + p, std::string("kill -9 of ") + p + " at " +
                                           fl::FormatDouble(100 * s.kill_at) + " % of the run");
    sc.kill = p;
  }
  return v;
}

std::vector<uint8_t> Copy(const void* data, int size) {
  const auto* p = static_cast<const uint8_t*>(data);
  return std::vector<uint8_t>(p, p + size);
}

// What the bench sees of one run.
struct Observed {
  std::map<std::string, int64_t> sent_sensor, got_sensor;  // per channel, sensor -> estimator hop
  std::map<std::string, int64_t> sent_estimator, got_estimator;
  // STATUS_* counters per status channel: of the current run, and summed over earlier runs.
  std::map<std::string, std::map<std::string, double>> last_counts, total_counts;
  std::set<int64_t> laser_stamps;                       // of the scans the simulator sent
  std::vector<std::pair<double, int64_t>> fused_poses;  // (wall s, utime)
  std::map<std::string, std::vector<std::pair<double, int64_t>>> outputs;  // channel -> same
};

struct Outcome {
  fl::bench::Run run;
  double fused_ate_m = -1;
};

using bf::FusedAte;

Outcome RunScenario(const Setup& s, const Scenario& sc, int index) {
  const std::string dir = s.out_dir + "/" + sc.name;
  std::filesystem::create_directories(dir);
  std::filesystem::remove(dir + "/fusion.journal");
  std::filesystem::remove(dir + "/fusion.journal.retired");
  const int port = s.port + 3 * index;
  auto url = [&](int p) {
    return "udpm://239.255.76.67:" + std::to_string(p) + "?ttl=0&recv_buf_size=16777216";
  };
  const std::string url_s = url(port), url_e = url(port + 1), url_f = url(port + 2);
  auto bus_s = fl::MakeLcm(url_s), bus_e = fl::MakeLcm(url_e), bus_f = fl::MakeLcm(url_f);
  bf::FaultInjector hop_se(sc.sensors), hop_ef(sc.estimators);
  fl::LcmLogWriter log(dir + "/run.lcmlog");
  Observed ob;
  const std::regex sensor_re(kSensorChannels), estimator_re(kEstimatorChannels);
  double t_now = Now();

  bus_s->SubscribeRaw(".*", [&](const std::string& ch, const void* d, int n, fl::Utime) {
    if (ch == "GROUND_TRUTH") log.Write(ch, d, n, WallUs());
    if (std::regex_match(ch, sensor_re)) ++ob.sent_sensor[ch];
    hop_se.Push(ch, Copy(d, n), t_now);
  });
  bus_s->Subscribe<bot_core::planar_lidar_t>(
      "LASER", [&](const auto& m, const std::string&) { ob.laser_stamps.insert(m.utime); });
  bus_e->SubscribeRaw(".*", [&](const std::string& ch, const void* d, int n, fl::Utime) {
    if (std::regex_match(ch, sensor_re)) ++ob.got_sensor[ch];
    if (std::regex_match(ch, estimator_re)) ++ob.sent_estimator[ch];
    if (ch != "STEREO") hop_ef.Push(ch, Copy(d, n), t_now);  // the fusion has no use for images
  });
  bus_f->SubscribeRaw(".*", [&](const std::string& ch, const void* d, int n, fl::Utime) {
    if (std::regex_match(ch, estimator_re)) ++ob.got_estimator[ch];
    if (ch.rfind("FUSED_", 0) == 0 || ch.rfind("STATUS_", 0) == 0 || ch.rfind("RBPF_", 0) == 0 ||
        ch.rfind("VO_", 0) == 0) {
      log.Write(ch, d, n, WallUs());
    }
  });
  bus_f->Subscribe<fusionloc::fused_pose_t>("FUSED_POSE", [&](const auto& m, const std::string&) {
    ob.fused_poses.emplace_back(Now(), m.utime);
    ob.outputs["FUSED_POSE"].emplace_back(Now(), m.utime);
  });
  bus_f->Subscribe<bot_core::pose_t>(
      "RBPF_POSE|VO_POSE",
      [&](const auto& m, const std::string& ch) { ob.outputs[ch].emplace_back(Now(), m.utime); });
  bus_f->Subscribe<fusionloc::status_t>("STATUS_.*", [&](const auto& m, const std::string& ch) {
    // Counters of the process's current run; a restarted process counts from 0 again, so the
    // last run's counts are added to the totals when messages_in goes down.
    std::map<std::string, double> now = {{"dropped", static_cast<double>(m.messages_dropped)},
                                         {"in", static_cast<double>(m.messages_in)}};
    for (int k = 0; k < m.num_keys; ++k) {
      const std::string& key = m.keys[static_cast<size_t>(k)];
      if (key.rfind("gaps_", 0) == 0 || key.rfind("lcm_", 0) == 0) {
        now[key] = m.values[static_cast<size_t>(k)];
      }
    }
    auto& last = ob.last_counts[ch];
    if (now["in"] < last["in"]) {
      for (const auto& [k, v] : last) ob.total_counts[ch][k] += v;
    }
    last = now;
  });

  fl::procman::DeputyOptions dopt;
  dopt.name = "bench-faults";
  dopt.log_dir = dir;
  dopt.vars = {{"BIN", s.bin},
               {"CONFIG", s.config_dir},
               {"URL_S", url_s},
               {"URL_E", url_e},
               {"URL_F", url_f},
               {"DIR", dir},
               {"WORLD", s.world},
               {"DURATION", fl::FormatDouble(s.duration_s)},
               {"SEED", std::to_string(s.seed)}};
  double killed_at = -1;
  double respawned_at = -1;  // when the killed command runs again (a new pid)
  int killed_pid = -1;
  fl::bench::SimPipeline pipeline(
      dopt, {{"rbpf_slam",
              "${BIN}/fl-rbpf-slam --lcm-url=${URL_E} --config ${CONFIG}/rbpf_slam.yaml", true},
             {"stereo_vo",
              "${BIN}/fl-stereo-vo --lcm-url=${URL_E} --config ${CONFIG}/stereo_vo.yaml", true},
             {"fusion",
              "${BIN}/fl-fusion --lcm-url=${URL_F} --config ${CONFIG}/fusion.yaml --journal "
              "${DIR}/fusion.journal",
              true},
             {"sim",
              "${BIN}/fl-sim --lcm-url=${URL_S} --robot ${CONFIG}/robot/sim.yaml --world "
              "${WORLD} --duration ${DURATION} --seed ${SEED} --rate 1",
              false}});
  // Crashes: an exit seen while running that is neither our kill nor a clean stop.
  pipeline.set_expected_exit([&](const fl::procman::CommandStatus& c) {
    return killed_at > 0 && c.spec.name == sc.kill && WIFSIGNALED(c.exit_status) &&
           WTERMSIG(c.exit_status) == SIGKILL;
  });
  auto spin = [&](double seconds, const std::function<bool()>& done) {
    const double end = Now() + seconds;
    fl::bench_faults::FaultEvent e;
    while (Now() < end && !fl::ShutdownRequested() && !(done && done())) {
      t_now = Now();
      bus_s->HandleSubscriptions(1);
      for (auto* bus : {bus_s.get(), bus_e.get(), bus_f.get()}) {
        for (int k = 0; k < 200 && bus->HandleSubscriptions(0) > 0; ++k) t_now = Now();
      }
      t_now = Now();
      while (hop_se.Pop(t_now, &e))
        bus_e->PublishRaw(e.channel, e.data.data(), static_cast<int>(e.data.size()), 0);
      while (hop_ef.Pop(t_now, &e))
        bus_f->PublishRaw(e.channel, e.data.data(), static_cast<int>(e.data.size()), 0);
      pipeline.Poll();
    }
  };
  pipeline.Start([&](double seconds) { spin(seconds, nullptr); });
  const double t0 = Now();
  fl::bench::Progress progress("bench faults " + sc.name, static_cast<int64_t>(s.duration_s));
  double next_measure = Now() + 1.0;
  while (!pipeline.SimExited() && !fl::ShutdownRequested() && Now() - t0 < 3 * s.duration_s + 30) {
    spin(0.05, nullptr);
    if (!sc.kill.empty() && killed_at < 0 && Now() - t0 >= s.kill_at * s.duration_s) {
      for (const auto& c : pipeline.Commands()) {
        if (c.spec.name == sc.kill && c.pid > 0) {
          killed_at = Now();
          killed_pid = c.pid;
          ::kill(c.pid, SIGKILL);
        }
      }
    }
    if (killed_at > 0 && respawned_at < 0) {
      for (const auto& c : pipeline.Commands()) {
        if (c.spec.name == sc.kill && c.pid > 0 && c.pid != killed_pid) respawned_at = Now();
      }
    }
    if (Now() >= next_measure) {
      pipeline.Measure();
      next_measure += 1.0;
      progress.Update(
          std::min<int64_t>(static_cast<int64_t>(Now() - t0), static_cast<int64_t>(s.duration_s)));
    }
  }
  progress.Finish();
  // Late messages still held by the hops, then the last scans through the estimators and the
  // fusion; the fusion publishes its final trajectory when stopped.
  spin(1.5, nullptr);
  hop_se.Flush();
  hop_ef.Flush();
  spin(3.0, nullptr);
  pipeline.StopAll();
  // The fusion's final FUSED_TRAJECTORY, published on its way out.
  {
    const double end = Now() + 1.0;
    while (Now() < end) {
      bus_f->HandleSubscriptions(5);
    }
  }
  pipeline.Poll();
  int crashes = pipeline.crashes();
  std::ostringstream crash_note;
  crash_note << pipeline.crash_note();
  for (const auto& c : pipeline.Commands()) {
    // A process that had to be SIGKILLed at the stop, or exited non-zero then, failed too.
    if (c.exited && c.spec.name != "sim" &&
        !(WIFEXITED(c.exit_status) && WEXITSTATUS(c.exit_status) == 0) &&
        !(c.spec.name == sc.kill && c.starts == 1)) {
      ++crashes;
      crash_note << c.spec.name << " ended with wait status " << c.exit_status
                 << " at the stop (see " << c.log_path << "); ";
    }
  }
  log.Close();

  Outcome out;
  fl::bench::Run& run = out.run;
  run.name = sc.name;
  run.input = "world " + s.world + ", " + fl::FormatDouble(s.duration_s) + " s real time, seed " +
              std::to_string(s.seed) + ": " + sc.description;
  std::string note;
  out.fused_ate_m = FusedAte(dir + "/run.lcmlog", &note);
  int64_t lost = 0;
  for (const auto& [ch, n] : ob.sent_sensor) lost += std::max<int64_t>(0, n - ob.got_sensor[ch]);
  for (const auto& [ch, n] : ob.sent_estimator)
    lost += std::max<int64_t>(0, n - ob.got_estimator[ch]);
  // rejected: inputs the processes dropped (their own checks, LCM duplicates and decode
  // errors); gaps_reported: input gaps they saw (StatusReporter's gaps_<CHANNEL>).
  double rejected = 0, gaps = 0;
  for (const auto& [ch, counts] : ob.last_counts) {
    for (const auto& [k, v] : counts) {
      const double total = v + ob.total_counts[ch][k];
      if (k == "dropped" || k.rfind("lcm_", 0) == 0) rejected += total;
      if (k.rfind("gaps_", 0) == 0) gaps += total;
    }
  }
  // recovery_s: a kill: wall time from the kill to the respawned process's first new output
  // (its pose channel; the fusion's FUSED_POSE); a clock jump: data time from the window's end to
  // the first fused pose stamped after it; otherwise the longest stretch of data time without
  // a fused pose.
  double recovery = -1;
  if (!sc.kill.empty() && killed_at > 0) {
    const std::string ch = sc.kill == "rbpf_slam"   ? "RBPF_POSE"
                           : sc.kill == "stereo_vo" ? "VO_POSE"
                                                    : "FUSED_POSE";
    int64_t newest = 0;
    for (const auto& [at, utime] : ob.outputs[ch]) {
      if (at < killed_at) newest = std::max(newest, utime);
    }
    // Only the respawned process's outputs: one the killed process sent just before the kill
    // may arrive just after it.
    for (const auto& [at, utime] : ob.outputs[ch]) {
      if (respawned_at > 0 && at >= respawned_at && utime > newest) {
        recovery = at - killed_at;
        break;
      }
    }
    if (recovery < 0) note += ch + " never resumed after the kill; ";
  } else {
    std::vector<int64_t> stamps;
    for (const auto& p : ob.fused_poses) stamps.push_back(p.second);
    std::sort(stamps.begin(), stamps.end());
    stamps.erase(std::unique(stamps.begin(), stamps.end()), stamps.end());
    if (sc.window_end_s >= 0 && !stamps.empty()) {
      const int64_t end = stamps.front() + fl::SecondsToUtime(sc.window_end_s);
      auto it = std::upper_bound(stamps.begin(), stamps.end(), end);
      if (it != stamps.end()) recovery = 1e-6 * static_cast<double>(*it - end);
    } else {
      double gap = 0;
      for (size_t i = 1; i < stamps.size(); ++i) {
        gap = std::max(gap, 1e-6 * static_cast<double>(stamps[i] - stamps[i - 1]));
      }
      recovery = gap;
    }
  }
  // Duplicates must never be counted twice: a fused pose stamp repeated is one counted twice.
  std::map<int64_t, int> per_stamp;
  int64_t repeated = 0;
  for (const auto& p : ob.fused_poses) {
    if (++per_stamp[p.second] == 2) ++repeated;
  }
  int64_t unfused = 0;
  for (int64_t t : ob.laser_stamps) unfused += per_stamp.count(t) ? 0 : 1;
  run.Add("crashes", crashes)
      .Add("fused_ate_m", out.fused_ate_m)
      .Add("fused_ate_ratio", -1)  // filled in against the undisturbed run
      .Add("messages_lost", static_cast<double>(lost))
      .Add("recovery_s", recovery)
      .Add("rejected", rejected)
      .Add("gaps_reported", gaps)
      .Add("fused_poses", static_cast<double>(per_stamp.size()))
      .Add("fused_pose_stamps_repeated", static_cast<double>(repeated))
      .Add("scans_without_fused_pose", static_cast<double>(unfused));
  const bf::FaultCounts& a = hop_se.counts();
  const bf::FaultCounts& b = hop_ef.counts();
  run.Add("injected_dropped", static_cast<double>(a.dropped + b.dropped))
      .Add("injected_duplicated", static_cast<double>(a.duplicated + b.duplicated))
      .Add("injected_delayed", static_cast<double>(a.delayed + b.delayed))
      .Add("injected_shifted", static_cast<double>(a.shifted + b.shifted))
      .Add("injected_silenced", static_cast<double>(a.silenced + b.silenced))
      .Add("injected_corrupted", static_cast<double>(a.corrupted + b.corrupted));
  int respawns = 0;
  for (const auto& c : pipeline.Commands()) respawns += c.respawns;
  run.Add("respawns", respawns);
  std::ostringstream n;
  n << note << crash_note.str();
  if (!a.corruptions.empty() || !b.corruptions.empty()) {
    std::ofstream list(dir + "/corruptions.txt");
    for (const auto& c : a.corruptions) list << c << "\n";
    for (const auto& c : b.corruptions) list << c << "\n";
    n << "corruptions, e.g. ";
    for (size_t i = 0; i < std::min<size_t>(3, a.corruptions.size()); ++i)
      n << a.corruptions[i] << "; ";
    for (size_t i = 0; i < std::min<size_t>(2, b.corruptions.size()); ++i)
      n << b.corruptions[i] << "; ";
  }
  run.note = bf::TrimNote(n.str());
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  fl::Program program(
      "fl-bench-faults",
      "Faults injected into the simulated robot through the real processes (dropped, "
      "duplicated, reordered and late messages between drivers, estimators and fusion; a "
      "sensor clock jumping back and forward; the laser silent for 10 s; NaN and out-of-range "
      "values in every input "
      "type; kill -9 of each process under the procman deputy) and into its files (damaged "
      "logs, full disks), each run compared with the undisturbed one. Targets: crashes 0, "
      "fused_ate_ratio <= 2 with 10 % loss.");
  fl::bench::CommonArgs common;
  fl::bench::AddCommonFlags(&program.cli(), &common, "faults");
  Setup s;
  std::string only;
  bool no_files = false, only_files = false;
  char self[4096] = {0};
  if (readlink("/proc/self/exe", self, sizeof(self) - 1) > 0) {
    s.bin = std::filesystem::path(self).parent_path().string();
  }
  s.config_dir = "config";
  s.out_dir = "out/bench/faults";
  program.cli().AddFlag("bin", &s.bin, "folder of the fl-* programs");
  program.cli().AddFlag("config-dir", &s.config_dir,
                        "folder of rbpf_slam.yaml, stereo_vo.yaml, fusion.yaml, robot/sim.yaml");
  program.cli().AddFlag("out", &s.out_dir, "folder for each run's logs");
  program.cli().AddFlag("world", &s.world, "simulated world: paper or corridor");
  program.cli().AddFlag("duration", &s.duration_s, "[s] simulated (= wall) time per run");
  program.cli().AddFlag("seed", &s.seed, "simulator and fault seed");
  program.cli().AddFlag("kill-at", &s.kill_at, "fraction of a run at which kill -9 is sent");
  program.cli().AddFlag(
      "port", &s.port,
      "first UDP port of the benchmark's LCM buses (loopback, ttl=0; three per run)");
  program.cli().AddFlag("only", &only,
                        "comma-separated runs to do (the undisturbed one is always done); "
                        "default: all");
  program.cli().AddFlag("no-file-faults", &no_files,
                        "skip the file faults (damaged logs, full disks)");
  program.cli().AddFlag("file-faults-only", &only_files, "only the file faults (no process runs)");
  program.cli().AddCheck([&]() -> std::string {
    if (no_files && only_files) return "--no-file-faults and --file-faults-only exclude each other";
    if (!(s.duration_s >= 10)) return "--duration must be >= 10 s";
    if (!(s.kill_at > 0 && s.kill_at < 1)) return "--kill-at must be in (0, 1)";
    return "";
  });
  if (!program.Parse(argc, argv)) return program.exit_code();
  return program.Run([&] {
    fl::InstallShutdownHandlers();
    std::vector<Scenario> scenarios = Scenarios(s);
    const std::vector<std::string> file_names = bf::FileFaultNames();
    std::set<std::string> wanted;
    std::vector<std::string> wanted_files;
    std::stringstream in(only);
    for (std::string r; std::getline(in, r, ',');) {
      if (r.empty()) continue;
      bool known = false;
      for (const auto& sc : scenarios) known = known || sc.name == r;
      if (std::find(file_names.begin(), file_names.end(), r) != file_names.end()) {
        wanted_files.push_back(r);
        continue;
      }
      if (!known) {
        std::string names;
        for (const auto& sc : scenarios) names += " " + sc.name;
        for (const auto& n : file_names) names += " " + n;
        throw fl::UsageError("--only: no run '" + r + "'; runs:" + names);
      }
      wanted.insert(r);
    }
    // --only naming file faults alone runs no process scenario, and the reverse.
    const bool run_processes = !only_files && !(wanted.empty() && !wanted_files.empty());
    const bool run_files = !no_files && !(!wanted.empty() && wanted_files.empty());
    fl::bench::Report report("faults");
    double reference = -1;
    for (size_t i = 0; i < scenarios.size() && run_processes; ++i) {
      const Scenario& sc = scenarios[i];
      if (i > 0 && !wanted.empty() && !wanted.count(sc.name)) continue;
      Outcome o = RunScenario(s, sc, static_cast<int>(i));
      if (i == 0) reference = o.fused_ate_m;
      for (auto& [k, v] : o.run.metrics) {
        if (k == "fused_ate_ratio")
          v = reference > 0 && o.fused_ate_m >= 0 ? o.fused_ate_m / reference : -1;
      }
      std::cout << sc.name << ": crashes " << o.run.Get("crashes") << ", fused ATE "
                << std::setprecision(3) << o.fused_ate_m << " m, ratio "
                << o.run.Get("fused_ate_ratio") << ", messages lost " << o.run.Get("messages_lost")
                << ", recovery " << o.run.Get("recovery_s") << " s" << std::endl;
      report.AddRun(o.run);
      if (fl::ShutdownRequested()) return fl::kExitFailure;
    }
    if (run_files) {
      bf::FileFaultSetup fs;
      fs.bin = s.bin;
      fs.config_dir = s.config_dir;
      fs.out_dir = s.out_dir;
      fs.world = s.world;
      fs.duration_s = s.duration_s;
      fs.seed = s.seed;
      fs.port = s.port + 3 * static_cast<int>(scenarios.size());
      for (fl::bench::Run& run : bf::RunFileFaults(fs, wanted_files)) {
        std::cout << run.name << ": crashes " << run.Get("crashes") << ", exit code "
                  << run.Get("exit_code") << std::endl;
        report.AddRun(std::move(run));
        if (fl::ShutdownRequested()) return fl::kExitFailure;
      }
    }
    std::cout << "each run's logs and files: " << s.out_dir << "/RUN/" << std::endl;
    fl::bench::Publish(report, common);
    return fl::kExitOk;
  });
}
