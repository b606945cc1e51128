#include "fusionloc/rbpf_slam/icp.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <unordered_map>

namespace fl::rbpf {

std::vector<PointNormal> ComputeNormals(const std::vector<Eigen::Vector2d>& pts, double max_gap) {
  std::vector<PointNormal> out;
  out.reserve(pts.size());
  const int n = static_cast<int>(pts.size());
  for (int i = 0; i < n; ++i) {
    Eigen::Vector2d mean = pts[i];
    int count = 1;
    for (int k = i - 2; k <= i + 2; ++k) {
      if (k == i || k < 0 || k >= n) continue;
      if ((pts[k] - pts[i]).norm() > max_gap) continue;
      mean += pts[k];
      ++count;
    }
    if (count < 3) continue;
    mean /= count;
    Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
    for (int k = i - 2; k <= i + 2; ++k) {
      if (k < 0 || k >= n || (pts[k] - pts[i]).norm() > max_gap) continue;
      const Eigen::Vector2d d = pts[k] - mean;
      cov += d * d.transpose();
    }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(cov);
    // A line: the small eigenvalue must be much smaller than the large one.
    if (es.eigenvalues()(0) > 0.1 * es.eigenvalues()(1)) continue;
    PointNormal pn;
    pn.p = pts[i];
    pn.n = es.eigenvectors().col(0).normalized();
    out.push_back(pn);
  }
  return out;
}

namespace {
// A uniform hash grid over the reference points for nearest-neighbour queries.
class PointHash {
 public:
  PointHash(const std::vector<PointNormal>& pts, double cell) : pts_(pts), inv_(1.0 / cell) {
    for (size_t i = 0; i < pts.size(); ++i) map_[Key(Cell(pts[i].p.x()), Cell(pts[i].p.y()))].push_back(static_cast<int>(i));
  }
  // Index of the nearest reference point within max_d, or -1.
  int Nearest(const Eigen::Vector2d& q, double max_d) const {
    const int cx = Cell(q.x()), cy = Cell(q.y());
    int best = -1;
    double best_d2 = max_d * max_d;
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        const auto it = map_.find(Key(cx + dx, cy + dy));
        if (it == map_.end()) continue;
        for (int i : it->second) {
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
    return (static_cast<int64_t>(x) << 32) ^ static_cast<int64_t>(static_cast<uint32_t>(y));
  }
  const std::vector<PointNormal>& pts_;
  double inv_;
  std::unordered_map<int64_t, std::vector<int>> map_;
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
  const PointHash hash(reference, o.max_correspondence_m);
  fl::Pose2 T = initial;
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  double sum_sq = 0.0;
  int pairs = 0;
  bool converged = false;
  for (int it = 0; it < o.max_iterations; ++it) {
    // Pairing distance shrinks geometrically over the first iterations.
    const double frac = std::min(1.0, it / 8.0);
    const double max_d = o.max_correspondence_m *
                         std::pow(o.final_correspondence_m / o.max_correspondence_m, frac);
    const double c = std::cos(T.theta), s = std::sin(T.theta);
    H.setZero();
    Eigen::Vector3d g = Eigen::Vector3d::Zero();
    sum_sq = 0.0;
    pairs = 0;
    for (const Eigen::Vector2d& q : query) {
      const Eigen::Vector2d w(T.x + c * q.x() - s * q.y(), T.y + s * q.x() + c * q.y());
      const int j = hash.Nearest(w, max_d);
      if (j < 0) continue;
      const Eigen::Vector2d& n = reference[j].n;
      const double e = n.dot(w - reference[j].p);
      const Eigen::Vector3d J(n.x(), n.y(), n.x() * (-s * q.x() - c * q.y()) + n.y() * (c * q.x() - s * q.y()));
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
    const Eigen::Vector3d delta = -(H + 1e-9 * Eigen::Matrix3d::Identity()).ldlt().solve(g);
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
  // Information at the solution (unweighted Hessian, as the Gaussian fit supports it).
  {
    const double c = std::cos(T.theta), s = std::sin(T.theta);
    Eigen::Matrix3d Hs = Eigen::Matrix3d::Zero();
    for (const Eigen::Vector2d& q : query) {
      const Eigen::Vector2d w(T.x + c * q.x() - s * q.y(), T.y + s * q.x() + c * q.y());
      const int j = hash.Nearest(w, o.final_correspondence_m);
      if (j < 0) continue;
      const Eigen::Vector2d& n = reference[j].n;
      const Eigen::Vector3d J(n.x(), n.y(), n.x() * (-s * q.x() - c * q.y()) + n.y() * (c * q.x() - s * q.y()));
      Hs.noalias() += J * J.transpose();
    }
    r.information = Hs / (o.sigma * o.sigma);
  }
  if (pairs < o.min_points) {
    r.failure = "only " + std::to_string(pairs) + " point pairs (need " + std::to_string(o.min_points) + ")";
  } else if (r.inlier_fraction < o.min_inlier_fraction) {
    r.failure = "inlier fraction " + std::to_string(r.inlier_fraction) + " below " +
                std::to_string(o.min_inlier_fraction);
  } else if (r.rms > o.max_rms) {
    r.failure = "RMS " + std::to_string(r.rms) + " m above " + std::to_string(o.max_rms);
  } else {
    // A good fit is accepted even if the last steps were still creeping below 1e-5 m.
    r.ok = true;
  }
  return r;
}

}  // namespace fl::rbpf
