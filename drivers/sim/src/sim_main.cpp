// fl-sim: the simulated robot. Publishes LASER, ODOMETRY, STEREO, STEREO_CALIBRATION, the
// mountings (LASER_TO_BASE, CAMERA_TO_BASE) and GROUND_TRUTH live over LCM, or writes them to an
// LCM log faster than real time.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <stdexcept>
#include <thread>

#include "fusionloc/common/lcm_process.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/common/number_format.hpp"
#include "fusionloc/common/robot_description.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/common/status_reporter.hpp"
#include "fusionloc/common/yaml_options.hpp"
#include "fusionloc/sim/simulator.hpp"
#include "fusionloc/sim/top_view.hpp"
#include "fusionloc/status_t.hpp"

namespace {

int RunLive(const fl::sim::SimOptions& options, const fl::LcmProcess& process, double rate) {
  auto lcm = process.Open();
  const fl::ChannelMap& channels = process.channels();
  fl::StatusReporter status(lcm.get(), "fl-sim");
  fl::sim::Simulator sim(options);
  const int8_t ok = fusionloc::status_t::LEVEL_OK;
  status.SetState(ok, "publishing world '" + options.world.name + "'");
  FL_LOG(INFO) << "world '" << options.world.name << "', " << sim.total_frames() << " steps of "
               << options.step_s << " s, rate " << rate << "x, on " << lcm->url();
  const auto wall_start = std::chrono::steady_clock::now();
  fl::sim::SimFrame frame;
  int64_t frames = 0;
  fl::RateLimitedWarning behind;
  while (!fl::ShutdownRequested() && sim.Step(&frame)) {
    if (rate > 0) {
      const double due_s = static_cast<double>(frame.step) * options.step_s / rate;
      const auto due = wall_start + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                        std::chrono::duration<double>(due_s));
      const double late_s =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - due).count();
      if (late_s > 0.5) {
        behind.Warn("running " + std::to_string(late_s) +
                    " s behind the requested pace; use a lower --rate, camera.supersampling: 1, "
                    "or write a log (--log) and replay it");
        status.SetState(fusionloc::status_t::LEVEL_WARN, "behind the requested pace");
      } else if (late_s < 0.1) {
        status.SetState(ok, "publishing world '" + options.world.name + "'");
      }
      std::this_thread::sleep_until(due);
    }
    const auto t0 = std::chrono::steady_clock::now();
    fl::sim::VisitMessages(frame, [&](const char* channel, const auto& msg) {
      lcm->Publish(channels(channel), msg, frame.utime);
      status.CountOut();
    });
    ++frames;
    status.AddItemTime(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    status.Set("sim_time_s", static_cast<double>(frame.step) * options.step_s);
    status.Set("route_x_m", frame.T_world_base.x);
    status.Set("route_y_m", frame.T_world_base.y);
    status.Tick();
  }
  status.SetState(ok, fl::ShutdownRequested() ? "stopped" : "finished");
  status.Tick(true);
  FL_LOG(INFO) << "published " << frames << " steps (" << lcm->messages_published() << " messages)";
  return 0;
}

int RunLog(const fl::sim::SimOptions& options, const std::string& path,
           const fl::ChannelMap& channels) {
  fl::InstallShutdownHandlers();
  const auto start = std::chrono::steady_clock::now();
  auto last = start;
  const fl::sim::LogStats stats = fl::sim::WriteLog(
      options, path,
      [&](int64_t done, int64_t total) {
        // WriteLog deletes the partial output when this throws.
        if (fl::ShutdownRequested()) throw std::runtime_error("interrupted; no log written");
        const auto now = std::chrono::steady_clock::now();
        if (now - last < std::chrono::seconds(2) && done != total) return;
        last = now;
        const double elapsed = std::chrono::duration<double>(now - start).count();
        const double eta = done > 0 ? elapsed * static_cast<double>(total - done) / done : 0;
        FL_LOG(INFO) << "step " << done << "/" << total << " ("
                     << (100 * done / std::max<int64_t>(total, 1)) << "%), eta "
                     << static_cast<int>(eta + 0.5) << " s";
      },
      channels);
  const double wall =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  FL_LOG(INFO) << "wrote " << path << ": " << stats.frames << " steps, " << stats.events
               << " messages, " << stats.bytes / 1e6 << " MB of payload in " << wall << " s ("
               << options.duration_s / std::max(wall, 1e-9) << "x real time)";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  fl::Program program("fl-sim",
                      "Simulated differential-drive robot with a planar laser, a stereo camera and "
                      "wheel odometry, in a ray-cast textured world. Publishes live over LCM, or "
                      "writes an LCM log (--log) as fast as it can. Same options and seed give a "
                      "byte-identical log.");
  fl::CommandLine& cli = program.cli();
  fl::sim::SimOptions options;
  program.AddOptions(&options, "config/sim_paper.yaml; the flags below override it");
  std::string world, log_path, top_view, robot_path;
  int64_t seed = -1;
  double duration = -1.0, rate = 1.0, camera_rate_hz = 0.0;
  double snapshot_time = -1.0;
  std::string snapshot;
  cli.AddFlag("world", &world, "world: paper | corridor (default: the config's, else paper)");
  cli.AddFlag("seed", &seed,
              "random seed for the world layout and all noise (>= 0; -1 = the config's, else 1)");
  cli.AddFlag("duration", &duration,
              "simulated seconds (-1 = the config's, else 100 paper, 240 corridor)");
  cli.AddFlag("camera-rate-hz", &camera_rate_hz,
              "stereo camera rate [Hz], a divisor of the step rate (0 = the config's, else 10; "
              "2 = the MSIF paper's, for fl-stereo-vo with config/stereo_vo_2hz.yaml)");
  cli.AddFlag("robot", &robot_path,
              "robot description (docs/ROBOT.md) for the sensors' mounting; default: the "
              "simulated robot's, the same as config/robot/sim.yaml");
  cli.AddFlag("log", &log_path, "write an LCM log to this file instead of publishing live");
  cli.AddFlag("rate", &rate,
              "live pace: 1 = real time, 2 = twice as fast, 0 = as fast as possible");
  cli.AddFlag("top-view", &top_view,
              "write a PNG top view of the world, route and driven "
              "trajectory to this file and exit");
  cli.AddFlag("snapshot", &snapshot,
              "write the stereo pair at --snapshot-time as "
              "PREFIX_left.png / PREFIX_right.png and exit");
  cli.AddFlag("snapshot-time", &snapshot_time, "simulated time of --snapshot [s]");
  fl::LcmProcess process(
      &program, {},
      {{"LASER_TO_BASE", "bot_core.rigid_transform_t", "T_base_laser, first and every 1 s"},
       {"CAMERA_TO_BASE", "bot_core.rigid_transform_t", "T_base_camera, first and every 1 s"},
       {"STEREO_CALIBRATION", "fusionloc.stereo_calibration_t", "first and every 1 s"},
       {"GROUND_TRUTH", "bot_core.pose_t", "true T_world_base, 10 Hz"},
       {"ODOMETRY", "fusionloc.wheel_odometry_t", "10 Hz"},
       {"LASER", "bot_core.planar_lidar_t", "10 Hz, range 0 = no return"},
       {"STEREO", "bot_core.images_t", "LEFT+RIGHT gray 640x480, 10 Hz (camera.rate_hz)"},
       {"LASER_3D_TO_BASE", "bot_core.rigid_transform_t",
        "T_base_laser3d, first and every 1 s (laser3d.enabled)"},
       {"LASER_3D", "fusionloc.laser_scan_3d_t",
        "16-line laser, 10 Hz, before the stereo pair of its step (laser3d.enabled)"}});
  cli.AddEpilog(
      "\nExamples:\n"
      "  fl-sim --log paper.lcmlog                       # 100 s paper world, seed 1\n"
      "  fl-sim --world corridor --seed 3 --log c.lcmlog\n"
      "  fl-sim --camera-rate-hz 2 --log paper2.lcmlog   # the MSIF paper's 2 Hz camera\n"
      "  fl-sim --config config/sim_paper.yaml           # live, real time\n"
      "See docs/SIMULATOR.md.\n");
  cli.AddCheck([&]() -> std::string {  // the flags override the options file
    if (program.config_path().empty() && !world.empty()) {
      try {
        options = fl::sim::DefaultOptionsForWorld(world);
      } catch (const std::exception& e) {
        return e.what();
      }
    } else if (!world.empty() && world != options.world.name) {
      FL_LOG(WARN) << "--world " << world << " overrides world.name '" << options.world.name
                   << "' of " << program.config_path();
      options.world.name = world;
    }
    if (seed != -1) options.seed = seed;
    if (duration != -1.0) options.duration_s = duration;
    if (camera_rate_hz < 0.0 || !std::isfinite(camera_rate_hz)) {
      return "--camera-rate-hz " + fl::FormatDouble(camera_rate_hz) +
             " is not a rate; use a divisor of the step rate (10, 5, 2, ...) or 0 for the config's";
    }
    if (camera_rate_hz > 0.0) options.camera.rate_hz = camera_rate_hz;
    if (!robot_path.empty()) {
      fl::Status mounted = fl::Status::Ok();
      try {
        mounted = options.SetMounting(fl::LoadRobotDescription(robot_path));
      } catch (const fl::ConfigError& e) {
        return e.what();
      }
      if (!mounted.ok()) return robot_path + ": " + mounted.message();
    }
    if (rate < 0.0) {
      return "--rate " + fl::FormatDouble(rate) +
             " is negative; use 1 for real time or 0 for as fast as possible";
    }
    const fl::Status valid = options.Validate();
    return valid.ok() ? "" : "invalid options: " + valid.message();
  });
  if (!program.Parse(argc, argv)) return program.exit_code();
  return program.Run([&] {
    if (!top_view.empty()) {
      fl::sim::WriteTopView(options, top_view);
      FL_LOG(INFO) << "wrote " << top_view;
      return 0;
    }
    if (!snapshot.empty()) {
      fl::sim::WriteSnapshot(options, std::max(0.0, snapshot_time), snapshot);
      FL_LOG(INFO) << "wrote " << snapshot << "_left.png and _right.png";
      return 0;
    }
    if (!log_path.empty()) return RunLog(options, log_path, process.channels());
    return RunLive(options, process, rate);
  });
}
