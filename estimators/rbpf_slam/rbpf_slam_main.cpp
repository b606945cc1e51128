// fl-rbpf-slam: the laser RBPF-SLAM process: RbpfSlamNode (rbpf_slam_lcm.hpp) on the process
// edge (fusionloc/common/lcm_process.hpp).
#include <memory>

#include "fusionloc/rbpf_slam/rbpf_slam_lcm.hpp"

int main(int argc, char** argv) {
  using fl::rbpf::RbpfSlamNode;
  fl::Program program(RbpfSlamNode::kProgram,
                      "Laser RBPF-SLAM (GMapping-style particle filter with a scan-matching "
                      "proposal and likelihood-field weights, refined by ICP keyframe factors and "
                      "a Ceres pose graph with loop closures).");
  fl::rbpf::RbpfSlamOptions options;
  program.AddOptions(&options, "config/rbpf_slam.yaml");
  fl::rbpf::RbpfSlamNodeOptions node_options;
  node_options.AddFlags(&program.cli());
  fl::LcmProcess process(&program, RbpfSlamNode::Inputs(), RbpfSlamNode::Outputs());
  program.cli().AddEpilog(
      "\nExamples:\n"
      "  fl-rbpf-slam --config config/rbpf_slam.yaml\n"
      "  fl-rbpf-slam --lcm-url log:carmen.lcmlog,rbpf.lcmlog   # replay, outputs to rbpf.lcmlog\n"
      "Design: docs/RBPF_SLAM.md.\n");
  if (!program.Parse(argc, argv)) return program.exit_code();
  return program.Run([&] {
    return process.Run([&](fl::LcmInterface* lcm, const fl::ChannelMap& channels) {
      return std::make_unique<RbpfSlamNode>(options, node_options, lcm, channels);
    });
  });
}
