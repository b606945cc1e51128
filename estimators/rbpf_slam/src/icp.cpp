#include "fusionloc/rbpf_slam/icp.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

#include "fusionloc/rbpf_slam/scan_matcher.hpp"

namespace fl::rbpf {

double ScanRangeNoise(const std::vector<Eigen::Vector2d>& pts, double max_step) {
  std::vector<double> d;
  d.reserve(pts.size());
  const double s2 = max_step * max_step;
  for (size_t k = 1; k + 1 < pts.size(); ++k) {
    if ((pts[k] - pts[k - 1]).squaredNorm() > s2 || (pts[k + 1] - pts[k]).squaredNorm() > s2) {
      continue;
    }
    d.push_back(std::abs(pts[k - 1].norm() - 2.0 * pts[k].norm() + pts[k + 1].norm()));
  }
  if (d.size() < 10) return 0.0;
  std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
  return d[d.size() / 2] / (0.6745 * std::sqrt(6.0));
}

namespace {
// The unit normal at pts[i] from a line fit (PCA) over its neighbours in scan order within
// `radius` of it, not across a step above max_gap; false if fewer than 3 points or their scatter
// is not a line (small / large eigenvalue > max_eigen_ratio).
bool FitNormal(const std::vector<Eigen::Vector2d>& pts, int i, double radius,
               double max_eigen_ratio, double max_gap, Eigen::Vector2d* normal) {
  const int n = static_cast<int>(pts.size());
  const double r2 = radius * radius, g2 = max_gap * max_gap;
  int lo = i, hi = i;
  while (lo > 0 && (pts[lo - 1] - pts[lo]).squaredNorm() <= g2 &&
         (pts[lo - 1] - pts[i]).squaredNorm() <= r2) {
    --lo;
  }
  while (hi < n - 1 && (pts[hi + 1] - pts[hi]).squaredNorm() <= g2 &&
         (pts[hi + 1] - pts[i]).squaredNorm() <= r2) {
    ++hi;
  }
  const int count = hi - lo + 1;
  if (count < 3) return false;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (int k = lo; k <= hi; ++k) mean += pts[k];
  mean /= count;
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
  for (int k = lo; k <= hi; ++k) {
    const Eigen::Vector2d d = pts[k] - mean;
    cov += d * d.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(cov);
  // A line: the small eigenvalue must be much smaller than the large one.
  if (!(es.eigenvalues()(1) > 0.0) ||
      es.eigenvalues()(0) > max_eigen_ratio * es.eigenvalues()(1)) {
    return false;
  }
  *normal = es.eigenvectors().col(0).normalized();
  return true;
}

// Normals within (radius, max_gap) and, where wider, n_wide within (wide_radius, wide_gap).
std::vector<PointNormal> NormalsWithin(const std::vector<Eigen::Vector2d>& pts, double radius,
                                       double max_gap, double max_eigen_ratio, double wide_radius,
                                       double wide_gap) {
  const bool wider = wide_radius > radius || wide_gap > max_gap;
  std::vector<PointNormal> out;
  out.reserve(pts.size());
  for (int i = 0; i < static_cast<int>(pts.size()); ++i) {
    PointNormal pn;
    if (!FitNormal(pts, i, radius, max_eigen_ratio, max_gap, &pn.n)) continue;
    pn.p = pts[i];
    // Where the wide fit is no line (a corner, clutter), the point's own normal stands.
    if (!wider || !FitNormal(pts, i, wide_radius, max_eigen_ratio, wide_gap, &pn.n_wide)) {
      pn.n_wide = pn.n;
    }
    out.push_back(pn);
  }
  return out;
}
}  // namespace

std::vector<PointNormal> ComputeNormals(const std::vector<Eigen::Vector2d>& pts, double radius,
                                        double max_eigen_ratio, double max_gap) {
  return NormalsWithin(pts, radius, max_gap, max_eigen_ratio, radius, max_gap);
}

std::vector<PointNormal> ComputeNormals(const std::vector<Eigen::Vector2d>& pts,
                                        const IcpOptions& o) {
  return ComputeNormals(pts, o, ScanRangeNoise(pts));
}

std::vector<PointNormal> ComputeNormals(const std::vector<Eigen::Vector2d>& pts,
                                        const IcpOptions& o, double noise) {
  return NormalsWithin(pts, o.normal_radius, o.normal_max_gap, o.normal_max_eigen_ratio,
                       std::max(o.normal_radius, o.normal_radius_per_noise * noise),
                       std::max(o.normal_max_gap, o.normal_gap_per_noise * noise));
}

int IcpCovariance(const Eigen::Matrix3d& H, const Eigen::Matrix3d& M, int n, double correlation,
                  double length_m, const IcpOptions& o, Eigen::Matrix3d* covariance,
                  Eigen::Matrix3d* information) {
  const double L = length_m > 0.0 ? length_m : 1.0;
  const Eigen::Vector3d s(1.0, 1.0, 1.0 / L);  // (x, y, θ) -> scaled (x, y, L·θ)
  const Eigen::Matrix3d Hs = s.asDiagonal() * (0.5 * (H + H.transpose())) * s.asDiagonal();
  // Residual "meat" with the small-sample correction n/(n-3) and the σ̂ floor.
  const double dof = n > 3 ? static_cast<double>(n) / (n - 3) : 1.0;
  const Eigen::Matrix3d Ms = s.asDiagonal() *
                             (dof * 0.5 * (M + M.transpose()) + o.min_sigma * o.min_sigma * H) *
                             s.asDiagonal();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(Hs);
  const double rho = std::clamp(correlation, 0.0, 0.95);
  const double kappa = (1.0 + rho) / (1.0 - rho);
  const double max_var = o.max_sigma_xy * o.max_sigma_xy;  // scaled units: m² (θ: (L·rad)²)
  const double lmax = std::max(es.eigenvalues()(2), 0.0);
  // H⁺ over the constrained directions; the others get max_var.
  Eigen::Matrix3d Hp = Eigen::Matrix3d::Zero(), cov_s = Eigen::Matrix3d::Zero();
  int degenerate = 0;
  for (int k = 0; k < 3; ++k) {
    const double l = es.eigenvalues()(k);
    const Eigen::Vector3d v = es.eigenvectors().col(k);
    if (l > std::max(1e-9, o.degeneracy_ratio) * lmax && l > 0.0) {
      Hp += (1.0 / l) * v * v.transpose();
    } else {
      ++degenerate;
      cov_s += max_var * v * v.transpose();
    }
  }
  cov_s += kappa * Hp * Ms * Hp;  // sandwich: H⁻¹ (Σ J Jᵀ e²) H⁻¹
  // Back to (x, y, θ), add the floor, cap every eigenvalue (in scaled units) at max_var.
  Eigen::Matrix3d cov = s.asDiagonal() * cov_s * s.asDiagonal();
  cov += Eigen::Vector3d(o.floor_sigma_xy * o.floor_sigma_xy, o.floor_sigma_xy * o.floor_sigma_xy,
                         o.floor_sigma_theta * o.floor_sigma_theta)
             .asDiagonal();
  const Eigen::Matrix3d cs = s.cwiseInverse().asDiagonal() * cov * s.cwiseInverse().asDiagonal();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> ec(0.5 * (cs + cs.transpose()));
  Eigen::Matrix3d info_s = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d cov_capped_s = Eigen::Matrix3d::Zero();
  for (int k = 0; k < 3; ++k) {
    const double v = std::min(max_var, std::max(ec.eigenvalues()(k), 1e-12));
    const Eigen::Vector3d u = ec.eigenvectors().col(k);
    cov_capped_s += v * u * u.transpose();
    info_s += (1.0 / v) * u * u.transpose();
  }
  *covariance = s.asDiagonal() * cov_capped_s * s.asDiagonal();
  *information = s.cwiseInverse().asDiagonal() * info_s * s.cwiseInverse().asDiagonal();
  *covariance = 0.5 * (*covariance + covariance->transpose());
  *information = 0.5 * (*information + information->transpose());
  return degenerate;
}

namespace {
// A uniform grid over the reference points for nearest-neighbour queries, stored flat: the
// points' indices sorted by cell (within a cell in input order), and an open-addressing table
// from a cell to its range. Memory grows with the points, not with the area they span.
class PointHash {
 public:
  PointHash(const std::vector<PointNormal>& pts, double cell) : pts_(pts), inv_(1.0 / cell) {
    std::vector<std::pair<int64_t, int>> keyed(pts.size());
    for (size_t i = 0; i < pts.size(); ++i) {
      keyed[i] = {Key(Cell(pts[i].p.x()), Cell(pts[i].p.y())), static_cast<int>(i)};
    }
    std::sort(keyed.begin(), keyed.end());  // by cell, then by index: input order in a cell
    order_.resize(keyed.size());
    for (size_t i = 0; i < keyed.size(); ++i) {
      order_[i] = keyed[i].second;
      if (i == 0 || keyed[i].first != keyed[i - 1].first) {
        cell_keys_.push_back(keyed[i].first);
        cell_start_.push_back(static_cast<int>(i));
      }
    }
    cell_start_.push_back(static_cast<int>(keyed.size()));
    int bits = 4;
    while ((size_t{1} << bits) < 2 * cell_keys_.size()) ++bits;
    shift_ = 64 - bits;
    slots_.assign(size_t{1} << bits, -1);
    for (size_t c = 0; c < cell_keys_.size(); ++c) {
      size_t h = Slot(cell_keys_[c]);
      while (slots_[h] >= 0) h = (h + 1) & (slots_.size() - 1);
      slots_[h] = static_cast<int>(c);
    }
  }
  // Index of the nearest reference point within max_d, or -1 (ties: the first in the order of
  // the neighbouring cells, then of the input).
  int Nearest(const Eigen::Vector2d& q, double max_d) const {
    const int cx = Cell(q.x()), cy = Cell(q.y());
    int best = -1;
    double best_d2 = max_d * max_d;
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        const int c = Find(Key(cx + dx, cy + dy));
        if (c < 0) continue;
        for (int k = cell_start_[c]; k < cell_start_[c + 1]; ++k) {
          const int i = order_[k];
          const double d2 = (pts_[i].p - q).squaredNorm();
          if (d2 < best_d2) {
            best_d2 = d2;
            best = i;
          }
        }
      }
    }
    return best;
  }

 private:
  int Cell(double v) const { return static_cast<int>(std::floor(v * inv_)); }
  static int64_t Key(int x, int y) {
    // Shift as unsigned: shifting a negative int64 left is undefined before C++20 (UBSan).
    return static_cast<int64_t>((static_cast<uint64_t>(static_cast<uint32_t>(x)) << 32) |
                                static_cast<uint64_t>(static_cast<uint32_t>(y)));
  }
  size_t Slot(int64_t key) const {  // Fibonacci hashing: the top bits of key * 2^64/φ
    return static_cast<size_t>((static_cast<uint64_t>(key) * 0x9E3779B97F4A7C15ull) >> shift_);
  }
  int Find(int64_t key) const {
    for (size_t h = Slot(key);; h = (h + 1) & (slots_.size() - 1)) {
      const int c = slots_[h];
      if (c < 0) return -1;
      if (cell_keys_[c] == key) return c;
    }
  }
  const std::vector<PointNormal>& pts_;
  double inv_;
  std::vector<int> order_;          // point indices sorted by cell
  std::vector<int64_t> cell_keys_;  // distinct cells, ascending
  std::vector<int> cell_start_;     // cell c's points: order_[cell_start_[c] .. cell_start_[c+1])
  std::vector<int> slots_;          // open addressing (load <= 1/2): cell index or -1
  int shift_ = 60;
};
}  // namespace

IcpResult AlignPointToLine(const std::vector<PointNormal>& reference,
                           const std::vector<Eigen::Vector2d>& query, const fl::Pose2& initial,
                           const IcpOptions& o) {
  IcpResult r;
  r.T_ref_query = initial;
  if (static_cast<int>(reference.size()) < o.min_points ||
      static_cast<int>(query.size()) < o.min_points) {
    r.failure = "too few points (reference " + std::to_string(reference.size()) + ", query " +
                std::to_string(query.size()) + ", need " + std::to_string(o.min_points) + ")";
    return r;
  }
  // Cells as large as the pairing distance, so the 3 x 3 neighbourhood holds every point within
  // it: one grid for the wide first iterations, one for the final distance (about a tenth of
  // the candidates to test). The factor keeps the final cell above max_d's rounding.
  const PointHash coarse_hash(reference, o.max_correspondence_m);
  const double fine_cell = o.final_correspondence_m * (1.0 + 1e-9);
  const PointHash fine_hash(reference, fine_cell);
  double query_sq = 0.0;
  for (const Eigen::Vector2d& q : query) query_sq += q.squaredNorm();
  const double length_m = std::sqrt(query_sq / static_cast<double>(query.size()));
  fl::Pose2 T = initial;
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  double sum_sq = 0.0;
  int pairs = 0;
  bool converged = false;
  for (int it = 0; it < o.max_iterations; ++it) {
    // Pairing distance shrinks geometrically over the first iterations.
    const double frac = std::min(1.0, it / 8.0);
    const double max_d =
        o.max_correspondence_m * std::pow(o.final_correspondence_m / o.max_correspondence_m, frac);
    const double c = std::cos(T.theta), s = std::sin(T.theta);
    H.setZero();
    Eigen::Vector3d g = Eigen::Vector3d::Zero();
    sum_sq = 0.0;
    pairs = 0;
    for (const Eigen::Vector2d& q : query) {
      const Eigen::Vector2d w(T.x + c * q.x() - s * q.y(), T.y + s * q.x() + c * q.y());
      const int j = (max_d <= fine_cell ? fine_hash : coarse_hash).Nearest(w, max_d);
      if (j < 0) continue;
      const Eigen::Vector2d& n = reference[j].n;
      const double e = n.dot(w - reference[j].p);
      const Eigen::Vector3d J = PoseJacobian(n, q, c, s);
      // Huber weight at 2 x the final pairing distance / 4 keeps outliers from dominating.
      const double k = 0.5 * o.final_correspondence_m;
      const double wgt = std::abs(e) <= k ? 1.0 : k / std::abs(e);
      H.noalias() += wgt * J * J.transpose();
      g.noalias() += wgt * J * e;
      sum_sq += e * e;
      ++pairs;
    }
    r.iterations = it + 1;
    if (pairs < o.min_points) break;
    // Once the pairing distance is final, steps only along the directions the scene constrains
    // (the rest stays where the coarse iterations left it instead of drifting on normal noise;
    // icp.hpp). The coarse iterations move freely: far from the solution the Hessian of wrong
    // pairs says little about the scene.
    const Eigen::Matrix3d P = frac >= 1.0
                                  ? WellConstrainedProjector(H, length_m, o.degeneracy_ratio)
                                  : Eigen::Matrix3d::Identity();
    const Eigen::Vector3d delta = P * (-(H + 1e-9 * Eigen::Matrix3d::Identity()).ldlt().solve(g));
    if (!delta.allFinite()) break;
    T = fl::Pose2(T.x + delta.x(), T.y + delta.y(), fl::WrapAngle(T.theta + delta.z()));
    if (frac >= 1.0 && delta.head<2>().norm() < 1e-5 && std::abs(delta.z()) < 1e-5) {
      converged = true;
      break;
    }
  }
  r.T_ref_query = T;
  r.pairs = pairs;
  r.converged = converged;
  r.rms = pairs > 0 ? std::sqrt(sum_sq / pairs) : 0.0;
  r.inlier_fraction = static_cast<double>(pairs) / static_cast<double>(query.size());
  // Covariance at the solution (icp.hpp): unweighted Hessian, residual variance, lag-1
  // correlation of the residuals of consecutive query beams.
  {
    const double c = std::cos(T.theta), s = std::sin(T.theta);
    Eigen::Matrix3d Hs = Eigen::Matrix3d::Zero();
    Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
    Eigen::Matrix3d Hw = Eigen::Matrix3d::Zero();  // H and M with the wide normals (icp.hpp)
    Eigen::Matrix3d Mw = Eigen::Matrix3d::Zero();
    double e2 = 0.0, e_lag = 0.0, length_sq = 0.0;
    int n = 0, prev_index = -2;
    double prev_e = 0.0;
    for (size_t i = 0; i < query.size(); ++i) {
      const Eigen::Vector2d& q = query[i];
      const Eigen::Vector2d w(T.x + c * q.x() - s * q.y(), T.y + s * q.x() + c * q.y());
      const int j = fine_hash.Nearest(w, o.final_correspondence_m);
      if (j < 0) continue;
      const Eigen::Vector2d& nj = reference[j].n;
      const double e = nj.dot(w - reference[j].p);
      const Eigen::Vector3d J = PoseJacobian(nj, q, c, s);
      Hs.noalias() += J * J.transpose();
      M.noalias() += (e * e) * J * J.transpose();
      const Eigen::Vector2d& nw = reference[j].n_wide;
      const Eigen::Vector3d Jw =
          (nw == nj || nw.squaredNorm() == 0.0) ? J : PoseJacobian(nw, q, c, s);
      Hw.noalias() += Jw * Jw.transpose();
      Mw.noalias() += (e * e) * Jw * Jw.transpose();
      e2 += e * e;
      if (prev_index == static_cast<int>(i) - 1) e_lag += e * prev_e;
      prev_index = static_cast<int>(i);
      prev_e = e;
      length_sq += q.squaredNorm();
      ++n;
    }
    r.length_m = n > 0 ? std::sqrt(length_sq / n) : 1.0;
    if (Hw != Hs) {
      // Directions the wide normals leave unconstrained and the point's own ones do not: their
      // information came from the normals' noise (icp.hpp).
      int narrow = 0, wide = 0;
      WellConstrainedProjector(Hs, r.length_m, o.degeneracy_ratio, &narrow);
      WellConstrainedProjector(Hw, r.length_m, o.degeneracy_ratio, &wide);
      r.noise_made_dims = std::max(0, wide - narrow);
      Hs = Hw;
      M = Mw;
    }
    r.hessian = Hs;
    r.sigma = n > 3 ? std::sqrt(e2 / (n - 3)) : o.max_rms;
    r.correlation = e2 > 0.0 ? e_lag / e2 : 0.0;
    r.degenerate_dims =
        IcpCovariance(Hs, M, n, r.correlation, r.length_m, o, &r.covariance, &r.information);
  }
  if (pairs < o.min_points) {
    r.failure = "only " + std::to_string(pairs) + " point pairs (need " +
                std::to_string(o.min_points) + ")";
  } else if (r.inlier_fraction < o.min_inlier_fraction) {
    r.failure = "inlier fraction " + std::to_string(r.inlier_fraction) + " below " +
                std::to_string(o.min_inlier_fraction);
  } else if (r.rms > o.max_rms) {
    r.failure = "RMS " + std::to_string(r.rms) + " m above " + std::to_string(o.max_rms);
    r.failed_only_rms = true;
  } else {
    // A good fit is accepted even if the last steps were still creeping below 1e-5 m.
    r.ok = true;
  }
  return r;
}

}  // namespace fl::rbpf
