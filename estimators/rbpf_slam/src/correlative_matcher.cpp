#include "fusionloc/rbpf_slam/correlative_matcher.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace fl::rbpf {

namespace {

// Lookup grid over the reference points: fine values L and the coarse block maxima C.
class LookupGrid {
 public:
  LookupGrid(const std::vector<Eigen::Vector2d>& ref, double res, double sigma, int k) : res_(res) {
    Eigen::Vector2d lo = ref[0], hi = ref[0];
    for (const auto& p : ref) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
    const double margin = 3.0 * sigma + res;
    origin_ = lo - Eigen::Vector2d::Constant(margin);
    w_ = static_cast<int>(std::ceil((hi.x() - lo.x() + 2 * margin) / res)) + 1;
    h_ = static_cast<int>(std::ceil((hi.y() - lo.y() + 2 * margin) / res)) + 1;
    fine_.assign(static_cast<size_t>(w_) * h_, 0.0f);
    const int r = static_cast<int>(std::ceil(3.0 * sigma / res));
    const double inv2s2 = 1.0 / (2.0 * sigma * sigma);
    for (const auto& p : ref) {
      const Eigen::Vector2d c = (p - origin_) / res;
      const int cx = static_cast<int>(std::floor(c.x())), cy = static_cast<int>(std::floor(c.y()));
      for (int y = std::max(0, cy - r); y <= std::min(h_ - 1, cy + r); ++y) {
        for (int x = std::max(0, cx - r); x <= std::min(w_ - 1, cx + r); ++x) {
          const double dx = (x + 0.5 - c.x()) * res, dy = (y + 0.5 - c.y()) * res;
          const float v = static_cast<float>(std::exp(-(dx * dx + dy * dy) * inv2s2));
          float& cell = fine_[static_cast<size_t>(y) * w_ + x];
          cell = std::max(cell, v);
        }
      }
    }
    // C(x, y) = max over [x, x+k) x [y, y+k) of L, separably.
    std::vector<float> rows(fine_.size(), 0.0f);
    for (int y = 0; y < h_; ++y) {
      for (int x = 0; x < w_; ++x) {
        float m = 0.0f;
        for (int a = 0; a < k && x + a < w_; ++a)
          m = std::max(m, fine_[static_cast<size_t>(y) * w_ + x + a]);
        rows[static_cast<size_t>(y) * w_ + x] = m;
      }
    }
    coarse_.assign(fine_.size(), 0.0f);
    for (int y = 0; y < h_; ++y) {
      for (int x = 0; x < w_; ++x) {
        float m = 0.0f;
        for (int b = 0; b < k && y + b < h_; ++b)
          m = std::max(m, rows[static_cast<size_t>(y + b) * w_ + x]);
        coarse_[static_cast<size_t>(y) * w_ + x] = m;
      }
    }
  }

  // Cell index of a point (may be outside the grid).
  void Cell(const Eigen::Vector2d& p, int* cx, int* cy) const {
    *cx = static_cast<int>(std::floor((p.x() - origin_.x()) / res_));
    *cy = static_cast<int>(std::floor((p.y() - origin_.y()) / res_));
  }
  int width() const { return w_; }
  int height() const { return h_; }
  // Rows of the fine values L and the coarse maxima C (0 <= y < height()); outside the grid
  // both are 0.
  const float* FineRow(int y) const { return fine_.data() + static_cast<size_t>(y) * w_; }
  const float* CoarseRow(int y) const { return coarse_.data() + static_cast<size_t>(y) * w_; }

 private:
  double res_;
  Eigen::Vector2d origin_;
  int w_ = 0, h_ = 0;
  std::vector<float> fine_, coarse_;
};

// Integer division rounding up / down, for any numerator and a positive denominator.
int CeilDiv(int a, int b) { return a >= 0 ? (a + b - 1) / b : -((-a) / b); }
int FloorDivPos(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

struct CoarseCandidate {
  float bound;
  int angle, ix, iy;  // angle index, coarse translation origin in cells
};

}  // namespace

CorrelativeResult CorrelativeMatch(const std::vector<Eigen::Vector2d>& reference,
                                   const std::vector<Eigen::Vector2d>& query,
                                   const fl::Pose2& initial, const CorrelativeOptions& options) {
  const Status s = options.Validate();
  if (!s.ok()) throw std::invalid_argument("CorrelativeMatch: " + s.message());
  CorrelativeResult out;
  out.T_ref_query = initial;
  if (reference.empty() || query.empty()) return out;

  // Evenly subsampled query points.
  std::vector<Eigen::Vector2d> q;
  const size_t n_use = options.max_points > 0
                           ? std::min(query.size(), static_cast<size_t>(options.max_points))
                           : query.size();
  q.reserve(n_use);
  for (size_t i = 0; i < n_use; ++i) q.push_back(query[i * query.size() / n_use]);
  const double inv_n = 1.0 / static_cast<double>(q.size());

  double step = options.angular_step;
  if (step <= 0.0) {
    std::vector<double> r;
    r.reserve(q.size());
    for (const auto& p : q) r.push_back(p.norm());
    const size_t i95 = (r.size() * 95) / 100;
    std::nth_element(r.begin(), r.begin() + std::min(i95, r.size() - 1), r.end());
    step = options.resolution / std::max(r[std::min(i95, r.size() - 1)], 1.0);
  }
  const int na = options.angular_window > 0.0
                     ? static_cast<int>(std::ceil(options.angular_window / step - 1e-9))
                     : 0;
  const int k = options.coarse_factor;
  const int nt = static_cast<int>(std::ceil(options.linear_window / options.resolution - 1e-9));
  const LookupGrid grid(reference, options.resolution, options.sigma, k);

  // Per heading: the cells of the rotated query points, translated by the initial guess.
  const int n_angles = 2 * na + 1;
  std::vector<std::vector<int>> cells(n_angles);
  std::vector<CoarseCandidate> cand;
  const int nc = (2 * nt) / k + 1;  // coarse translations per axis: -nt, -nt + k, ... <= nt
  std::vector<double> sums(static_cast<size_t>(nc) * nc);
  for (int a = 0; a < n_angles; ++a) {
    const double th = initial.theta + (a - na) * step;
    const fl::Pose2 T(initial.x, initial.y, th);
    std::vector<int>& c = cells[a];
    c.resize(2 * q.size());
    for (size_t i = 0; i < q.size(); ++i) grid.Cell(T * q[i], &c[2 * i], &c[2 * i + 1]);
    // sums[row * nc + col] for the translation (ix, iy) = (-nt + col k, -nt + row k). The loop
    // runs point by point (each point's row of the table is read in order); every sum still
    // adds its points in the same order, and a point outside the grid adds 0, so it is skipped.
    std::fill(sums.begin(), sums.end(), 0.0);
    for (size_t i = 0; i < q.size(); ++i) {
      const int cx = c[2 * i], cy = c[2 * i + 1];
      // Columns whose x = cx - nt + col k lies in [0, w).
      const int col0 = std::max(0, CeilDiv(-(cx - nt), k));
      const int col1 = std::min(nc - 1, FloorDivPos(grid.width() - 1 - (cx - nt), k));
      if (col0 > col1) continue;
      for (int row = 0; row < nc; ++row) {
        const int y = cy - nt + row * k;
        if (y < 0 || y >= grid.height()) continue;
        const float* line = grid.CoarseRow(y);
        double* out_row = &sums[static_cast<size_t>(row) * nc];
        for (int col = col0; col <= col1; ++col) out_row[col] += line[cx - nt + col * k];
      }
    }
    for (int row = 0; row < nc; ++row) {
      for (int col = 0; col < nc; ++col) {
        cand.push_back({static_cast<float>(sums[static_cast<size_t>(row) * nc + col] * inv_n), a,
                        -nt + col * k, -nt + row * k});
      }
    }
  }
  std::sort(cand.begin(), cand.end(),
            [](const CoarseCandidate& x, const CoarseCandidate& y) { return x.bound > y.bound; });

  // Expand coarse cells in order of their bound until none can beat the best exact score. Ties
  // go to the pose nearer the initial guess.
  std::vector<double> block(static_cast<size_t>(k) * k);
  double best = -1.0, best_dist = 0.0;
  int best_a = na, best_x = 0, best_y = 0;
  for (const CoarseCandidate& cc : cand) {
    if (cc.bound + 1e-6 < best) break;
    const std::vector<int>& c = cells[cc.angle];
    // The block's translations: ix in [cc.ix, x_end), iy in [cc.iy, y_end); the sums run point by
    // point as above.
    const int x_end = std::min(cc.ix + k, nt + 1), y_end = std::min(cc.iy + k, nt + 1);
    std::fill(block.begin(), block.end(), 0.0);
    for (size_t i = 0; i < q.size(); ++i) {
      const int cx = c[2 * i], cy = c[2 * i + 1];
      const int ix0 = std::max(cc.ix, -cx), ix1 = std::min(x_end, grid.width() - cx);
      if (ix0 >= ix1) continue;
      for (int iy = std::max(cc.iy, -cy); iy < std::min(y_end, grid.height() - cy); ++iy) {
        const float* line = grid.FineRow(cy + iy);
        double* out_row = &block[static_cast<size_t>(iy - cc.iy) * k];
        for (int ix = ix0; ix < ix1; ++ix) out_row[ix - cc.ix] += line[cx + ix];
      }
    }
    for (int iy = cc.iy; iy < y_end; ++iy) {
      for (int ix = cc.ix; ix < x_end; ++ix) {
        const double sum = block[static_cast<size_t>(iy - cc.iy) * k + (ix - cc.ix)];
        ++out.evaluated;
        const double score = sum * inv_n;
        const double dist = std::hypot(ix * options.resolution, iy * options.resolution) +
                            std::abs((cc.angle - na) * step) * 1.0;
        if (score > best + 1e-9 || (score > best - 1e-9 && dist < best_dist)) {
          best = score;
          best_dist = dist;
          best_a = cc.angle;
          best_x = ix;
          best_y = iy;
        }
      }
    }
  }
  out.ok = true;
  out.score = best;
  out.at_window_edge =
      std::abs(best_x) == nt || std::abs(best_y) == nt || (na > 0 && std::abs(best_a - na) == na);
  out.T_ref_query =
      fl::Pose2(initial.x + best_x * options.resolution, initial.y + best_y * options.resolution,
                initial.theta + (best_a - na) * step);
  return out;
}

}  // namespace fl::rbpf
