// fl-stereo-driver: stereo pairs from a side-by-side UVC camera (V4L2) or a folder of image
// pairs, rectified, on STEREO with the calibration on STEREO_CALIBRATION (StereoDriverNode).
#include "fusionloc/common/program.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/stereo/stereo_driver_lcm.hpp"

int main(int argc, char** argv) {
  using fl::stereo::StereoDriverNode;
  fl::Program program(StereoDriverNode::kProgram,
                      "Stereo camera driver: a UVC camera with both views side by side (V4L2) "
                      "split into left and right, or a folder of image pairs (KITTI raw, KITTI "
                      "odometry, left/ + right/) played at a requested rate; rectified with the "
                      "calibration file's maps; publishes the pair and the calibration.");
  fl::stereo::StereoDriverOptions options;
  program.AddOptions(&options, "config/stereo_driver.yaml");
  std::string folder, device, calibration, log, capture;
  double rate_hz = 0.0;
  program.cli().AddFlag("folder", &folder, "play the image pairs of this folder (no camera)");
  program.cli().AddFlag("rate", &rate_hz, "[Hz] folder playback rate, overrides folder.rate_hz");
  program.cli().AddFlag("device", &device, "V4L2 camera, overrides camera.device");
  program.cli().AddFlag("calibration", &calibration,
                        "calibration file (fl-stereo-calibrate), overrides calibration");
  program.cli().AddFlag("log", &log,
                        "folder: write the messages to this LCM log at full speed instead of "
                        "publishing them");
  program.cli().AddFlag("capture", &capture,
                        "camera: save a raw pair every capture_period_s in this folder "
                        "(left/, right/) for fl-stereo-calibrate; overrides capture_folder");
  fl::LcmProcess process(&program, {}, StereoDriverNode::Outputs());
  program.cli().AddEpilog(
      "\nExamples:\n"
      "  fl-stereo-driver --calibration rig.yaml                       # /dev/video0\n"
      "  fl-stereo-driver --capture pairs/      # chessboard pairs for fl-stereo-calibrate\n"
      "  fl-stereo-driver --folder ../shared/data/stereo/kitti_raw_2011_09_26_drive_0001\n"
      "  fl-stereo-driver --folder pairs/ --calibration rig.yaml --rate 5 --log pairs.lcmlog\n"
      "Folder time stamps: the start time plus frame / rate. Calibrate: fl-stereo-calibrate; "
      "devices and permissions: docs/HARDWARE.md.\n");
  if (!program.Parse(argc, argv)) return program.exit_code();
  return program.Run([&] {
    if (!device.empty()) options.camera.device = device;
    if (!calibration.empty()) options.calibration = calibration;
    if (rate_hz != 0.0) options.folder.rate_hz = rate_hz;
    if (!capture.empty()) options.capture_folder = capture;
    if (auto s = options.Validate(); !s.ok()) throw fl::UsageError(s.message());
    if (!log.empty()) {
      if (folder.empty()) throw fl::UsageError("--log needs --folder");
      options.realtime = false;
      fl::InstallShutdownHandlers();
      fl::stereo::LogWriterLcm lcm(log);
      StereoDriverNode node(options, folder, &lcm, process.channels());
      const int rc = node.Run();
      lcm.Close();
      return rc;
    }
    auto lcm = process.Open();
    StereoDriverNode node(options, folder, lcm.get(), process.channels());
    return node.Run();
  });
}
