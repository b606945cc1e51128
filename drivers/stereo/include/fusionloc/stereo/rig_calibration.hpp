// The calibration file of a stereo rig (written by fl-stereo-calibrate, read by
// fl-stereo-driver), and rectification with OpenCV (stereoRectify + initUndistortRectifyMap,
// maps computed once). Camera frames: x right, y down, z forward (optical).
//
//   width: 640                 # [px] one view
//   height: 480
//   rectified: false           # true: the camera delivers rectified pairs (no maps)
//   left:  {fx: 500, fy: 500, cx: 319.5, cy: 239.5, distortion: [k1, k2, p1, p2, k3]}
//   right: {fx: ..., ...}
//   rotation: [9 numbers]      # R, row-major: x_right = R x_left + T
//   translation: [-0.12, 0, 0] # T [m]
//   rms_reprojection_px: 0.1   # fl-stereo-calibrate's RMS error (0: unknown)
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "fusionloc/common/status.hpp"

namespace fl::stereo {

struct CameraIntrinsics {
  double fx = 0.0;  // [px] focal length along x
  double fy = 0.0;  // [px] focal length along y
  double cx = 0.0;  // [px] principal point x
  double cy = 0.0;  // [px] principal point y
  // OpenCV's model: k1, k2, p1, p2[, k3[, k4, k5, k6]]; empty: no distortion.
  std::vector<double> distortion;

  template <class Archive>
  void Serialize(Archive* a) {
    a->Visit("fx", &fx);
    a->Visit("fy", &fy);
    a->Visit("cx", &cx);
    a->Visit("cy", &cy);
    a->Visit("distortion", &distortion);
  }
  cv::Mat K() const;  // 3x3 CV_64F
  cv::Mat D() const;  // 1xN CV_64F (1x5 zeros if empty)
};

struct RigCalibration {
  int width = 0;           // [px] one view's columns
  int height = 0;          // [px] rows
  bool rectified = false;  // the images are already rectified row-aligned pairs
  CameraIntrinsics left, right;
  std::vector<double> rotation{1, 0, 0, 0, 1, 0, 0, 0, 1};  // [-] R, row-major
  std::vector<double> translation{0, 0, 0};                 // [m] T
  double rms_reprojection_px = 0.0;                         // [px] 0: unknown

  template <class Archive>
  void Serialize(Archive* a) {
    a->Visit("width", &width);
    a->Visit("height", &height);
    a->Visit("rectified", &rectified);
    a->Visit("left", &left);
    a->Visit("right", &right);
    a->Visit("rotation", &rotation);
    a->Visit("translation", &translation);
    a->Visit("rms_reprojection_px", &rms_reprojection_px);
  }
  fl::Status Validate() const;
  cv::Mat R() const;  // 3x3 CV_64F
  cv::Mat T() const;  // 3x1 CV_64F
};

// Reads and validates a calibration file; throws fl::ConfigError naming the file and the fix.
RigCalibration LoadRigCalibration(const std::string& path);
// Writes it (with a header comment); throws std::runtime_error if it cannot.
void SaveRigCalibration(const RigCalibration& c, const std::string& path,
                        const std::string& comment = "");

// The rectified pinhole pair the driver publishes (fusionloc.stereo_calibration_t).
struct RectifiedCamera {
  int width = 0, height = 0;              // [px]
  double fx = 0, fy = 0, cx = 0, cy = 0;  // [px] both views
  double baseline = 0;                    // [m] right optical centre at +baseline along left x
};

class Rectifier {
 public:
  // Computes the rectification and the maps once (nothing to compute if c.rectified).
  // `c` must be valid.
  explicit Rectifier(const RigCalibration& c);

  // Rectified views of a raw pair (copies if the calibration says rectified). The images
  // must be width x height; throws std::invalid_argument naming the size otherwise.
  void Rectify(const cv::Mat& left, const cv::Mat& right, cv::Mat* left_out,
               cv::Mat* right_out) const;
  const RectifiedCamera& camera() const { return camera_; }
  bool needs_maps() const { return !map_left_x_.empty(); }
  // stereoRectify's outputs (identity / the input's intrinsics if rectified).
  const cv::Mat& R1() const { return R1_; }
  const cv::Mat& R2() const { return R2_; }
  const cv::Mat& P1() const { return P1_; }
  const cv::Mat& P2() const { return P2_; }
  const cv::Mat& map_left_x() const { return map_left_x_; }
  const cv::Mat& map_left_y() const { return map_left_y_; }
  const cv::Mat& map_right_x() const { return map_right_x_; }
  const cv::Mat& map_right_y() const { return map_right_y_; }

 private:
  RigCalibration calibration_;
  RectifiedCamera camera_;
  cv::Mat R1_, R2_, P1_, P2_;
  cv::Mat map_left_x_, map_left_y_, map_right_x_, map_right_y_;
};

}  // namespace fl::stereo
