#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <opencv2/videoio.hpp>
#include <stdexcept>
#include <thread>

#include "fusionloc/stereo/sources.hpp"

namespace fl::stereo {

fl::Status CameraSourceOptions::Validate() const {
  if (device.empty()) return fl::Status::Error("camera.device is empty (e.g. /dev/video0)");
  if (width <= 0 || height <= 0 || width % 2 != 0) {
    return fl::Status::Error(
        "camera.width (both views side by side, even) and camera.height "
        "must be > 0");
  }
  if (!(fps > 0)) return fl::Status::Error("camera.fps must be > 0");
  if (fourcc.size() != 4) return fl::Status::Error("camera.fourcc must be 4 characters (MJPG)");
  if (!(frame_timeout_s > 0) || !(reconnect_interval_s > 0)) {
    return fl::Status::Error("camera.frame_timeout_s and camera.reconnect_interval_s must be > 0");
  }
  return fl::Status::Ok();
}

std::string CheckVideoDevice(const std::string& device) {
  struct stat st {};
  if (::stat(device.c_str(), &st) != 0) {
    if (errno == ENOENT) {
      return "camera '" + device +
             "' does not exist: is it plugged in? (`ls /dev/video*`, `v4l2-ctl "
             "--list-devices`; config/udev/ names it /dev/stereo_camera)";
    }
    return "camera '" + device + "': " + std::strerror(errno);
  }
  if (!S_ISCHR(st.st_mode)) {
    return "camera '" + device +
           "' is not a video device (not a character device); give the "
           "V4L2 node, e.g. /dev/video0, or --folder for image pairs";
  }
  if (::access(device.c_str(), R_OK | W_OK) != 0) {
    return "camera '" + device +
           "': permission denied: add your user to group video (`sudo usermod -aG video "
           "$USER`, then log in again) or install config/udev/60-fusionloc-stereo-camera.rules "
           "(group fusionloc), see docs/HARDWARE.md";
  }
  return "";
}

namespace {

class V4l2Grabber : public FrameGrabber {
 public:
  explicit V4l2Grabber(const CameraSourceOptions& o) : options_(o) {}
  bool Open(std::string* error) override {
    const std::string check = CheckVideoDevice(options_.device);
    if (!check.empty()) {
      *error = check;
      return false;
    }
    cap_.release();
    if (!cap_.open(options_.device, cv::CAP_V4L2) || !cap_.isOpened()) {
      *error = "camera '" + options_.device +
               "': V4L2 cannot capture from it (not a camera, a metadata node, or busy: "
               "`v4l2-ctl -d " +
               options_.device + " --all`, `fuser " + options_.device + "`)";
      return false;
    }
    const std::string& f = options_.fourcc;
    cap_.set(cv::CAP_PROP_FOURCC, cv::VideoWriter::fourcc(f[0], f[1], f[2], f[3]));
    cap_.set(cv::CAP_PROP_FRAME_WIDTH, options_.width);
    cap_.set(cv::CAP_PROP_FRAME_HEIGHT, options_.height);
    cap_.set(cv::CAP_PROP_FPS, options_.fps);
    const int w = static_cast<int>(cap_.get(cv::CAP_PROP_FRAME_WIDTH));
    const int h = static_cast<int>(cap_.get(cv::CAP_PROP_FRAME_HEIGHT));
    if (w != options_.width || h != options_.height) {
      *error = "camera '" + options_.device + "' gives " + std::to_string(w) + "x" +
               std::to_string(h) + ", not the " + std::to_string(options_.width) + "x" +
               std::to_string(options_.height) +
               " asked (both views side by side); list its modes with `v4l2-ctl -d " +
               options_.device + " --list-formats-ext`";
      cap_.release();
      return false;
    }
    return true;
  }
  bool Read(cv::Mat* frame) override { return cap_.read(*frame) && !frame->empty(); }
  void Close() override { cap_.release(); }
  std::string name() const override { return options_.device; }

 private:
  CameraSourceOptions options_;
  cv::VideoCapture cap_;
};

}  // namespace

std::unique_ptr<FrameGrabber> MakeV4l2Grabber(const CameraSourceOptions& options) {
  return std::make_unique<V4l2Grabber>(options);
}

SideBySideCamera::SideBySideCamera(std::unique_ptr<FrameGrabber> grabber,
                                   const CameraSourceOptions& options)
    : grabber_(std::move(grabber)), options_(options) {
  std::string error;
  if (!grabber_->Open(&error)) throw std::runtime_error(error);
  connected_ = true;
  last_frame_ = MonotonicUtime();
}

bool SideBySideCamera::Next(StereoFrame* frame) {
  const Utime now = MonotonicUtime();
  if (!connected_) {
    if (now - last_attempt_ < SecondsToUtime(options_.reconnect_interval_s)) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
      return false;
    }
    last_attempt_ = now;
    std::string error;
    if (!grabber_->Open(&error)) {
      problem_ = error;
      return false;
    }
    connected_ = true;
    ++reconnects_;
    problem_.clear();
    last_frame_ = now;
    last_frame_utime_ = 0;
  }
  cv::Mat full;
  if (!grabber_->Read(&full)) {
    ++dropped_;
    if (MonotonicUtime() - last_frame_ > SecondsToUtime(options_.frame_timeout_s)) {
      grabber_->Close();
      connected_ = false;
      ++disconnects_;
      last_attempt_ = MonotonicUtime();
      problem_ = "camera '" + grabber_->name() + "': no frame for " +
                 std::to_string(options_.frame_timeout_s) + " s; reopening";
    }
    return false;
  }
  if (full.cols != options_.width || full.rows != options_.height) {
    ++dropped_;
    problem_ = "camera '" + grabber_->name() + "' sent a " + std::to_string(full.cols) + "x" +
               std::to_string(full.rows) + " frame, not " + std::to_string(options_.width) + "x" +
               std::to_string(options_.height);
    return false;
  }
  const Utime t = NowUtime();
  last_frame_ = MonotonicUtime();
  // A gap of more than 1.5 frame periods means the camera or the USB bus dropped frames.
  if (last_frame_utime_ > 0) {
    const double periods = UtimeToSeconds(t - last_frame_utime_) * options_.fps;
    if (periods > 1.5) dropped_ += static_cast<int64_t>(std::lround(periods)) - 1;
  }
  last_frame_utime_ = t;
  const int half = full.cols / 2;
  cv::Mat a = full(cv::Rect(0, 0, half, full.rows)).clone();
  cv::Mat b = full(cv::Rect(half, 0, half, full.rows)).clone();
  frame->left = options_.swap ? b : a;
  frame->right = options_.swap ? a : b;
  frame->utime = t;
  frame->name = std::to_string(frames_);
  ++frames_;
  return true;
}

}  // namespace fl::stereo
