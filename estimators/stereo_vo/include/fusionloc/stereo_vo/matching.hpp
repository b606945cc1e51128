// Features and the quadrilateral ("circular") matching of MSIF §2:
//   left_t <-> right_t   (stereo, epipolar rows +-tolerance, disparity in (0, d_max])
//   left_t -> left_t+1, right_t -> right_t+1   (temporal, in motion-predicted windows)
//   left_t+1 <-> right_t+1   (stereo)
// A feature is kept only if left_t -> right_t -> right_t+1 -> left_t+1 -> left_t closes, the
// slope test passes and the parallax constraint holds (see CloseQuadrilaterals).
#pragma once

#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <string>
#include <vector>

#include "fusionloc/common/status.hpp"

namespace fl::vo {

struct FeatureOptions {
  int fast_threshold = 16;    // [gray levels] FAST corner threshold
  int cell_size_px = 32;      // [px] grid bucketing cell (features spread evenly)
  int features_per_cell = 4;  // strongest FAST corners kept per cell and pyramid level
  int pyramid_levels = 1;     // ORB pyramid levels (1 = full resolution only)
  double scale_factor = 1.2;  // [-] ORB pyramid scale between levels
  template <class A>
  void Serialize(A* a) {
    a->Visit("fast_threshold", &fast_threshold);
    a->Visit("cell_size_px", &cell_size_px);
    a->Visit("features_per_cell", &features_per_cell);
    a->Visit("pyramid_levels", &pyramid_levels);
    a->Visit("scale_factor", &scale_factor);
  }
  fl::Status Validate() const;
};

// Features of one image with a grid index for window queries.
class Features {
 public:
  std::vector<cv::KeyPoint> keypoints;  // pt in full-resolution pixels; octave = pyramid level
  cv::Mat descriptors;                  // N x 32 CV_8U (rBRIEF, upright)

  int size() const { return static_cast<int>(keypoints.size()); }
  // Rebuilds the grid index after keypoints change.
  void BuildIndex(int width, int height, int cell_px = 16);
  // Calls f(index) for every keypoint inside [x0, x1] x [y0, y1].
  template <class F>
  void ForEachInWindow(float x0, float x1, float y0, float y1, F&& f) const {
    if (cols_ == 0) return;
    const int c0 = std::max(0, static_cast<int>(x0) / cell_);
    const int c1 = std::min(cols_ - 1, static_cast<int>(std::max(0.f, x1)) / cell_);
    const int r0 = std::max(0, static_cast<int>(y0) / cell_);
    const int r1 = std::min(rows_ - 1, static_cast<int>(std::max(0.f, y1)) / cell_);
    for (int r = r0; r <= r1; ++r) {
      for (int c = c0; c <= c1; ++c) {
        for (int i : grid_[static_cast<size_t>(r * cols_ + c)]) {
          const cv::Point2f& p = keypoints[static_cast<size_t>(i)].pt;
          if (p.x >= x0 && p.x <= x1 && p.y >= y0 && p.y <= y1) f(i);
        }
      }
    }
  }

 private:
  int cell_ = 16, cols_ = 0, rows_ = 0;
  std::vector<std::vector<int>> grid_;
};

// Extracts FAST corners per pyramid level, keeps the strongest per grid cell, and computes
// upright ORB descriptors with OpenCV (whose pyramid serves levels > 0).
class FeatureExtractor {
 public:
  explicit FeatureExtractor(const FeatureOptions& options);
  void Extract(const cv::Mat& gray, Features* out);

 private:
  FeatureOptions options_;
  cv::Ptr<cv::ORB> orb_;
  std::vector<cv::KeyPoint> scratch_;
  std::vector<int> cell_best_;   // per grid cell: indices of its strongest corners
  std::vector<int> cell_count_;  // per grid cell: how many of them
};

struct MatchOptions {
  double epipolar_tolerance_px = 3.0;    // [px] |v_left - v_right| for stereo matches
  double max_disparity_px = 160.0;       // [px] d_max; disparity must be in (0, d_max]
  int max_hamming = 60;                  // [bits of 256] descriptor distance limit
  double ratio = 0.9;                    // best/second-best distance ratio (1 = off)
  double window_px = 20.0;               // [px] temporal half-window around the prediction
  double window_unpredicted_px = 250.0;  // [px] half-window of the global-shift search
  double slope_threshold = 0.35;         // K: |tan(angle between left and right flow)|
  double slope_min_flow_px = 3.0;        // [px] flows shorter than this skip the slope test
  double max_disparity_ratio = 1.6;      // parallax: d_t+1 / d_t within [1/r, r]
  template <class A>
  void Serialize(A* a) {
    a->Visit("epipolar_tolerance_px", &epipolar_tolerance_px);
    a->Visit("max_disparity_px", &max_disparity_px);
    a->Visit("max_hamming", &max_hamming);
    a->Visit("ratio", &ratio);
    a->Visit("window_px", &window_px);
    a->Visit("window_unpredicted_px", &window_unpredicted_px);
    a->Visit("slope_threshold", &slope_threshold);
    a->Visit("slope_min_flow_px", &slope_min_flow_px);
    a->Visit("max_disparity_ratio", &max_disparity_ratio);
  }
  fl::Status Validate() const;
};

// For each left keypoint, the index of its mutual-best right keypoint (or -1) with the
// epipolar tolerance and 0 < disparity <= d_max, same pyramid level.
std::vector<int> MatchStereo(const Features& left, const Features& right,
                             const MatchOptions& options);

// For each keypoint i of `from` with predicted[i].x >= 0, the best keypoint of `to` within
// +-radius of predicted[i] (same level, distance and ratio tests), or -1.
std::vector<int> MatchTemporal(const Features& from, const Features& to,
                               const std::vector<cv::Point2f>& predicted, double radius,
                               const MatchOptions& options);

// Sub-pixel alignment of a square patch by inverse-compositional Lucas-Kanade (translation):
// finds *p_target (start: its value) where the (2 half_window + 1)^2 patch of `target` best
// matches the patch of `templ` centred at p_templ (both 8-bit gray; bilinear sampling, central
// difference gradients of the template). Returns false, leaving *p_target unspecified, if the
// template has too little texture, a patch leaves its image or it does not converge within
// max_iterations. half_window in [2, 15]. No allocation: cheap for many points.
bool AlignPatch(const cv::Mat& templ, cv::Point2f p_templ, const cv::Mat& target, int half_window,
                cv::Point2f* p_target, int max_iterations = 10, float eps_px = 0.01f);

// One closed quadrilateral: keypoint indices in the four images (a = time t, b = time t+1).
struct Quad {
  int left_a, right_a, left_b, right_b;
};

struct QuadStats {
  int candidates = 0;         // left_a features with a stereo match at a
  int not_closed = 0;         // a temporal or stereo link missing or the loop ends elsewhere
  int slope_rejected = 0;     // the slope test failed
  int parallax_rejected = 0;  // disparity out of (0, d_max] or changed too much
  int kept = 0;
};

// The closed-loop check. stereo_a/stereo_b: left->right per left keypoint; temporal_left:
// left_a -> left_b; temporal_right: right_a -> right_b (all -1 for none). A left_a feature is
// kept if right_b(temporal_right[stereo_a[i]]) == stereo_b[temporal_left[i]] and:
//  - slope test: the flows f_l = left_b - left_a and f_r = right_b - right_a describe the same
//    scene motion, so their vertical parts agree within the epipolar tolerance and, when both
//    are longer than slope_min_flow_px, the lines have slopes k_l, k_r with
//    |k_l - k_r| / |1 + k_l k_r| (tan of the angle between them) <= K;
//  - parallax: both disparities in (0, d_max] and d_b / d_a within [1/r, r].
std::vector<Quad> CloseQuadrilaterals(const Features& left_a, const Features& right_a,
                                      const Features& left_b, const Features& right_b,
                                      const std::vector<int>& stereo_a,
                                      const std::vector<int>& stereo_b,
                                      const std::vector<int>& temporal_left,
                                      const std::vector<int>& temporal_right,
                                      const MatchOptions& options, QuadStats* stats);

}  // namespace fl::vo
