#include "fusionloc/stereo/chessboard_calibration.hpp"

#include <algorithm>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

namespace fl::stereo {

fl::Status ChessboardOptions::Validate() const {
  if (inner_cols < 2 || inner_rows < 2 || inner_cols == inner_rows) {
    return fl::Status::Error(
        "inner_cols and inner_rows must be >= 2 and different (a square board's orientation "
        "is ambiguous); count inner corners, e.g. 9 x 6 for a 10 x 7 squares board");
  }
  if (!(square_m > 0)) return fl::Status::Error("square_m must be > 0 [m]");
  if (distortion_terms != 4 && distortion_terms != 5 && distortion_terms != 8) {
    return fl::Status::Error("distortion_terms must be 4, 5 or 8");
  }
  if (min_views < 3) return fl::Status::Error("min_views must be >= 3");
  if (!(subpix_window_px >= 2)) return fl::Status::Error("subpix_window_px must be >= 2");
  return fl::Status::Ok();
}

std::vector<cv::Point2f> FindChessboard(const cv::Mat& gray, const ChessboardOptions& o) {
  std::vector<cv::Point2f> corners;
  const cv::Size pattern(o.inner_cols, o.inner_rows);
  if (!cv::findChessboardCorners(gray, pattern, corners,
                                 cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE)) {
    return {};
  }
  const int w = static_cast<int>(o.subpix_window_px);
  cv::cornerSubPix(gray, corners, cv::Size(w, w), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 50, 1e-3));
  // findChessboardCorners may start from either end of the board (a 180-degree ambiguity);
  // start from the one nearest the top-left so that both views of a pair agree.
  if (corners.front().x + corners.front().y > corners.back().x + corners.back().y) {
    std::reverse(corners.begin(), corners.end());
  }
  return corners;
}

StereoCalibrationResult CalibrateStereo(const std::vector<cv::Mat>& left,
                                        const std::vector<cv::Mat>& right,
                                        const ChessboardOptions& options) {
  if (auto s = options.Validate(); !s.ok()) throw std::invalid_argument(s.message());
  if (left.size() != right.size() || left.empty()) {
    throw std::invalid_argument("calibration needs as many left as right views (and some)");
  }
  const cv::Size size = left[0].size();
  std::vector<cv::Point3f> board;
  for (int r = 1; r <= options.inner_rows; ++r) {
    for (int c = 1; c <= options.inner_cols; ++c) {
      board.emplace_back(static_cast<float>(c * options.square_m),
                         static_cast<float>(r * options.square_m), 0.f);
    }
  }
  StereoCalibrationResult out;
  std::vector<std::vector<cv::Point3f>> object;
  std::vector<std::vector<cv::Point2f>> pl, pr;
  for (size_t i = 0; i < left.size(); ++i) {
    if (left[i].size() != size || right[i].size() != size) {
      throw std::invalid_argument("pair " + std::to_string(i) + " is not " +
                                  std::to_string(size.width) + "x" + std::to_string(size.height) +
                                  " like the first");
    }
    auto cl = FindChessboard(left[i], options);
    auto cr = cl.empty() ? std::vector<cv::Point2f>() : FindChessboard(right[i], options);
    if (cl.empty() || cr.empty()) {
      out.rejected.push_back(static_cast<int>(i));
      continue;
    }
    out.used.push_back(static_cast<int>(i));
    object.push_back(board);
    pl.push_back(std::move(cl));
    pr.push_back(std::move(cr));
  }
  if (static_cast<int>(out.used.size()) < options.min_views) {
    throw std::runtime_error(
        "the " + std::to_string(options.inner_cols) + "x" + std::to_string(options.inner_rows) +
        " chessboard was found in both views of " + std::to_string(out.used.size()) + " of " +
        std::to_string(left.size()) + " pairs; need " + std::to_string(options.min_views) +
        " (check inner_cols/inner_rows count inner corners, and show the whole board to both "
        "cameras, tilted, at several distances)");
  }
  int flags = 0;
  if (options.distortion_terms == 4) flags |= cv::CALIB_FIX_K3;
  if (options.distortion_terms == 8) flags |= cv::CALIB_RATIONAL_MODEL;
  cv::Mat K1, D1, K2, D2, R, T, E, F;
  std::vector<cv::Mat> rv, tv;
  const cv::TermCriteria crit(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 200, 1e-9);
  out.left_rms_px = cv::calibrateCamera(object, pl, size, K1, D1, rv, tv, flags, crit);
  out.right_rms_px = cv::calibrateCamera(object, pr, size, K2, D2, rv, tv, flags, crit);
  out.rms_px = cv::stereoCalibrate(object, pl, pr, K1, D1, K2, D2, size, R, T, E, F,
                                   flags | cv::CALIB_USE_INTRINSIC_GUESS, crit);
  RigCalibration& rig = out.rig;
  rig.width = size.width;
  rig.height = size.height;
  rig.rectified = false;
  auto intrinsics = [&](const cv::Mat& K, const cv::Mat& D) {
    CameraIntrinsics k;
    k.fx = K.at<double>(0, 0);
    k.fy = K.at<double>(1, 1);
    k.cx = K.at<double>(0, 2);
    k.cy = K.at<double>(1, 2);
    const int n = options.distortion_terms;
    for (int i = 0; i < n; ++i) k.distortion.push_back(D.at<double>(0, i));
    return k;
  };
  rig.left = intrinsics(K1, D1);
  rig.right = intrinsics(K2, D2);
  rig.rotation.assign(reinterpret_cast<const double*>(R.data),
                      reinterpret_cast<const double*>(R.data) + 9);
  rig.translation = {T.at<double>(0), T.at<double>(1), T.at<double>(2)};
  rig.rms_reprojection_px = out.rms_px;
  return out;
}

cv::Mat RectifiedPreview(const RigCalibration& rig, const cv::Mat& left, const cv::Mat& right,
                         int spacing_px) {
  const Rectifier rect(rig);
  cv::Mat l, r, side, bgr;
  rect.Rectify(left, right, &l, &r);
  cv::hconcat(l, r, side);
  if (side.channels() == 1) {
    cv::cvtColor(side, bgr, cv::COLOR_GRAY2BGR);
  } else {
    bgr = side;
  }
  for (int y = spacing_px / 2; y < bgr.rows; y += spacing_px) {
    cv::line(bgr, {0, y}, {bgr.cols - 1, y}, cv::Scalar(0, 255, 0), 1);
  }
  return bgr;
}

}  // namespace fl::stereo
