#include "fusionloc/sim_pipeline/sim_pipeline.hpp"

#include <sys/wait.h>

#include <chrono>
#include <stdexcept>

#include "fusionloc/common/shutdown.hpp"

namespace fl::bench {

double NowSeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

int64_t WallUs() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

SimPipeline::SimPipeline(procman::DeputyOptions options, std::vector<PipelineCommand> commands) {
  if (commands.empty()) throw std::invalid_argument("SimPipeline: no commands");
  orders_.host = options.name;
  deputy_ = std::make_unique<procman::Deputy>(std::move(options), nullptr);
  for (size_t i = 0; i < commands.size(); ++i) {
    procman::CommandOrder c;
    c.spec.sheriff_id = static_cast<int32_t>(i + 1);
    c.spec.name = commands[i].name;
    c.spec.exec = commands[i].exec;
    c.spec.auto_respawn = commands[i].auto_respawn;
    c.spec.stop_signal = 15;
    c.spec.stop_time_allowed_s = 15;
    c.desired_runid = i + 1 < commands.size() ? 1 : 0;  // the simulator once the others listen
    orders_.cmds.push_back(c);
  }
}

SimPipeline::~SimPipeline() = default;

void SimPipeline::Start(const std::function<void(double)>& spin, double settle_s) {
  orders_.utime_us = WallUs();
  deputy_->HandleOrders(orders_, WallUs());
  spin(settle_s);
  orders_.cmds.back().desired_runid = 1;
  orders_.utime_us = WallUs();
  deputy_->HandleOrders(orders_, WallUs());
}

void SimPipeline::Poll() {
  deputy_->Poll();
  for (const auto& c : deputy_->Commands()) {
    const auto it = state_.find(c.spec.name);
    const auto before = it == state_.end() ? procman::CommandState::kStopped : it->second;
    if (before == procman::CommandState::kRunning && c.state != procman::CommandState::kRunning &&
        c.state != procman::CommandState::kStopping && c.exited) {
      const int st = c.exit_status;
      const bool clean = WIFEXITED(st) && WEXITSTATUS(st) == 0;
      if (!clean && !stopped_ && !(expected_exit_ && expected_exit_(c))) {
        ++crashes_;
        crash_note_ << c.spec.name << " "
                    << (WIFSIGNALED(st) ? "killed by signal " + std::to_string(WTERMSIG(st))
                                        : "exit " + std::to_string(WEXITSTATUS(st)))
                    << " (see " << c.log_path << "); ";
      }
    }
    state_[c.spec.name] = c.state;
  }
}

void SimPipeline::Spin(LcmInterface* lcm, double seconds) {
  const double end = NowSeconds() + seconds;
  while (NowSeconds() < end && !ShutdownRequested()) {
    lcm->HandleSubscriptions(2);
    Poll();
  }
}

bool SimPipeline::SimExited() const {
  for (const auto& c : deputy_->Commands()) {
    if (c.spec.name == orders_.cmds.back().spec.name) return c.exited;
  }
  return false;
}

procman::HostStatus SimPipeline::Measure() { return deputy_->MeasureStatus(WallUs()); }

void SimPipeline::StopAll() {
  stopped_ = true;  // the stop signals' exits are not crashes
  deputy_->StopAll();
}

std::vector<procman::CommandStatus> SimPipeline::Commands() const { return deputy_->Commands(); }

std::map<std::string, int64_t> SimSchedule(const sim::SimOptions& o) {
  const int64_t frames = o.steps() + 1;
  auto count = [&](int64_t period) { return period <= 0 ? 0 : (frames - 1) / period + 1; };
  std::map<std::string, int64_t> n;
  n["GROUND_TRUTH"] = frames;
  // Calibration and mountings together, every calibration period (simulator.cpp).
  const int64_t every = count(o.PeriodSteps(1.0 / o.calibration_period_s));
  n["STEREO_CALIBRATION"] = o.camera.enabled ? every : 0;
  n["CAMERA_TO_BASE"] = o.camera.enabled ? every : 0;
  n["LASER_TO_BASE"] = o.laser.enabled ? every : 0;
  n["ODOMETRY"] = count(o.PeriodSteps(o.odometry.rate_hz));
  n["LASER"] = o.laser.enabled ? count(o.PeriodSteps(o.laser.rate_hz)) : 0;
  n["STEREO"] = o.camera.enabled ? count(o.PeriodSteps(o.camera.rate_hz)) : 0;
  n["LASER_3D_TO_BASE"] = o.laser3d.enabled ? every : 0;
  n["LASER_3D"] = o.laser3d.enabled ? count(o.PeriodSteps(o.laser3d.rate_hz)) : 0;
  return n;
}

}  // namespace fl::bench
