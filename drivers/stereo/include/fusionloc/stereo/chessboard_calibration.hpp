// Stereo calibration from chessboard views (OpenCV findChessboardCorners, cornerSubPix,
// calibrateCamera for each camera, then stereoCalibrate refining everything), and the
// rectified preview with epipolar lines. No I/O besides what the caller passes in.
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "fusionloc/common/status.hpp"
#include "fusionloc/stereo/rig_calibration.hpp"

namespace fl::stereo {

struct ChessboardOptions {
  int inner_cols = 9;             // inner corners along a board row (squares - 1)
  int inner_rows = 6;             // inner corners along a board column
  double square_m = 0.025;        // [m] side of one square (sets the baseline's scale)
  int distortion_terms = 5;       // 4 (k1 k2 p1 p2), 5 (+ k3) or 8 (rational model)
  int min_views = 8;              // fewer pairs with the board found in both views: an error
  double subpix_window_px = 5.0;  // [px] cornerSubPix half window

  template <class Archive>
  void Serialize(Archive* a) {
    a->Visit("inner_cols", &inner_cols);
    a->Visit("inner_rows", &inner_rows);
    a->Visit("square_m", &square_m);
    a->Visit("distortion_terms", &distortion_terms);
    a->Visit("min_views", &min_views);
    a->Visit("subpix_window_px", &subpix_window_px);
  }
  fl::Status Validate() const;
};

// The board's inner corners found to sub-pixel in an 8-bit gray image, ordered from the
// corner nearest the image's top-left (the same order in both views of a pair); empty if
// the whole board is not found.
std::vector<cv::Point2f> FindChessboard(const cv::Mat& gray, const ChessboardOptions& o);

struct StereoCalibrationResult {
  RigCalibration rig;        // rectified: false; rms_reprojection_px set
  double rms_px = 0.0;       // [px] stereoCalibrate's RMS reprojection error
  double left_rms_px = 0.0;  // [px] each camera alone (calibrateCamera)
  double right_rms_px = 0.0;
  std::vector<int> used;      // indices of the pairs used
  std::vector<int> rejected;  // board not found in one view or both
};

// Calibrates from pairs of 8-bit gray views of the board (all the same size). Throws
// std::runtime_error naming how many pairs had the board if fewer than min_views.
StereoCalibrationResult CalibrateStereo(const std::vector<cv::Mat>& left,
                                        const std::vector<cv::Mat>& right,
                                        const ChessboardOptions& options);

// The rectified pair side by side (BGR) with a horizontal line every `spacing_px` rows: on a
// good calibration every feature sits on the same line in both halves.
cv::Mat RectifiedPreview(const RigCalibration& rig, const cv::Mat& left, const cv::Mat& right,
                         int spacing_px = 24);

}  // namespace fl::stereo
