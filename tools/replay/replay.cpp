#include "replay.hpp"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <filesystem>
#include <memory>
#include <set>
#include <stdexcept>

#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/lcm_process.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/common/program.hpp"
#include "fusionloc/common/yaml_options.hpp"
#include "fusionloc/fusion/fusion_lcm.hpp"
#include "fusionloc/rbpf_slam/rbpf_slam_lcm.hpp"
#include "fusionloc/stereo_vo/stereo_vo_lcm.hpp"

namespace fl::replay {
namespace {

// Options of one stage: DIR/NAME if a config folder is given, else the built-in defaults.
template <class Options>
Options LoadStageOptions(const std::string& dir, const std::string& file) {
  if (dir.empty()) {
    Options o;
    if constexpr (internal::HasValidate<Options>::value) {
      const Status s = o.Validate();
      if (!s.ok()) throw ConfigError("built-in " + file + " defaults are invalid: " + s.message());
    }
    return o;
  }
  return LoadYamlFile<Options>((std::filesystem::path(dir) / file).string());
}

}  // namespace

ReplayReport RunReplay(const ReplayOptions& options,
                       const std::function<void(double, double)>& progress) {
  const bool want_rbpf =
      std::find(options.stages.begin(), options.stages.end(), "rbpf") != options.stages.end();
  const bool want_vo =
      std::find(options.stages.begin(), options.stages.end(), "vo") != options.stages.end();
  const bool want_fusion =
      std::find(options.stages.begin(), options.stages.end(), "fusion") != options.stages.end();
  for (const auto& s : options.stages) {
    if (s != "rbpf" && s != "vo" && s != "fusion") {
      throw UsageError("unknown stage '" + s + "' in --stages; use rbpf, vo and/or fusion");
    }
  }
  if (options.stages.empty()) throw UsageError("--stages names no stage; use rbpf,vo,fusion");

  // Load every options file before reading anything, so that a bad config costs no time.
  const auto rbpf_options =
      LoadStageOptions<rbpf::RbpfSlamOptions>(options.config_dir, "rbpf_slam.yaml");
  const auto vo_options =
      LoadStageOptions<vo::StereoVoOptions>(options.config_dir, "stereo_vo.yaml");
  const auto fusion_config =
      LoadStageOptions<fusion::FusionProcessConfig>(options.config_dir, "fusion.yaml");

  // The recorded outputs of the stages that run are produced anew, so leave them out.
  LogReplayOptions lo;
  lo.in_path = options.in_path;
  lo.out_path = options.out_path;
  lo.copy_inputs = true;
  lo.reorder_window_s = options.reorder_window_s;
  std::vector<std::string> produced;
  auto add_outputs = [&](const std::vector<ChannelSpec>& outs, const char* program) {
    for (const auto& c : outs) produced.push_back(c.name);
    produced.push_back(StatusChannel(program));
  };
  if (want_rbpf) add_outputs(rbpf::RbpfSlamNode::Outputs(), rbpf::RbpfSlamNode::kProgram);
  if (want_vo) add_outputs(vo::StereoVoNode::Outputs(), vo::StereoVoNode::kProgram);
  if (want_fusion) add_outputs(fusion::FusionNode::Outputs(), fusion::FusionNode::kProgram);
  lo.drop_channels.insert(produced.begin(), produced.end());
  std::unique_ptr<LcmInterface> lcm = MakeLogReplay(lo);

  ChannelMap channels;
  std::vector<std::unique_ptr<LcmNode>> nodes;
  if (want_rbpf) {
    nodes.push_back(std::make_unique<rbpf::RbpfSlamNode>(rbpf_options, rbpf::RbpfSlamNodeOptions{},
                                                         lcm.get(), channels));
  }
  if (want_vo) {
    nodes.push_back(std::make_unique<vo::StereoVoNode>(vo_options, lcm.get(), channels));
  }
  if (want_fusion) {
    fusion::FusionNodeOptions fo;
    fo.map_out = options.map_out;
    nodes.push_back(std::make_unique<fusion::FusionNode>(fusion_config, fo, lcm.get(), channels));
  }
  InputWatch watch(lcm.get(), 0.0);
  std::vector<LcmNode*> raw;
  for (auto& n : nodes) {
    raw.push_back(n.get());
    for (const auto& ch : n->RequiredInputs()) watch.Watch(ch, n.get());
  }
  auto data_span_s = [&lcm] {
    Utime first = 0, last = 0;
    return lcm->LogTimeSpan(&first, &last) ? UtimeToSeconds(last - first) : 0.0;
  };
  const auto t0 = std::chrono::steady_clock::now();
  SpinNodes(lcm.get(), raw, &watch, [&](double fraction) {
    if (progress) progress(fraction, data_span_s());
  });
  ReplayReport report;
  report.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  report.data_s = data_span_s();
  report.input_channels = lcm->LogChannelCounts();
  for (const auto& kv : report.input_channels) {
    if (lo.drop_channels.count(kv.first)) report.replaced[kv.first] = kv.second;
  }
  if (report.input_channels.empty()) {
    const std::string problems = lcm->LogProblems();
    throw std::runtime_error("'" + options.in_path + "' holds no LCM event" +
                             (problems.empty() ? " (the file is empty)" : ": " + problems) +
                             "; is it an LCM log (written by lcm-logger, fl-sim --log, "
                             "fl-carmen2lcm, fl-kitti2lcm)?");
  }
  bool any_stage_ran = false;
  for (auto& n : nodes) {
    StageReport s;
    s.program = n->status().process();
    for (const auto& ch : n->RequiredInputs()) {
      if (watch.received(ch) == 0) s.missing.push_back(ch);
    }
    if (s.missing.empty()) any_stage_ran = true;
    s.summary = n->Summary();
    s.failure = n->Failure();
    report.stages.push_back(std::move(s));
  }
  // What went to out_path: every published message and the delivered inputs.
  report.events_out = lcm->messages_published();
  for (const auto& kv : report.input_channels) {
    if (!lo.drop_channels.count(kv.first)) report.events_out += kv.second;
  }
  nodes.clear();
  lcm.reset();  // closes (and renames into place) the output log
  if (!any_stage_ran) {
    throw std::runtime_error("no stage had its inputs in '" + options.in_path +
                             "' (the RBPF-SLAM needs LASER and "
                             "ODOMETRY, the VO STEREO and STEREO_CALIBRATION); it holds " +
                             DescribeLogChannels(report.input_channels));
  }
  return report;
}

}  // namespace fl::replay
