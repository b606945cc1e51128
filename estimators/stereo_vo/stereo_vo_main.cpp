// fl-stereo-vo: the stereo visual odometry process. A thin LCM adapter around fl::vo::StereoVo.
//   in:  STEREO (bot_core.images_t LEFT/RIGHT, GRAY/RGB/BGR), STEREO_CALIBRATION
//   out: VO_POSE (bot_core.pose_t, T_world_base), VO_FACTORS (relative_pose_factor_t between
//        keyframes, base frame, SOURCE_VISION), VO_POINTS (point_cloud_t per keyframe, frame
//        "camera"), STATUS_FL_STEREO_VO (status_t).
#include <cmath>
#include <iostream>
#include <memory>
#include <opencv2/core/utility.hpp>

#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/command_line.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/common/status_reporter.hpp"
#include "fusionloc/common/yaml_options.hpp"
#include "fusionloc/status_t.hpp"
#include "fusionloc/stereo_vo/stereo_vo_lcm.hpp"

namespace {

bool SameCalibration(const fl::vo::StereoCalibration& a, const fl::vo::StereoCalibration& b) {
  auto close = [](double x, double y) { return std::abs(x - y) <= 1e-9 * (1 + std::abs(x)); };
  return a.width == b.width && a.height == b.height && close(a.fx, b.fx) && close(a.fy, b.fy) &&
         close(a.cx, b.cx) && close(a.cy, b.cy) && close(a.baseline, b.baseline) &&
         a.rectified == b.rectified && a.T_base_camera.isApprox(b.T_base_camera, 1e-9);
}

}  // namespace

int main(int argc, char** argv) {
  const std::string process = "fl-stereo-vo";
  fl::SetLogProcessName(process);
  fl::CommandLine cli(process,
                      "Stereo visual odometry: ORB features, quadrilateral matching, RANSAC + "
                      "SVD, Ceres refinement; publishes the VO pose, keyframe factors with "
                      "information matrices, and keyframe 3D points.");
  std::string url = fl::kDefaultLcmUrl;
  std::string config;
  std::string in_stereo = fl::channels::kStereo;
  std::string in_calib = fl::channels::kStereoCalibration;
  std::string out_pose = fl::channels::kVoPose;
  std::string out_factors = fl::channels::kVoFactors;
  std::string out_points = fl::channels::kVoPoints;
  std::string log_level = "info";
  bool print_config = false;
  int threads = 1;
  cli.AddFlag("lcm-url", &url,
              "LCM URL: udpm://... live, or log:IN.lcmlog,OUT.lcmlog to replay a log at full "
              "speed and write the outputs to OUT");
  cli.AddFlag("config", &config, "options YAML (e.g. config/stereo_vo.yaml); empty = defaults");
  cli.AddFlag("print-config", &print_config, "print the effective options as YAML and exit");
  cli.AddFlag("stereo-channel", &in_stereo, "input stereo images (bot_core.images_t)");
  cli.AddFlag("calibration-channel", &in_calib, "input calibration (stereo_calibration_t)");
  cli.AddFlag("pose-channel", &out_pose, "output pose T_world_base (bot_core.pose_t)");
  cli.AddFlag("factors-channel", &out_factors, "output keyframe factors");
  cli.AddFlag("points-channel", &out_points, "output keyframe points (point_cloud_t)");
  cli.AddFlag("threads", &threads, "OpenCV worker threads (1 keeps to one core)");
  cli.AddFlag("log-level", &log_level, "debug, info, warn or error");
  cli.AddEpilog(
      "\nExamples:\n"
      "  fl-stereo-vo --config config/stereo_vo.yaml\n"
      "  fl-stereo-vo --lcm-url log:kitti.lcmlog,vo.lcmlog   # replay, outputs to vo.lcmlog\n"
      "World frame: the base frame at the first tracked frame. A frame that cannot be tracked "
      "is reported in the status (no pose, no factor); tracking resumes at the next frame.\n");
  if (!cli.Parse(argc, argv)) return cli.exit_code();
  fl::LogLevel level;
  if (!fl::ParseLogLevel(log_level, &level)) {
    std::cerr << process << ": unknown --log-level '" << log_level
              << "' (use debug, info, warn or error)\n";
    return 2;
  }
  fl::SetLogLevel(level);

  fl::vo::StereoVoOptions options;
  try {
    if (!config.empty()) options = fl::LoadYamlFile<fl::vo::StereoVoOptions>(config);
    if (auto s = options.Validate(); !s.ok()) throw fl::ConfigError(s.message());
  } catch (const std::exception& e) {
    std::cerr << process << ": " << e.what() << "\n";
    return 2;
  }
  if (print_config) {
    std::cout << fl::SaveYamlString(options);
    return 0;
  }
  cv::setNumThreads(threads);

  std::unique_ptr<fl::LcmInterface> lcm;
  try {
    lcm = fl::MakeLcm(url);
  } catch (const std::exception& e) {
    std::cerr << process << ": " << e.what() << "\n";
    return 1;
  }
  fl::InstallShutdownHandlers();
  fl::StatusReporter status(lcm.get(), process);
  const int kOk = fusionloc::status_t::LEVEL_OK;
  const int kWarn = fusionloc::status_t::LEVEL_WARN;
  const int kError = fusionloc::status_t::LEVEL_ERROR;
  const int kStarting = fusionloc::status_t::LEVEL_STARTING;
  status.SetState(kStarting, "waiting for " + in_calib);

  std::unique_ptr<fl::vo::StereoVo> vo;
  fl::vo::StereoCalibration active_calibration;
  int64_t frames = 0, tracked = 0, not_tracked = 0, keyframes = 0;

  lcm->Subscribe<fusionloc::stereo_calibration_t>(
      in_calib, [&](const fusionloc::stereo_calibration_t& msg, const std::string&) {
        status.CountIn();
        const fl::vo::StereoCalibration calib = fl::vo::CalibrationFromLcm(msg);
        if (vo && SameCalibration(calib, active_calibration)) return;  // periodic repeat
        if (auto s = calib.Validate(); !s.ok()) {
          status.CountDropped(in_calib + ": " + s.message());
          status.SetState(kError, in_calib + ": " + s.message());
          FL_LOG(ERROR) << in_calib << ": " << s.message();
          return;  // keep the previous valid calibration, if any
        }
        if (vo) FL_LOG(WARN) << "calibration changed: restarting VO (new segment)";
        vo = std::make_unique<fl::vo::StereoVo>(options, calib);
        active_calibration = calib;
        status.SetState(kStarting, "calibration received; waiting for " + in_stereo);
        FL_LOG(INFO) << "calibration " << calib.width << "x" << calib.height << " fx " << calib.fx
                     << " baseline " << calib.baseline << " m";
      });

  lcm->Subscribe<bot_core::images_t>(
      in_stereo, [&](const bot_core::images_t& msg, const std::string&) {
        status.CountIn();
        if (!vo) {
          status.CountDropped("stereo frame before a valid " + in_calib +
                              " (waiting for the calibration)");
          return;
        }
        cv::Mat left, right;
        if (auto s = fl::vo::StereoImagesToGray(msg, &left, &right); !s.ok()) {
          status.CountDropped(in_stereo + ": " + s.message());
          return;
        }
        const fl::vo::StereoVoResult r = vo->AddStereoFrame(msg.utime, left, right);
        ++frames;
        status.AddItemTime(r.stats.ms_total);
        const fl::Utime stamp = lcm->last_message_utime();
        switch (r.state) {
          case fl::vo::TrackingState::kRejected:
            status.CountDropped(r.message);
            return;
          case fl::vo::TrackingState::kNotTracked:
            ++not_tracked;
            status.SetState(kWarn, r.message);
            FL_LOG(WARN) << "frame " << msg.utime << ": " << r.message;
            break;
          case fl::vo::TrackingState::kInitialized:
          case fl::vo::TrackingState::kTracked:
            ++tracked;
            status.SetState(kOk, r.message);
            if (r.new_segment) FL_LOG(WARN) << r.message;
            lcm->Publish(out_pose, fl::vo::PoseToLcm(r.utime, r.T_world_base), stamp);
            status.CountOut();
            if (r.factor) {
              lcm->Publish(out_factors, fl::vo::FactorToLcm(*r.factor), stamp);
              status.CountOut();
            }
            if (r.is_keyframe) {
              ++keyframes;
              lcm->Publish(out_points, fl::vo::KeyframePointsToLcm(r), stamp);
              status.CountOut();
            }
            break;
        }
        status.Set("frames", static_cast<double>(frames));
        status.Set("tracked", static_cast<double>(tracked));
        status.Set("not_tracked", static_cast<double>(not_tracked));
        status.Set("keyframes", static_cast<double>(keyframes));
        status.Set("inliers", r.stats.inliers);
        status.Set("features_left", r.stats.features_left);
        status.Set("segment", r.segment);
        // Online rectification check (docs/STEREO_VO.md): a large or drifting value means the
        // stereo calibration is off.
        status.Set("disparity_offset_px", r.stats.disparity_offset_px);
        status.Set("disparity_offset_sd_px", r.stats.disparity_offset_sd_px);
      });

  FL_LOG(INFO) << "listening on " << in_stereo << " and " << in_calib << " (" << lcm->url() << ")";
  while (!fl::ShutdownRequested()) {
    if (lcm->HandleSubscriptions(100) < 0) break;
    status.Tick();
  }
  status.Tick(true);
  FL_LOG(INFO) << "frames " << frames << ", tracked " << tracked << ", not tracked " << not_tracked
               << ", keyframes " << keyframes << ", dropped " << status.dropped();
  return 0;
}
