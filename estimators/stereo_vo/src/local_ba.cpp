#include "fusionloc/stereo_vo/local_ba.hpp"

#include <ceres/ceres.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_map>
#include <utility>

#include "ba_kernels.hpp"
#include "fusionloc/common/se3_between_cost.hpp"
#include "fusionloc/common/sqrt_information.hpp"
#include "fusionloc/stereo_vo/reprojection_cost.hpp"

namespace fl::vo {
namespace {

using Matrix6d = Eigen::Matrix<double, 6, 6>;
using PointXyz = std::array<double, 3>;

// Reprojection error (max over u_left, v, u_right) of p_o seen by keyframe pose T_o_k; +inf
// behind the camera.
double ObservationError(const StereoCamera& camera, const Eigen::Isometry3d& T_o_k,
                        const Eigen::Vector3d& p_o, const Eigen::Vector3d& uvu) {
  Eigen::Vector3d predicted;
  if (!camera.Project(T_o_k.inverse() * p_o, &predicted)) return HUGE_VAL;
  return (predicted - uvu).cwiseAbs().maxCoeff();
}

// StereoPointCostB with its pose perturbation split into the translation and the rotation blocks
// (same residual): with 3-parameter blocks only, Ceres runs its fixed-size 3x3x3 Schur
// eliminator instead of the dynamic one.
class SplitPoseCost {
 public:
  explicit SplitPoseCost(StereoPointCostB cost) : cost_(std::move(cost)) {}
  template <typename T>
  bool operator()(const T* const rho, const T* const phi, const T* const p_a, T* residual) const {
    const T delta[6] = {rho[0], rho[1], rho[2], phi[0], phi[1], phi[2]};
    return cost_(delta, p_a, residual);
  }
  static ceres::CostFunction* Create(const StereoCamera& camera, const Eigen::Isometry3d& T0_o_k,
                                     const Eigen::Vector3d& uvu) {
    return new ceres::AutoDiffCostFunction<SplitPoseCost, 3, 3, 3, 3>(
        new SplitPoseCost(StereoPointCostB(camera, T0_o_k, uvu)));
  }

 private:
  StereoPointCostB cost_;
};

// The keyframe motion prior: fl::Se3BetweenCost on the poses T_o_k = T0_o_k [R(phi) | rho] of
// keyframes i and j (p = R0 rho + t0, q = q0 q(phi)).
class KeyframeMotionCost {
 public:
  KeyframeMotionCost(const Eigen::Isometry3d& T0_o_i, const Eigen::Isometry3d& T0_o_j,
                     const Se3BetweenCost& between)
      : T0_o_i_(T0_o_i), T0_o_j_(T0_o_j), between_(between) {}
  template <typename T>
  bool operator()(const T* const rho_i, const T* const phi_i, const T* const rho_j,
                  const T* const phi_j, T* residual) const {
    T p_i[3], q_i[4], p_j[3], q_j[4];
    Pose(T0_o_i_, rho_i, phi_i, p_i, q_i);
    Pose(T0_o_j_, rho_j, phi_j, p_j, q_j);
    return between_(p_i, q_i, p_j, q_j, residual);
  }
  static ceres::CostFunction* Create(const Eigen::Isometry3d& T0_o_i,
                                     const Eigen::Isometry3d& T0_o_j,
                                     const Eigen::Isometry3d& T_i_j,
                                     const Eigen::Matrix<double, 6, 6>& sqrt_information) {
    return new ceres::AutoDiffCostFunction<KeyframeMotionCost, 6, 3, 3, 3, 3>(
        new KeyframeMotionCost(
            T0_o_i, T0_o_j,
            Se3BetweenCost(T_i_j.translation(), Eigen::Quaterniond(T_i_j.linear()),
                           sqrt_information)));
  }
  EIGEN_MAKE_ALIGNED_OPERATOR_NEW

 private:
  template <typename T>
  static void Pose(const Eigen::Isometry3d& T0, const T* rho, const T* phi, T* p, T* q) {
    for (int r = 0; r < 3; ++r) {
      p[r] = T(T0.linear()(r, 0)) * rho[0] + T(T0.linear()(r, 1)) * rho[1] +
             T(T0.linear()(r, 2)) * rho[2] + T(T0.translation()(r));
    }
    T q_wxyz[4];
    ceres::AngleAxisToQuaternion(phi, q_wxyz);
    const Eigen::Quaternion<T> q_phi(q_wxyz[0], q_wxyz[1], q_wxyz[2], q_wxyz[3]);
    const Eigen::Quaternion<T> q0 = Eigen::Quaterniond(T0.linear()).template cast<T>();
    Eigen::Map<Eigen::Quaternion<T>> q_out(q);
    q_out = q0 * q_phi;
  }
  Eigen::Isometry3d T0_o_i_, T0_o_j_;
  Se3BetweenCost between_;
};

// The laser depth point error of an observation by keyframe k (LocalBaOptions::laser_points),
//   p_k = R(-phi) (R0^T (p_o - t0) - rho),   r = s W (p_k - m)
// the point in keyframe k's frame by PointInFrameB (as StereoPointCostB).
class LaserPointCost {
 public:
  LaserPointCost(const Eigen::Isometry3d& T0_o_k, const Eigen::Vector3d& m_k,
                 const Eigen::Matrix3d& sW)
      : R0_(T0_o_k.linear()), t0_(T0_o_k.translation()), m_(m_k), sW_(sW) {}
  template <typename T>
  bool operator()(const T* const rho, const T* const phi, const T* const p_o, T* residual) const {
    T p_k[3];
    PointInFrameB(R0_, t0_, rho, phi, p_o, p_k);
    const T e[3] = {p_k[0] - T(m_(0)), p_k[1] - T(m_(1)), p_k[2] - T(m_(2))};
    for (int i = 0; i < 3; ++i) {
      residual[i] = T(sW_(i, 0)) * e[0] + T(sW_(i, 1)) * e[1] + T(sW_(i, 2)) * e[2];
    }
    return true;
  }
  static ceres::CostFunction* Create(const Eigen::Isometry3d& T0_o_k, const Eigen::Vector3d& m_k,
                                     const Eigen::Matrix3d& sW) {
    return new ceres::AutoDiffCostFunction<LaserPointCost, 3, 3, 3, 3>(
        new LaserPointCost(T0_o_k, m_k, sW));
  }

 private:
  Eigen::Matrix3d R0_;
  Eigen::Vector3d t0_, m_;
  Eigen::Matrix3d sW_;
};

Eigen::Isometry3d CurrentPose(const BaState& state, size_t k) {
  return ApplyDelta(state.T0_o_k[k], state.delta[k].data());
}

// Moves the solution into the linearisation points (delta back to zero).
void Relinearise(BaState* state) {
  for (size_t k = 0; k < state->T0_o_k.size(); ++k) {
    state->T0_o_k[k] = CurrentPose(*state, k);
    state->delta[k].fill(0.0);
  }
}

// RMS of the reprojection residual components over the kept observations [px].
double RmsPx(const StereoCamera& camera, const std::vector<BaTrack>& tracks,
             const std::vector<std::vector<bool>>& keep, const BaState& state) {
  std::vector<Eigen::Isometry3d> T_k_o(state.T0_o_k.size());
  for (size_t k = 0; k < T_k_o.size(); ++k) T_k_o[k] = CurrentPose(state, k).inverse();
  double sum = 0;
  int n = 0;
  for (size_t t = 0; t < tracks.size(); ++t) {
    const Eigen::Vector3d p_o(state.point[t][0], state.point[t][1], state.point[t][2]);
    for (size_t m = 0; m < tracks[t].observations.size(); ++m) {
      if (!keep[t][m]) continue;
      const auto& [k, obs] = tracks[t].observations[m];
      const Eigen::Vector3d& uvu = obs.uvu;
      Eigen::Vector3d predicted;
      if (!camera.Project(T_k_o[static_cast<size_t>(k)] * p_o, &predicted)) continue;
      sum += (predicted - uvu).squaredNorm();
      n += 3;
    }
  }
  return n > 0 ? std::sqrt(sum / n) : 0.0;
}

int CountKept(const std::vector<std::vector<bool>>& keep) {
  int n = 0;
  for (const auto& k : keep) n += static_cast<int>(std::count(k.begin(), k.end(), true));
  return n;
}

bool Solve(const LocalBaOptions& options, ceres::Problem* problem, int* iterations) {
  ceres::Solver::Options solver;
  solver.linear_solver_type = options.sparse_schur ? ceres::SPARSE_SCHUR : ceres::DENSE_SCHUR;
  solver.max_num_iterations = options.max_iterations;
  solver.function_tolerance = options.function_tolerance;
  solver.num_threads = 1;
  solver.logging_type = ceres::SILENT;
  solver.minimizer_progress_to_stdout = false;
  ceres::Solver::Summary summary;
  ceres::Solve(solver, problem, &summary);
  *iterations += static_cast<int>(summary.iterations.size());
  return summary.IsSolutionUsable();
}

// The motion prior of keyframe k (k >= 1) on its motion from keyframe k-1 as a square-root
// information of the between error (Se3BetweenCost); false if its covariance is unusable (then
// the reprojections alone hold the pair).
bool MotionPriorSqrtInformation(const BaKeyframe& kf, const LocalBaOptions& options,
                                Matrix6d* sqrt_information) {
  if (!kf.has_motion) return false;
  const Matrix6d cov_e = Se3BetweenErrorCovariance(
      kf.T_prev_camera.linear(), options.motion_prior_covariance_scale * kf.motion_covariance);
  const Matrix6d information = cov_e.ldlt().solve(Matrix6d::Identity());
  return SqrtInformation<6>(0.5 * (information + information.transpose()), sqrt_information);
}

// The analytic solver (see the header): the window's residual terms, linearised at the current
// poses T_o_k (keyframe 0 fixed at the identity) and points p_o.
class WindowBa {
 public:
  using Mat36 = Eigen::Matrix<double, 3, 6>;

  WindowBa(const StereoCamera& camera, const std::vector<BaKeyframe>& window,
           const std::vector<BaTrack>& tracks, const LocalBaOptions& options, double sigma_px,
           const std::vector<std::vector<bool>>& keep)
      : camera_(camera), huber_{options.huber_px}, n_(window.size()) {
    for (size_t t = 0; t < tracks.size(); ++t) {
      const auto& observations = tracks[t].observations;
      int kept = 0;
      for (size_t m = 0; m < observations.size(); ++m) kept += keep.empty() || keep[t][m];
      if (kept < options.min_track_keyframes) continue;
      Point point;
      point.track = t;
      for (size_t m = 0; m < observations.size(); ++m) {
        if (!keep.empty() && !keep[t][m]) continue;
        const auto& [k, obs] = observations[m];
        Term term;
        term.k = k;
        term.z = obs.uvu;
        point.terms.push_back(term);
        if (options.laser_points && obs.has_point) {
          term.laser = true;
          term.z = obs.m_camera;
          term.sW = sigma_px * obs.W_camera;
          point.terms.push_back(term);
        }
      }
      points_.push_back(std::move(point));
    }
    if (options.motion_prior) {
      for (size_t k = 1; k < window.size(); ++k) {
        Prior prior;
        prior.k = k;
        prior.T_prev = window[k].T_prev_camera;
        if (MotionPriorSqrtInformation(window[k], options, &prior.sqrt_information)) {
          priors_.push_back(prior);
        }
      }
    }
    Hinv_.resize(points_.size());
    gp_.resize(points_.size());
    blocks_.resize(points_.size());
  }

  bool empty() const { return points_.empty() && priors_.empty(); }
  size_t pose_dims() const { return 6 * (n_ - 1); }

  // Robust cost 1/2 sum rho(|r|^2) + 1/2 sum |r_prior|^2; +inf if a point is behind a camera.
  double Cost(const std::vector<Eigen::Isometry3d>& T, const std::vector<PointXyz>& p) const {
    double cost = 0;
    Eigen::Vector3d r;
    for (const Point& point : points_) {
      const Eigen::Vector3d p_o(p[point.track][0], p[point.track][1], p[point.track][2]);
      for (const Term& term : point.terms) {
        if (!TermResidual(term, T[term.k], p_o, &r)) return kInf;
        cost += huber_.Rho(r.squaredNorm());
      }
    }
    for (const Prior& prior : priors_) {
      Vector6 r6;
      if (!PriorResidual(prior, T, &r6, nullptr)) return kInf;
      cost += r6.squaredNorm();
    }
    return 0.5 * cost;
  }

  // The reduced system S dy = -g over the free poses (keyframes 1..n-1, 6 each) at (T, p):
  // S = H_cc - sum_p H_cp H_pp^-1 H_pc. robust: Huber weights (else plain Gauss-Newton); lambda:
  // LM damping of the points' blocks and of S's diagonal. A pose no term touches gets an
  // identity block (its step stays zero) and *constrained false. false if a point's block is
  // singular or a point is behind a camera.
  bool Linearise(const std::vector<Eigen::Isometry3d>& T, const std::vector<PointXyz>& p,
                 bool robust, double lambda, Eigen::MatrixXd* S, Eigen::VectorXd* g,
                 std::vector<bool>* constrained) {
    const int dims = static_cast<int>(pose_dims());
    S->setZero(dims, dims);
    g->setZero(dims);
    constrained->assign(n_, false);
    (*constrained)[0] = true;  // the gauge
    for (size_t i = 0; i < points_.size(); ++i) {
      Eigen::Matrix3d Hpp;
      if (!LinearisePoint(i, T, p, robust, S, g, &Hpp, constrained)) return false;
      if (lambda > 0) Hpp.diagonal() *= (1.0 + lambda);
      if (!EliminatePoint(i, Hpp, S, g)) return false;
    }
    for (const Prior& prior : priors_) {
      Vector6 r6;
      Matrix6d J[2];  // d r / d delta_{k-1}, d r / d delta_k
      if (!PriorResidual(prior, T, &r6, J)) return false;
      const int kk[2] = {static_cast<int>(prior.k) - 1, static_cast<int>(prior.k)};
      for (int x = 0; x < 2; ++x) {
        if (kk[x] == 0) continue;
        (*constrained)[kk[x]] = true;
        g->segment<6>(6 * (kk[x] - 1)).noalias() += J[x].transpose() * r6;
        for (int y = 0; y < 2; ++y) {
          if (kk[y] == 0) continue;
          S->block<6, 6>(6 * (kk[x] - 1), 6 * (kk[y] - 1)).noalias() += J[x].transpose() * J[y];
        }
      }
    }
    for (size_t k = 1; k < n_; ++k) {
      if ((*constrained)[k]) continue;
      S->block<6, 6>(6 * (k - 1), 6 * (k - 1)).setIdentity();
    }
    if (lambda > 0) S->diagonal() *= (1.0 + lambda);
    return true;
  }

  // Point i's terms at (T, p): its block H_pp (undamped), g_p, and its pose blocks H_pc
  // (blocks_[i]) and their contributions to the pose system's diagonal blocks and gradient.
  bool LinearisePoint(size_t i, const std::vector<Eigen::Isometry3d>& T,
                      const std::vector<PointXyz>& p, bool robust, Eigen::MatrixXd* S,
                      Eigen::VectorXd* g, Eigen::Matrix3d* Hpp_out,
                      std::vector<bool>* constrained) {
    const Point& point = points_[i];
    const Eigen::Vector3d p_o(p[point.track][0], p[point.track][1], p[point.track][2]);
    Eigen::Matrix3d Hpp = Eigen::Matrix3d::Zero();
    Eigen::Vector3d gp = Eigen::Vector3d::Zero();
    auto& blocks = blocks_[i];
    blocks.clear();
    for (const Term& term : point.terms) {
      const Eigen::Isometry3d& T_o_k = T[term.k];
      const Eigen::Matrix3d& R = T_o_k.linear();
      const Eigen::Vector3d q =
          term.k == 0 ? p_o : Eigen::Vector3d(R.transpose() * (p_o - T_o_k.translation()));
      Eigen::Vector3d r;
      Eigen::Matrix3d Jq;  // d r / d q
      if (term.laser) {
        r = term.sW * (q - term.z);
        Jq = term.sW;
      } else {
        if (!ba::StereoResidual(camera_, q, term.z, &r)) return false;
        Jq = ba::StereoProjectionJacobian(camera_, q);
      }
      const double w = robust ? huber_.Weight(r.squaredNorm()) : 1.0;
      // With A = w Jq^T Jq, b = w Jq^T r, Qx = [q]x, Jp = Jq R^T and Jc = Jq [-I, Qx] (the
      // header's Jacobians), every block follows from the 3x3 A:
      //   w Jp^T Jp = R A R^T,  w Jp^T r = R b,  w Jc^T r = [-b; Qx^T b],
      //   w Jc^T Jc = [A, -A Qx; -(A Qx)^T, Qx^T A Qx],  H_pc = w Jp^T Jc = [-R A, R A Qx].
      const Eigen::Matrix3d A = w * Jq.transpose() * Jq;
      const Eigen::Vector3d b = w * Jq.transpose() * r;
      if (term.k == 0) {
        Hpp += A;
        gp += b;
        continue;
      }
      const Eigen::Matrix3d RA = R * A;
      Hpp.noalias() += RA * R.transpose();
      gp.noalias() += R * b;
      const Eigen::Matrix3d Qx = ba::Skew(q);
      const Eigen::Matrix3d AQ = A * Qx;
      const int a = 6 * (term.k - 1);
      S->block<3, 3>(a, a) += A;
      S->block<3, 3>(a, a + 3) -= AQ;
      S->block<3, 3>(a + 3, a) -= AQ.transpose();
      S->block<3, 3>(a + 3, a + 3).noalias() += Qx.transpose() * AQ;
      g->segment<3>(a) -= b;
      g->segment<3>(a + 3).noalias() += Qx.transpose() * b;
      Mat36 Hpc;
      Hpc.leftCols<3>() = -RA;
      Hpc.rightCols<3>().noalias() = R * AQ;
      if (!blocks.empty() && blocks.back().first == term.k) {
        blocks.back().second += Hpc;  // the laser term of the same observation
      } else {
        blocks.emplace_back(term.k, Hpc);
      }
      (*constrained)[term.k] = true;
    }
    *Hpp_out = Hpp;
    gp_[i] = gp;
    return true;
  }

  // Eliminates point i from the pose system with its (damped) block Hpp:
  // S -= H_cp H_pp^-1 H_pc, g -= H_cp H_pp^-1 g_p. false if Hpp is not positive definite.
  bool EliminatePoint(size_t i, const Eigen::Matrix3d& Hpp, Eigen::MatrixXd* S,
                      Eigen::VectorXd* g) {
    const auto& blocks = blocks_[i];
    const Eigen::LDLT<Eigen::Matrix3d> ldlt(Hpp);
    if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0)) return false;
    Hinv_[i] = ldlt.solve(Eigen::Matrix3d::Identity());
    const Eigen::Vector3d Hinv_gp = Hinv_[i] * gp_[i];
    for (size_t x = 0; x < blocks.size(); ++x) {
      const auto& [ka, Ba] = blocks[x];
      const int a = 6 * (ka - 1);
      const Eigen::Matrix<double, 6, 3> BaT_Hinv = Ba.transpose() * Hinv_[i];
      g->segment<6>(a).noalias() -= Ba.transpose() * Hinv_gp;
      // S is symmetric: the blocks on and above the diagonal, mirrored.
      for (size_t y = x; y < blocks.size(); ++y) {
        const auto& [kb, Bb] = blocks[y];
        const int b = 6 * (kb - 1);
        const Matrix6d X = BaT_Hinv * Bb;
        S->block<6, 6>(a, b) -= X;
        if (b != a) S->block<6, 6>(b, a) -= X.transpose();
      }
    }
    return true;
  }

  // The points' steps for the pose step dy (after Linearise): dp = -H_pp^-1 (g_p + H_pc dy).
  void StepPoints(const Eigen::VectorXd& dy, std::vector<PointXyz>* p) const {
    for (size_t i = 0; i < points_.size(); ++i) {
      Eigen::Vector3d rhs = gp_[i];
      for (const auto& [k, B] : blocks_[i]) rhs.noalias() += B * dy.segment<6>(6 * (k - 1));
      const Eigen::Vector3d dp = -Hinv_[i] * rhs;
      for (int c = 0; c < 3; ++c) (*p)[points_[i].track][c] += dp(c);
    }
  }

  static constexpr double kInf = std::numeric_limits<double>::infinity();

 private:
  using Vector6 = Eigen::Matrix<double, 6, 1>;
  // One residual of a point: its reprojection into keyframe k (z = the observation), or with
  // laser, its laser depth point error (z = the measured point m, sW = s W).
  struct Term {
    int k = 0;
    bool laser = false;
    Eigen::Vector3d z = Eigen::Vector3d::Zero();
    Eigen::Matrix3d sW = Eigen::Matrix3d::Zero();
  };
  struct Point {
    size_t track = 0;  // index into the tracks (and the state's points)
    std::vector<Term> terms;
  };
  struct Prior {
    size_t k = 0;  // on the motion from keyframe k-1 to k
    Eigen::Isometry3d T_prev = Eigen::Isometry3d::Identity();
    Matrix6d sqrt_information = Matrix6d::Identity();
  };

  bool TermResidual(const Term& term, const Eigen::Isometry3d& T_o_k, const Eigen::Vector3d& p_o,
                    Eigen::Vector3d* r) const {
    const Eigen::Vector3d q =
        term.k == 0 ? p_o : Eigen::Vector3d(T_o_k.linear().transpose() * (p_o - T_o_k.translation()));
    if (term.laser) {
      *r = term.sW * (q - term.z);
      return true;
    }
    return ba::StereoResidual(camera_, q, term.z, r);
  }

  // The prior's residual at (T_o_{k-1}, T_o_k) and (J not null) its Jacobians with respect to
  // the two poses' perturbations at zero, by autodiff of KeyframeMotionCost.
  bool PriorResidual(const Prior& prior, const std::vector<Eigen::Isometry3d>& T, Vector6* r,
                     Matrix6d J[2]) const {
    const std::unique_ptr<ceres::CostFunction> cost(KeyframeMotionCost::Create(
        T[prior.k - 1], T[prior.k], prior.T_prev, prior.sqrt_information));
    const double zero[3] = {0, 0, 0};
    const double* parameters[4] = {zero, zero, zero, zero};
    if (J == nullptr) return cost->Evaluate(parameters, r->data(), nullptr);
    Eigen::Matrix<double, 6, 3, Eigen::RowMajor> blocks[4];
    double* jacobians[4] = {blocks[0].data(), blocks[1].data(), blocks[2].data(),
                            blocks[3].data()};
    if (!cost->Evaluate(parameters, r->data(), jacobians)) return false;
    for (int x = 0; x < 2; ++x) {
      J[x].leftCols<3>() = blocks[2 * x];
      J[x].rightCols<3>() = blocks[2 * x + 1];
    }
    return true;
  }

  StereoCamera camera_;
  ba::Huber huber_;
  size_t n_ = 0;
  std::vector<Point> points_;
  std::vector<Prior> priors_;
  // Per point, from the last Linearise: H_pp^-1, g_p and its pose blocks H_pc (keyframe, 3x6).
  std::vector<Eigen::Matrix3d> Hinv_;
  std::vector<Eigen::Vector3d> gp_;
  std::vector<std::vector<std::pair<int, Mat36>>> blocks_;
};

// Levenberg-Marquardt as the two-view refinement's (RefineAnalytic in motion.cpp): at most
// max_iterations accepted steps; the state's poses and points move, its deltas stay zero.
bool SolveAnalytic(const LocalBaOptions& options, WindowBa* ba, BaState* state, int* iterations) {
  std::vector<Eigen::Isometry3d>& T = state->T0_o_k;
  double cost = ba->Cost(T, state->point);
  if (!std::isfinite(cost)) return false;
  double lambda = 1e-4;
  Eigen::MatrixXd S;
  Eigen::VectorXd g;
  std::vector<bool> constrained;
  std::vector<Eigen::Isometry3d> T_trial;
  std::vector<PointXyz> p_trial;
  int accepted = 0;
  for (int attempts = 0; accepted < options.max_iterations && attempts < 3 * options.max_iterations;
       ++attempts) {
    if (!ba->Linearise(T, state->point, true, lambda, &S, &g, &constrained)) return false;
    const Eigen::VectorXd dy = -S.ldlt().solve(g);
    if (!dy.allFinite()) return false;
    p_trial = state->point;
    ba->StepPoints(dy, &p_trial);
    T_trial = T;
    for (size_t k = 1; k < T.size(); ++k) T_trial[k] = ApplyDelta(T[k], dy.data() + 6 * (k - 1));
    const double new_cost = ba->Cost(T_trial, p_trial);
    if (new_cost < cost) {
      ++accepted;
      const double decrease = (cost - new_cost) / std::max(cost, 1e-12);
      T.swap(T_trial);
      state->point.swap(p_trial);
      cost = new_cost;
      lambda = std::max(1e-9, lambda / 5.0);
      if (decrease < options.function_tolerance || dy.norm() < 1e-10) break;
    } else {
      lambda *= 10.0;
      if (lambda > 1e6) break;
    }
  }
  *iterations += accepted;
  return true;
}

// Covariance of the newest relative pose T_ij (see the header), unit pixel noise, at the
// state: the robust Gauss-Newton Hessian with the points marginalised (WindowBa::Linearise,
// lambda 0), inverted, then delta_ij = delta_j - Ad(T_ij^-1) delta_i.
bool LastRelativeCovariance(WindowBa* ba, const BaState& state, Matrix6d* cov) {
  Eigen::MatrixXd S;
  Eigen::VectorXd g;
  std::vector<bool> constrained;
  if (!ba->Linearise(state.T0_o_k, state.point, true, 0.0, &S, &g, &constrained)) return false;
  const size_t n = state.T0_o_k.size();
  const size_t i = n - 2, j = n - 1;
  if (!constrained[j]) return false;  // the newest keyframe is unconstrained
  S = 0.5 * (S + S.transpose());
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(S);
  if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0)) return false;
  const Eigen::MatrixXd poses = ldlt.solve(Eigen::MatrixXd::Identity(S.rows(), S.cols()));
  const int bj = static_cast<int>(6 * (j - 1));
  const Matrix6d s_jj = poses.block<6, 6>(bj, bj);
  *cov = s_jj;
  if (i >= 1 && constrained[i]) {
    const int bi = static_cast<int>(6 * (i - 1));
    // delta_ij = delta_j - A delta_i, A = Ad(T_ij^-1).
    const Eigen::Isometry3d T_ij = state.T0_o_k[i].inverse() * state.T0_o_k[j];
    const Matrix6d A = Adjoint(T_ij.inverse());
    const Matrix6d cross = A * poses.block<6, 6>(bi, bj);  // Cov(A delta_i, delta_j)
    *cov = s_jj + A * poses.block<6, 6>(bi, bi) * A.transpose() - cross - cross.transpose();
  }
  *cov = 0.5 * (*cov + cov->transpose());
  return cov->allFinite();
}

}  // namespace

fl::Status LocalBaOptions::Validate() const {
  if (window_keyframes < 2 || window_keyframes > 30) {
    return fl::Status::Error("local_ba.window_keyframes must be in [2, 30]");
  }
  if (min_track_keyframes < 2 || min_track_keyframes > window_keyframes) {
    return fl::Status::Error("local_ba.min_track_keyframes must be in [2, window_keyframes]");
  }
  if (max_iterations < 1) return fl::Status::Error("local_ba.max_iterations must be >= 1");
  if (!(function_tolerance >= 0 && function_tolerance < 1)) {
    return fl::Status::Error("local_ba.function_tolerance must be in [0, 1)");
  }
  if (!(huber_px > 0 && outlier_threshold_px > 0)) {
    return fl::Status::Error("local_ba.huber_px and local_ba.outlier_threshold_px must be > 0");
  }
  if (min_points < 3) return fl::Status::Error("local_ba.min_points must be >= 3");
  if (!(motion_prior_covariance_scale > 0)) {
    return fl::Status::Error("local_ba.motion_prior_covariance_scale must be > 0");
  }
  return fl::Status::Ok();
}

std::vector<BaTrack> CollectTracks(const StereoCamera& camera,
                                   const std::vector<BaKeyframe>& window, int min_track_keyframes) {
  std::vector<BaTrack> all;
  if (window.empty()) return all;
  std::unordered_map<int64_t, size_t> index;
  for (size_t k = 0; k < window.size(); ++k) {
    for (const BaObservation& o : window[k].observations) {
      if (o.track_id < 0 || !(o.uvu(0) - o.uvu(2) > 0) || !o.uvu.allFinite()) continue;
      auto [it, inserted] = index.emplace(o.track_id, all.size());
      if (inserted) {
        all.emplace_back();
        all.back().track_id = o.track_id;
      }
      BaTrack& t = all[it->second];
      // One observation per keyframe (the first).
      if (!t.observations.empty() && t.observations.back().first == static_cast<int>(k)) continue;
      t.observations.emplace_back(static_cast<int>(k), o);
    }
  }
  const Eigen::Isometry3d T_world_o = window[0].T_world_camera;
  std::vector<BaTrack> shared;
  for (BaTrack& t : all) {
    if (static_cast<int>(t.observations.size()) < min_track_keyframes) continue;
    // Triangulate where the disparity is largest (the most precise depth).
    const auto best = std::max_element(
        t.observations.begin(), t.observations.end(), [](const auto& a, const auto& b) {
          return a.second.uvu(0) - a.second.uvu(2) < b.second.uvu(0) - b.second.uvu(2);
        });
    const Eigen::Vector3d& z = best->second.uvu;
    const Eigen::Isometry3d T_o_k = T_world_o.inverse() * window[best->first].T_world_camera;
    t.p_o = T_o_k * camera.Triangulate(z(0), z(1), z(0) - z(2));
    // Observations from where the point would be behind the camera cannot be evaluated.
    std::vector<std::pair<int, BaObservation>> visible;
    for (const auto& obs : t.observations) {
      const Eigen::Isometry3d T_o_m = T_world_o.inverse() * window[obs.first].T_world_camera;
      if ((T_o_m.inverse() * t.p_o).z() > 1e-3) visible.push_back(obs);
    }
    t.observations = std::move(visible);
    if (static_cast<int>(t.observations.size()) >= min_track_keyframes) {
      shared.push_back(std::move(t));
    }
  }
  return shared;
}

BaState InitialState(const std::vector<BaKeyframe>& window, const std::vector<BaTrack>& tracks) {
  BaState state;
  const Eigen::Isometry3d T_o_world =
      window.empty() ? Eigen::Isometry3d::Identity() : window[0].T_world_camera.inverse();
  for (const BaKeyframe& kf : window) {
    state.T0_o_k.push_back(T_o_world * kf.T_world_camera);
    state.delta.push_back({0, 0, 0, 0, 0, 0});
  }
  if (!state.T0_o_k.empty()) state.T0_o_k[0].setIdentity();
  for (const BaTrack& t : tracks) state.point.push_back({t.p_o.x(), t.p_o.y(), t.p_o.z()});
  return state;
}

void BuildProblem(const StereoCamera& camera, const std::vector<BaKeyframe>& window,
                  const std::vector<BaTrack>& tracks, const LocalBaOptions& options,
                  double sigma_px, const std::vector<std::vector<bool>>& keep, BaState* state,
                  ceres::Problem* problem) {
  double* d0 = state->delta.empty() ? nullptr : state->delta[0].data();
  // One robust loss for every image and laser residual (the problem deletes it once).
  ceres::LossFunction* loss = new ceres::HuberLoss(options.huber_px);
  bool loss_used = false;
  for (size_t t = 0; t < tracks.size(); ++t) {
    const auto& observations = tracks[t].observations;
    int kept = 0;
    for (size_t m = 0; m < observations.size(); ++m) kept += keep.empty() || keep[t][m];
    if (kept < options.min_track_keyframes) continue;
    double* point = state->point[t].data();
    for (size_t m = 0; m < observations.size(); ++m) {
      if (!keep.empty() && !keep[t][m]) continue;
      const auto& [k, obs] = observations[m];
      loss_used = true;
      double* delta = state->delta[k].data();
      if (k == 0) {
        problem->AddResidualBlock(StereoPointCostA::Create(camera, obs.uvu), loss, point);
      } else {
        problem->AddResidualBlock(SplitPoseCost::Create(camera, state->T0_o_k[k], obs.uvu), loss,
                                  delta, delta + 3, point);
      }
      if (options.laser_points && obs.has_point) {
        problem->AddResidualBlock(
            LaserPointCost::Create(state->T0_o_k[k], obs.m_camera, sigma_px * obs.W_camera), loss,
            delta, delta + 3, point);
        if (k == 0) {  // keyframe 0 is the gauge
          problem->SetParameterBlockConstant(d0);
          problem->SetParameterBlockConstant(d0 + 3);
        }
      }
    }
  }
  if (!loss_used) delete loss;
  if (!options.motion_prior) return;
  for (size_t k = 1; k < window.size() && k < state->delta.size(); ++k) {
    const BaKeyframe& kf = window[k];
    Matrix6d sqrt_information;
    if (!MotionPriorSqrtInformation(kf, options, &sqrt_information)) continue;
    double* di = state->delta[k - 1].data();
    double* dj = state->delta[k].data();
    problem->AddResidualBlock(KeyframeMotionCost::Create(state->T0_o_k[k - 1], state->T0_o_k[k],
                                                         kf.T_prev_camera, sqrt_information),
                              nullptr, di, di + 3, dj, dj + 3);
    if (k == 1) {  // keyframe 0 is the gauge
      problem->SetParameterBlockConstant(d0);
      problem->SetParameterBlockConstant(d0 + 3);
    }
  }
}

LocalBaResult LocalBundleAdjustment(const StereoCamera& camera,
                                    const std::vector<BaKeyframe>& window,
                                    const LocalBaOptions& options, double sigma_px) {
  LocalBaResult result;
  for (const BaKeyframe& kf : window) result.T_world_camera.push_back(kf.T_world_camera);
  if (window.size() < 2) {
    result.message = "fewer than 2 keyframes in the window";
    return result;
  }
  const std::vector<BaTrack> tracks = CollectTracks(camera, window, options.min_track_keyframes);
  result.points = static_cast<int>(tracks.size());
  if (result.points < options.min_points) {
    result.message = std::to_string(result.points) + " tracks shared by the window (local_ba." +
                     "min_points " + std::to_string(options.min_points) + ")";
    return result;
  }
  BaState state = InitialState(window, tracks);
  std::vector<std::vector<bool>> keep(tracks.size());
  for (size_t t = 0; t < tracks.size(); ++t) keep[t].assign(tracks[t].observations.size(), true);
  result.initial_rms_px = RmsPx(camera, tracks, keep, state);

  // Solve, drop the observations the solution does not explain, solve again.
  for (int round = 0; round < 2; ++round) {
    bool solved = false;
    if (options.use_ceres) {
      ceres::Problem problem;
      BuildProblem(camera, window, tracks, options, sigma_px, keep, &state, &problem);
      solved = problem.NumResidualBlocks() > 0 && Solve(options, &problem, &result.iterations);
      if (solved) Relinearise(&state);
    } else {
      WindowBa ba(camera, window, tracks, options, sigma_px, keep);
      solved = !ba.empty() && SolveAnalytic(options, &ba, &state, &result.iterations);
    }
    if (!solved) {
      result.message = "the window's bundle adjustment did not converge";
      return result;
    }
    if (round == 1) break;
    int outliers = 0;
    for (size_t t = 0; t < tracks.size(); ++t) {
      const Eigen::Vector3d p_o(state.point[t][0], state.point[t][1], state.point[t][2]);
      for (size_t m = 0; m < tracks[t].observations.size(); ++m) {
        const auto& [k, obs] = tracks[t].observations[m];
        if (ObservationError(camera, state.T0_o_k[k], p_o, obs.uvu) >
            options.outlier_threshold_px) {
          keep[t][m] = false;
          ++outliers;
        }
      }
    }
    result.outliers = outliers;
    if (outliers == 0) break;
  }
  result.observations = CountKept(keep);
  if (options.laser_points) {
    for (size_t t = 0; t < tracks.size(); ++t) {
      for (size_t m = 0; m < tracks[t].observations.size(); ++m) {
        result.laser_points += keep[t][m] && tracks[t].observations[m].second.has_point;
      }
    }
  }
  result.final_rms_px = RmsPx(camera, tracks, keep, state);

  // Covariance at the solution (either solver's).
  {
    WindowBa ba(camera, window, tracks, options, sigma_px, keep);
    Matrix6d cov;
    if (LastRelativeCovariance(&ba, state, &cov)) {
      result.covariance_ok = true;
      result.covariance_last = sigma_px * sigma_px * cov;
    }
  }
  const Eigen::Isometry3d& T_world_o = window[0].T_world_camera;
  for (size_t k = 0; k < window.size(); ++k) {
    result.T_world_camera[k] = T_world_o * state.T0_o_k[k];
  }
  result.ok = true;
  return result;
}

}  // namespace fl::vo
