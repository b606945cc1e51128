// Where stereo pairs come from: a folder of image pairs played at a requested rate, or a UVC
// camera that delivers both views side by side in one frame (V4L2 through OpenCV).
#pragma once

#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "fusionloc/common/status.hpp"
#include "fusionloc/common/time.hpp"

namespace fl::stereo {

struct StereoFrame {
  Utime utime = 0;  // [us] data time (folder) or host time at capture (camera)
  cv::Mat left;     // 8-bit gray or BGR
  cv::Mat right;
  std::string name;  // file name (folder) or frame number (camera)
};

// ---- folder playback ----

// The image pairs of a folder, paired by file name:
//   KITTI raw        image_00/data/*.png + image_01/data/*.png
//   KITTI odometry   image_0/*.png + image_1/*.png
//   plain            left/* + right/*
struct ImagePairs {
  std::string layout;  // "KITTI raw", "KITTI odometry" or "left/right"
  std::string left_dir, right_dir;
  std::vector<std::string> left, right;  // paired paths, in name order
  std::vector<std::string> unpaired;     // files with no partner on the other side
};
// Throws std::runtime_error naming the folder and the expected layouts if there are no pairs,
// and (unless skip_unpaired) naming the first image without its partner.
ImagePairs ListImagePairs(const std::string& folder, bool skip_unpaired);

struct FolderSourceOptions {
  double rate_hz = 10.0;       // [Hz] playback rate: frame i is stamped start + i / rate_hz
  bool skip_unpaired = false;  // an image without its partner: false stops with an error,
                               // true skips it (counted in the status)
  int start_frame = 0;         // first pair played
  int max_frames = -1;         // pairs played (-1: all)
  bool loop = false;           // start again after the last pair

  template <class Archive>
  void Serialize(Archive* a) {
    a->Visit("rate_hz", &rate_hz);
    a->Visit("skip_unpaired", &skip_unpaired);
    a->Visit("start_frame", &start_frame);
    a->Visit("max_frames", &max_frames);
    a->Visit("loop", &loop);
  }
  fl::Status Validate() const;
};

class FolderSource {
 public:
  // Lists the pairs (see ListImagePairs); frame i gets utime start_utime + i / rate_hz.
  FolderSource(const std::string& folder, const FolderSourceOptions& options, Utime start_utime);
  // The next pair; false at the end. An image that cannot be read, or a pair of different
  // sizes, is skipped and counted in unreadable() with its reason in last_problem().
  bool Next(StereoFrame* frame);
  // [us] data time of frame `i` (for pacing).
  Utime FrameUtime(int64_t i) const;
  int64_t played() const { return played_; }
  int64_t unreadable() const { return unreadable_; }
  const std::string& last_problem() const { return last_problem_; }
  const ImagePairs& pairs() const { return pairs_; }
  size_t size() const { return end_ - begin_; }

 private:
  FolderSourceOptions options_;
  ImagePairs pairs_;
  Utime start_utime_;
  size_t begin_ = 0, end_ = 0, next_ = 0;
  int64_t played_ = 0, unreadable_ = 0;
  std::string last_problem_;
};

// ---- side-by-side camera ----

// One frame grabber (V4L2 through OpenCV in the driver; a scripted one in tests).
class FrameGrabber {
 public:
  virtual ~FrameGrabber() = default;
  // Opens the device; false with `error` naming the device and the fix.
  virtual bool Open(std::string* error) = 0;
  // The next frame (both views side by side); false if none came (timeout, device gone).
  virtual bool Read(cv::Mat* frame) = 0;
  virtual void Close() = 0;
  virtual std::string name() const = 0;
};

struct CameraSourceOptions {
  std::string device = "/dev/video0";  // V4L2 device (config/udev/ names one /dev/stereo_camera)
  int width = 1280;                    // [px] frame width, both views side by side
  int height = 480;                    // [px]
  double fps = 30.0;                   // [Hz] requested frame rate
  std::string fourcc = "MJPG";         // pixel format asked of the camera (MJPG, YUYV)
  bool swap = false;                   // true: the right view is the left half
  double frame_timeout_s = 1.0;        // [s] no frame for this long: the camera is gone
  double reconnect_interval_s = 1.0;   // [s] between attempts to reopen it

  template <class Archive>
  void Serialize(Archive* a) {
    a->Visit("device", &device);
    a->Visit("width", &width);
    a->Visit("height", &height);
    a->Visit("fps", &fps);
    a->Visit("fourcc", &fourcc);
    a->Visit("swap", &swap);
    a->Visit("frame_timeout_s", &frame_timeout_s);
    a->Visit("reconnect_interval_s", &reconnect_interval_s);
  }
  fl::Status Validate() const;
};

// Checks that `device` can be a camera before OpenCV tries it: "" if so, else the error
// naming it and the fix (missing, not a character device, permission denied).
std::string CheckVideoDevice(const std::string& device);

// The V4L2 grabber (cv::VideoCapture with cv::CAP_V4L2).
std::unique_ptr<FrameGrabber> MakeV4l2Grabber(const CameraSourceOptions& options);

class SideBySideCamera {
 public:
  // Opens the grabber; throws std::runtime_error with its error if it cannot.
  SideBySideCamera(std::unique_ptr<FrameGrabber> grabber, const CameraSourceOptions& options);
  // Waits for the next frame and splits it into left and right (stamped with host time).
  // False if none came: a read failure is a dropped frame; after frame_timeout_s without a
  // frame the camera is closed and reopened every reconnect_interval_s (counted).
  bool Next(StereoFrame* frame);

  bool connected() const { return connected_; }
  int64_t frames() const { return frames_; }
  int64_t dropped() const { return dropped_; }  // failed reads and frame-time gaps
  int64_t disconnects() const { return disconnects_; }
  int64_t reconnects() const { return reconnects_; }
  const std::string& problem() const { return problem_; }

 private:
  std::unique_ptr<FrameGrabber> grabber_;
  CameraSourceOptions options_;
  bool connected_ = false;
  Utime last_frame_ = 0, last_attempt_ = 0, last_frame_utime_ = 0;
  int64_t frames_ = 0, dropped_ = 0, disconnects_ = 0, reconnects_ = 0;
  std::string problem_;
};

}  // namespace fl::stereo
