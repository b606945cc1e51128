#include "fusionloc/stereo/rig_calibration.hpp"

#include <cmath>
#include <fstream>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "fusionloc/common/yaml_options.hpp"

namespace fl::stereo {
namespace {

fl::Status CheckIntrinsics(const CameraIntrinsics& k, const std::string& which) {
  if (!(k.fx > 0) || !(k.fy > 0) || !std::isfinite(k.cx) || !std::isfinite(k.cy)) {
    return fl::Status::Error(which + ": fx and fy must be > 0 and cx, cy finite");
  }
  const size_t n = k.distortion.size();
  if (!(n == 0 || n == 4 || n == 5 || n == 8)) {
    return fl::Status::Error(which + ": distortion has " + std::to_string(n) +
                             " numbers; OpenCV's model takes 4, 5 or 8 (k1 k2 p1 p2 [k3 ...])");
  }
  return fl::Status::Ok();
}

}  // namespace

cv::Mat CameraIntrinsics::K() const {
  return (cv::Mat_<double>(3, 3) << fx, 0, cx, 0, fy, cy, 0, 0, 1);
}

cv::Mat CameraIntrinsics::D() const {
  if (distortion.empty()) return cv::Mat::zeros(1, 5, CV_64F);
  cv::Mat d(1, static_cast<int>(distortion.size()), CV_64F);
  for (size_t i = 0; i < distortion.size(); ++i)
    d.at<double>(0, static_cast<int>(i)) = distortion[i];
  return d;
}

cv::Mat RigCalibration::R() const {
  cv::Mat r(3, 3, CV_64F);
  for (int i = 0; i < 9; ++i) r.at<double>(i / 3, i % 3) = rotation[static_cast<size_t>(i)];
  return r;
}

cv::Mat RigCalibration::T() const {
  return (cv::Mat_<double>(3, 1) << translation[0], translation[1], translation[2]);
}

fl::Status RigCalibration::Validate() const {
  if (width <= 0 || height <= 0) {
    return fl::Status::Error("width and height (one view, pixels) must be > 0");
  }
  if (auto s = CheckIntrinsics(left, "left"); !s.ok()) return s;
  if (auto s = CheckIntrinsics(right, "right"); !s.ok()) return s;
  if (rotation.size() != 9) return fl::Status::Error("rotation needs 9 numbers (row-major R)");
  if (translation.size() != 3) return fl::Status::Error("translation needs 3 numbers [m]");
  const cv::Mat r = R();
  const double err = cv::norm(r * r.t() - cv::Mat::eye(3, 3, CV_64F));
  if (!(err < 1e-6) || !(cv::determinant(r) > 0)) {
    return fl::Status::Error("rotation is not a rotation matrix (R R^T != I or det <= 0)");
  }
  if (!(cv::norm(T()) > 1e-6)) return fl::Status::Error("translation (the baseline) is zero");
  if (rectified) {
    const bool same =
        left.fx == right.fx && left.fy == right.fy && left.cx == right.cx && left.cy == right.cy;
    const bool row_aligned = err < 1e-9 && cv::norm(r - cv::Mat::eye(3, 3, CV_64F)) < 1e-9 &&
                             std::abs(translation[1]) < 1e-9 && std::abs(translation[2]) < 1e-9 &&
                             translation[0] < 0;
    if (!same || !row_aligned) {
      return fl::Status::Error(
          "rectified: true needs equal left/right intrinsics, rotation I and translation "
          "(-baseline, 0, 0); set rectified: false to rectify with the maps");
    }
  }
  return fl::Status::Ok();
}

RigCalibration LoadRigCalibration(const std::string& path) {
  RigCalibration c = LoadYamlFile<RigCalibration>(path);
  if (auto s = c.Validate(); !s.ok()) {
    throw ConfigError(path + ": " + s.message() + " (make one with fl-stereo-calibrate)");
  }
  return c;
}

void SaveRigCalibration(const RigCalibration& c, const std::string& path,
                        const std::string& comment) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error("cannot write the calibration file '" + path + "'");
  out << "# Stereo rig calibration (fl-stereo-driver --calibration). Camera frames: x right, "
         "y down, z forward.\n";
  if (!comment.empty()) out << "# " << comment << "\n";
  out << SaveYamlString(c);
  if (!out) throw std::runtime_error("write failed: '" + path + "'");
}

Rectifier::Rectifier(const RigCalibration& c) : calibration_(c) {
  if (auto s = c.Validate(); !s.ok()) throw std::invalid_argument(s.message());
  camera_.width = c.width;
  camera_.height = c.height;
  if (c.rectified) {
    camera_.fx = c.left.fx;
    camera_.fy = c.left.fy;
    camera_.cx = c.left.cx;
    camera_.cy = c.left.cy;
    camera_.baseline = -c.translation[0];
    R1_ = cv::Mat::eye(3, 3, CV_64F);
    R2_ = cv::Mat::eye(3, 3, CV_64F);
    P1_ = (cv::Mat_<double>(3, 4) << camera_.fx, 0, camera_.cx, 0, 0, camera_.fy, camera_.cy, 0, 0,
           0, 1, 0);
    P2_ = P1_.clone();
    P2_.at<double>(0, 3) = -camera_.fx * camera_.baseline;
    return;
  }
  const cv::Size size(c.width, c.height);
  cv::Mat Q;
  // alpha 0: only valid pixels in the rectified views; same principal point in both.
  cv::stereoRectify(c.left.K(), c.left.D(), c.right.K(), c.right.D(), size, c.R(), c.T(), R1_, R2_,
                    P1_, P2_, Q, cv::CALIB_ZERO_DISPARITY, 0.0, size);
  cv::initUndistortRectifyMap(c.left.K(), c.left.D(), R1_, P1_, size, CV_32FC1, map_left_x_,
                              map_left_y_);
  cv::initUndistortRectifyMap(c.right.K(), c.right.D(), R2_, P2_, size, CV_32FC1, map_right_x_,
                              map_right_y_);
  camera_.fx = P1_.at<double>(0, 0);
  camera_.fy = P1_.at<double>(1, 1);
  camera_.cx = P1_.at<double>(0, 2);
  camera_.cy = P1_.at<double>(1, 2);
  camera_.baseline = -P2_.at<double>(0, 3) / P2_.at<double>(0, 0);
}

void Rectifier::Rectify(const cv::Mat& left, const cv::Mat& right, cv::Mat* left_out,
                        cv::Mat* right_out) const {
  for (const cv::Mat* m : {&left, &right}) {
    if (m->cols != calibration_.width || m->rows != calibration_.height) {
      throw std::invalid_argument(
          "image is " + std::to_string(m->cols) + "x" + std::to_string(m->rows) +
          " but the calibration is for " + std::to_string(calibration_.width) + "x" +
          std::to_string(calibration_.height) + " (wrong calibration file or camera resolution)");
    }
  }
  if (!needs_maps()) {
    left.copyTo(*left_out);
    right.copyTo(*right_out);
    return;
  }
  cv::remap(left, *left_out, map_left_x_, map_left_y_, cv::INTER_LINEAR, cv::BORDER_CONSTANT);
  cv::remap(right, *right_out, map_right_x_, map_right_y_, cv::INTER_LINEAR, cv::BORDER_CONSTANT);
}

}  // namespace fl::stereo
