#include "fusionloc/stereo_vo/matching.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/core/hal/hal.hpp>
#include <opencv2/imgproc.hpp>

namespace fl::vo {
namespace {

constexpr int kDescriptorBytes = 32;
constexpr int kBorderPx = 16;  // ORB's 31x31 patch (upright) must fit in the image

struct Best {
  int index = -1;
  int distance = std::numeric_limits<int>::max();
  int second = std::numeric_limits<int>::max();
};

// Best and second-best Hamming distance among `to`'s keypoints of `octave` in the window.
Best BestInWindow(const uint8_t* desc, int octave, const Features& to, float x0, float x1, float y0,
                  float y1) {
  Best b;
  to.ForEachInWindow(x0, x1, y0, y1, [&](int j) {
    if (to.keypoints[static_cast<size_t>(j)].octave != octave) return;
    const int d = cv::hal::normHamming(desc, to.descriptors.ptr<uint8_t>(j), kDescriptorBytes);
    if (d < b.distance) {
      b.second = b.distance;
      b.distance = d;
      b.index = j;
    } else if (d < b.second) {
      b.second = d;
    }
  });
  return b;
}

bool Accept(const Best& b, const MatchOptions& o) {
  if (b.index < 0 || b.distance > o.max_hamming) return false;
  if (b.second == std::numeric_limits<int>::max()) return true;
  return b.distance < o.ratio * b.second;
}

}  // namespace

fl::Status FeatureOptions::Validate() const {
  if (fast_threshold < 1 || fast_threshold > 200) {
    return fl::Status::Error("features.fast_threshold must be in [1, 200], got " +
                             std::to_string(fast_threshold));
  }
  if (cell_size_px < 8) return fl::Status::Error("features.cell_size_px must be >= 8");
  if (features_per_cell < 1) return fl::Status::Error("features.features_per_cell must be >= 1");
  if (pyramid_levels < 1 || pyramid_levels > 8) {
    return fl::Status::Error("features.pyramid_levels must be in [1, 8]");
  }
  if (!(scale_factor > 1.0 && scale_factor <= 2.0)) {
    return fl::Status::Error("features.scale_factor must be in (1, 2]");
  }
  return fl::Status::Ok();
}

fl::Status MatchOptions::Validate() const {
  if (!(epipolar_tolerance_px >= 0 && epipolar_tolerance_px <= 20)) {
    return fl::Status::Error("matching.epipolar_tolerance_px must be in [0, 20]");
  }
  if (!(max_disparity_px > 1)) return fl::Status::Error("matching.max_disparity_px must be > 1");
  if (max_hamming < 1 || max_hamming > 256) {
    return fl::Status::Error("matching.max_hamming must be in [1, 256]");
  }
  if (!(ratio > 0 && ratio <= 1)) return fl::Status::Error("matching.ratio must be in (0, 1]");
  if (!(window_px > 0 && window_unpredicted_px >= window_px)) {
    return fl::Status::Error(
        "matching.window_px must be > 0 and window_unpredicted_px >= window_px");
  }
  if (!(slope_threshold > 0)) return fl::Status::Error("matching.slope_threshold must be > 0");
  if (!(slope_min_flow_px >= 0)) return fl::Status::Error("matching.slope_min_flow_px >= 0");
  if (!(max_disparity_ratio > 1)) {
    return fl::Status::Error("matching.max_disparity_ratio must be > 1");
  }
  return fl::Status::Ok();
}

void Features::BuildIndex(int width, int height, int cell_px) {
  cell_ = std::max(4, cell_px);
  cols_ = std::max(1, (width + cell_ - 1) / cell_);
  rows_ = std::max(1, (height + cell_ - 1) / cell_);
  grid_.assign(static_cast<size_t>(cols_ * rows_), {});
  for (int i = 0; i < size(); ++i) {
    const cv::Point2f& p = keypoints[static_cast<size_t>(i)].pt;
    const int c = std::clamp(static_cast<int>(p.x) / cell_, 0, cols_ - 1);
    const int r = std::clamp(static_cast<int>(p.y) / cell_, 0, rows_ - 1);
    grid_[static_cast<size_t>(r * cols_ + c)].push_back(i);
  }
}

FeatureExtractor::FeatureExtractor(const FeatureOptions& options) : options_(options) {
  orb_ = cv::ORB::create(100000, static_cast<float>(options.scale_factor), options.pyramid_levels,
                         kBorderPx, 0, 2, cv::ORB::FAST_SCORE, 31, options.fast_threshold);
}

void FeatureExtractor::Extract(const cv::Mat& gray, Features* out) {
  out->keypoints.clear();
  cv::Mat level_image = gray;
  for (int level = 0; level < options_.pyramid_levels; ++level) {
    const double scale = std::pow(options_.scale_factor, level);
    if (level > 0) {
      cv::resize(gray, level_image,
                 cv::Size(cvRound(gray.cols / scale), cvRound(gray.rows / scale)), 0, 0,
                 cv::INTER_LINEAR);
    }
    scratch_.clear();
    cv::FAST(level_image, scratch_, options_.fast_threshold, true);
    // Grid bucketing: the strongest `features_per_cell` corners of each cell, kept sorted per
    // cell by insertion (O(N k), no sort of all corners).
    const int cell = options_.cell_size_px;
    const int cols = (level_image.cols + cell - 1) / cell;
    const int rows = (level_image.rows + cell - 1) / cell;
    const int k = options_.features_per_cell;
    cell_best_.assign(static_cast<size_t>(cols * rows * k), -1);
    cell_count_.assign(static_cast<size_t>(cols * rows), 0);
    for (int i = 0; i < static_cast<int>(scratch_.size()); ++i) {
      const cv::KeyPoint& kp = scratch_[static_cast<size_t>(i)];
      const cv::Point2f& p = kp.pt;
      if (p.x < kBorderPx || p.y < kBorderPx || p.x >= level_image.cols - kBorderPx ||
          p.y >= level_image.rows - kBorderPx) {
        continue;
      }
      const int c = static_cast<int>(p.y) / cell * cols + static_cast<int>(p.x) / cell;
      int* best = &cell_best_[static_cast<size_t>(c * k)];
      int& n = cell_count_[static_cast<size_t>(c)];
      // Position of the new corner among the cell's best (descending response).
      int pos = n;
      while (pos > 0 && scratch_[static_cast<size_t>(best[pos - 1])].response < kp.response) --pos;
      if (pos >= k) continue;
      for (int m = std::min(n, k - 1); m > pos; --m) best[m] = best[m - 1];
      best[pos] = i;
      n = std::min(n + 1, k);
    }
    for (int c = 0; c < cols * rows; ++c) {
      for (int m = 0; m < cell_count_[static_cast<size_t>(c)]; ++m) {
        const int i = cell_best_[static_cast<size_t>(c * k + m)];
        cv::KeyPoint kp = scratch_[static_cast<size_t>(i)];
        kp.pt.x = static_cast<float>(kp.pt.x * scale);
        kp.pt.y = static_cast<float>(kp.pt.y * scale);
        kp.octave = level;
        kp.angle = 0;  // upright descriptors: frame-to-frame rotation about the axis is small
        kp.size = static_cast<float>(31 * scale);
        out->keypoints.push_back(kp);
      }
    }
  }
  orb_->compute(gray, out->keypoints, out->descriptors);
  out->BuildIndex(gray.cols, gray.rows);
}

namespace {

// The patch of half size h around p, plus a margin of `margin` px, lies inside the image for
// bilinear sampling.
inline bool PatchInside(const cv::Mat& img, cv::Point2f p, int h, int margin) {
  const float lo = static_cast<float>(h + margin);
  return p.x >= lo && p.y >= lo && p.x < static_cast<float>(img.cols - 1 - h - margin) &&
         p.y < static_cast<float>(img.rows - 1 - h - margin);
}

// Samples the side x side patch (side = 2 h + 1) of an 8-bit image centred at c (bilinear; a
// translation keeps the same interpolation weights for every pixel). The patch must be inside
// (PatchInside). kSide > 0: the side as a compile-time constant (vectorised inner loop).
template <int kSide>
inline void SamplePatch(const cv::Mat& img, cv::Point2f c, int h, float* out) {
  const int side = kSide > 0 ? kSide : 2 * h + 1;
  const float x = c.x - static_cast<float>(h), y = c.y - static_cast<float>(h);
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  const float ax = x - static_cast<float>(x0), ay = y - static_cast<float>(y0);
  const float w00 = (1.f - ax) * (1.f - ay), w01 = ax * (1.f - ay), w10 = (1.f - ax) * ay,
              w11 = ax * ay;
  const size_t step = img.step[0];
  const uint8_t* r0 = img.ptr<uint8_t>(y0) + x0;
  for (int i = 0; i < side; ++i, r0 += step) {
    const uint8_t* r1 = r0 + step;
    float* o = out + i * side;
    for (int j = 0; j < side; ++j) {
      o[j] = w00 * r0[j] + w01 * r0[j + 1] + w10 * r1[j] + w11 * r1[j + 1];
    }
  }
}

template <int kSide>
bool AlignPatchImpl(const cv::Mat& templ, cv::Point2f p_templ, const cv::Mat& target, int h,
                    cv::Point2f* p_target, int max_iterations, float eps_px) {
  constexpr int kMaxSide = 31;
  const int side = kSide > 0 ? kSide : 2 * h + 1, big = side + 2, n = side * side;
  // Template with a one-pixel ring for the central-difference gradients.
  float ring[(kMaxSide + 2) * (kMaxSide + 2)], t[kMaxSide * kMaxSide], gx[kMaxSide * kMaxSide],
      gy[kMaxSide * kMaxSide], r[kMaxSide * kMaxSide];
  SamplePatch<kSide + 2 * (kSide > 0)>(templ, p_templ, h + 1, ring);
  float hxx = 0, hxy = 0, hyy = 0;
  for (int i = 0, k = 0; i < side; ++i) {
    const float* row = ring + (i + 1) * big + 1;
    for (int j = 0; j < side; ++j, ++k) {
      t[k] = row[j];
      gx[k] = 0.5f * (row[j + 1] - row[j - 1]);
      gy[k] = 0.5f * (row[j + big] - row[j - big]);
      hxx += gx[k] * gx[k];
      hxy += gx[k] * gy[k];
      hyy += gy[k] * gy[k];
    }
  }
  const double det = static_cast<double>(hxx) * hyy - static_cast<double>(hxy) * hxy;
  // Too little texture, or an edge (one direction unconstrained): the mean of the gradient
  // products per pixel (det / n^2) below 1e-2 gray^4 / px^2.
  if (!(det > 1e-2 * static_cast<double>(n) * static_cast<double>(n))) return false;
  cv::Point2f p = *p_target;
  for (int it = 0; it < max_iterations; ++it) {
    if (!PatchInside(target, p, h, 0)) return false;
    SamplePatch<kSide>(target, p, h, r);
    float bx = 0, by = 0;
    for (int k = 0; k < n; ++k) {
      const float e = r[k] - t[k];
      bx += gx[k] * e;
      by += gy[k] * e;
    }
    const double dx = (hyy * static_cast<double>(bx) - hxy * static_cast<double>(by)) / det;
    const double dy = (hxx * static_cast<double>(by) - hxy * static_cast<double>(bx)) / det;
    p.x -= static_cast<float>(dx);
    p.y -= static_cast<float>(dy);
    if (dx * dx + dy * dy < static_cast<double>(eps_px) * eps_px) {
      *p_target = p;
      return PatchInside(target, p, h, 0);
    }
  }
  return false;
}

}  // namespace

bool AlignPatch(const cv::Mat& templ, cv::Point2f p_templ, const cv::Mat& target, int half_window,
                cv::Point2f* p_target, int max_iterations, float eps_px) {
  const int h = half_window;
  if (h < 2 || 2 * h + 1 > 31 || templ.type() != CV_8UC1 || target.type() != CV_8UC1) {
    return false;
  }
  if (!PatchInside(templ, p_templ, h, 1) || !PatchInside(target, *p_target, h, 0)) return false;
  if (h == 5)
    return AlignPatchImpl<11>(templ, p_templ, target, h, p_target, max_iterations, eps_px);
  return AlignPatchImpl<0>(templ, p_templ, target, h, p_target, max_iterations, eps_px);
}

std::vector<int> MatchStereo(const Features& left, const Features& right,
                             const MatchOptions& options) {
  std::vector<int> result(static_cast<size_t>(left.size()), -1);
  std::vector<int> reverse(static_cast<size_t>(right.size()), -2);  // -2: not computed yet
  const float tol = static_cast<float>(options.epipolar_tolerance_px);
  const float dmax = static_cast<float>(options.max_disparity_px);
  constexpr float kMinDisparity = 1e-3f;  // disparity strictly positive
  for (int i = 0; i < left.size(); ++i) {
    const cv::KeyPoint& kl = left.keypoints[static_cast<size_t>(i)];
    const Best b = BestInWindow(left.descriptors.ptr<uint8_t>(i), kl.octave, right, kl.pt.x - dmax,
                                kl.pt.x - kMinDisparity, kl.pt.y - tol, kl.pt.y + tol);
    if (!Accept(b, options)) continue;
    // Mutual check: the right feature's best left match in its own window must be i.
    int& rev = reverse[static_cast<size_t>(b.index)];
    if (rev == -2) {
      const cv::KeyPoint& kr = right.keypoints[static_cast<size_t>(b.index)];
      const Best br =
          BestInWindow(right.descriptors.ptr<uint8_t>(b.index), kr.octave, left,
                       kr.pt.x + kMinDisparity, kr.pt.x + dmax, kr.pt.y - tol, kr.pt.y + tol);
      rev = Accept(br, options) ? br.index : -1;
    }
    if (rev == i) result[static_cast<size_t>(i)] = b.index;
  }
  return result;
}

std::vector<int> MatchTemporal(const Features& from, const Features& to,
                               const std::vector<cv::Point2f>& predicted, double radius,
                               const MatchOptions& options) {
  std::vector<int> result(static_cast<size_t>(from.size()), -1);
  const float r = static_cast<float>(radius);
  for (int i = 0; i < from.size() && i < static_cast<int>(predicted.size()); ++i) {
    const cv::Point2f& p = predicted[static_cast<size_t>(i)];
    if (p.x < 0) continue;
    const Best b = BestInWindow(from.descriptors.ptr<uint8_t>(i),
                                from.keypoints[static_cast<size_t>(i)].octave, to, p.x - r, p.x + r,
                                p.y - r, p.y + r);
    if (Accept(b, options)) result[static_cast<size_t>(i)] = b.index;
  }
  return result;
}

std::vector<Quad> CloseQuadrilaterals(const Features& left_a, const Features& right_a,
                                      const Features& left_b, const Features& right_b,
                                      const std::vector<int>& stereo_a,
                                      const std::vector<int>& stereo_b,
                                      const std::vector<int>& temporal_left,
                                      const std::vector<int>& temporal_right,
                                      const MatchOptions& options, QuadStats* stats) {
  QuadStats s;
  std::vector<Quad> quads;
  auto get = [](const std::vector<int>& v, int i) {
    return i >= 0 && i < static_cast<int>(v.size()) ? v[static_cast<size_t>(i)] : -1;
  };
  // Each left_b / right_b feature may close only one loop.
  std::vector<char> used_b(static_cast<size_t>(left_b.size()), 0);
  for (int i = 0; i < left_a.size(); ++i) {
    const int ra = get(stereo_a, i);
    if (ra < 0 || ra >= right_a.size()) continue;
    ++s.candidates;
    const int lb = get(temporal_left, i);
    const int rb = get(temporal_right, ra);
    if (lb < 0 || rb < 0 || lb >= left_b.size() || rb >= right_b.size() ||
        get(stereo_b, lb) != rb || used_b[static_cast<size_t>(lb)]) {
      ++s.not_closed;
      continue;
    }
    const cv::Point2f pla = left_a.keypoints[static_cast<size_t>(i)].pt;
    const cv::Point2f pra = right_a.keypoints[static_cast<size_t>(ra)].pt;
    const cv::Point2f plb = left_b.keypoints[static_cast<size_t>(lb)].pt;
    const cv::Point2f prb = right_b.keypoints[static_cast<size_t>(rb)].pt;
    // Parallax constraint.
    const double da = pla.x - pra.x, db = plb.x - prb.x;
    if (!(da > 0 && db > 0 && da <= options.max_disparity_px && db <= options.max_disparity_px) ||
        db > options.max_disparity_ratio * da || da > options.max_disparity_ratio * db) {
      ++s.parallax_rejected;
      continue;
    }
    // Slope test on the two temporal flows.
    const cv::Point2f fl = plb - pla, fr = prb - pra;
    bool slope_ok = std::abs(fl.y - fr.y) <= options.epipolar_tolerance_px;
    const double nl = std::hypot(fl.x, fl.y), nr = std::hypot(fr.x, fr.y);
    if (slope_ok && nl >= options.slope_min_flow_px && nr >= options.slope_min_flow_px) {
      // tan of the angle between the lines = |k_l - k_r| / |1 + k_l k_r| = |cross| / |dot|.
      const double cross = static_cast<double>(fl.x) * fr.y - static_cast<double>(fl.y) * fr.x;
      const double dot = static_cast<double>(fl.x) * fr.x + static_cast<double>(fl.y) * fr.y;
      slope_ok = dot > 0 && std::abs(cross) <= options.slope_threshold * dot;
    }
    if (!slope_ok) {
      ++s.slope_rejected;
      continue;
    }
    used_b[static_cast<size_t>(lb)] = 1;
    quads.push_back({i, ra, lb, rb});
  }
  s.kept = static_cast<int>(quads.size());
  if (stats != nullptr) *stats = s;
  return quads;
}

}  // namespace fl::vo
