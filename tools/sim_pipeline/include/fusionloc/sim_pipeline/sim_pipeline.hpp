// The simulated robot's processes under a procman deputy that runs in the benchmark's own
// process (fl::procman::Deputy): what `bench system`, `bench faults` and `bench soak` share.
//
// The commands are given in start order; the LAST one is the simulator. Start() starts the
// others, lets them subscribe while the caller's loop spins, then starts the simulator; the
// run ends when the simulator exits (SimExited()). Poll() reaps exits, respawns and counts
// crashes: an exit seen while a command was running that is neither a clean exit (status 0)
// nor one the caller expected (set_expected_exit, e.g. its own kill -9).
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/procman/deputy.hpp"
#include "fusionloc/sim/sim_options.hpp"

namespace fl::bench {

// [s] steady clock, and [us since the epoch] wall clock (procman orders).
double NowSeconds();
int64_t WallUs();

struct PipelineCommand {
  std::string name;  // procman command name; its output goes to LOG_DIR/<name>.log
  std::string exec;  // command line, ${VAR}s from DeputyOptions::vars
  bool auto_respawn = false;
};

class SimPipeline {
 public:
  // Throws std::invalid_argument (no commands, bad deputy options).
  SimPipeline(procman::DeputyOptions options, std::vector<PipelineCommand> commands);
  ~SimPipeline();  // stops every command

  // Starts all but the last command, calls spin(settle_s) (the caller's loop, which must call
  // Poll()), then starts the simulator.
  void Start(const std::function<void(double)>& spin, double settle_s = 2.5);
  // Deputy poll and crash watch; call every few ms.
  void Poll();
  // Handles `lcm`'s messages and polls for `seconds` (or until a shutdown is requested): the
  // loop of a benchmark with one bus.
  void Spin(LcmInterface* lcm, double seconds);
  bool SimExited() const;
  // CPU and memory of every command now (procman's /proc figures).
  procman::HostStatus Measure();
  // Stops every command; exits from then on are not crashes.
  void StopAll();
  std::vector<procman::CommandStatus> Commands() const;
  // An exit for which this returns true is not a crash (default: none).
  void set_expected_exit(std::function<bool(const procman::CommandStatus&)> expected) {
    expected_exit_ = std::move(expected);
  }
  int crashes() const { return crashes_; }
  // "fusion killed by signal 11 (see DIR/fusion.log); ..." for every crash.
  std::string crash_note() const { return crash_note_.str(); }

 private:
  std::unique_ptr<procman::Deputy> deputy_;
  procman::Orders orders_;
  std::map<std::string, procman::CommandState> state_;
  std::function<bool(const procman::CommandStatus&)> expected_exit_;
  bool stopped_ = false;
  int crashes_ = 0;
  std::ostringstream crash_note_;
};

// Messages of each channel the simulator publishes for `o` (its deterministic schedule):
// GROUND_TRUTH, STEREO_CALIBRATION, CAMERA_TO_BASE, LASER_TO_BASE, ODOMETRY, LASER, STEREO,
// LASER_3D_TO_BASE and LASER_3D (0 when off).
std::map<std::string, int64_t> SimSchedule(const sim::SimOptions& o);

}  // namespace fl::bench
