// fl-stereo-vo: the stereo visual odometry process: StereoVoNode (stereo_vo_lcm.hpp) on the
// process edge (fusionloc/common/lcm_process.hpp).
#include <memory>
#include <opencv2/core/utility.hpp>

#include "fusionloc/stereo_vo/stereo_vo_lcm.hpp"

int main(int argc, char** argv) {
  using fl::vo::StereoVoNode;
  fl::Program program(StereoVoNode::kProgram,
                      "Stereo visual odometry: ORB features, quadrilateral matching, RANSAC + "
                      "SVD, Ceres refinement; publishes the VO pose, keyframe factors with "
                      "information matrices, and keyframe 3D points.");
  fl::vo::StereoVoOptions options;
  program.AddOptions(&options, "config/stereo_vo.yaml");
  int threads = 1;
  program.cli().AddFlag("threads", &threads, "OpenCV worker threads (1 keeps to one core)");
  bool laser_aided = false;
  program.cli().AddFlag("laser-aided", &laser_aided,
                        "laser-aided mode (sets laser_depth.enabled): features take their depth "
                        "from the LASER_3D scans (docs/STEREO_VO.md)");
  fl::LcmProcess process(&program, StereoVoNode::Inputs(), StereoVoNode::Outputs());
  program.cli().AddEpilog(
      "\nExamples:\n"
      "  fl-stereo-vo --config config/stereo_vo.yaml\n"
      "  fl-stereo-vo --lcm-url log:kitti.lcmlog,vo.lcmlog   # replay, outputs to vo.lcmlog\n"
      "  fl-stereo-vo --channel STEREO=CAM_FRONT            # another input channel\n"
      "  fl-stereo-vo --laser-aided --lcm-url log:k04.lcmlog,vo.lcmlog  # with LASER_3D\n"
      "World frame: the base frame at the first tracked frame. A frame that cannot be tracked "
      "is reported in the status (no pose, no factor); tracking resumes at the next frame.\n");
  program.cli().AddCheck([&]() -> std::string {  // the flag overrides the options file
    if (!laser_aided) return "";
    options.laser_depth.enabled = true;
    const fl::Status valid = options.Validate();
    return valid.ok() ? "" : "--laser-aided: " + valid.message();
  });
  if (!program.Parse(argc, argv)) return program.exit_code();
  cv::setNumThreads(threads);
  return program.Run([&] {
    return process.Run([&](fl::LcmInterface* lcm, const fl::ChannelMap& channels) {
      return std::make_unique<StereoVoNode>(options, lcm, channels);
    });
  });
}
