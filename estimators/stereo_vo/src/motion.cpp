#include "fusionloc/stereo_vo/motion.hpp"

#include <ceres/ceres.h>

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <memory>

#include "fusionloc/stereo_vo/reprojection_cost.hpp"

namespace fl::vo {
namespace {

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d s;
  s << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return s;
}

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

}  // namespace

RefineResult RefineMotion(const StereoCamera& cam, const std::vector<StereoCorrespondence>& corr,
                          const std::vector<int>& inliers, const Eigen::Isometry3d& T_a_b_initial,
                          const RefineOptions& options, std::vector<Eigen::Vector3d>* points_a) {
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
