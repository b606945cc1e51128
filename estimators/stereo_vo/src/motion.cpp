#include "fusionloc/stereo_vo/motion.hpp"

#include <ceres/ceres.h>

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>

#include "ba_kernels.hpp"
#include "fusionloc/stereo_vo/reprojection_cost.hpp"

namespace fl::vo {
namespace {

using ba::Skew;

}  // namespace

bool SolveRigidSvd(const std::vector<Eigen::Vector3d>& p_a, const std::vector<Eigen::Vector3d>& p_b,
                   const std::vector<int>& idx, Eigen::Isometry3d* T_a_b,
                   const std::vector<double>* weights) {
  const size_t n = idx.empty() ? p_a.size() : idx.size();
  if (n < 3 || p_a.size() != p_b.size()) return false;
  if (weights != nullptr && weights->size() != p_a.size()) return false;
  auto index = [&](size_t k) { return idx.empty() ? k : static_cast<size_t>(idx[k]); };
  auto weight = [&](size_t k) { return weights == nullptr ? 1.0 : (*weights)[index(k)]; };
  // Centroids (eq. 16), cross-covariance H = sum w (p_b - mu_b)(p_a - mu_a)^T (eq. 17).
  Eigen::Vector3d mu_a = Eigen::Vector3d::Zero(), mu_b = Eigen::Vector3d::Zero();
  double wsum = 0;
  for (size_t k = 0; k < n; ++k) {
    const double w = weight(k);
    mu_a += w * p_a[index(k)];
    mu_b += w * p_b[index(k)];
    wsum += w;
  }
  if (!(wsum > 0)) return false;
  mu_a /= wsum;
  mu_b /= wsum;
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  double spread = 0;
  for (size_t k = 0; k < n; ++k) {
    const Eigen::Vector3d db = p_b[index(k)] - mu_b;
    H += weight(k) * db * (p_a[index(k)] - mu_a).transpose();
    spread += weight(k) * db.squaredNorm();
  }
  if (!(spread > 1e-18)) return false;
  // R = V diag(1, 1, det(V U^T)) U^T (eq. 18), t = mu_a - R mu_b.
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d s = svd.singularValues();
  // Rank < 2 (all points on a line): rotation about that line is unobservable.
  if (!(s(1) > 1e-9 * std::max(1.0, s(0)))) return false;
  const Eigen::Matrix3d U = svd.matrixU(), V = svd.matrixV();
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  D(2, 2) = (V * U.transpose()).determinant() < 0 ? -1.0 : 1.0;
  const Eigen::Matrix3d R = V * D * U.transpose();
  T_a_b->setIdentity();
  T_a_b->linear() = R;
  T_a_b->translation() = mu_a - R * mu_b;
  return R.allFinite() && T_a_b->translation().allFinite();
}

double ForwardReprojectionError(const StereoCamera& cam, const Eigen::Isometry3d& T_a_b,
                                const StereoCorrespondence& c) {
  Eigen::Vector3d uvu;
  if (!cam.Project(T_a_b.inverse() * c.p_a, &uvu)) return 1e9;
  return (uvu - c.obs_b).cwiseAbs().maxCoeff();
}

RansacResult RansacMotion(const StereoCamera& cam, const std::vector<StereoCorrespondence>& corr,
                          const RansacOptions& options) {
  RansacResult result;
  const int n = static_cast<int>(corr.size());
  if (n < std::max(3, options.min_inliers)) return result;
  std::vector<Eigen::Vector3d> p_a(corr.size()), p_b(corr.size());
  std::vector<double> precision(corr.size());
  for (size_t i = 0; i < corr.size(); ++i) {
    p_a[i] = corr[i].p_a;
    p_b[i] = corr[i].p_b;
    const double da = corr[i].obs_a(0) - corr[i].obs_a(2), db = corr[i].obs_b(0) - corr[i].obs_b(2);
    precision[i] = da * da * db * db;
  }
  std::mt19937 rng(static_cast<uint32_t>(options.seed));
  // Minimal samples come from the nearer half (larger disparity at both times): the 3D-3D
  // solution needs depth, and far points' depth is too noisy (sigma_z ~ z^2 sigma_d / (f b)).
  std::vector<std::pair<double, int>> by_disparity(corr.size());
  for (int i = 0; i < n; ++i) {
    const StereoCorrespondence& c = corr[static_cast<size_t>(i)];
    by_disparity[static_cast<size_t>(i)] = {
        -std::min(c.obs_a(0) - c.obs_a(2), c.obs_b(0) - c.obs_b(2)), i};
  }
  std::sort(by_disparity.begin(), by_disparity.end());
  const int pool_size = std::max(std::min(n, 8), n / 2);
  std::uniform_int_distribution<int> pick_pool(0, pool_size - 1);
  auto pick = [&](std::mt19937&) {
    return by_disparity[static_cast<size_t>(pick_pool(rng))].second;
  };

  auto count_inliers = [&](const Eigen::Isometry3d& T, std::vector<int>* inliers) {
    inliers->clear();
    const Eigen::Isometry3d T_b_a = T.inverse();
    Eigen::Vector3d uvu;
    for (int i = 0; i < n; ++i) {
      if (!cam.Project(T_b_a * corr[i].p_a, &uvu)) continue;
      if ((uvu - corr[i].obs_b).cwiseAbs().maxCoeff() <= options.inlier_threshold_px) {
        inliers->push_back(i);
      }
    }
  };

  std::vector<int> best, current;
  Eigen::Isometry3d best_T = Eigen::Isometry3d::Identity();
  int needed = options.max_iterations;
  const int min_iterations = std::min(options.max_iterations, 30);
  int it = 0;
  for (; it < needed && it < options.max_iterations; ++it) {
    int s[3];
    s[0] = pick(rng);
    do s[1] = pick(rng);
    while (s[1] == s[0]);
    do s[2] = pick(rng);
    while (s[2] == s[0] || s[2] == s[1]);
    Eigen::Isometry3d T;
    if (!SolveRigidSvd(p_a, p_b, {s[0], s[1], s[2]}, &T)) continue;
    count_inliers(T, &current);
    if (current.size() > best.size()) {
      best.swap(current);
      best_T = T;
      const double w = static_cast<double>(best.size()) / n;
      const double p_fail = 1.0 - w * w * w;
      if (p_fail < 1e-12) {
        needed = std::max(min_iterations, it + 1);
      } else {
        const double k = std::log(1.0 - options.confidence) / std::log(p_fail);
        needed = std::min(options.max_iterations,
                          std::max(min_iterations, static_cast<int>(std::ceil(k)) + 1));
      }
    }
  }
  result.iterations = it;
  if (static_cast<int>(best.size()) < options.min_inliers) return result;
  // Re-estimate from all inliers, then re-collect inliers (twice converges in practice).
  for (int round = 0; round < 2; ++round) {
    Eigen::Isometry3d T;
    if (!SolveRigidSvd(p_a, p_b, best, &T, &precision)) break;
    count_inliers(T, &current);
    if (current.size() < best.size()) break;
    best.swap(current);
    best_T = T;
  }
  result.ok = static_cast<int>(best.size()) >= options.min_inliers;
  result.T_a_b = best_T;
  result.inliers = std::move(best);
  return result;
}

namespace {

// Two-view bundle adjustment: pose perturbation and every inlier point (frame a).
RefineResult RefineJoint(const StereoCamera& cam, const std::vector<StereoCorrespondence>& corr,
                         const std::vector<int>& inliers, const Eigen::Isometry3d& T0,
                         const RefineOptions& options, std::vector<Eigen::Vector3d>* points_a) {
  RefineResult result;
  result.T_a_b = T0;
  const size_t n = inliers.size();
  if (n < 3) return result;
  std::vector<Eigen::Vector3d> pts(n);
  for (size_t k = 0; k < n; ++k) pts[k] = corr[static_cast<size_t>(inliers[k])].p_a;
  double delta[6] = {0, 0, 0, 0, 0, 0};
  std::vector<ceres::CostFunction*> cost_a(n), cost_b(n);
  ceres::Problem problem;
  for (size_t k = 0; k < n; ++k) {
    const StereoCorrespondence& c = corr[static_cast<size_t>(inliers[k])];
    cost_a[k] = StereoPointCostA::Create(cam, c.obs_a);
    cost_b[k] = StereoPointCostB::Create(cam, T0, c.obs_b);
    problem.AddResidualBlock(cost_a[k], new ceres::HuberLoss(options.huber_px), pts[k].data());
    problem.AddResidualBlock(cost_b[k], new ceres::HuberLoss(options.huber_px), delta,
                             pts[k].data());
  }
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_SCHUR;
  so.max_num_iterations = options.max_iterations;
  so.num_threads = 1;
  so.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  if (!summary.IsSolutionUsable()) return result;
  result.initial_cost = summary.initial_cost;
  result.final_cost = summary.final_cost;
  result.iterations = static_cast<int>(summary.iterations.size());
  result.T_a_b = ApplyDelta(T0, delta);

  // Pose information = Schur complement of the points in J^T J (at the solution).
  using J36 = Eigen::Matrix<double, 3, 6, Eigen::RowMajor>;
  using J33 = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;
  Eigen::Matrix<double, 6, 6> S = Eigen::Matrix<double, 6, 6>::Zero();
  double sum_sq = 0, plain_sq = 0;
  const double clip = 9.0 * options.huber_px * options.huber_px;
  for (size_t k = 0; k < n; ++k) {
    Eigen::Vector3d ra, rb;
    J33 jla, jlb;
    J36 jx;
    const double* pa_params[] = {pts[k].data()};
    double* ja[] = {jla.data()};
    const double* pb_params[] = {delta, pts[k].data()};
    double* jb[] = {jx.data(), jlb.data()};
    if (!cost_a[k]->Evaluate(pa_params, ra.data(), ja) ||
        !cost_b[k]->Evaluate(pb_params, rb.data(), jb)) {
      return result;
    }
    const Eigen::Matrix3d Hll = jla.transpose() * jla + jlb.transpose() * jlb;
    const Eigen::Matrix<double, 6, 3> Hxl = jx.transpose() * jlb;
    S += jx.transpose() * jx - Hxl * Hll.ldlt().solve(Hxl.transpose());
    for (int i = 0; i < 3; ++i) {
      sum_sq += std::min(ra(i) * ra(i), clip) + std::min(rb(i) * rb(i), clip);
      plain_sq += ra(i) * ra(i) + rb(i) * rb(i);
    }
  }
  const double dof = std::max(1.0, 3.0 * static_cast<double>(n) - 6.0);
  const double sigma2 = std::max(options.min_sigma_px * options.min_sigma_px, sum_sq / dof);
  result.rms_px = std::sqrt(plain_sq / (6.0 * static_cast<double>(n)));
  S = 0.5 * (S + S.transpose());
  Eigen::FullPivLU<Eigen::Matrix<double, 6, 6>> lu(S);
  if (!lu.isInvertible()) return result;
  result.covariance = options.covariance_scale * sigma2 * lu.inverse();
  result.covariance = 0.5 * (result.covariance + result.covariance.transpose());
  result.ok = result.covariance.allFinite() && result.T_a_b.matrix().allFinite() &&
              result.covariance.diagonal().minCoeff() > 0;
  if (points_a != nullptr) *points_a = pts;
  return result;
}

// Two-view bundle adjustment with analytic Jacobians, Levenberg-Marquardt on the reduced
// (Schur complement) system. Unknowns: the pose perturbation y = [rho; phi] of
// T_a_b = T Exp(y) (ApplyDelta), optionally the disparity offset increment c, and every point
// p_a (frame a). Residuals per point (pixels), Huber-weighted per 3-vector as Ceres does:
//   A: pi(p_a) - obs_a            B: pi(p_b) - obs_b,   p_b = R(phi)^T (R^T (p_a - t) - rho)
// with pi(p) = (fx x/z + cx, fy y/z + cy, fx (x - b)/z + cx) and c g subtracted from u_right's
// observation (residual_u_right = pi_2 - obs_2 - c g, g = OffsetBasis(obs_2)). At y = 0, with
// q = R^T (p_a - t):
//   d p_b / d rho = -I,  d p_b / d phi = [q]x,  d p_b / d p_a = R^T,  d r_u_right / d c = -g,
//   d pi / d p = [fx/z 0 -fx x/z^2; 0 fy/z -fy y/z^2; fx/z 0 -fx (x-b)/z^2].
// With PointMeasurements (laser-aided mode), a measured point adds r_a = s W_a (p_a - m_a) and/or
// r_b = s W_b (p_b - m_b) (3D point errors, Huber-weighted as one 3-vector each):
//   d r_a / d p_a = s W_a,  d r_b / d p_a = s W_b R^T,  d r_b / d [rho phi] = s W_b [-I, [q]x].
// Each iteration eliminates the points (3x3 blocks), solves the 6- or 7-dimensional reduced
// system, back-substitutes the points, and accepts the step if the robust cost decreased.
class TwoViewBa {
 public:
  using Mat3 = Eigen::Matrix3d;
  using Vec3 = Eigen::Vector3d;
  static constexpr int kMaxGlobal = 8;  // 6 pose + offset, padded (vectorisation)
  using MatG = Eigen::Matrix<double, kMaxGlobal, kMaxGlobal>;
  using VecG = Eigen::Matrix<double, kMaxGlobal, 1>;
  using MatG3 = Eigen::Matrix<double, kMaxGlobal, 3>;

  TwoViewBa(const StereoCamera& cam, const std::vector<StereoCorrespondence>& corr,
            const std::vector<int>& inliers, double huber_px, double prior_weight,
            const PointMeasurements* measured = nullptr)
      : cam_(cam), huber_(huber_px), prior_weight_(prior_weight), ng_(prior_weight > 0 ? 7 : 6) {
    obs_a_.reserve(inliers.size());
    obs_b_.reserve(inliers.size());
    pts_.reserve(inliers.size());
    for (int i : inliers) {
      const StereoCorrespondence& c = corr[static_cast<size_t>(i)];
      obs_a_.push_back(c.obs_a);
      obs_b_.push_back(c.obs_b);
      pts_.push_back(c.p_a);
    }
    if (measured != nullptr && measured->per_correspondence.size() == corr.size()) {
      const double s = measured->pixel_sigma_px;
      for (size_t k = 0; k < inliers.size(); ++k) {
        const PointMeasurement& m = measured->per_correspondence[static_cast<size_t>(inliers[k])];
        if (!m.has_a && !m.has_b) continue;
        Measured e;
        e.k = k;
        e.has_a = m.has_a;
        e.has_b = m.has_b;
        e.m_a = m.m_a;
        e.m_b = m.m_b;
        e.W_a = s * m.W_a;
        e.W_b = s * m.W_b;
        if (m.has_a) pts_[k] = m.m_a;
        measured_.push_back(e);
      }
    }
    hpp_.resize(pts_.size());
    hgp_.resize(pts_.size());
    gp_.resize(pts_.size());
  }

  int size() const { return static_cast<int>(pts_.size()); }
  // 3D point error components (3 per measurement), for the degrees of freedom.
  int measured_components() const {
    int n = 0;
    for (const Measured& e : measured_) n += 3 * (static_cast<int>(e.has_a) + e.has_b);
    return n;
  }
  int num_global() const { return ng_; }
  const std::vector<Vec3>& points() const { return pts_; }

  // Robust cost 1/2 sum rho(|r|^2) (+ the prior) at (T, c, points); +inf if a point is behind
  // a camera.
  double Cost(const Eigen::Isometry3d& T, double c, const std::vector<Vec3>& pts) const {
    const Mat3 Rt = T.linear().transpose();
    double cost = 0;
    Vec3 r;
    for (size_t k = 0; k < pts.size(); ++k) {
      if (!Residual(pts[k], obs_a_[k], c, &r)) return kInf;
      cost += Rho(r.squaredNorm());
      if (!Residual(Rt * (pts[k] - T.translation()), obs_b_[k], c, &r)) return kInf;
      cost += Rho(r.squaredNorm());
    }
    for (const Measured& e : measured_) {
      const Vec3& p = pts[e.k];
      if (e.has_a) cost += Rho((e.W_a * (p - e.m_a)).squaredNorm());
      if (e.has_b) cost += Rho((e.W_b * (Rt * (p - T.translation()) - e.m_b)).squaredNorm());
    }
    return 0.5 * cost + 0.5 * prior_weight_ * c * c;
  }

  // Builds the reduced system at (T, c, pts_): S y = -s (S = H_gg - sum H_gp H_pp^-1 H_pg).
  // robust = false: plain Gauss-Newton Hessian (for the covariance). lambda: LM damping.
  // Also accumulates sum of min(r^2, clip) and sum r^2 over residual components.
  bool Build(const Eigen::Isometry3d& T, double c, bool robust, double lambda, MatG* S, VecG* s,
             double* clipped_sq = nullptr, double* plain_sq = nullptr) {
    const Mat3 Rt = T.linear().transpose();
    MatG Hgg = MatG::Zero();
    VecG gg = VecG::Zero();
    const double clip = 9.0 * huber_ * huber_;
    double csq = 0, psq = 0, psq_measured = 0;
    const auto AddSquares = [clip](const Vec3& r, double* clipped, double* plain) {
      for (int i = 0; i < 3; ++i) {
        *clipped += std::min(r(i) * r(i), clip);
        *plain += r(i) * r(i);
      }
    };
    size_t next_measured = 0;
    for (size_t k = 0; k < pts_.size(); ++k) {
      const Vec3& p = pts_[k];
      const Vec3 q = Rt * (p - T.translation());
      Vec3 ra, rb;
      if (!Residual(p, obs_a_[k], c, &ra) || !Residual(q, obs_b_[k], c, &rb)) return false;
      for (int i = 0; i < 3; ++i) {
        csq += std::min(ra(i) * ra(i), clip) + std::min(rb(i) * rb(i), clip);
        psq += ra(i) * ra(i) + rb(i) * rb(i);
      }
      const double wa = robust ? Weight(ra.squaredNorm()) : 1.0;
      const double wb = robust ? Weight(rb.squaredNorm()) : 1.0;
      const Mat3 Ja = ProjectionJacobian(p);  // d r_a / d p
      const Mat3 Jq = ProjectionJacobian(q);
      const Mat3 Jb = Jq * Rt;  // d r_b / d p
      // d r_b / d [rho phi]: Jq [-I, [q]x]; d r / d c = (0, 0, -1) in both views.
      Eigen::Matrix<double, 3, kMaxGlobal> Jg = Eigen::Matrix<double, 3, kMaxGlobal>::Zero();
      Jg.block<3, 3>(0, 0) = -Jq;
      Jg.block<3, 3>(0, 3) = Jq * Skew(q);
      if (ng_ == 7) Jg(2, 6) = -Basis(obs_b_[k]);
      Mat3 Hpp = wa * Ja.transpose() * Ja + wb * Jb.transpose() * Jb;
      Vec3 gp = wa * Ja.transpose() * ra + wb * Jb.transpose() * rb;
      MatG3 Hgp = wb * Jg.transpose() * Jb;
      Hgg += wb * Jg.transpose() * Jg;
      gg += wb * Jg.transpose() * rb;
      if (ng_ == 7) {  // view a's u_right also depends on c
        const double ga = Basis(obs_a_[k]);
        Hgg(6, 6) += wa * ga * ga;
        gg(6) += -wa * ga * ra(2);
        Hgp.row(6) += -wa * ga * Ja.row(2);
      }
      if (next_measured < measured_.size() && measured_[next_measured].k == k) {
        // 3D point errors: d r_a / d p = W_a; d r_b / d p = W_b R^T, d r_b / d [rho phi] =
        // W_b [-I, [q]x] (as for the reprojection above, without the projection).
        const Measured& e = measured_[next_measured++];
        if (e.has_a) {
          const Vec3 r = e.W_a * (p - e.m_a);
          const double w = robust ? Weight(r.squaredNorm()) : 1.0;
          AddSquares(r, &csq, &psq_measured);
          Hpp += w * e.W_a.transpose() * e.W_a;
          gp += w * e.W_a.transpose() * r;
        }
        if (e.has_b) {
          const Vec3 r = e.W_b * (q - e.m_b);
          const double w = robust ? Weight(r.squaredNorm()) : 1.0;
          AddSquares(r, &csq, &psq_measured);
          const Mat3 Jp = e.W_b * Rt;
          Eigen::Matrix<double, 3, kMaxGlobal> Jm = Eigen::Matrix<double, 3, kMaxGlobal>::Zero();
          Jm.block<3, 3>(0, 0) = -e.W_b;
          Jm.block<3, 3>(0, 3) = e.W_b * Skew(q);
          Hpp += w * Jp.transpose() * Jp;
          gp += w * Jp.transpose() * r;
          Hgp += w * Jm.transpose() * Jp;
          Hgg += w * Jm.transpose() * Jm;
          gg += w * Jm.transpose() * r;
        }
      }
      if (lambda > 0) Hpp.diagonal() *= (1.0 + lambda);
      hpp_[k] = Hpp.inverse();
      if (!hpp_[k].allFinite()) return false;
      hgp_[k] = Hgp;
      gp_[k] = gp;
      Hgg -= Hgp * hpp_[k] * Hgp.transpose();
      gg -= Hgp * (hpp_[k] * gp);
    }
    if (ng_ == 7) {
      Hgg(6, 6) += prior_weight_;
      gg(6) += prior_weight_ * c;
    }
    if (lambda > 0) Hgg.diagonal().head(ng_) *= (1.0 + lambda);
    if (ng_ < kMaxGlobal) {  // unused rows/cols: identity so the 7x7 solve stays regular
      for (int i = ng_; i < kMaxGlobal; ++i) Hgg(i, i) = 1.0;
    }
    *S = Hgg;
    *s = gg;
    if (clipped_sq != nullptr) *clipped_sq = csq;
    if (plain_sq != nullptr) *plain_sq = psq;
    return true;
  }

  // Step for the points given the global step dy (after Build).
  void PointSteps(const VecG& dy, std::vector<Vec3>* dp) const {
    dp->resize(pts_.size());
    for (size_t k = 0; k < pts_.size(); ++k) {
      (*dp)[k] = -hpp_[k] * (gp_[k] + hgp_[k].transpose() * dy);
    }
  }
  std::vector<Vec3>& mutable_points() { return pts_; }

  static constexpr double kInf = std::numeric_limits<double>::infinity();

 private:
  bool Residual(const Vec3& p, const Vec3& obs, double c, Vec3* r) const {
    if (!ba::StereoResidual(cam_, p, obs, r)) return false;
    (*r)(2) -= c * Basis(obs);
    return true;
  }
  // How the offset at the image centre scales at this observation (OffsetBasis).
  double Basis(const Vec3& obs) const { return OffsetBasis(cam_, obs(2)); }
  Mat3 ProjectionJacobian(const Vec3& p) const { return ba::StereoProjectionJacobian(cam_, p); }
  double Rho(double s) const { return ba::Huber{huber_}.Rho(s); }
  double Weight(double s) const { return ba::Huber{huber_}.Weight(s); }

  // A point's 3D measurements (PointMeasurements), W scaled by the pixel sigma; k: the point.
  struct Measured {
    size_t k = 0;
    bool has_a = false, has_b = false;
    Vec3 m_a, m_b;
    Mat3 W_a, W_b;
  };

  StereoCamera cam_;
  std::vector<Measured> measured_;  // in increasing k
  double huber_, prior_weight_;
  int ng_;
  std::vector<Vec3> obs_a_, obs_b_, pts_;
  std::vector<Mat3> hpp_;
  std::vector<MatG3, Eigen::aligned_allocator<MatG3>> hgp_;
  std::vector<Vec3> gp_;
};

RefineResult RefineAnalytic(const StereoCamera& cam, const std::vector<StereoCorrespondence>& corr,
                            const std::vector<int>& inliers, const Eigen::Isometry3d& T0,
                            const RefineOptions& options, std::vector<Eigen::Vector3d>* points_a,
                            const OffsetPrior* offset, const PointMeasurements* measured) {
  RefineResult result;
  result.T_a_b = T0;
  if (inliers.size() < 3) return result;
  const double prior_weight =
      offset != nullptr ? offset->sigma_px * offset->sigma_px / offset->variance_px2 : 0.0;
  TwoViewBa ba(cam, corr, inliers, options.huber_px, prior_weight, measured);
  Eigen::Isometry3d T = T0;
  double c = 0;
  double cost = ba.Cost(T, c, ba.points());
  if (!std::isfinite(cost)) return result;
  result.initial_cost = cost;
  double lambda = 1e-4;
  TwoViewBa::MatG S;
  TwoViewBa::VecG s;
  std::vector<Eigen::Vector3d> dp, trial;
  const int ng = ba.num_global();
  int it = 0;
  for (int attempts = 0; it < options.max_iterations && attempts < 3 * options.max_iterations;
       ++attempts) {
    if (!ba.Build(T, c, true, lambda, &S, &s)) return result;
    const TwoViewBa::VecG dy = -S.ldlt().solve(s);
    if (!dy.allFinite()) return result;
    ba.PointSteps(dy, &dp);
    trial = ba.points();
    for (size_t k = 0; k < trial.size(); ++k) trial[k] += dp[k];
    double d6[6];
    for (int i = 0; i < 6; ++i) d6[i] = dy(i);
    const Eigen::Isometry3d T_new = ApplyDelta(T, d6);
    const double c_new = ng == 7 ? c + dy(6) : 0.0;
    const double new_cost = ba.Cost(T_new, c_new, trial);
    if (new_cost < cost) {
      ++it;
      const double decrease = (cost - new_cost) / std::max(cost, 1e-12);
      T = T_new;
      c = c_new;
      ba.mutable_points().swap(trial);
      cost = new_cost;
      lambda = std::max(1e-9, lambda / 5.0);
      if (decrease < 1e-7 || dy.head(ng).norm() < 1e-10) break;
    } else {
      lambda *= 10.0;
      if (lambda > 1e6) break;
    }
  }
  result.iterations = it;
  result.final_cost = cost;
  result.T_a_b = T;

  // Covariance: sigma^2 (reduced Gauss-Newton Hessian)^-1 at the solution, no robust weights,
  // sigma^2 from the residuals with the Huber width bounding the outliers' influence.
  double clipped_sq = 0, plain_sq = 0;
  if (!ba.Build(T, c, false, 0.0, &S, &s, &clipped_sq, &plain_sq)) return result;
  const double n = static_cast<double>(ba.size());
  const double dof = std::max(1.0, 3.0 * n - 6.0 + ba.measured_components());
  const double sigma2 = std::max(options.min_sigma_px * options.min_sigma_px, clipped_sq / dof);
  result.rms_px = std::sqrt(plain_sq / (6.0 * n));
  result.sigma_px = std::sqrt(sigma2);
  S = 0.5 * (S + S.transpose());
  Eigen::FullPivLU<TwoViewBa::MatG> lu(S);
  if (!lu.isInvertible()) return result;
  const TwoViewBa::MatG Sinv = lu.inverse();
  // Pose covariance conditional on the offset (its 6x6 block of the reduced Hessian), as for
  // any calibration parameter: the offset's error is shared by all frames (systematic), so
  // marginalising it into every factor would count it as independent per factor, and in a
  // scene at a single depth it is confounded with the scale (a fronto-parallel plane).
  const Eigen::Matrix<double, 6, 6> S66 = S.topLeftCorner<6, 6>();
  Eigen::FullPivLU<Eigen::Matrix<double, 6, 6>> lu6(S66);
  if (!lu6.isInvertible()) return result;
  result.covariance = options.covariance_scale * sigma2 * lu6.inverse();
  result.covariance = 0.5 * (result.covariance + result.covariance.transpose());
  if (ng == 7) {
    result.offset_estimated = true;
    result.offset_px = c;
    result.offset_variance_px2 = sigma2 * Sinv(6, 6);
    // Information from the data alone: 1 / Sinv(6,6) is the Schur complement of c, which is
    // the data's part plus the prior weight (unit-pixel scale); divide by sigma^2 for 1/px^2.
    result.offset_data_information = std::max(0.0, 1.0 / Sinv(6, 6) - prior_weight) / sigma2;
  }
  result.ok = result.covariance.allFinite() && result.T_a_b.matrix().allFinite() &&
              result.covariance.diagonal().minCoeff() > 0 && std::isfinite(c);
  if (points_a != nullptr) *points_a = ba.points();
  return result;
}

}  // namespace

Eigen::Matrix3d PointSqrtInformation(const Eigen::Vector3d& ray, double sigma_depth_m,
                                     double sigma_lateral_m) {
  // Sigma^-1 = (1/lat^2) (I - e e^T) + (1/dep^2) e e^T (the eigen-decomposition of Sigma), so
  // Sigma^-1/2 = (1/lat) (I - e e^T) + (1/dep) e e^T. sigma_depth is along z; along the
  // unit ray it is sigma_depth |ray|.
  const Eigen::Vector3d e = ray.normalized();
  const double dep = sigma_depth_m * ray.norm();
  const Eigen::Matrix3d P = e * e.transpose();
  return (Eigen::Matrix3d::Identity() - P) / sigma_lateral_m + P / dep;
}

RefineResult RefineMotion(const StereoCamera& cam, const std::vector<StereoCorrespondence>& corr,
                          const std::vector<int>& inliers, const Eigen::Isometry3d& T_a_b_initial,
                          const RefineOptions& options, std::vector<Eigen::Vector3d>* points_a,
                          const OffsetPrior* offset, const PointMeasurements* measured) {
  if (options.optimize_points && !options.use_ceres) {
    return RefineAnalytic(cam, corr, inliers, T_a_b_initial, options, points_a, offset, measured);
  }
  if (offset != nullptr || measured != nullptr) {
    // Only the analytic two-view bundle adjustment models the offset and the 3D point errors
    // (Validate rejects the combination in StereoVoOptions); refuse rather than silently
    // ignore them.
    RefineResult refused;
    refused.T_a_b = T_a_b_initial;
    return refused;
  }
  if (options.optimize_points) {
    return RefineJoint(cam, corr, inliers, T_a_b_initial, options, points_a);
  }
  RefineResult result;
  result.T_a_b = T_a_b_initial;
  if (inliers.size() < 3) return result;

  auto build = [&](const Eigen::Isometry3d& T0, double* delta, ceres::Problem* problem,
                   bool robust) {
    for (int i : inliers) {
      const StereoCorrespondence& c = corr[static_cast<size_t>(i)];
      problem->AddResidualBlock(
          StereoReprojectionCost::Create(cam, T0, c.p_a, c.obs_b, StereoReprojectionCost::kForward),
          robust ? new ceres::HuberLoss(options.huber_px) : nullptr, delta);
      problem->AddResidualBlock(StereoReprojectionCost::Create(cam, T0, c.p_b, c.obs_a,
                                                               StereoReprojectionCost::kBackward),
                                robust ? new ceres::HuberLoss(options.huber_px) : nullptr, delta);
    }
  };

  // 1) Solve around the initial estimate.
  double delta[6] = {0, 0, 0, 0, 0, 0};
  {
    ceres::Problem problem;
    build(T_a_b_initial, delta, &problem, true);
    ceres::Solver::Options so;
    so.linear_solver_type = ceres::DENSE_QR;
    so.max_num_iterations = options.max_iterations;
    so.num_threads = 1;
    so.logging_type = ceres::SILENT;
    so.minimizer_progress_to_stdout = false;
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem, &summary);
    if (!summary.IsSolutionUsable()) return result;
    result.initial_cost = summary.initial_cost;
    result.final_cost = summary.final_cost;
    result.iterations = static_cast<int>(summary.iterations.size());
  }
  result.T_a_b = ApplyDelta(T_a_b_initial, delta);

  // 2) Linearise at the solution (delta = 0) for the covariance, without the robust loss so
  // the residuals give an unbiased noise estimate.
  double zero[6] = {0, 0, 0, 0, 0, 0};
  ceres::Problem problem;
  build(result.T_a_b, zero, &problem, false);
  double cost = 0;
  std::vector<double> residuals;
  ceres::CRSMatrix jac;
  if (!problem.Evaluate(ceres::Problem::EvaluateOptions(), &cost, &residuals, nullptr, &jac)) {
    return result;
  }
  Eigen::Matrix<double, 6, 6> JtJ = Eigen::Matrix<double, 6, 6>::Zero();
  for (int r = 0; r < jac.num_rows; ++r) {
    Eigen::Matrix<double, 6, 1> row = Eigen::Matrix<double, 6, 1>::Zero();
    for (int k = jac.rows[r]; k < jac.rows[r + 1]; ++k) row(jac.cols[k]) = jac.values[k];
    JtJ += row * row.transpose();
  }
  // Noise from the residuals, with the Huber width bounding the outliers' influence.
  double sum_sq = 0;
  for (double r : residuals) sum_sq += std::min(r * r, 9.0 * options.huber_px * options.huber_px);
  const double dof = std::max(1.0, static_cast<double>(residuals.size()) - 6.0);
  const double sigma2 = std::max(options.min_sigma_px * options.min_sigma_px, sum_sq / dof);
  result.rms_px = std::sqrt(2.0 * cost / std::max<size_t>(1, residuals.size()));
  Eigen::FullPivLU<Eigen::Matrix<double, 6, 6>> lu(JtJ);
  if (!lu.isInvertible()) return result;
  result.covariance = options.covariance_scale * sigma2 * lu.inverse();
  result.covariance = 0.5 * (result.covariance + result.covariance.transpose());
  result.ok = result.covariance.allFinite() && result.T_a_b.matrix().allFinite();
  if (points_a != nullptr) {
    points_a->clear();
    for (int i : inliers) points_a->push_back(corr[static_cast<size_t>(i)].p_a);
  }
  return result;
}

Eigen::Matrix<double, 6, 6> Adjoint(const Eigen::Isometry3d& T) {
  Eigen::Matrix<double, 6, 6> ad = Eigen::Matrix<double, 6, 6>::Zero();
  const Eigen::Matrix3d R = T.linear();
  ad.block<3, 3>(0, 0) = R;
  ad.block<3, 3>(0, 3) = Skew(T.translation()) * R;
  ad.block<3, 3>(3, 3) = R;
  return ad;
}

Eigen::Matrix<double, 6, 6> ComposeCovariance(const Eigen::Matrix<double, 6, 6>& cov_ab,
                                              const Eigen::Isometry3d& T_bc,
                                              const Eigen::Matrix<double, 6, 6>& cov_bc) {
  const Eigen::Matrix<double, 6, 6> ad = Adjoint(T_bc.inverse());
  return ad * cov_ab * ad.transpose() + cov_bc;
}

Eigen::Matrix<double, 6, 6> ChangeFrameCovariance(const Eigen::Matrix<double, 6, 6>& cov,
                                                  const Eigen::Isometry3d& S) {
  const Eigen::Matrix<double, 6, 6> ad = Adjoint(S);
  return ad * cov * ad.transpose();
}

}  // namespace fl::vo
