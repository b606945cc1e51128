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
  if (!(odometry_nodes_after_s >= 0.0 && odometry_nodes_after_s <= 3600.0) ||
      !(odometry_node_period_s > 0.0 && odometry_node_period_s <= 10.0)) {
    return Status::Error(
        "odometry_nodes_after_s must be in [0, 3600] s (0: never) and odometry_node_period_s "
        "in (0, 10] s");
  }
  if (max_pending_factors < 1) return Status::Error("max_pending_factors must be >= 1");
  if (!(active_window_s == 0.0 || (active_window_s >= 10.0 && active_window_s <= 1e6))) {
    return Status::Error("active_window_s must be 0 (keep every node) or in [10, 1e6] s");
  }
  if (!(map_node_spacing_m > 0.0 && map_node_spacing_m <= 100.0) ||
      !(map_node_spacing_rad > 0.0 && map_node_spacing_rad <= M_PI)) {
    return Status::Error(
        "map_node_spacing_m must be in (0, 100] m and map_node_spacing_rad in "
        "(0, pi] rad");
  }
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

Eigen::Matrix3d TransformBetweenInformation(const Eigen::Matrix3d& information, const Pose2& P,
                                            const Pose2& Z, const Pose2& Q) {
  const Eigen::Matrix2d R_P = Eigen::Rotation2Dd(P.theta).toRotationMatrix();
  const Eigen::Matrix2d R_Z = Eigen::Rotation2Dd(Z.theta).toRotationMatrix();
  Eigen::Matrix3d A = Eigen::Matrix3d::Identity();
  A.topLeftCorner<2, 2>() = R_P;
  A.topRightCorner<2, 1>() = R_P * R_Z * Eigen::Vector2d(-Q.y, Q.x);
  const Eigen::Matrix3d A_inv = A.inverse();
  const Eigen::Matrix3d out = A_inv.transpose() * information * A_inv;
  return 0.5 * (out + out.transpose());
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
  if (TakeOverOdometryNode(utime, T_map_base)) return Status::Ok();
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
  newest_laser_utime_ = utime;
  AddNode(std::move(node), /*from_laser=*/true);
  return Status::Ok();
}

bool FactorGraphFusion::TakeOverOdometryNode(Utime utime, const Pose2& T_map_base) {
  if (!Finite(T_map_base) || num_nodes() == num_fixed_ || utime < nodes_[num_fixed_].utime ||
      utime > nodes_.back().utime) {
    return false;
  }
  const auto it = std::lower_bound(nodes_.begin() + num_fixed_, nodes_.end(), utime,
                                   [](const Node& n, Utime time) { return n.utime < time; });
  if (it == nodes_.end() || it->utime != utime || !it->from_odometry) return false;
  it->T_map_base_rbpf = Pose2(T_map_base.x, T_map_base.y, WrapAngle(T_map_base.theta));
  it->from_odometry = false;
  --counters_.odometry_nodes;
  newest_laser_utime_ = std::max(newest_laser_utime_, utime);  // the laser is back
  return true;
}

void FactorGraphFusion::AddOdometryNodeIfLaserSilent(Utime t) {
  // (The first node is a laser pose's: nodes_ not empty means newest_laser_utime_ is set.)
  if (options_.odometry_nodes_after_s <= 0.0 || nodes_.empty() || t <= nodes_.back().utime ||
      UtimeDifference(newest_laser_utime_, t) < SecondsToUtime(options_.odometry_nodes_after_s)) {
    return;
  }
  // Nodes every period from the newest node up to t: the first ones fill the time it took to
  // notice the outage, so that the vision factors of that time find their nodes too.
  const Utime period = std::max<Utime>(1, SecondsToUtime(options_.odometry_node_period_s));
  while (UtimeDifference(nodes_.back().utime, t) >= period) {
    const Node& prev = nodes_.back();
    const Utime next = prev.utime + period;
    Pose2 T_odom_prev, T_odom_next;
    if (!OdometryAt(prev.utime, &T_odom_prev) || !OdometryAt(next, &T_odom_next)) return;
    const Pose2 motion = T_odom_prev.between(T_odom_next);
    Node node;
    node.utime = next;
    node.T_map_base_rbpf = prev.T_map_base_rbpf * motion;  // stands in for the RBPF's pose
    node.state = ToVector(ToPose2(prev.state) * motion);
    node.from_odometry = true;
    ++counters_.odometry_nodes;
    AddNode(std::move(node), /*from_laser=*/false);
  }
}

void FactorGraphFusion::AddNode(Node node, bool from_laser) {
  nodes_.push_back(std::move(node));
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
    prior.sqrt_information = sigma.cwiseInverse().asDiagonal();
    MakeCost(&prior);
    AddGraphFactor(std::move(prior));
  }
  if (index > 0 && from_laser &&
      (options_.laser_chain_factors == "always" ||
       (options_.laser_chain_factors == "odometry_gaps" && !options_.use_wheel_odometry))) {
    AddChainFactor(index);
  }
  AttachPendingFactors();
  AddOdometryFactors();
  if (options_.full_solve_every_n_nodes > 0 &&
      counters_.nodes - nodes_at_last_full_solve_ >= options_.full_solve_every_n_nodes) {
    full_solve_requested_ = true;
  }
  RetireOldNodes();
}

Status FactorGraphFusion::PlaceLateLaserPose(Utime utime, const Pose2& T_map_base,
                                             TrajectoryPoint* out) {
  const std::string what = "late laser pose at " + TimeText(utime);
  if (!Finite(T_map_base)) {
    return Reject(&counters_.rejected_non_finite, what + " has NaN/Inf; dropped");
  }
  if (nodes_.empty() || utime > nodes_.back().utime) {
    return Reject(&counters_.rejected_node_time,
                  what + " is not older than the newest node; it gets a node (AddLaserPose)");
  }
  const int b = TimelineLowerBound(utime);  // first timeline entry at or after utime
  if ((b < TimelineSize() && TimelineUtime(b) == utime) || late_placed_.count(utime) > 0) {
    return Reject(&counters_.rejected_node_time,
                  what +
                      ": a pose with this stamp was taken already (a repeated message); "
                      "dropped");
  }
  const int n =
      b == 0 || (b < TimelineSize() && TimelineUtime(b) - utime < utime - TimelineUtime(b - 1))
          ? b
          : b - 1;
  const Utime tol = SecondsToUtime(options_.attach_max_gap_s);
  if (n >= TimelineSize() || std::llabs(utime - TimelineUtime(n)) > tol) {
    return Reject(&counters_.rejected_node_time, what + ": no node within " +
                                                     FormatDouble(options_.attach_max_gap_s) +
                                                     " s of it to place it on; dropped");
  }
  const Pose2 T_map_t_rbpf(T_map_base.x, T_map_base.y, WrapAngle(T_map_base.theta));
  out->utime = utime;
  out->T_map_base = TimelinePose(n) * TimelineRbpf(n).between(T_map_t_rbpf);
  late_placed_.insert(utime);
  if (late_placed_.size() > kMaxLatePlacedStamps) late_placed_.erase(late_placed_.begin());
  newest_laser_utime_ = std::max(newest_laser_utime_, utime);  // the laser is back
  ++counters_.late_laser_poses_placed;
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

int FactorGraphFusion::TimelineSize() const {
  return static_cast<int>(retired_.size()) + num_nodes() - num_fixed_;
}

Utime FactorGraphFusion::TimelineUtime(int k) const {
  const int r = static_cast<int>(retired_.size());
  return k < r ? retired_.at(static_cast<size_t>(k)).utime : nodes_[num_fixed_ + k - r].utime;
}

Pose2 FactorGraphFusion::TimelinePose(int k) const {
  const int r = static_cast<int>(retired_.size());
  return k < r ? retired_.at(static_cast<size_t>(k)).T_map_base
               : ToPose2(nodes_[num_fixed_ + k - r].state);
}

Pose2 FactorGraphFusion::TimelineRbpf(int k) const {
  const int r = static_cast<int>(retired_.size());
  return k < r ? retired_.at(static_cast<size_t>(k)).T_map_base_rbpf
               : nodes_[num_fixed_ + k - r].T_map_base_rbpf;
}

void FactorGraphFusion::TimelineNode(int k, int* node, Pose2* T_node_k) const {
  const int r = static_cast<int>(retired_.size());
  if (k >= r) {
    *node = num_fixed_ + k - r;
    *T_node_k = Pose2();
    return;
  }
  const RetiredRecord d = retired_.at(static_cast<size_t>(k));
  const auto it = std::lower_bound(nodes_.begin(), nodes_.begin() + num_fixed_, d.anchor_utime,
                                   [](const Node& n, Utime time) { return n.utime < time; });
  *node = static_cast<int>(it - nodes_.begin());
  *T_node_k = ToPose2(it->state).between(d.T_map_base);
}

int FactorGraphFusion::TimelineLowerBound(Utime t) const {
  // The retired part (in memory or spilled) only for times it covers: the recent times most
  // lookups ask for never touch a spill file.
  if (!retired_.empty() && t <= retired_.back().utime) {
    return static_cast<int>(retired_.LowerBound(t));
  }
  const auto it = std::lower_bound(nodes_.begin() + num_fixed_, nodes_.end(), t,
                                   [](const Node& n, Utime time) { return n.utime < time; });
  return static_cast<int>(retired_.size()) + static_cast<int>(it - (nodes_.begin() + num_fixed_));
}

bool FactorGraphFusion::Attach(Utime t, int* node, Pose2* T_node_t) const {
  if (nodes_.empty()) return false;
  const Utime tol = SecondsToUtime(options_.attach_tolerance_s);
  const int b = TimelineLowerBound(t);  // first timeline entry at or after t
  if (b == 0) {
    // At or before the first node: no interpolation possible; exact or within tolerance.
    if (TimelineUtime(0) - t > tol) return false;
    TimelineNode(0, node, T_node_t);
    return true;
  }
  if (b == TimelineSize()) return false;  // beyond the newest node (the caller waits)
  const int a = b - 1;
  const Utime ta = TimelineUtime(a), tb = TimelineUtime(b);
  const int n = (t - ta <= tb - t) ? a : b;
  if (std::llabs(t - TimelineUtime(n)) > tol &&
      tb - ta > SecondsToUtime(options_.attach_max_gap_s)) {
    return false;
  }
  const double alpha = static_cast<double>(t - ta) / static_cast<double>(tb - ta);
  const Pose2 T_map_t = Interpolate(TimelineRbpf(a), TimelineRbpf(b), alpha);
  Pose2 T_node_n;
  TimelineNode(n, node, &T_node_n);
  *T_node_t = T_node_n * TimelineRbpf(n).between(T_map_t);
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
  if (nodes_[ni].fixed && nodes_[nj].fixed) {
    ++counters_.retired_factors;  // between two frozen poses: it can move nothing
    return Status::Ok();
  }
  if (ni == nj) {
    return Reject(&counters_.rejected_same_node,
                  what + ": both times attach to the same laser node; dropped");
  }
  Factor factor;
  factor.i = ni;
  factor.j = nj;
  factor.T_i_j = T_ni_ti * T_ti_tj * T_nj_tj.inverse();
  factor.information =
      TransformBetweenInformation(information, T_ni_ti, T_ti_tj, T_nj_tj.inverse());
  factor.source = f.source;
  factor.is_loop_closure = f.is_loop_closure;
  if (!SqrtInformation<3>(factor.information, &factor.sqrt_information)) {
    return Reject(&counters_.rejected_information,
                  what + ": information not positive definite once attached; dropped");
  }
  MakeCost(&factor);
  if (f.is_loop_closure && options_.full_solve_on_loop_closure) full_solve_requested_ = true;
  AddGraphFactor(std::move(factor));
  return Status::Ok();
}

void FactorGraphFusion::AddGraphFactor(Factor factor) {
  const int index = static_cast<int>(factors_.size());
  int oldest = -1;
  for (int e : {factor.i, factor.j}) {
    if (e >= 0 && !nodes_[e].fixed && (oldest < 0 || e < oldest)) oldest = e;
  }
  nodes_[factor.i].factors.push_back(index);
  if (factor.j >= 0) nodes_[factor.j].factors.push_back(index);
  factors_.push_back(std::move(factor));
  ++counters_.factors_added;
  if (oldest >= 0 && (oldest_touched_node_ < 0 || oldest < oldest_touched_node_)) {
    oldest_touched_node_ = oldest;
  }
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
  AddSequentialFactor(j, motion, sxy, sth, FactorSource::kLaser);
}

void FactorGraphFusion::AddSequentialFactor(int j, const Pose2& motion, double sigma_xy,
                                            double sigma_theta, FactorSource source) {
  const Eigen::Vector3d sqrt_info(1 / sigma_xy, 1 / sigma_xy, 1 / sigma_theta);
  Factor factor;
  factor.i = j - 1;
  factor.j = j;
  factor.T_i_j = motion;
  factor.information = sqrt_info.cwiseAbs2().asDiagonal();
  factor.sqrt_information = sqrt_info.asDiagonal();
  factor.source = source;
  MakeCost(&factor);
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
    // Late: inserted by its stamp between the kept samples around it.
    const auto at =
        std::lower_bound(odometry_.begin(), odometry_.end(), utime,
                         [](const OdomSample& s, Utime time) { return s.utime < time; });
    if (at->utime == utime || at == odometry_.begin()) {
      ++counters_.rejected_odometry;
      const std::string m =
          "odometry at " + TimeText(utime) +
          (at->utime == utime
               ? " repeats a sample's stamp; dropped"
               : " is older than every kept sample (" + TimeText(odometry_.front().utime) +
                     ": the node pairs it could serve are done); dropped");
      warnings_->odometry.Warn(m);
      return Status::Error(m);
    }
    odometry_.insert(at, {utime, T_odom_base});
    ++counters_.late_odometry_placed;
    AddOdometryFactors();
    return Status::Ok();
  }
  odometry_.push_back({utime, T_odom_base});
  AddOdometryFactors();
  AddOdometryNodeIfLaserSilent(utime);
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
    AddSequentialFactor(j, motion, sxy, sth, FactorSource::kWheelOdometry);
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
  optimised_until_ = nodes_.back().utime;
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
        if (e < first || nodes_[e].fixed) problem.SetParameterBlockConstant(block);
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
  for (const Node& node : nodes_) {
    job->states_.push_back(node.state);
    job->fixed_.push_back(node.fixed ? 1 : 0);
  }
  job->factors_.reserve(factors_.size());
  for (const Factor& f : factors_) job->factors_.push_back({f.i, f.j, f.cost, f.loss});
  job->max_iterations_ = options_.full_max_iterations;
  job->num_factors_at_snapshot_ = num_factors();
  full_solve_requested_ = false;
  nodes_at_last_full_solve_ = counters_.nodes;
  job_outstanding_ = true;
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
  for (size_t k = 0; k < states_.size(); ++k) {
    double* s = states_[k].data();
    if (!problem.HasParameterBlock(s)) continue;
    problem.SetManifold(s, &manifold);
    if (k < fixed_.size() && fixed_[k]) problem.SetParameterBlockConstant(s);
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
  job_outstanding_ = false;
  const int solved = static_cast<int>(job.states_.size());
  if (!job.summary_.ran || solved == 0 || solved > num_nodes()) return;
  if (job.summary_.termination == "FAILURE") return;
  const Pose2 old_anchor = ToPose2(nodes_[solved - 1].state);
  const Pose2 new_anchor = ToPose2(job.states_[solved - 1]);
  for (int k = solved; k < num_nodes(); ++k) {
    const Pose2 rel = old_anchor.between(ToPose2(nodes_[k].state));
    nodes_[k].state = ToVector(new_anchor * rel);
  }
  for (int k = 0; k < solved; ++k) {
    if (!nodes_[k].fixed) nodes_[k].state = job.states_[k];
  }
  optimised_until_ = std::max(optimised_until_, nodes_[solved - 1].utime);
  FillUnconstrained(0);
  ++counters_.full_solves;
  last_summary_ = job.summary_;
}

void FactorGraphFusion::FillUnconstrained(int first) {
  const int n = num_nodes();
  int k = std::max(first, 1);
  while (k < n) {
    if (!nodes_[k].factors.empty() || nodes_[k].fixed) {
      ++k;
      continue;
    }
    // A run [k, m) of nodes without factors, between constrained nodes a = k-1 and b = m.
    int m = k;
    while (m < n && nodes_[m].factors.empty() && !nodes_[m].fixed) ++m;
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
  if (nodes_.empty()) return false;
  // The trajectory: the retired nodes (frozen), then the active nodes.
  auto utime = [&](int k) { return TimelineUtime(k); };
  auto pose = [&](int k) { return TimelinePose(k); };
  const Utime first = retired_.empty() ? nodes_[num_fixed_].utime : retired_.front_utime();
  if (t < first || t > utime(TimelineSize() - 1)) return false;
  const int lo = TimelineLowerBound(t);
  if (utime(lo) == t) {
    *T_map_base = pose(lo);
    return true;
  }
  const Utime ta = utime(lo - 1), tb = utime(lo);
  const double alpha = static_cast<double>(t - ta) / static_cast<double>(tb - ta);
  *T_map_base = Interpolate(pose(lo - 1), pose(lo), alpha);
  return true;
}

std::vector<TrajectoryPoint> FactorGraphFusion::Trajectory(Utime from) const {
  const size_t first_retired = retired_.LowerBound(from);
  std::vector<TrajectoryPoint> out;
  out.reserve(retired_.size() - first_retired + nodes_.size());
  retired_.ForEach(first_retired,
                   [&out](const RetiredRecord& d) { out.push_back({d.utime, d.T_map_base}); });
  for (int k = num_fixed_; k < num_nodes(); ++k) {
    if (nodes_[k].utime >= from) out.push_back({nodes_[k].utime, ToPose2(nodes_[k].state)});
  }
  return out;
}

void FactorGraphFusion::RetireOldNodes() {
  if (options_.active_window_s <= 0.0 || job_outstanding_ || nodes_.empty()) return;
  const int n = num_nodes();
  const int first = num_fixed_;
  const Utime cutoff = nodes_.back().utime - SecondsToUtime(options_.active_window_s);
  constexpr double kBatchS = 10.0;  // each retirement rebuilds the graph's indices
  if (first >= n || nodes_[first].utime >= cutoff - SecondsToUtime(kBatchS)) return;
  // Never the newest max_window_nodes (a late factor's window), nor a node whose odometry
  // pair is still open.
  const int limit = std::min({n - options_.max_window_nodes,
                              options_.use_wheel_odometry ? next_odom_pair_ - 1 : n, n - 1});
  int end = first;
  // Only nodes that some solve has placed (a journal restore adds nodes without solving).
  while (end < limit && nodes_[end].utime < cutoff && nodes_[end].utime <= optimised_until_) ++end;
  if (end == first) return;

  // 1. Each retired node: kept as a map node, or merged into the nearest map node near it.
  std::vector<int> map_nodes;
  for (int k = 0; k < first; ++k) map_nodes.push_back(k);
  std::vector<int> anchor(static_cast<size_t>(n), -1);
  for (int k = 0; k < n; ++k) anchor[static_cast<size_t>(k)] = k;
  for (int k = first; k < end; ++k) {
    Node& node = nodes_[k];
    const Pose2 p = ToPose2(node.state);
    int best = -1;
    double best_d = options_.map_node_spacing_m;
    for (int m : map_nodes) {
      const Eigen::Vector3d& q = nodes_[m].state;
      const double d = std::hypot(q[0] - p.x, q[1] - p.y);
      if (d <= best_d && std::fabs(WrapAngle(q[2] - p.theta)) <= options_.map_node_spacing_rad) {
        best = m;
        best_d = d;
      }
    }
    if (best < 0) {
      node.fixed = true;
      map_nodes.push_back(k);
    } else {
      anchor[static_cast<size_t>(k)] = best;
      ++counters_.merged_nodes;
    }
    retired_.push_back(
        {node.utime, p, node.T_map_base_rbpf, nodes_[anchor[static_cast<size_t>(k)]].utime});
    ++counters_.retired_nodes;
  }
  // 2. New indices: the map nodes (old, then new, in time order), then the active nodes.
  std::vector<int> index(static_cast<size_t>(n), -1);
  int next = 0;
  for (int k = 0; k < n; ++k) {
    if (k >= end || nodes_[k].fixed) index[static_cast<size_t>(k)] = next++;
  }
  // 3. Factors: merged ends re-anchored onto their map node; all-fixed factors dropped.
  std::vector<Factor> factors;
  factors.reserve(factors_.size());
  for (Factor& f : factors_) {
    const int ai = anchor[static_cast<size_t>(f.i)];
    const int aj = f.j < 0 ? -1 : anchor[static_cast<size_t>(f.j)];
    const bool fixed_i = nodes_[ai].fixed;
    const bool fixed_j = aj < 0 || nodes_[aj].fixed;
    if ((fixed_i && fixed_j) || ai == aj) {
      ++counters_.retired_factors;
      continue;
    }
    if (ai != f.i || aj != f.j) {
      // T_a_i = T_map_a^-1 T_map_i (both frozen); Z' = T_ai_i Z T_j_aj.
      const Pose2 P = ToPose2(nodes_[ai].state).between(ToPose2(nodes_[f.i].state));
      const Pose2 Q = ToPose2(nodes_[f.j].state).between(ToPose2(nodes_[aj].state));
      const Eigen::Matrix3d information = TransformBetweenInformation(f.information, P, f.T_i_j, Q);
      if (!SqrtInformation<3>(information, &f.sqrt_information)) {
        ++counters_.retired_factors;
        continue;
      }
      f.T_i_j = P * f.T_i_j * Q;
      f.information = information;
      MakeCost(&f);
      ++counters_.reanchored_factors;
    }
    f.i = index[static_cast<size_t>(ai)];
    f.j = aj < 0 ? -1 : index[static_cast<size_t>(aj)];
    factors.push_back(std::move(f));
  }
  // 4. The nodes, their factor lists and the indices that point into them.
  std::deque<Node> nodes;
  for (int k = 0; k < n; ++k) {
    if (index[static_cast<size_t>(k)] < 0) continue;
    nodes.push_back(std::move(nodes_[k]));
    nodes.back().factors.clear();
  }
  for (int fi = 0; fi < static_cast<int>(factors.size()); ++fi) {
    nodes[factors[fi].i].factors.push_back(fi);
    if (factors[fi].j >= 0) nodes[factors[fi].j].factors.push_back(fi);
  }
  if (options_.use_wheel_odometry) {
    next_odom_pair_ = index[static_cast<size_t>(next_odom_pair_ - 1)] + 1;
  }
  if (oldest_touched_node_ >= 0) {
    oldest_touched_node_ = index[static_cast<size_t>(std::max(oldest_touched_node_, end))];
  }
  num_fixed_ = static_cast<int>(map_nodes.size());
  nodes_ = std::move(nodes);
  factors_ = std::move(factors);
}

void FactorGraphFusion::MakeCost(Factor* f) const {
  if (f->is_prior) {
    f->cost.reset(Se2PriorCost::Create(ToVector(f->T_i_j), f->sqrt_information));
    f->loss = nullptr;
  } else {
    f->cost.reset(Se2BetweenCost::Create(f->T_i_j, f->sqrt_information));
    f->loss = f->source == FactorSource::kWheelOdometry ? nullptr : robust_loss_;
  }
}

// Saved state: version 1. Counts before sequences; a node's factor list is rebuilt from the
// factors. Each read names what it reads, so that a damaged state names its field.
namespace {
constexpr char kStateMagic[] = "FLFUSION";
constexpr uint32_t kStateVersion = 2;  // 2: the retired trajectory may be spilled

void PutSummary(StateWriter* w, const SolveSummary& s) {
  w->Put(static_cast<uint8_t>(s.ran));
  w->Put(static_cast<uint8_t>(s.full));
  w->Put(s.termination);
  w->Put(static_cast<int32_t>(s.iterations));
  w->Put(s.initial_cost);
  w->Put(s.final_cost);
  w->Put(s.time_ms);
  w->Put(static_cast<int32_t>(s.num_nodes));
  w->Put(static_cast<int32_t>(s.num_factors));
}

SolveSummary GetSummary(StateReader* r) {
  SolveSummary s;
  s.ran = r->GetBool("summary.ran");
  s.full = r->GetBool("summary.full");
  s.termination = r->GetString("summary.termination");
  s.iterations = r->Get<int32_t>("summary.iterations");
  s.initial_cost = r->Get<double>("summary.initial_cost");
  s.final_cost = r->Get<double>("summary.final_cost");
  s.time_ms = r->Get<double>("summary.time_ms");
  s.num_nodes = r->Get<int32_t>("summary.num_nodes");
  s.num_factors = r->Get<int32_t>("summary.num_factors");
  return s;
}

// The counters in one list, for both directions.
template <class F>
void ForEachCounter(FusionCounters* c, F f) {
  for (int64_t* v :
       {&c->nodes, &c->factors_added, &c->rejected_node_time, &c->rejected_non_finite,
        &c->rejected_information, &c->rejected_no_node, &c->rejected_same_node,
        &c->dropped_pending_overflow, &c->rejected_odometry, &c->late_laser_poses_placed,
        &c->late_odometry_placed, &c->odometry_gaps, &c->odometry_factors, &c->chain_factors,
        &c->odometry_nodes,
        &c->full_solves, &c->updates, &c->retired_nodes, &c->merged_nodes,
        &c->reanchored_factors, &c->retired_factors}) {
    f(v);
  }
}

void PutRelativePoseFactor(StateWriter* w, const RelativePoseFactor& f) {
  w->Put(f.utime_i);
  w->Put(f.utime_j);
  w->Put(Eigen::Matrix4d(f.T_i_j.matrix()));
  w->Put(f.information);
  w->Put(static_cast<int8_t>(f.source));
  w->Put(static_cast<uint8_t>(f.is_loop_closure));
}

FactorSource GetSource(StateReader* r, const char* what) {
  const int8_t s = r->Get<int8_t>(what);
  if (s < 0 || s > static_cast<int8_t>(FactorSource::kWheelOdometry)) {
    r->Fail(std::string(what) + ": no factor source " + std::to_string(s));
  }
  return static_cast<FactorSource>(s);
}

template <int R, int C>
Eigen::Matrix<double, R, C> GetFiniteMatrix(StateReader* r, const char* what) {
  Eigen::Matrix<double, R, C> m;
  r->Get(&m, what);
  if (!m.allFinite()) r->Fail(std::string(what) + " is not finite");
  return m;
}

Pose2 GetFinitePose(StateReader* r, const char* what) {
  const Pose2 p = r->GetPose2(what);
  if (!Finite(p)) r->Fail(std::string(what) + " is not finite");
  return p;
}

RelativePoseFactor GetRelativePoseFactor(StateReader* r) {
  RelativePoseFactor f;
  f.utime_i = r->Get<int64_t>("pending.utime_i");
  f.utime_j = r->Get<int64_t>("pending.utime_j");
  f.T_i_j.matrix() = GetFiniteMatrix<4, 4>(r, "pending.T_i_j");
  f.information = GetFiniteMatrix<6, 6>(r, "pending.information");
  f.source = GetSource(r, "pending.source");
  f.is_loop_closure = r->GetBool("pending.is_loop_closure");
  return f;
}

// Smallest saved sizes, for StateReader::Count.
constexpr size_t kNodeBytes = 8 + 3 * 8 + 3 * 8 + 2;
constexpr size_t kFactorBytes = 4 + 4 + 3 * 8 + 2 * 9 * 8 + 3;
constexpr size_t kPendingBytes = 8 + 8 + 16 * 8 + 36 * 8 + 2 + 3 * 8 + 9 * 8;
constexpr size_t kPoseSampleBytes = 8 + 3 * 8;

}  // namespace

void FactorGraphFusion::SaveState(StateWriter* w) const {
  if (job_outstanding_) {
    throw std::logic_error("FactorGraphFusion::SaveState while a full-solve job is outstanding");
  }
  w->Begin(kStateMagic, kStateVersion);
  w->PutCount(nodes_.size());
  for (const Node& n : nodes_) {
    w->Put(n.utime);
    w->Put(n.T_map_base_rbpf);
    w->Put(n.state);
    w->Put(static_cast<uint8_t>(n.fixed));
    w->Put(static_cast<uint8_t>(n.from_odometry));
  }
  w->PutCount(factors_.size());
  for (const Factor& f : factors_) {
    w->Put(static_cast<int32_t>(f.i));
    w->Put(static_cast<int32_t>(f.j));
    w->Put(f.T_i_j);
    w->Put(f.information);
    w->Put(f.sqrt_information);
    w->Put(static_cast<int8_t>(f.source));
    w->Put(static_cast<uint8_t>(f.is_loop_closure));
    w->Put(static_cast<uint8_t>(f.is_prior));
  }
  w->PutCount(pending_.size());
  for (const PendingFactor& p : pending_) {
    PutRelativePoseFactor(w, p.factor);
    w->Put(p.T_i_j);
    w->Put(p.information);
  }
  w->PutCount(odometry_.size());
  for (const OdomSample& o : odometry_) {
    w->Put(o.utime);
    w->Put(o.T_odom_base);
  }
  w->PutCount(late_placed_.size());
  for (Utime t : late_placed_) w->Put(t);
  retired_.SaveState(w);
  w->Put(newest_laser_utime_);
  w->Put(static_cast<int32_t>(next_odom_pair_));
  w->Put(static_cast<int32_t>(oldest_touched_node_));
  w->Put(static_cast<uint8_t>(full_solve_requested_));
  w->Put(nodes_at_last_full_solve_);
  w->Put(static_cast<int32_t>(num_fixed_));
  w->Put(optimised_until_);
  w->Put(latest_covariance_);
  PutSummary(w, last_summary_);
  FusionCounters counters = counters_;
  ForEachCounter(&counters, [w](int64_t* v) { w->Put(*v); });
}

void FactorGraphFusion::LoadState(StateReader* r) {
  r->Begin(kStateMagic, kStateVersion);
  // Read into a new object, checked, then swapped in: a bad state leaves this one unchanged.
  FactorGraphFusion s(options_);
  const size_t num_nodes = r->Count(kNodeBytes, "nodes");
  for (size_t k = 0; k < num_nodes; ++k) {
    Node n;
    n.utime = r->Get<int64_t>("node.utime");
    if (!s.nodes_.empty() && n.utime <= s.nodes_.back().utime) {
      r->Fail("node " + std::to_string(k) + ": its utime is not after the previous node's");
    }
    n.T_map_base_rbpf = GetFinitePose(r, "node.T_map_base_rbpf");
    n.state = GetFiniteMatrix<3, 1>(r, "node.state");
    n.fixed = r->GetBool("node.fixed");
    n.from_odometry = r->GetBool("node.from_odometry");
    s.nodes_.push_back(std::move(n));
  }
  const int n = static_cast<int>(num_nodes);
  const size_t num_factors = r->Count(kFactorBytes, "factors");
  s.factors_.reserve(num_factors);
  for (size_t k = 0; k < num_factors; ++k) {
    Factor f;
    f.i = r->Get<int32_t>("factor.i");
    f.j = r->Get<int32_t>("factor.j");
    if (f.i < 0 || f.i >= n || f.j < -1 || f.j >= n || f.i == f.j) {
      r->Fail("factor " + std::to_string(k) + " joins nodes " + std::to_string(f.i) + " and " +
              std::to_string(f.j) + " of " + std::to_string(n));
    }
    f.T_i_j = GetFinitePose(r, "factor.T_i_j");
    f.information = GetFiniteMatrix<3, 3>(r, "factor.information");
    f.sqrt_information = GetFiniteMatrix<3, 3>(r, "factor.sqrt_information");
    f.source = GetSource(r, "factor.source");
    f.is_loop_closure = r->GetBool("factor.is_loop_closure");
    f.is_prior = r->GetBool("factor.is_prior");
    if (f.is_prior != (f.j < 0)) r->Fail("factor " + std::to_string(k) + ": a prior has no j");
    s.MakeCost(&f);
    s.nodes_[f.i].factors.push_back(static_cast<int>(k));
    if (f.j >= 0) s.nodes_[f.j].factors.push_back(static_cast<int>(k));
    s.factors_.push_back(std::move(f));
  }
  const size_t num_pending = r->Count(kPendingBytes, "pending factors");
  for (size_t k = 0; k < num_pending; ++k) {
    PendingFactor p;
    p.factor = GetRelativePoseFactor(r);
    p.T_i_j = GetFinitePose(r, "pending.T_i_j (planar)");
    p.information = GetFiniteMatrix<3, 3>(r, "pending.information (planar)");
    s.pending_.push_back(std::move(p));
  }
  const size_t num_odometry = r->Count(kPoseSampleBytes, "odometry samples");
  for (size_t k = 0; k < num_odometry; ++k) {
    OdomSample o;
    o.utime = r->Get<int64_t>("odometry.utime");
    o.T_odom_base = GetFinitePose(r, "odometry.T_odom_base");
    if (!s.odometry_.empty() && o.utime <= s.odometry_.back().utime) {
      r->Fail("odometry sample " + std::to_string(k) + " is not after the previous one");
    }
    s.odometry_.push_back(o);
  }
  const size_t num_late = r->Count(8, "late laser pose stamps");
  for (size_t k = 0; k < num_late; ++k) s.late_placed_.insert(r->Get<int64_t>("late stamp"));
  s.retired_.SpillTo(retired_.spill_file(), retired_.keep_in_memory(), retired_.spill_batch());
  s.retired_.LoadState(r);
  s.newest_laser_utime_ = r->Get<int64_t>("newest_laser_utime");
  s.next_odom_pair_ = r->Get<int32_t>("next_odom_pair");
  s.oldest_touched_node_ = r->Get<int32_t>("oldest_touched_node");
  s.full_solve_requested_ = r->GetBool("full_solve_requested");
  s.nodes_at_last_full_solve_ = r->Get<int64_t>("nodes_at_last_full_solve");
  s.num_fixed_ = r->Get<int32_t>("num_fixed");
  s.optimised_until_ = r->Get<int64_t>("optimised_until");
  r->Get(&s.latest_covariance_, "latest_covariance");
  s.last_summary_ = GetSummary(r);
  ForEachCounter(&s.counters_, [r](int64_t* v) { *v = r->Get<int64_t>("counter"); });
  // What the graph's code takes for granted.
  if (s.next_odom_pair_ < 1 || s.next_odom_pair_ > n + 1 || s.oldest_touched_node_ < -1 ||
      s.oldest_touched_node_ >= n || s.num_fixed_ < 0 || s.num_fixed_ > n) {
    r->Fail("its graph indices (odometry pair, oldest touched node, map nodes) are out of range");
  }
  for (int k = 0; k < n; ++k) {
    if (s.nodes_[k].fixed != (k < s.num_fixed_)) {
      r->Fail("node " + std::to_string(k) + ": the map nodes must come first");
    }
  }
  if (!s.retired_.empty() && s.num_fixed_ < n &&
      s.retired_.back().utime >= s.nodes_[s.num_fixed_].utime) {
    r->Fail("the retired nodes must be older than the active ones");
  }
  // Every retired pose's anchor is a map node (the spilled ones read back from their file).
  s.retired_.ForEach(0, [&s, r](const RetiredRecord& rn) {
    const auto it = std::lower_bound(
        s.nodes_.begin(), s.nodes_.begin() + s.num_fixed_, rn.anchor_utime,
        [](const Node& node, Utime time) { return node.utime < time; });
    if (it == s.nodes_.begin() + s.num_fixed_ || it->utime != rn.anchor_utime) {
      r->Fail("retired node at utime " + std::to_string(rn.utime) + ": no map node at its anchor");
    }
  });
  *this = std::move(s);
}

}  // namespace fl::fusion
