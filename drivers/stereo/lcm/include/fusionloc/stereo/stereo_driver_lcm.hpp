// fl-stereo-driver's LCM side (target fl_stereo_lcm; the core library fl_stereo has no LCM).
//   out: STEREO (bot_core.images_t, LEFT + RIGHT rectified, one time stamp),
//        STEREO_CALIBRATION (fusionloc.stereo_calibration_t, intrinsics and baseline of the
//        rectified pair; first and every calibration_period_s), STATUS_FL_STEREO_DRIVER.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "bot_core/images_t.hpp"
#include "fusionloc/common/lcm_process.hpp"
#include "fusionloc/stereo/rig_calibration.hpp"
#include "fusionloc/stereo/sources.hpp"
#include "fusionloc/stereo_calibration_t.hpp"

namespace fl::stereo {

struct StereoDriverOptions {
  // Calibration file (fl-stereo-calibrate's output). "" with a KITTI folder: the folder's
  // own calibration (rectified pairs).
  std::string calibration;
  double calibration_period_s = 1.0;  // [s] STEREO_CALIBRATION repeat period (data time)
  bool gray = true;                   // publish 8-bit GRAY (false: BGR for a color source)
  bool realtime = true;               // folder: play at rate_hz in wall time (false: at once)
  // Camera: also save raw (unrectified) pairs here as left/NNNNNN.png + right/NNNNNN.png, for
  // fl-stereo-calibrate; without a calibration the driver then only captures. "" = off.
  std::string capture_folder;
  double capture_period_s = 1.0;  // [s] at most one captured pair per period
  FolderSourceOptions folder;
  CameraSourceOptions camera;

  template <class Archive>
  void Serialize(Archive* a) {
    a->Visit("calibration", &calibration);
    a->Visit("calibration_period_s", &calibration_period_s);
    a->Visit("gray", &gray);
    a->Visit("realtime", &realtime);
    a->Visit("capture_folder", &capture_folder);
    a->Visit("capture_period_s", &capture_period_s);
    a->Visit("folder", &folder);
    a->Visit("camera", &camera);
  }
  fl::Status Validate() const;
};

// The calibration for a folder: the file if given, else a KITTI folder's own (rectified).
// Throws fl::ConfigError / std::runtime_error naming the file and the fix.
RigCalibration CalibrationForFolder(const std::string& calibration_path, const std::string& folder);

fusionloc::stereo_calibration_t CalibrationToLcm(const RectifiedCamera& c, Utime utime);
// LEFT and RIGHT in one message; 8-bit gray (GRAY) or 3-channel (BGR) images.
bot_core::images_t PairToLcm(const cv::Mat& left, const cv::Mat& right, Utime utime);

class StereoDriverNode {
 public:
  static constexpr const char* kProgram = "fl-stereo-driver";
  static std::vector<ChannelSpec> Outputs();

  // Folder playback (folder != "") or the V4L2 camera. Throws (exit 1) for a folder without
  // pairs, a device that is not a camera, a calibration that does not match the images.
  StereoDriverNode(const StereoDriverOptions& options, const std::string& folder, LcmInterface* lcm,
                   const ChannelMap& channels);
  // A camera from another grabber (tests); `calibration` nullptr: capture only.
  StereoDriverNode(const StereoDriverOptions& options, std::unique_ptr<FrameGrabber> grabber,
                   const RigCalibration* calibration, LcmInterface* lcm,
                   const ChannelMap& channels);
  ~StereoDriverNode();

  // Publishes the next pair (false: a folder's end, or no camera frame this time).
  bool Step();
  // Steps until the folder ends or shutdown; returns the exit code.
  int Run();

  StatusReporter& status() { return status_; }
  int64_t published() const { return published_; }
  const Rectifier* rectifier() const { return rectifier_.get(); }
  int64_t captured() const { return captured_; }
  const FolderSource* folder_source() const { return folder_.get(); }
  const SideBySideCamera* camera_source() const { return camera_.get(); }

 private:
  void Publish(StereoFrame* frame);
  void Capture(const StereoFrame& frame);
  void UpdateStatus();

  StereoDriverOptions options_;
  LcmInterface* lcm_;
  std::string ch_stereo_, ch_calibration_;
  StatusReporter status_;
  std::unique_ptr<Rectifier> rectifier_;
  std::unique_ptr<FolderSource> folder_;
  std::unique_ptr<SideBySideCamera> camera_;
  Utime last_calibration_ = 0;
  bool calibration_sent_ = false;
  int64_t published_ = 0;
  Utime start_monotonic_ = 0;
  Utime last_capture_ = 0;
  int64_t captured_ = 0;
};

}  // namespace fl::stereo

namespace fl::stereo {

// An LcmInterface that writes what is published to an LCM log (stamped with the utime given
// to Publish) and receives nothing: fl-stereo-driver --log plays a folder into a log at full
// speed.
class LogWriterLcm : public LcmInterface {
 public:
  explicit LogWriterLcm(const std::string& path) : writer_(path), path_(path) {}
  void PublishRaw(const std::string& channel, const void* data, int size, Utime utime) override {
    writer_.Write(channel, data, size, utime);
    if (utime > now_) now_ = utime;
    CountPublished();
  }
  // Data time: the latest stamp written (wall time before the first), so that the status
  // messages in the log are stamped like the data.
  Utime Now() const override { return now_; }
  void SubscribeRaw(const std::string&, RawHandler) override {}
  int HandleSubscriptions(int) override { return 0; }
  std::string url() const override { return "log file " + path_; }
  void Close() { writer_.Close(); }

 private:
  LcmLogWriter writer_;
  std::string path_;
  Utime now_ = NowUtime();
};

}  // namespace fl::stereo
