// fl-replay: the RBPF-SLAM, the stereo VO and the fusion, through the same adapters as the
// live processes (RbpfSlamNode, StereoVoNode, FusionNode), in one process over a recorded
// log, as fast as the CPU allows.
//
// Input events are delivered in time-stamp order; what a stage publishes is delivered to the
// next stages before the next input event, stamped with the data time of the input that
// caused it, so that the stages see what separate processes would see over live LCM, without
// the timing of a live run. Recorded outputs of the stages that run (a demo's RBPF_*, VO_*,
// FUSED_*, their STATUS_*) are left out of the input and produced anew. The output log holds
// the inputs and every output; the same log and configuration give the same bytes.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

namespace fl::replay {

struct ReplayOptions {
  std::string in_path;     // LCM log to replay
  std::string out_path;    // output LCM log ("" = none)
  std::string config_dir;  // rbpf_slam.yaml, stereo_vo.yaml, fusion.yaml ("" = built-in defaults)
  std::string map_out;     // prefix of the fusion's saved 3D map ("" = not saved)
  // Stages to run, in pipeline order: any of rbpf, vo, fusion.
  std::vector<std::string> stages = {"rbpf", "vo", "fusion"};
  double reorder_window_s = 0.5;  // [s] of log time within which events are put in time order
};

struct StageReport {
  std::string program;               // fl-rbpf-slam, fl-stereo-vo, fl-fusion
  std::vector<std::string> missing;  // required inputs that never arrived
  std::string summary;               // the node's closing line
  std::string failure;               // what it could not do ("" = nothing); exit non-zero
};

struct ReplayReport {
  std::vector<StageReport> stages;
  std::map<std::string, int64_t> input_channels;  // events of the input log per channel
  std::map<std::string, int64_t> replaced;        // recorded outputs left out, per channel
  int64_t events_out = 0;                         // events written to out_path, if any
  double wall_s = 0.0;                            // [s] wall time of the replay
  double data_s = 0.0;                            // [s] span of data time replayed
};

// Runs the replay. Throws fl::ConfigError (bad options file), fl::UsageError (unknown stage)
// or std::runtime_error (unreadable log; a log with no event; no stage had its inputs), each
// naming the cause. `progress(fraction, data_s)` is called about twice a second.
ReplayReport RunReplay(const ReplayOptions& options,
                       const std::function<void(double fraction, double data_s)>& progress = {});

}  // namespace fl::replay
