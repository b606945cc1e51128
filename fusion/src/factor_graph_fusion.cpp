#include "fusionloc/fusion/factor_graph_fusion.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>

#include "fusionloc/common/log.hpp"
#include "fusionloc/common/number_format.hpp"
#include "fusionloc/common/solver_threads.hpp"
#include "fusionloc/fusion/cost_functions.hpp"

namespace fl::fusion {
namespace {

using Clock = std::chrono::steady_clock;

double MsSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

Pose2 ToPose2(const Eigen::Vector3d& v) { return Pose2(v[0], v[1], v[2]); }
Eigen::Vector3d ToVector(const Pose2& p) { return Eigen::Vector3d(p.x, p.y, p.theta); }

bool Finite(const Pose2& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.theta);
}

std::string TimeText(Utime t) {
  std::ostringstream s;
  s.precision(6);
  s << std::fixed << UtimeToSeconds(t) << " s";
  return s.str();
}

ceres::Problem::Options BorrowingProblemOptions() {
  ceres::Problem::Options o;
  o.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  o.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  o.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  o.enable_fast_removal = false;
  return o;
}

void FillSummary(const ceres::Solver::Summary& s, SolveSummary* out) {
  out->ran = true;
  out->termination = ceres::TerminationTypeToString(s.termination_type);
  out->iterations = s.num_successful_steps + s.num_unsuccessful_steps;
  out->initial_cost = s.initial_cost;
  out->final_cost = s.final_cost;
}

}  // namespace

struct FactorGraphFusion::Warnings {
  RateLimitedWarning node;
  RateLimitedWarning factor;
  RateLimitedWarning odometry;
};

const char* FactorSourceName(FactorSource source) {
  switch (source) {
    case FactorSource::kLaser:
      return "laser";
    case FactorSource::kVision:
      return "vision";
    case FactorSource::kWheelOdometry:
      return "wheel-odometry";
  }
  return "unknown";
}

Status FusionOptions::Validate() const {
  if (!(attach_tolerance_s > 0.0 && attach_tolerance_s < 10.0)) {
    return Status::Error("attach_tolerance_s must be in (0, 10) s (about half a laser period)");
  }
  if (!(attach_max_gap_s >= 0.0 && attach_max_gap_s < 10.0)) {
    return Status::Error("attach_max_gap_s must be in [0, 10) s (0: no attachment across gaps)");
  }
  if (window_size < 2) return Status::Error("window_size must be >= 2 nodes");
  if (max_window_nodes < window_size) {
    return Status::Error("max_window_nodes must be >= window_size");
  }
  if (window_max_iterations < 1 || full_max_iterations < 1) {
    return Status::Error("window_max_iterations and full_max_iterations must be >= 1");
  }
  if (full_solve_every_n_nodes < 0) {
    return Status::Error("full_solve_every_n_nodes must be >= 0 (0: never)");
  }
  if (robust_loss != "none" && robust_loss != "huber" && robust_loss != "cauchy") {
    return Status::Error("robust_loss '" + robust_loss + "' unknown; use none, huber or cauchy");
  }
  if (!(robust_loss_scale > 0.0)) return Status::Error("robust_loss_scale must be > 0");
  if (!(prior_sigma_xy > 0.0) || !(prior_sigma_theta > 0.0)) {
    return Status::Error("prior_sigma_xy and prior_sigma_theta must be > 0");
  }
  if (!(odom_sigma_xy_min > 0.0) || !(odom_sigma_theta_min > 0.0) ||
      !(odom_sigma_xy_per_m >= 0.0) || !(odom_sigma_theta_per_rad >= 0.0) ||
      !(odom_sigma_theta_per_m >= 0.0)) {
    return Status::Error("odom_sigma_*_min must be > 0 and the per-unit terms >= 0");
  }
  if (!(chain_sigma_xy_min > 0.0) || !(chain_sigma_theta_min > 0.0) ||
      !(chain_sigma_xy_per_m >= 0.0) || !(chain_sigma_theta_per_rad >= 0.0)) {
    return Status::Error("chain_sigma_*_min must be > 0 and the per-unit terms >= 0");
  }
  if (!(odom_max_gap_s > 0.0)) return Status::Error("odom_max_gap_s must be > 0");
  if (!(odom_max_latency_s > 0.0)) return Status::Error("odom_max_latency_s must be > 0");
  if (laser_chain_factors != "odometry_gaps" && laser_chain_factors != "always" &&
      laser_chain_factors != "never") {
    return Status::Error("laser_chain_factors '" + laser_chain_factors +
                         "' unknown; use odometry_gaps, always or never");
  }
  if (max_pending_factors < 1) return Status::Error("max_pending_factors must be >= 1");
  return Status::Ok();
}

std::string SolveSummary::ToString(bool with_time) const {
  if (!ran) return "no solve yet";
  std::ostringstream s;
  s << (full ? "full" : "window") << ": " << termination << ", iterations " << iterations
    << ", cost " << initial_cost << " -> " << final_cost << ", " << num_nodes << " nodes, "
    << num_factors << " factors";
  if (with_time) s << ", " << time_ms << " ms";
  return s.str();
}

bool ReduceInformationToPlanar(const Eigen::Matrix<double, 6, 6>& information,
                               Eigen::Matrix3d* planar, std::string* reason) {
  if (!information.allFinite()) {
    *reason = "information matrix has NaN or Inf";
    return false;
  }
  const double scale = information.cwiseAbs().maxCoeff();
  if (!(scale > 0.0)) {
    *reason = "information matrix is zero";
    return false;
  }
  if ((information - information.transpose()).cwiseAbs().maxCoeff() > 1e-6 * scale) {
    *reason = "information matrix is not symmetric";
    return false;
  }
  const int idx[3] = {0, 1, 5};
  const int out_of_plane[3] = {2, 3, 4};
  bool planar_only = true;
  for (int r : out_of_plane) {
    for (int c = 0; c < 6; ++c) {
      if (information(r, c) != 0.0 || information(c, r) != 0.0) planar_only = false;
    }
  }
  Eigen::Matrix3d result;
  if (planar_only) {
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) result(r, c) = information(idx[r], idx[c]);
    }
  } else {
    Eigen::LLT<Eigen::Matrix<double, 6, 6>> llt(information);
    if (llt.info() != Eigen::Success ||
        llt.matrixL().toDenseMatrix().diagonal().minCoeff() <= 1e-12 * std::sqrt(scale)) {
      *reason = "6x6 information matrix is singular or not positive definite";
      return false;
    }
    const Eigen::Matrix<double, 6, 6> covariance =
        llt.solve(Eigen::Matrix<double, 6, 6>::Identity());
    Eigen::Matrix3d planar_cov;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) planar_cov(r, c) = covariance(idx[r], idx[c]);
    }
    planar_cov = 0.5 * (planar_cov + planar_cov.transpose());
    result = planar_cov.inverse();
    result = 0.5 * (result + result.transpose());
  }
  Eigen::Matrix3d sqrt_info;
  if (!SqrtInformation<3>(result, &sqrt_info)) {
    *reason = "(x, y, yaw) information is singular or not positive definite";
    return false;
  }
  *planar = result;
  return true;
}

FactorGraphFusion::FactorGraphFusion(const FusionOptions& options)
    : options_(options), manifold_(new Pose2Manifold), warnings_(new Warnings) {
  const Status s = options_.Validate();
  if (!s.ok()) throw std::invalid_argument("FusionOptions: " + s.message());
  if (options_.robust_loss == "huber") {
    robust_loss_ = std::make_shared<ceres::HuberLoss>(options_.robust_loss_scale);
  } else if (options_.robust_loss == "cauchy") {
    robust_loss_ = std::make_shared<ceres::CauchyLoss>(options_.robust_loss_scale);
  }
}

FactorGraphFusion::~FactorGraphFusion() = default;
FactorGraphFusion::FactorGraphFusion(FactorGraphFusion&&) noexcept = default;
FactorGraphFusion& FactorGraphFusion::operator=(FactorGraphFusion&&) noexcept = default;

Status FactorGraphFusion::Reject(int64_t* counter, const std::string& message) {
  ++*counter;
  warnings_->factor.Warn(message);
  return Status::Error(message);
}

Status FactorGraphFusion::AddLaserPose(Utime utime, const Pose2& T_map_base) {
  if (!Finite(T_map_base)) {
    return Reject(&counters_.rejected_non_finite,
                  "laser pose at " + TimeText(utime) + " has NaN/Inf; dropped");
  }
  if (!nodes_.empty() && utime <= nodes_.back().utime) {
    return Reject(&counters_.rejected_node_time, "laser pose at " + TimeText(utime) +
                                                     " is not newer than the newest node (" +
                                                     TimeText(nodes_.back().utime) +
                                                     "); dropped (laser poses must arrive in "
                                                     "time order)");
  }
  Node node;
  node.utime = utime;
  node.T_map_base_rbpf = Pose2(T_map_base.x, T_map_base.y, WrapAngle(T_map_base.theta));
  if (nodes_.empty()) {
    node.state = ToVector(node.T_map_base_rbpf);
  } else {
    const Node& prev = nodes_.back();
    const Pose2 motion = prev.T_map_base_rbpf.between(node.T_map_base_rbpf);
    node.state = ToVector(ToPose2(prev.state) * motion);
  }
  nodes_.push_back(node);
  ++counters_.nodes;
  const int index = static_cast<int>(nodes_.size()) - 1;
  if (index == 0) {
    Factor prior;
    prior.i = 0;
    prior.is_prior = true;
    prior.T_i_j = node.T_map_base_rbpf;
    const Eigen::Vector3d sigma(options_.prior_sigma_xy, options_.prior_sigma_xy,
                                options_.prior_sigma_theta);
    prior.information = sigma.cwiseInverse().cwiseAbs2().asDiagonal();
    const Eigen::Matrix3d sqrt_info = sigma.cwiseInverse().asDiagonal();
    prior.cost.reset(Se2PriorCost::Create(node.state, sqrt_info));
    AddGraphFactor(std::move(prior));
  }
  if (index > 0 &&
      (options_.laser_chain_factors == "always" ||
       (options_.laser_chain_factors == "odometry_gaps" && !options_.use_wheel_odometry))) {
    AddChainFactor(index);
  }
  AttachPendingFactors();
  AddOdometryFactors();
  if (options_.full_solve_every_n_nodes > 0 &&
      num_nodes() - nodes_at_last_full_solve_ >= options_.full_solve_every_n_nodes) {
    full_solve_requested_ = true;
  }
  return Status::Ok();
}

Status FactorGraphFusion::AddFactor(const RelativePoseFactor& f) {
  const std::string what = std::string(FactorSourceName(f.source)) + " factor " +
                           TimeText(f.utime_i) + " -> " + TimeText(f.utime_j);
  if (!f.T_i_j.matrix().allFinite()) {
    return Reject(&counters_.rejected_non_finite, what + ": transform has NaN/Inf; dropped");
  }
  const Eigen::Matrix3d r = f.T_i_j.linear();
  if ((r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-6 ||
      r.determinant() < 0.0) {
    return Reject(&counters_.rejected_non_finite,
                  what + ": rotation is not orthonormal (bad quaternion?); dropped");
  }
  Eigen::Matrix3d planar;
  std::string reason;
  if (!ReduceInformationToPlanar(f.information, &planar, &reason)) {
    int64_t* counter = f.information.allFinite() ? &counters_.rejected_information
                                                 : &counters_.rejected_non_finite;
    return Reject(counter, what + ": " + reason + "; dropped");
  }
  if (f.utime_i == f.utime_j) {
    return Reject(&counters_.rejected_same_node, what + ": both times are equal; dropped");
  }
  const Pose2 T_i_j = Pose2::FromIsometry3(f.T_i_j);
  if (nodes_.empty() || std::max(f.utime_i, f.utime_j) > nodes_.back().utime) {
    // Early: wait for the laser node of its time.
    if (static_cast<int>(pending_.size()) >= options_.max_pending_factors) {
      pending_.pop_front();
      ++counters_.dropped_pending_overflow;
      warnings_->factor.Warn("more than " + std::to_string(options_.max_pending_factors) +
                             " factors wait for laser nodes (is RBPF_POSE flowing?); dropped "
                             "the oldest");
    }
    PendingFactor p;
    p.factor = f;
    p.T_i_j = T_i_j;
    p.information = planar;
    pending_.push_back(p);
    return Status::Ok();
  }
  return AttachFactor(f, T_i_j, planar);
}

bool FactorGraphFusion::Attach(Utime t, int* node, Pose2* T_node_t) const {
  if (nodes_.empty()) return false;
  const Utime tol = SecondsToUtime(options_.attach_tolerance_s);
  const auto it = std::lower_bound(nodes_.begin(), nodes_.end(), t,
                                   [](const Node& n, Utime time) { return n.utime < time; });
  const int b = static_cast<int>(it - nodes_.begin());
  if (b == 0) {
    // At or before the first node: no interpolation possible; exact or within tolerance.
    if (nodes_.front().utime - t > tol) return false;
    *node = 0;
    *T_node_t = Pose2();
    return true;
  }
  if (b == num_nodes()) return false;  // beyond the newest node (the caller waits)
  const int a = b - 1;
  const Node& na = nodes_[a];
  const Node& nb = nodes_[b];
  const int n = (t - na.utime <= nb.utime - t) ? a : b;
  if (std::llabs(t - nodes_[n].utime) > tol &&
      nb.utime - na.utime > SecondsToUtime(options_.attach_max_gap_s)) {
    return false;
  }
  const double alpha = static_cast<double>(t - na.utime) / static_cast<double>(nb.utime - na.utime);
  const Pose2 T_map_t = Interpolate(na.T_map_base_rbpf, nb.T_map_base_rbpf, alpha);
  *node = n;
  *T_node_t = nodes_[n].T_map_base_rbpf.between(T_map_t);
  return true;
}

Status FactorGraphFusion::AttachFactor(const RelativePoseFactor& f, const Pose2& T_ti_tj,
                                       const Eigen::Matrix3d& information) {
  const std::string what = std::string(FactorSourceName(f.source)) + " factor " +
                           TimeText(f.utime_i) + " -> " + TimeText(f.utime_j);
  int ni = -1, nj = -1;
  Pose2 T_ni_ti, T_nj_tj;
  if (!Attach(f.utime_i, &ni, &T_ni_ti)) {
    return Reject(&counters_.rejected_no_node,
                  what + ": no laser node within " + FormatDouble(options_.attach_tolerance_s) +
                      " s of " + TimeText(f.utime_i) + ", nor two within " +
                      FormatDouble(options_.attach_max_gap_s) + " s around it; dropped");
  }
  if (!Attach(f.utime_j, &nj, &T_nj_tj)) {
    return Reject(&counters_.rejected_no_node,
                  what + ": no laser node within " + FormatDouble(options_.attach_tolerance_s) +
                      " s of " + TimeText(f.utime_j) + ", nor two within " +
                      FormatDouble(options_.attach_max_gap_s) + " s around it; dropped");
  }
  if (ni == nj) {
    return Reject(&counters_.rejected_same_node,
                  what + ": both times attach to the same laser node; dropped");
  }
  Factor factor;
  factor.i = ni;
  factor.j = nj;
  factor.T_i_j = T_ni_ti * T_ti_tj * T_nj_tj.inverse();
  factor.information = information;
  factor.source = f.source;
  factor.is_loop_closure = f.is_loop_closure;
  Eigen::Matrix3d sqrt_info;
  SqrtInformation<3>(information, &sqrt_info);  // checked by ReduceInformationToPlanar
  factor.cost.reset(Se2BetweenCost::Create(factor.T_i_j, sqrt_info));
  if (f.source != FactorSource::kWheelOdometry) factor.loss = robust_loss_;
  if (f.is_loop_closure && options_.full_solve_on_loop_closure) full_solve_requested_ = true;
  AddGraphFactor(std::move(factor));
  return Status::Ok();
}

void FactorGraphFusion::AddGraphFactor(Factor factor) {
  const int index = static_cast<int>(factors_.size());
  const int oldest = factor.j < 0 ? factor.i : std::min(factor.i, factor.j);
  nodes_[factor.i].factors.push_back(index);
  if (factor.j >= 0) nodes_[factor.j].factors.push_back(index);
  factors_.push_back(std::move(factor));
  ++counters_.factors_added;
  if (oldest_touched_node_ < 0 || oldest < oldest_touched_node_) oldest_touched_node_ = oldest;
}

void FactorGraphFusion::AttachPendingFactors() {
  const Utime newest = nodes_.back().utime;
  for (auto it = pending_.begin(); it != pending_.end();) {
    if (std::max(it->factor.utime_i, it->factor.utime_j) <= newest) {
      AttachFactor(it->factor, it->T_i_j, it->information);  // rejections are counted
      it = pending_.erase(it);
    } else {
      ++it;
    }
  }
}

void FactorGraphFusion::AddChainFactor(int j) {
  const Node& prev = nodes_[j - 1];
  const Pose2 motion = prev.T_map_base_rbpf.between(nodes_[j].T_map_base_rbpf);
  const double dist = std::hypot(motion.x, motion.y);
  const double sxy = options_.chain_sigma_xy_min + options_.chain_sigma_xy_per_m * dist;
  const double sth =
      options_.chain_sigma_theta_min + options_.chain_sigma_theta_per_rad * std::fabs(motion.theta);
  ++counters_.chain_factors;
  AddSequentialFactor(j, motion, sxy, sth, FactorSource::kLaser, robust_loss_);
}

void FactorGraphFusion::AddSequentialFactor(int j, const Pose2& motion, double sigma_xy,
                                            double sigma_theta, FactorSource source,
                                            std::shared_ptr<ceres::LossFunction> loss) {
  const Eigen::Vector3d sqrt_info(1 / sigma_xy, 1 / sigma_xy, 1 / sigma_theta);
  Factor factor;
  factor.i = j - 1;
  factor.j = j;
  factor.T_i_j = motion;
  factor.information = sqrt_info.cwiseAbs2().asDiagonal();
  factor.source = source;
  factor.cost.reset(Se2BetweenCost::Create(motion, sqrt_info.asDiagonal()));
  factor.loss = std::move(loss);
  AddGraphFactor(std::move(factor));
}

Status FactorGraphFusion::AddOdometry(Utime utime, const Pose2& T_odom_base) {
  if (!options_.use_wheel_odometry) return Status::Ok();
  if (!Finite(T_odom_base)) {
    ++counters_.rejected_odometry;
    const std::string m = "odometry at " + TimeText(utime) + " has NaN/Inf; dropped";
    warnings_->odometry.Warn(m);
    return Status::Error(m);
  }
  if (!odometry_.empty() && utime <= odometry_.back().utime) {
    ++counters_.rejected_odometry;
    const std::string m = "odometry at " + TimeText(utime) + " is not newer than the last (" +
                          TimeText(odometry_.back().utime) + "); dropped";
    warnings_->odometry.Warn(m);
    return Status::Error(m);
  }
  odometry_.push_back({utime, T_odom_base});
  AddOdometryFactors();
  // Keep only what the next node pairs may still need.
  const Utime keep_from = next_odom_pair_ - 1 < num_nodes()
                              ? nodes_[next_odom_pair_ - 1].utime
                              : (nodes_.empty() ? odometry_.front().utime : nodes_.back().utime);
  while (odometry_.size() > 2 && odometry_[1].utime <= keep_from) odometry_.pop_front();
  return Status::Ok();
}

bool FactorGraphFusion::OdometryAt(Utime t, Pose2* T_odom_base) const {
  const auto it = std::lower_bound(odometry_.begin(), odometry_.end(), t,
                                   [](const OdomSample& s, Utime time) { return s.utime < time; });
  if (it == odometry_.end()) return false;
  if (it->utime == t) {
    *T_odom_base = it->T_odom_base;
    return true;
  }
  if (it == odometry_.begin()) return false;
  const OdomSample& a = *(it - 1);
  const OdomSample& b = *it;
  if (SecondsBetween(a.utime, b.utime) > options_.odom_max_gap_s) return false;
  const double alpha = static_cast<double>(t - a.utime) / static_cast<double>(b.utime - a.utime);
  *T_odom_base = Interpolate(a.T_odom_base, b.T_odom_base, alpha);
  return true;
}

void FactorGraphFusion::AddOdometryFactors() {
  if (!options_.use_wheel_odometry) return;
  const bool chain_in_gaps = options_.laser_chain_factors == "odometry_gaps";
  while (next_odom_pair_ < num_nodes()) {
    const int j = next_odom_pair_;
    if (odometry_.empty() || odometry_.back().utime < nodes_[j].utime) {
      // Not covered yet. Wait for late odometry, but not forever (no odometry at all, or a
      // dead odometry driver): past the latency bound the pair is a gap.
      const double behind = UtimeToSeconds(nodes_.back().utime - nodes_[j].utime);
      if (behind <= options_.odom_max_latency_s) return;
      ++next_odom_pair_;
      ++counters_.odometry_gaps;
      if (chain_in_gaps) AddChainFactor(j);
      continue;
    }
    ++next_odom_pair_;
    Pose2 a, b;
    if (!OdometryAt(nodes_[j - 1].utime, &a) || !OdometryAt(nodes_[j].utime, &b)) {
      ++counters_.odometry_gaps;
      if (chain_in_gaps) AddChainFactor(j);
      continue;
    }
    const Pose2 motion = a.between(b);
    const double dist = std::hypot(motion.x, motion.y);
    const double sxy = options_.odom_sigma_xy_min + options_.odom_sigma_xy_per_m * dist;
    const double sth = options_.odom_sigma_theta_min +
                       options_.odom_sigma_theta_per_rad * std::fabs(motion.theta) +
                       options_.odom_sigma_theta_per_m * dist;
    ++counters_.odometry_factors;
    AddSequentialFactor(j, motion, sxy, sth, FactorSource::kWheelOdometry, nullptr);
  }
}

SolveSummary FactorGraphFusion::Update() {
  SolveSummary summary;
  if (nodes_.empty()) return summary;
  const int n = num_nodes();
  int first = std::max(0, n - options_.window_size);
  if (oldest_touched_node_ >= 0 && oldest_touched_node_ < first) {
    if (n - oldest_touched_node_ <= options_.max_window_nodes) {
      first = oldest_touched_node_;
    } else {
      full_solve_requested_ = true;  // the rest waits for the full solve
    }
  }
  oldest_touched_node_ = -1;
  summary = SolveWindow(first);
  ++counters_.updates;
  if (summary.ran) last_summary_ = summary;
  return summary;
}

SolveSummary FactorGraphFusion::SolveWindow(int first) {
  const auto t0 = Clock::now();
  SolveSummary summary;
  const int n = num_nodes();
  ceres::Problem problem(BorrowingProblemOptions());
  int num_factors = 0;
  for (int k = first; k < n; ++k) {
    for (int fi : nodes_[k].factors) {
      Factor& f = factors_[fi];
      if (std::max(f.i, f.j) != k) continue;  // added once, at its newest node
      if (f.j < 0) {
        problem.AddResidualBlock(f.cost.get(), f.loss.get(), nodes_[f.i].state.data());
      } else {
        problem.AddResidualBlock(f.cost.get(), f.loss.get(), nodes_[f.i].state.data(),
                                 nodes_[f.j].state.data());
      }
      ++num_factors;
      for (int e : {f.i, f.j}) {
        if (e < 0) continue;
        double* block = nodes_[e].state.data();
        problem.SetManifold(block, manifold_.get());
        if (e < first) problem.SetParameterBlockConstant(block);
      }
    }
  }
  if (num_factors == 0) return summary;
  ceres::Solver::Options options;
  options.max_num_iterations = options_.window_max_iterations;
  options.linear_solver_type =
      n - first <= 80 ? ceres::DENSE_NORMAL_CHOLESKY : ceres::SPARSE_NORMAL_CHOLESKY;
  options.num_threads = 1;
  options.logging_type = ceres::SILENT;
  ConfigureSparseSolverThreads(options.num_threads);  // CHOLMOD's OpenMP teams: see header
  ceres::Solver::Summary s;
  ceres::Solve(options, &problem, &s);
  FillSummary(s, &summary);
  summary.num_nodes = n - first;
  summary.num_factors = num_factors;
  FillUnconstrained(first);
  latest_covariance_.setZero();
  double* newest = nodes_.back().state.data();
  if (options_.compute_covariance && problem.HasParameterBlock(newest) && n - first <= 100) {
    // Marginal covariance of the newest node: the (x, y, theta) block of (J^T J)^-1 over the
    // window's free nodes (dense; the window is small). Left zero if J^T J is singular.
    ceres::Problem::EvaluateOptions eval;
    for (int k = first; k < n; ++k) {
      double* block = nodes_[k].state.data();
      if (problem.HasParameterBlock(block)) eval.parameter_blocks.push_back(block);
    }
    ceres::CRSMatrix jac;
    if (problem.Evaluate(eval, nullptr, nullptr, nullptr, &jac)) {
      Eigen::MatrixXd j = Eigen::MatrixXd::Zero(jac.num_rows, jac.num_cols);
      for (int r = 0; r < jac.num_rows; ++r) {
        for (int q = jac.rows[r]; q < jac.rows[r + 1]; ++q) j(r, jac.cols[q]) = jac.values[q];
      }
      const Eigen::MatrixXd h = j.transpose() * j;
      Eigen::LLT<Eigen::MatrixXd> llt(h);
      if (llt.info() == Eigen::Success) {
        Eigen::MatrixXd e = Eigen::MatrixXd::Zero(h.rows(), 3);
        e.bottomRows(3).setIdentity();  // the newest node is the last block
        const Eigen::MatrixXd x = llt.solve(e);
        if (x.allFinite()) latest_covariance_ = x.bottomRows(3);
      }
    }
  }
  summary.time_ms = MsSince(t0);
  return summary;
}

std::unique_ptr<FullSolveJob> FactorGraphFusion::PrepareFullSolve() {
  auto job = std::make_unique<FullSolveJob>();
  job->states_.reserve(nodes_.size());
  for (const Node& node : nodes_) job->states_.push_back(node.state);
  job->factors_.reserve(factors_.size());
  for (const Factor& f : factors_) job->factors_.push_back({f.i, f.j, f.cost, f.loss});
  job->max_iterations_ = options_.full_max_iterations;
  job->num_factors_at_snapshot_ = num_factors();
  full_solve_requested_ = false;
  nodes_at_last_full_solve_ = num_nodes();
  return job;
}

void FullSolveJob::Run() {
  const auto t0 = Clock::now();
  summary_ = SolveSummary();
  summary_.full = true;
  if (factors_.empty()) return;
  Pose2Manifold manifold;
  ceres::Problem problem(BorrowingProblemOptions());
  for (JobFactor& f : factors_) {
    if (f.j < 0) {
      problem.AddResidualBlock(f.cost.get(), f.loss.get(), states_[f.i].data());
    } else {
      problem.AddResidualBlock(f.cost.get(), f.loss.get(), states_[f.i].data(),
                               states_[f.j].data());
    }
  }
  for (Eigen::Vector3d& s : states_) {
    if (problem.HasParameterBlock(s.data())) problem.SetManifold(s.data(), &manifold);
  }
  ceres::Solver::Options options;
  options.max_num_iterations = max_iterations_;
  options.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  options.num_threads = 1;
  options.logging_type = ceres::SILENT;
  ConfigureSparseSolverThreads(options.num_threads);  // CHOLMOD's OpenMP teams: see header
  ceres::Solver::Summary s;
  ceres::Solve(options, &problem, &s);
  FillSummary(s, &summary_);
  summary_.full = true;
  summary_.num_nodes = static_cast<int>(states_.size());
  summary_.num_factors = static_cast<int>(factors_.size());
  summary_.time_ms = MsSince(t0);
}

void FactorGraphFusion::ApplyFullSolve(const FullSolveJob& job) {
  const int solved = static_cast<int>(job.states_.size());
  if (!job.summary_.ran || solved == 0 || solved > num_nodes()) return;
  if (job.summary_.termination == "FAILURE") return;
  const Pose2 old_anchor = ToPose2(nodes_[solved - 1].state);
  const Pose2 new_anchor = ToPose2(job.states_[solved - 1]);
  for (int k = solved; k < num_nodes(); ++k) {
    const Pose2 rel = old_anchor.between(ToPose2(nodes_[k].state));
    nodes_[k].state = ToVector(new_anchor * rel);
  }
  for (int k = 0; k < solved; ++k) nodes_[k].state = job.states_[k];
  FillUnconstrained(0);
  ++counters_.full_solves;
  last_summary_ = job.summary_;
}

void FactorGraphFusion::FillUnconstrained(int first) {
  const int n = num_nodes();
  int k = std::max(first, 1);
  while (k < n) {
    if (!nodes_[k].factors.empty()) {
      ++k;
      continue;
    }
    // A run [k, m) of nodes without factors, between constrained nodes a = k-1 and b = m.
    int m = k;
    while (m < n && nodes_[m].factors.empty()) ++m;
    const Node& a = nodes_[k - 1];
    for (int q = k; q < m; ++q) {
      const Pose2 fwd = ToPose2(a.state) * a.T_map_base_rbpf.between(nodes_[q].T_map_base_rbpf);
      if (m == n) {
        nodes_[q].state = ToVector(fwd);
        continue;
      }
      const Node& b = nodes_[m];
      const Pose2 bwd = ToPose2(b.state) * b.T_map_base_rbpf.between(nodes_[q].T_map_base_rbpf);
      const double alpha =
          static_cast<double>(nodes_[q].utime - a.utime) / static_cast<double>(b.utime - a.utime);
      nodes_[q].state =
          Eigen::Vector3d((1 - alpha) * fwd.x + alpha * bwd.x, (1 - alpha) * fwd.y + alpha * bwd.y,
                          WrapAngle(fwd.theta + alpha * WrapAngle(bwd.theta - fwd.theta)));
    }
    k = m;
  }
}

SolveSummary FactorGraphFusion::FullSolve() {
  std::unique_ptr<FullSolveJob> job = PrepareFullSolve();
  job->Run();
  ApplyFullSolve(*job);
  return job->summary();
}

bool FactorGraphFusion::Latest(TrajectoryPoint* out) const {
  if (nodes_.empty()) return false;
  out->utime = nodes_.back().utime;
  out->T_map_base = ToPose2(nodes_.back().state);
  return true;
}

bool FactorGraphFusion::PoseAt(Utime t, Pose2* T_map_base) const {
  if (nodes_.empty() || t < nodes_.front().utime || t > nodes_.back().utime) return false;
  const auto it = std::lower_bound(nodes_.begin(), nodes_.end(), t,
                                   [](const Node& n, Utime time) { return n.utime < time; });
  if (it->utime == t) {
    *T_map_base = ToPose2(it->state);
    return true;
  }
  const Node& a = *(it - 1);
  const Node& b = *it;
  const double alpha = static_cast<double>(t - a.utime) / static_cast<double>(b.utime - a.utime);
  *T_map_base = Interpolate(ToPose2(a.state), ToPose2(b.state), alpha);
  return true;
}

std::vector<TrajectoryPoint> FactorGraphFusion::Trajectory() const {
  std::vector<TrajectoryPoint> out;
  out.reserve(nodes_.size());
  for (const Node& n : nodes_) out.push_back({n.utime, ToPose2(n.state)});
  return out;
}

}  // namespace fl::fusion
