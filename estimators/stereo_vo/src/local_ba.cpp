#include "fusionloc/stereo_vo/local_ba.hpp"

#include <ceres/ceres.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <unordered_map>
#include <utility>

#include "fusionloc/common/se3_between_cost.hpp"
#include "fusionloc/common/sqrt_information.hpp"
#include "fusionloc/stereo_vo/reprojection_cost.hpp"

namespace fl::vo {
namespace {

using Matrix6d = Eigen::Matrix<double, 6, 6>;

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
  double sum = 0;
  int n = 0;
  for (size_t t = 0; t < tracks.size(); ++t) {
    const Eigen::Vector3d p_o(state.point[t][0], state.point[t][1], state.point[t][2]);
    for (size_t m = 0; m < tracks[t].observations.size(); ++m) {
      if (!keep[t][m]) continue;
      const auto& [k, obs] = tracks[t].observations[m];
      const Eigen::Vector3d& uvu = obs.uvu;
      Eigen::Vector3d predicted;
      if (!camera.Project(CurrentPose(state, k).inverse() * p_o, &predicted)) continue;
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
  solver.num_threads = 1;
  solver.logging_type = ceres::SILENT;
  solver.minimizer_progress_to_stdout = false;
  ceres::Solver::Summary summary;
  ceres::Solve(solver, problem, &summary);
  *iterations += static_cast<int>(summary.iterations.size());
  return summary.IsSolutionUsable();
}

// Covariance of the free keyframe poses (unit pixel noise) with the points marginalised: the
// Gauss-Newton Hessian J^T J of the robustified residuals (Problem::Evaluate applies the loss),
// reduced to the poses by the Schur complement S = H_cc - sum_p H_cp H_pp^-1 H_pc, inverted.
// *free gets the keyframe index of each 6-block of *cov.
bool PoseCovariance(const BaState& state, ceres::Problem* problem, Eigen::MatrixXd* cov,
                    std::vector<size_t>* free) {
  ceres::Problem::EvaluateOptions eval;
  free->clear();
  for (size_t k = 1; k < state.delta.size(); ++k) {
    double* d = const_cast<double*>(state.delta[k].data());
    if (problem->HasParameterBlock(d)) {
      eval.parameter_blocks.push_back(d);      // rho
      eval.parameter_blocks.push_back(d + 3);  // phi
      free->push_back(k);
    }
  }
  const int poses = static_cast<int>(free->size());
  if (poses == 0) return false;
  const int pose_cols = 6 * poses;
  std::vector<double*> points;
  for (const auto& p : state.point) {
    double* x = const_cast<double*>(p.data());
    if (problem->HasParameterBlock(x)) points.push_back(x);
  }
  eval.parameter_blocks.insert(eval.parameter_blocks.end(), points.begin(), points.end());
  eval.apply_loss_function = true;
  eval.num_threads = 1;
  ceres::CRSMatrix J;
  if (!problem->Evaluate(eval, nullptr, nullptr, nullptr, &J)) return false;
  Eigen::MatrixXd H_cc = Eigen::MatrixXd::Zero(pose_cols, pose_cols);
  std::vector<Eigen::Matrix3d> H_pp(points.size(), Eigen::Matrix3d::Zero());
  std::vector<Eigen::MatrixXd> H_pc(points.size(), Eigen::MatrixXd::Zero(3, pose_cols));
  for (int r = 0; r < J.num_rows; ++r) {
    // A reprojection row touches at most one pose (6 columns) and one point; a motion prior row
    // two poses and no point.
    Eigen::Matrix<double, 6, 1> pose_row = Eigen::Matrix<double, 6, 1>::Zero();
    Eigen::Vector3d point_row = Eigen::Vector3d::Zero();
    int pose = -1, point = -1;
    bool two_poses = false;
    for (int e = J.rows[r]; e < J.rows[r + 1]; ++e) {
      const int c = J.cols[e];
      if (c < pose_cols) {
        two_poses = two_poses || (pose >= 0 && pose != c / 6);
        pose = c / 6;
        pose_row(c % 6) = J.values[e];
      } else {
        point = (c - pose_cols) / 3;
        point_row((c - pose_cols) % 3) = J.values[e];
      }
    }
    if (two_poses) {
      Eigen::VectorXd row = Eigen::VectorXd::Zero(pose_cols);
      for (int e = J.rows[r]; e < J.rows[r + 1]; ++e) row(J.cols[e]) = J.values[e];
      H_cc.noalias() += row * row.transpose();
      continue;
    }
    if (pose >= 0)
      H_cc.block<6, 6>(6 * pose, 6 * pose).noalias() += pose_row * pose_row.transpose();
    if (point >= 0) {
      H_pp[point].noalias() += point_row * point_row.transpose();
      if (pose >= 0) {
        H_pc[point].block<3, 6>(0, 6 * pose).noalias() += point_row * pose_row.transpose();
      }
    }
  }
  Eigen::MatrixXd S = H_cc;
  for (size_t p = 0; p < points.size(); ++p) {
    const Eigen::LDLT<Eigen::Matrix3d> ldlt(H_pp[p]);
    if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0)) return false;
    S.noalias() -= H_pc[p].transpose() * ldlt.solve(H_pc[p]);
  }
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(S);
  if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0)) return false;
  *cov = ldlt.solve(Eigen::MatrixXd::Identity(pose_cols, pose_cols));
  return cov->allFinite();
}

// Covariance of the newest relative pose (see the header), unit pixel noise.
bool LastRelativeCovariance(const BaState& state, ceres::Problem* problem, Matrix6d* cov) {
  Eigen::MatrixXd poses;
  std::vector<size_t> free;
  if (!PoseCovariance(state, problem, &poses, &free)) return false;
  const size_t n = state.T0_o_k.size();
  const size_t i = n - 2, j = n - 1;
  const auto block = [&](size_t k) {
    return static_cast<int>(std::find(free.begin(), free.end(), k) - free.begin());
  };
  const int bj = block(j), bi = block(i);
  if (bj == static_cast<int>(free.size())) return false;  // the newest keyframe is unconstrained
  const Matrix6d s_jj = poses.block<6, 6>(6 * bj, 6 * bj);
  *cov = s_jj;
  if (bi < static_cast<int>(free.size())) {
    // delta_ij = delta_j - A delta_i, A = Ad(T_ij^-1).
    const Eigen::Isometry3d T_ij = state.T0_o_k[i].inverse() * state.T0_o_k[j];
    const Matrix6d A = Adjoint(T_ij.inverse());
    const Matrix6d cross = A * poses.block<6, 6>(6 * bi, 6 * bj);  // Cov(A delta_i, delta_j)
    *cov = s_jj + A * poses.block<6, 6>(6 * bi, 6 * bi) * A.transpose() - cross - cross.transpose();
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
    if (!kf.has_motion) continue;
    Eigen::Matrix<double, 6, 6> sqrt_information;
    const Eigen::Matrix<double, 6, 6> cov_e = Se3BetweenErrorCovariance(
        kf.T_prev_camera.linear(), options.motion_prior_covariance_scale * kf.motion_covariance);
    const Eigen::Matrix<double, 6, 6> information =
        cov_e.ldlt().solve(Eigen::Matrix<double, 6, 6>::Identity());
    if (!SqrtInformation<6>(0.5 * (information + information.transpose()), &sqrt_information)) {
      continue;  // no usable covariance: the reprojections alone
    }
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
    {
      ceres::Problem problem;
      BuildProblem(camera, window, tracks, options, sigma_px, keep, &state, &problem);
      if (problem.NumResidualBlocks() == 0 || !Solve(options, &problem, &result.iterations)) {
        result.message = "the window's bundle adjustment did not converge";
        return result;
      }
    }
    Relinearise(&state);
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

  // Covariance at the solution (delta = 0 there after Relinearise).
  {
    ceres::Problem problem;
    BuildProblem(camera, window, tracks, options, sigma_px, keep, &state, &problem);
    Matrix6d cov;
    if (LastRelativeCovariance(state, &problem, &cov)) {
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
