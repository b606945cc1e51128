// fl-fusion: the fusion process: FusionNode (fusion_lcm.hpp) on the process edge
// (fusionloc/common/lcm_process.hpp). SIGUSR1 saves the 3D map now.
#include <csignal>
#include <memory>

#include "fusionloc/fusion/fusion_lcm.hpp"

namespace {
void OnSigusr1(int) { fl::fusion::FusionNode::RequestMapSave(); }
}  // namespace

int main(int argc, char** argv) {
  using fl::fusion::FusionNode;
  fl::Program program(
      FusionNode::kProgram,
      "Fuses the laser RBPF-SLAM, the stereo VO and wheel odometry in a Ceres factor graph "
      "(SE(2) poses at the laser rate, incremental window updates, full solve on loop closure); "
      "saves the 3D map (PCD + PNG top view) on exit and on SIGUSR1.");
  fl::fusion::FusionProcessConfig config;
  program.AddOptions(&config, "config/fusion.yaml");
  fl::fusion::FusionNodeOptions node_options;
  node_options.AddFlags(&program.cli());
  fl::LcmProcess process(&program, FusionNode::Inputs(), FusionNode::Outputs());
  program.cli().AddEpilog(
      "\nExample: fl-fusion --config config/fusion.yaml --lcm-url "
      "log:rbpf_and_vo.lcmlog,fused.lcmlog\n"
      "         kill -USR1 <pid>   # save the 3D map now\n"
      "To fuse a sensor log offline (RBPF-SLAM, VO and fusion in one pass), use fl-replay.\n");
  if (!program.Parse(argc, argv)) return program.exit_code();
  std::signal(SIGUSR1, OnSigusr1);
  return program.Run([&] {
    return process.Run([&](fl::LcmInterface* lcm, const fl::ChannelMap& channels) {
      return std::make_unique<FusionNode>(config, node_options, lcm, channels);
    });
  });
}
