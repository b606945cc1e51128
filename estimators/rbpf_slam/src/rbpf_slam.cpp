#include "fusionloc/rbpf_slam/rbpf_slam.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>

#include "fusionloc/common/number_format.hpp"
#include "fusionloc/rbpf_slam/correlative_matcher.hpp"
#include "fusionloc/rbpf_slam/scan_matcher.hpp"

namespace fl::rbpf {

namespace {
// Weak information for a sequential graph edge when ICP failed (keeps the graph connected):
// σ = 0.1 m, 0.05 rad.
Eigen::Matrix3d WeakInformation() { return Eigen::Vector3d(100.0, 100.0, 400.0).asDiagonal(); }

// Whether a relative pose is below both `m` metres and `rad` radians (strictly) ...
bool Within(const fl::Pose2& d, double m, double rad) {
  return std::hypot(d.x, d.y) < m && std::abs(d.theta) < rad;
}
// ... or above either.
bool Beyond(const fl::Pose2& d, double m, double rad) {
  return std::hypot(d.x, d.y) > m || std::abs(d.theta) > rad;
}

// A sequential ICP result is trusted only within 0.5 m / 0.3 rad of where it started.
// The fit ended within 0.5 m / 0.3 rad of where it started.
bool CloseToStart(const IcpResult& icp, const fl::Pose2& start) {
  return Within(start.between(icp.T_ref_query), 0.5, 0.3);
}
bool NearStart(const IcpResult& icp, const fl::Pose2& start) {
  return icp.ok && CloseToStart(icp, start);
}

// An ICP fit that failed only the RMS gate, with its RMS within rms_per_noise times the scan's
// range noise and near its start (graph.noisy_factor_rms_per_noise).
bool NoisyButRightFit(const IcpResult& icp, double range_noise, double rms_per_noise,
                      const fl::Pose2& start) {
  return icp.failed_only_rms && icp.rms <= rms_per_noise * range_noise && CloseToStart(icp, start);
}
}  // namespace

RbpfSlam::RbpfSlam(const RbpfSlamOptions& options)
    : opt_(options),
      rng_(static_cast<uint32_t>(options.seed)),
      rebuild_map_(options.grid) {
  const Status s = options.Validate();
  if (!s.ok()) throw std::invalid_argument("RbpfSlamOptions: " + s.message());
  particles_.reserve(options.particles);
  for (int i = 0; i < options.particles; ++i) {
    particles_.push_back(Particle{fl::Pose2(), 0.0, TiledGrid(options.grid)});
  }
}

fl::Status RbpfSlam::SetBaseLaser(const fl::Pose2& T_base_laser) {
  if (!std::isfinite(T_base_laser.x) || !std::isfinite(T_base_laser.y) ||
      !std::isfinite(T_base_laser.theta)) {
    return Status::Error("T_base_laser is not finite");
  }
  if (input_.initialized()) {
    return Status::Error("T_base_laser can only be set before the first scan");
  }
  T_base_laser_ = T_base_laser;
  return Status::Ok();
}

double RbpfSlam::EffectiveSampleSize(const std::vector<double>& w) {
  double s = 0.0;
  for (double x : w) s += x * x;
  return s > 0.0 ? 1.0 / s : 0.0;
}

std::vector<int> RbpfSlam::SystematicResample(const std::vector<double>& w, double u0) {
  const int n = static_cast<int>(w.size());
  std::vector<int> parents(n);
  double c = w.empty() ? 0.0 : w[0];
  int i = 0;
  for (int m = 0; m < n; ++m) {
    const double u = (u0 + m) / n;
    while (u > c && i < n - 1) c += w[++i];
    parents[m] = i;
  }
  return parents;
}

std::vector<double> RbpfSlam::NormalizedWeights() const {
  double mx = -std::numeric_limits<double>::infinity();
  for (const auto& p : particles_) mx = std::max(mx, p.log_w);
  std::vector<double> w(particles_.size());
  double sum = 0.0;
  for (size_t i = 0; i < particles_.size(); ++i) {
    w[i] = std::exp(particles_[i].log_w - mx);
    sum += w[i];
  }
  for (double& x : w) x /= sum;
  return w;
}

int RbpfSlam::BestIndex() const {
  int best = 0;
  for (size_t i = 1; i < particles_.size(); ++i) {
    if (particles_[i].log_w > particles_[best].log_w) best = static_cast<int>(i);
  }
  return best;
}

fl::Pose2 RbpfSlam::CurrentPose() const {
  return particles_[best_].pose * odom_at_processed_.between(input_.odom());
}

const TiledGrid& RbpfSlam::BestMap() const { return particles_[best_].map; }

int ScanToBasePoints(const LaserScan& scan, const fl::Pose2& T_base_laser, double max_range,
                     std::vector<Eigen::Vector2d>* points_base) {
  points_base->clear();
  int left_out = 0;
  const double c = std::cos(T_base_laser.theta), s = std::sin(T_base_laser.theta);
  for (size_t k = 0; k < scan.ranges.size(); ++k) {
    const float r = scan.ranges[k];
    if (!std::isfinite(r) || r <= 0.0f || r > max_range) {
      ++left_out;
      continue;
    }
    const double a = scan.rad0 + static_cast<double>(k) * scan.radstep;
    const double lx = r * std::cos(a), ly = r * std::sin(a);
    points_base->emplace_back(T_base_laser.x + c * lx - s * ly, T_base_laser.y + s * lx + c * ly);
  }
  return left_out;
}

void RbpfSlam::ConvertScan(const LaserScan& scan, ScanResult* result) {
  stats_.invalid_beams += ScanToBasePoints(scan, T_base_laser_, opt_.grid.max_range, &hits_base_);
  match_base_.clear();
  for (size_t k = 0; k < hits_base_.size(); k += opt_.matcher.beam_step) {
    match_base_.push_back(hits_base_[k]);
  }
  result->valid_beams = static_cast<int>(hits_base_.size());
}

fl::Status RbpfSlam::AddScan(const LaserScan& scan, const fl::Pose2& odom_pose,
                             ScanResult* result, bool defer_keyframe) {
  ScanResult local;
  ScanResult* res = result ? result : &local;
  *res = ScanResult();
  if (keyframe_pending_) {
    FinishScan(res);
    const std::vector<KeyframeFactor> factors = std::move(res->factors);
    const bool graph_changed = res->graph_changed;
    *res = ScanResult();
    res->factors = factors;
    res->graph_changed = graph_changed;
  }
  // --- Validate the input before touching any state; the odometry step (ScanInput).
  ScanInput::Step in;
  Status error;
  switch (input_.Accept(scan, odom_pose, opt_.motion, &in, &error)) {
    case ScanInput::Verdict::kTimeBackwards:
      ++stats_.dropped_time_backwards;
      return error;
    case ScanInput::Verdict::kBadInput:
      ++stats_.rejected_bad_scan;
      return error;
    case ScanInput::Verdict::kAccepted:
      break;
  }
  ++stats_.scans;
  ConvertScan(scan, res);

  if (in.first) {
    odom_at_processed_ = odom_pose;
    for (auto& p : particles_) p.pose = odom_pose;
    Integrate(&particles_[0]);
    for (size_t i = 1; i < particles_.size(); ++i) particles_[i].map = particles_[0].map;
    ++stats_.processed;
    res->processed = true;
    res->T_world_base = odom_pose;
    res->neff = static_cast<double>(particles_.size());
    MaybeAddKeyframe(scan.utime, res);
    RecordScan({scan.utime, 0, fl::Pose2(), odom_pose, true});
    return Status::Ok();
  }

  // A jump in the odometry is replaced by "no motion" plus noise.
  const double dt_s = in.dt_s;
  const fl::Pose2& step = in.odometry_step;
  if (in.odometry_jump) {
    ++stats_.odometry_jumps;
    pending_jump_ = true;
    res->odometry_jump = true;
  }
  const fl::Pose2 delta = odom_at_processed_.between(input_.odom());
  const bool moved = std::hypot(delta.x, delta.y) >= opt_.linear_update ||
                     std::abs(delta.theta) >= opt_.angular_update;
  // A scan taken in a fast turn of a dense scan stream waits for the next one (the motion
  // accumulates): its content may not match its time stamp.
  const bool fast_turn = opt_.max_turn_rate > 0.0 && dt_s <= opt_.turn_skip_max_gap &&
                         std::abs(step.theta) > opt_.max_turn_rate * dt_s;
  if (fast_turn && (moved || pending_jump_)) ++stats_.skipped_fast_turn;
  if (fast_turn) last_fast_turn_ = scan.utime;
  if ((moved || pending_jump_) && !fast_turn) {
    ProcessFilter(delta, pending_jump_, res);
    pending_jump_ = false;
    odom_at_processed_ = input_.odom();
    path_length_ += std::hypot(delta.x, delta.y);
    keyframe_pending_ = true;
    pending_utime_ = scan.utime;
    if (defer_keyframe) {
      res->T_world_base = CurrentPose();
      res->keyframe_pending = true;
      return Status::Ok();
    }
    FinishScan(res);
    return Status::Ok();
  }
  res->T_world_base = CurrentPose();
  bool matched = false;
  if (opt_.match_between_updates) {
    const MatchResult mr =
        MatchScan(particles_[best_].map, match_base_, res->T_world_base, opt_.matcher);
    stats_.matcher_evaluations += mr.evaluations;
    if (mr.ok) {
      res->T_world_base = mr.T_world_base;
      matched = true;
      ++stats_.matched_between_updates;
    }
  }
  matched = PlaceAgainstKeyframe(scan.utime, &res->T_world_base) || matched;
  const int kf = anchor_.keyframe;
  RecordScan({scan.utime, kf, graph_.pose(kf).between(res->T_world_base), input_.odom(), matched});
  return Status::Ok();
}

const RbpfSlam::Keyframe* RbpfSlam::PlacementKeyframe(fl::Utime utime) const {
  const int kf = anchor_.keyframe;
  if (kf < 0 || kf >= static_cast<int>(keyframes_.size())) return nullptr;
  const Keyframe& keyframe = keyframes_[static_cast<size_t>(kf)];
  if (keyframe.utime == utime) return nullptr;  // the keyframe's own scan
  return &keyframe;
}

bool RbpfSlam::PlaceAgainstKeyframe(fl::Utime utime, fl::Pose2* T_world_base) {
  if (RefineAgainstKeyframe(utime, T_world_base)) return true;
  const bool in_turn =
      opt_.turn_search.enabled && last_fast_turn_ &&
      static_cast<double>(utime - *last_fast_turn_) * 1e-6 <= opt_.turn_search_after_s;
  return in_turn && SearchAgainstKeyframe(utime, T_world_base);
}

bool RbpfSlam::SearchAgainstKeyframe(fl::Utime utime, fl::Pose2* T_world_base) {
  const Keyframe* keyframe = PlacementKeyframe(utime);
  if (keyframe == nullptr) return false;
  ++stats_.turn_searches;
  const fl::Pose2& T_world_kf = graph_.pose(anchor_.keyframe);
  const CorrelativeResult cr = CorrelativeMatch(
      keyframe->points_base, hits_base_, T_world_kf.between(*T_world_base), opt_.turn_search);
  if (!Usable(cr, opt_.turn_search)) return false;
  const IcpResult icp =
      AlignPointToLine(keyframe->normals_base, hits_base_, cr.T_ref_query, opt_.icp);
  if (!icp.ok || icp.degenerate_dims > 0) return false;
  *T_world_base = T_world_kf * icp.T_ref_query;
  ++stats_.turn_scans_placed;
  return true;
}

bool RbpfSlam::RefineAgainstKeyframe(fl::Utime utime, fl::Pose2* T_world_base) {
  if (!opt_.refine_scans_with_icp) return false;
  const Keyframe* keyframe = PlacementKeyframe(utime);
  if (keyframe == nullptr ||
      !RefineAgainst(*keyframe, graph_.pose(anchor_.keyframe), hits_base_, T_world_base)) {
    return false;
  }
  ++stats_.scans_refined;
  return true;
}

bool RbpfSlam::RefineAgainst(const Keyframe& keyframe, const fl::Pose2& T_world_kf,
                             const std::vector<Eigen::Vector2d>& points_base,
                             fl::Pose2* T_world_base) const {
  const fl::Pose2 T_kf_base = T_world_kf.between(*T_world_base);
  const IcpResult icp = AlignPointToLine(keyframe.normals_base, points_base, T_kf_base, opt_.icp);
  if (!icp.ok || icp.degenerate_dims > 0) return false;
  const fl::Pose2 correction = T_kf_base.between(icp.T_ref_query);
  if (std::hypot(correction.x, correction.y) > opt_.refine_max_correction_m ||
      std::abs(correction.theta) > opt_.refine_max_correction_rad) {
    return false;
  }
  *T_world_base = T_world_kf * icp.T_ref_query;
  return true;
}

fl::Status RbpfSlam::PlaceLateScan(const LaserScan& scan, const fl::Pose2& odom_pose,
                                   fl::Pose2* T_world_base) {
  const std::string at = "late scan at utime " + std::to_string(scan.utime);
  const auto refuse = [&](const std::string& why) {
    ++stats_.dropped_time_backwards;
    return Status::Error(at + why + "; dropped");
  };
  if (!(opt_.late_scan_max_age_s > 0.0)) {
    return refuse(": late scans are not placed (late_scan_max_age_s 0)");
  }
  if (!input_.initialized() || scan.utime > input_.last_utime()) {
    return refuse(" is not older than the newest scan (AddScan takes it)");
  }
  const Status content = input_.CheckContent(scan, odom_pose);
  if (!content.ok()) {
    ++stats_.rejected_bad_scan;
    return content;
  }
  const auto after = std::upper_bound(recent_.begin(), recent_.end(), scan.utime,
                                      [](fl::Utime t, const RecentScan& r) { return t < r.utime; });
  if (after != recent_.begin() && std::prev(after)->utime == scan.utime) {
    return refuse(": a scan with this stamp was taken already (a repeated message)");
  }
  if (after == recent_.begin() ||
      SecondsBetween(scan.utime, input_.last_utime()) > opt_.late_scan_max_age_s) {
    return refuse(" is more than late_scan_max_age_s (" + FormatDouble(opt_.late_scan_max_age_s) +
                  " s) older than the newest scan");
  }
  const RecentScan& before = *std::prev(after);
  // The odometry from the scan before (a step beyond the jump limits is not trusted: none).
  fl::Pose2 step = before.odom_raw.between(odom_pose);
  if (opt_.motion.IsOdometryJump(step, SecondsBetween(before.utime, scan.utime))) {
    step = fl::Pose2();
  }
  const fl::Pose2& T_world_kf = graph_.pose(before.keyframe);
  fl::Pose2 pose = T_world_kf * before.T_kf_base * step;
  std::vector<Eigen::Vector2d> points_base;
  stats_.invalid_beams += ScanToBasePoints(scan, T_base_laser_, opt_.grid.max_range, &points_base);
  const bool refined =
      opt_.refine_scans_with_icp && RefineAgainst(keyframes_[static_cast<size_t>(before.keyframe)],
                                                  T_world_kf, points_base, &pose);
  const RecentScan late{scan.utime, before.keyframe, T_world_kf.between(pose), before.odom * step,
                        odom_pose};
  if (keep_scan_path_) {
    const auto at_path =
        std::upper_bound(path_.begin(), path_.end(), scan.utime,
                         [](fl::Utime t, const PathRecord& r) { return t < r.utime; });
    path_.insert(at_path,
                 PathRecord{late.utime, late.keyframe, late.T_kf_base, late.odom, refined});
  }
  recent_.insert(after, late);
  ++stats_.late_scans_placed;
  *T_world_base = pose;
  return Status::Ok();
}

void RbpfSlam::FinishScan(ScanResult* res) {
  if (!keyframe_pending_) return;
  keyframe_pending_ = false;
  res->keyframe_pending = false;
  MaybeAddKeyframe(pending_utime_, res);
  res->T_world_base = CurrentPose();
  PlaceAgainstKeyframe(pending_utime_, &res->T_world_base);
  const int kf = anchor_.keyframe;
  RecordScan({pending_utime_, kf, graph_.pose(kf).between(res->T_world_base), input_.odom(), true});
}

void RbpfSlam::ProcessFilter(const fl::Pose2& delta, bool jump, ScanResult* res) {
  ++stats_.processed;
  res->processed = true;
  const MotionOptions& m = opt_.motion;
  const double trans = std::hypot(delta.x, delta.y), rot = std::abs(delta.theta);
  double sx = m.srr * std::abs(delta.x) + m.srt * rot;
  double sy = m.srr * std::abs(delta.y) + m.srt * rot;
  double st = m.stt * rot + m.str * trans;
  if (jump) {
    sx = std::hypot(sx, m.jump_sigma_m);
    sy = std::hypot(sy, m.jump_sigma_m);
    st = std::hypot(st, m.jump_sigma_rad);
  }
  std::normal_distribution<double> n01(0.0, 1.0);
  MatcherOptions mo = opt_.matcher;
  if (jump) {
    mo.max_correction_m = std::max(mo.max_correction_m, 3.0 * m.jump_sigma_m);
    mo.max_correction_rad = std::max(mo.max_correction_rad, 3.0 * m.jump_sigma_rad);
  }
  // 1-2. Sample the motion model, refine by scan matching, weight by the likelihood field.
  for (Particle& p : particles_) {
    const fl::Pose2 noisy(delta.x + sx * n01(rng_), delta.y + sy * n01(rng_),
                          delta.theta + st * n01(rng_));
    const fl::Pose2 predicted = p.pose * noisy;
    const MatchResult mr = MatchScan(p.map, match_base_, predicted, mo);
    if (!mr.ok) ++stats_.match_failures;
    stats_.matcher_evaluations += mr.evaluations;
    if (mr.degenerate_dims > 0) ++stats_.degenerate_matches;
    p.pose = mr.T_world_base;
    p.log_w += mr.log_likelihood / opt_.matcher.likelihood_gain;
  }
  // Keep log weights bounded (normalise in log space).
  double mx = -std::numeric_limits<double>::infinity();
  for (const auto& p : particles_) mx = std::max(mx, p.log_w);
  for (auto& p : particles_) p.log_w -= mx;
  const std::vector<double> w = NormalizedWeights();
  res->neff = EffectiveSampleSize(w);
  best_ = BestIndex();
  if (opt_.graph.enabled && opt_.graph.recovery_search.enabled &&
      KeyframeDue(particles_[best_].pose)) {
    pre_scan_map_ = particles_[best_].map;  // the resampled best particle's map, before the scan
  }
  // 3. Adaptive resampling (eq. 4); 4. integrate the scan (once per distinct parent).
  if (res->neff < opt_.neff_threshold * static_cast<double>(particles_.size())) {
    ++stats_.resamples;
    res->resampled = true;
    std::uniform_real_distribution<double> u(0.0, 1.0);
    const std::vector<int> parents = SystematicResample(w, u(rng_));
    std::vector<int> first_child(particles_.size(), -1);
    for (size_t i = 0; i < parents.size(); ++i) {
      if (first_child[parents[i]] < 0) first_child[parents[i]] = static_cast<int>(i);
    }
    for (size_t i = 0; i < particles_.size(); ++i) {
      if (first_child[i] >= 0) Integrate(&particles_[i]);
    }
    std::vector<Particle> next;
    next.reserve(particles_.size());
    int new_best = 0;
    for (size_t i = 0; i < parents.size(); ++i) {
      next.push_back(particles_[parents[i]]);
      next.back().log_w = 0.0;
      if (parents[i] == best_ && first_child[best_] == static_cast<int>(i))
        new_best = static_cast<int>(i);
    }
    particles_ = std::move(next);
    best_ = new_best;
  } else {
    for (Particle& p : particles_) Integrate(&p);
  }
  res->T_world_base = particles_[best_].pose;
}

bool RbpfSlam::Integrate(Particle* p) { return IntegrateInto(&p->map, p->pose, hits_base_); }

bool RbpfSlam::IntegrateInto(TiledGrid* map, const fl::Pose2& T_world_base,
                             const std::vector<Eigen::Vector2d>& points_base) {
  endpoints_world_.resize(points_base.size());
  is_hit_.assign(points_base.size(), 1);
  for (size_t k = 0; k < points_base.size(); ++k)
    endpoints_world_[k] = T_world_base * points_base[k];
  if (map->IntegrateScan(T_world_base * T_base_laser_.translation(), endpoints_world_, is_hit_))
    return true;
  ++stats_.map_integrations_refused;
  return false;
}

bool RbpfSlam::KeyframeDue(const fl::Pose2& pose) const {
  if (keyframes_.empty()) return true;
  const fl::Pose2 d = (graph_.pose(anchor_.keyframe) * anchor_.T_kf_anchor).between(pose);
  return std::hypot(d.x, d.y) >= opt_.graph.keyframe_distance ||
         std::abs(d.theta) >= opt_.graph.keyframe_angle;
}

void RbpfSlam::MaybeAddKeyframe(fl::Utime utime, ScanResult* res) {
  const fl::Pose2 pose = particles_[best_].pose;
  // Held only for this scan's keyframe decision.
  const std::optional<TiledGrid> pre_scan_map = std::move(pre_scan_map_);
  pre_scan_map_.reset();
  if (!KeyframeDue(pose)) return;
  const GraphOptions& g = opt_.graph;
  const Revisit revisit = EarlierKeyframesNear(pose);
  // Reuse once the revisit is in the graph (the anchor closed a loop, or is itself a reuse): the
  // first keyframes of a return are new and close the loop (the graph corrects the drift). In
  // a place already full of keyframes, whatever the loop.
  const bool place_full =
      g.max_keyframes_per_place > 0 && revisit.count >= g.max_keyframes_per_place;
  const bool loop_in_graph = anchor_.reused || anchor_.keyframe == last_closure_keyframe_;
  if (revisit.nearest >= 0 && (loop_in_graph || place_full) &&
      ReuseKeyframe(revisit.nearest, utime, pose, res)) {
    return;
  }
  if (place_full) {
    // Anchored to the nearest keyframe as the filter has it: no node, no factor, no correction.
    anchor_ = Anchor{revisit.nearest, graph_.pose(revisit.nearest).between(pose), input_.odom(),
                     stats_.odometry_jumps, true};
    ++stats_.keyframes_bounded;
    return;
  }
  Keyframe kf;
  kf.utime = utime;
  kf.points_base = hits_base_;
  kf.range_noise = ScanRangeNoise(kf.points_base);
  kf.normals_base = ComputeNormals(kf.points_base, opt_.icp, kf.range_noise);
  kf.path_length = path_length_;
  kf.odom = input_.odom();
  kf.odometry_jumps = stats_.odometry_jumps;
  keyframes_.push_back(std::move(kf));
  const int j = graph_.AddNode(pose);
  ++stats_.keyframes;
  res->new_keyframe = true;
  const Anchor from = anchor_;
  anchor_ = Anchor{j, fl::Pose2(), input_.odom(), stats_.odometry_jumps, false};
  if (j == 0) return;
  const int i = from.keyframe;
  const fl::Pose2 prior = graph_.pose(i).between(pose);
  PoseGraphEdge edge;
  edge.i = i;
  edge.j = j;
  edge.information = WeakInformation();
  bool edge_from_icp = false;
  if (opt_.graph.enabled) {
    IcpResult icp =
        AlignPointToLine(keyframes_[i].normals_base, keyframes_[j].points_base, prior, opt_.icp);
    bool icp_ok = NearStart(icp, prior);
    bool moved_node = false;  // by the divergence check or the lost-track search
    if (opt_.graph.divergence_check) {
      // Did the filter lock onto a wrong match? ICP from the odometry's relative pose too.
      const fl::Pose2 odom_rel = OdometryFromAnchor(from, j);
      const fl::Pose2 diff = prior.between(odom_rel);
      if (Beyond(diff, 0.05, 0.03)) {
        const IcpResult alt = AlignPointToLine(keyframes_[i].normals_base,
                                               keyframes_[j].points_base, odom_rel, opt_.icp);
        const bool alt_ok = NearStart(alt, odom_rel);
        // The better fit of the two starts; when it is the filter's, it must agree with the
        // odometry's (two independent starts, one answer). Where both fit about as well (a
        // featureless corridor), the odometry's wins when the filter's motion is unlikely
        // under the motion model: the filter slid (options.hpp).
        const bool clearly_better =
            alt.inlier_fraction > icp.inlier_fraction + g.divergence_min_gain;
        const bool filter_slid = g.divergence_odometry_chi2 > 0.0 && icp_ok && alt_ok &&
                                 alt.rms <= g.divergence_odometry_rms_ratio * icp.rms &&
                                 OdometryChi2(from, j, prior) > g.divergence_odometry_chi2;
        const bool use_alt = !icp_ok || clearly_better || filter_slid;
        const IcpResult& best = use_alt ? alt : icp;
        const fl::Pose2 agree = alt.T_ref_query.between(best.T_ref_query);
        const bool corroborated = use_alt || Within(agree, 0.05, 0.02);
        const fl::Pose2 moved = prior.between(best.T_ref_query);
        if (alt_ok && corroborated && Beyond(moved, 0.1, 0.05)) {
          // The filter diverged: move node j (and the particles) to where ICP puts it.
          ++stats_.divergences;
          if (use_alt) icp = alt;
          icp_ok = true;
          CorrectNewestKeyframe(j, pose, graph_.pose(i) * icp.T_ref_query);
          moved_node = true;
        }
      }
    }
    // ICP failed, or it put j far from the filter's pose: has the filter lost track?
    const fl::Pose2 icp_moved = prior.between(icp.T_ref_query);
    if (!moved_node && pre_scan_map && (!icp_ok || Beyond(icp_moved, 0.1, 0.05))) {
      fl::Pose2 corrected;
      IcpResult from_corrected;
      if (SearchLostTrack(i, j, pose, OdometryFromAnchor(from, j), *pre_scan_map,
                          icp_ok ? &icp : nullptr, &corrected, &from_corrected)) {
        ++stats_.recoveries;
        CorrectNewestKeyframe(j, pose, corrected);
        icp = from_corrected;
        icp_ok = icp.ok;
      }
    }
    if (icp_ok && g.degenerate_from_odometry && icp.noise_made_dims > 0 &&
        from.odometry_jumps == keyframes_[j].odometry_jumps) {
      const fl::Pose2 kept = OdometryAlongDegenerate(icp, OdometryFromAnchor(from, j));
      if (Beyond(icp.T_ref_query.between(kept), 0.01, 0.005)) {
        ++stats_.degenerate_kept;
        icp.T_ref_query = kept;
        CorrectNewestKeyframe(j, graph_.pose(j), graph_.pose(i) * kept);
      }
    }
    if (icp_ok) {
      edge.T_i_j = icp.T_ref_query;
      edge.information = GraphEdgeInformation(icp);
      edge_from_icp = true;
      res->factors.push_back(Factor(i, j, icp, false));
    } else {
      ++stats_.icp_failures;
      if (NoisyButRightFit(icp, keyframes_[j].range_noise, g.noisy_factor_rms_per_noise, prior)) {
        ++stats_.noisy_factors;
        res->factors.push_back(Factor(i, j, icp, false));  // for the fusion only (options.hpp)
      }
    }
  }
  // Without ICP, a weak edge holds j where it is (the filter's pose, or the recovered one).
  if (!edge_from_icp) edge.T_i_j = graph_.pose(i).between(graph_.pose(j));
  graph_.AddEdge(edge);
  // Where ICP succeeded, a filter edge also holds j where the filter put it (it knows the
  // corridor's axis from the odometry and the map); not across a flagged odometry jump.
  if (edge_from_icp && opt_.graph.filter_edges &&
      from.odometry_jumps == keyframes_[j].odometry_jumps) {
    graph_.AddEdge(FilterEdge(from, j));
  }
  if (opt_.graph.enabled) SearchLoopClosure(j, res);
}

Eigen::Vector2d RbpfSlam::OdometrySigma(const Anchor& from, int j, double scale) const {
  const GraphOptions& g = opt_.graph;
  const MotionOptions& m = opt_.motion;
  const fl::Pose2 odom = from.odom.between(keyframes_[j].odom);
  const double d = std::hypot(odom.x, odom.y), r = std::abs(odom.theta);
  return {std::max(scale * (m.srr * d + m.srt * r), g.filter_edge_min_sigma_m),
          std::max(scale * (m.stt * r + m.str * d), g.filter_edge_min_sigma_rad)};
}

double RbpfSlam::OdometryChi2(const Anchor& from, int j, const fl::Pose2& T_i_j) const {
  const Eigen::Vector2d sigma = OdometrySigma(from, j, 1.0);
  const fl::Pose2 e = OdometryFromAnchor(from, j).between(T_i_j);
  return (e.x * e.x + e.y * e.y) / (sigma(0) * sigma(0)) +
         e.theta * e.theta / (sigma(1) * sigma(1));
}

fl::Pose2 RbpfSlam::OdometryAlongDegenerate(const IcpResult& icp, const fl::Pose2& odom_rel) const {
  // I − P projects a step onto H's unconstrained directions (scan_matcher.hpp).
  const Eigen::Matrix3d P =
      WellConstrainedProjector(icp.hessian, icp.length_m, opt_.icp.degeneracy_ratio);
  const fl::Pose2& t = icp.T_ref_query;
  const Eigen::Vector3d d(odom_rel.x - t.x, odom_rel.y - t.y,
                          fl::WrapAngle(odom_rel.theta - t.theta));
  const Eigen::Vector3d step = (Eigen::Matrix3d::Identity() - P) * d;
  return fl::Pose2(t.x + step.x(), t.y + step.y(), fl::WrapAngle(t.theta + step.z()));
}

fl::Pose2 RbpfSlam::OdometryFromAnchor(const Anchor& from, int j) const {
  return from.T_kf_anchor * from.odom.between(keyframes_[j].odom);
}

RbpfSlam::Revisit RbpfSlam::EarlierKeyframesNear(const fl::Pose2& pose) const {
  const GraphOptions& g = opt_.graph;
  Revisit r;
  if (!g.enabled || g.reuse_distance <= 0.0) return r;
  double best_d = g.reuse_distance;
  for (int c = 0; c < graph_.num_nodes(); ++c) {
    // A revisit: at least loop_min_travel of path back, as for a loop closure.
    if (path_length_ - keyframes_[c].path_length < g.loop_min_travel) continue;
    const fl::Pose2 d = graph_.pose(c).between(pose);
    const double dist = std::hypot(d.x, d.y);
    if (dist >= g.reuse_distance || std::abs(d.theta) >= g.reuse_angle) continue;
    ++r.count;
    if (dist < best_d) {
      best_d = dist;
      r.nearest = c;
    }
  }
  return r;
}

bool RbpfSlam::ReuseKeyframe(int c, fl::Utime utime, const fl::Pose2& pose, ScanResult* res) {
  const GraphOptions& g = opt_.graph;
  // Verified as a loop closure is (ICP against the submap around c, with its thresholds), from
  // the graph's relative pose; it must stay close to it: a revisit that has drifted further
  // closes its loop instead. Along a corridor's axis ICP sees no error: there the filter's own
  // estimate stands.
  const fl::Pose2 prior = graph_.pose(c).between(pose);
  IcpOptions io = opt_.icp;
  io.min_inlier_fraction = g.loop_min_inlier_fraction;
  io.max_rms = g.loop_max_rms;
  const IcpResult icp = AlignPointToLine(LoopSubmap(c, path_length_), hits_base_, prior, io);
  const fl::Pose2 correction = prior.between(icp.T_ref_query);
  if (!icp.ok || !Within(correction, g.reuse_max_correction_m, g.reuse_max_correction_rad)) {
    ++stats_.reuse_rejections;
    return false;
  }
  fl::Pose2 T_c_anchor = prior;
  if (!Within(correction, g.feedback_min_correction_m, 0.02)) {
    // The filter has drifted from the map it revisits: localise it there, as a loop closure's
    // feedback does (the particles moved, their maps those of the keyframes; with the
    // keyframes bounded, and unchanged since the last rebuild, that is a copy).
    const fl::Pose2 T_corr = graph_.pose(c) * icp.T_ref_query * pose.inverse();
    for (Particle& p : particles_) p.pose = T_corr * p.pose;
    RebuildMaps();
    ++stats_.reuse_corrections;
    T_c_anchor = icp.T_ref_query;
  }
  anchor_ = Anchor{c, T_c_anchor, input_.odom(), stats_.odometry_jumps, true};
  ++stats_.keyframe_reuses;
  KeyframeFactor f = Factor(c, c, icp, true);
  f.keyframe_j = -1;  // the scan, not a keyframe
  f.utime_j = utime;
  res->factors.push_back(f);
  return true;
}

bool RbpfSlam::SearchLostTrack(int i, int j, const fl::Pose2& pose, const fl::Pose2& odom_rel,
                               const TiledGrid& map_before_scan, const IcpResult* icp_from_filter,
                               fl::Pose2* corrected, IcpResult* icp) const {
  const GraphOptions& g = opt_.graph;
  const fl::Pose2 T_world_i = graph_.pose(i);
  // Candidate: where ICP from the filter's pose went, or, if it failed, the best pose of a wide
  // search of j's scan against i's around the filter's pose; refined on the map (whose many
  // scans constrain it better than one keyframe).
  fl::Pose2 start;
  if (icp_from_filter) {
    start = T_world_i * icp_from_filter->T_ref_query;
  } else {
    // Around the filter's relative pose and, where the odometry's differs, around that too
    // (the filter may have been pulled away from a right odometry step); the better score wins.
    const fl::Pose2 filter_rel = T_world_i.between(pose);
    CorrelativeResult cr = CorrelativeMatch(keyframes_[i].points_base, keyframes_[j].points_base,
                                            filter_rel, g.recovery_search);
    if (g.recovery_search_from_odometry && Beyond(filter_rel.between(odom_rel), 0.05, 0.03)) {
      const CorrelativeResult from_odom = CorrelativeMatch(
          keyframes_[i].points_base, keyframes_[j].points_base, odom_rel, g.recovery_search);
      if (Usable(from_odom, g.recovery_search) &&
          (!Usable(cr, g.recovery_search) || from_odom.score > cr.score)) {
        cr = from_odom;
      }
    }
    if (!Usable(cr, g.recovery_search)) return false;
    start = T_world_i * cr.T_ref_query;
  }
  const MatchResult mr = MatchScan(map_before_scan, match_base_, start, opt_.matcher);
  const fl::Pose2 candidate = mr.ok ? mr.T_world_base : start;
  // The map decides: the scan must fit it clearly better there than where the filter put it.
  const double n = static_cast<double>(match_base_.size());
  const double gain = (ScanLogLikelihood(map_before_scan, match_base_, candidate, opt_.matcher) -
                       ScanLogLikelihood(map_before_scan, match_base_, pose, opt_.matcher)) /
                      n;
  if (!(gain >= g.recovery_min_gain)) return false;
  *corrected = candidate;
  const fl::Pose2 T_i_j = T_world_i.between(candidate);
  *icp = AlignPointToLine(keyframes_[i].normals_base, keyframes_[j].points_base, T_i_j, opt_.icp);
  icp->ok = NearStart(*icp, T_i_j);
  return true;
}

void RbpfSlam::CorrectNewestKeyframe(int j, const fl::Pose2& pose, const fl::Pose2& corrected) {
  const fl::Pose2 T_corr = corrected * pose.inverse();
  graph_.set_pose(j, corrected);
  for (Particle& p : particles_) p.pose = T_corr * p.pose;
  RebuildMaps();
}

KeyframeFactor RbpfSlam::Factor(int i, int j, const IcpResult& icp, bool is_loop_closure) const {
  KeyframeFactor f;
  f.keyframe_i = i;
  f.keyframe_j = j;
  f.utime_i = keyframes_[i].utime;
  f.utime_j = keyframes_[j].utime;
  f.T_i_j = icp.T_ref_query;
  f.information = icp.information;
  f.is_loop_closure = is_loop_closure;
  f.rms = icp.rms;
  f.inlier_fraction = icp.inlier_fraction;
  return f;
}

PoseGraphEdge RbpfSlam::FilterEdge(const Anchor& from, int j) const {
  const GraphOptions& g = opt_.graph;
  PoseGraphEdge e;
  e.i = from.keyframe;
  e.j = j;
  e.T_i_j = graph_.pose(e.i).between(graph_.pose(j));
  // The std grows with the odometry's motion since the anchoring scan (the motion model's
  // noise, which the filter's particles sampled), not with the filter's (which includes any
  // correction).
  const Eigen::Vector2d sigma = OdometrySigma(from, j, g.filter_edge_sigma_scale);
  const double s_xy = sigma(0), s_th = sigma(1);
  e.information =
      Eigen::Vector3d(1.0 / (s_xy * s_xy), 1.0 / (s_xy * s_xy), 1.0 / (s_th * s_th)).asDiagonal();
  e.huber_scale = g.filter_edge_huber;
  return e;
}

Eigen::Matrix3d RbpfSlam::GraphEdgeInformation(const IcpResult& icp) const {
  const double s = opt_.graph.edge_sigma;
  if (s <= 0.0) return icp.information;
  // H/σ² may be singular along a corridor: keep it positive definite with the calibrated
  // information's smallest eigenvalue.
  Eigen::Matrix3d info = icp.hessian / (s * s);
  info.diagonal().array() +=
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(icp.information).eigenvalues()(0);
  return info;
}

void RbpfSlam::SearchLoopClosure(int j, ScanResult* res) {
  const GraphOptions& g = opt_.graph;
  if (last_closure_keyframe_ >= 0 && j - last_closure_keyframe_ < g.loop_closure_spacing) return;
  const fl::Pose2 pj = graph_.pose(j);
  // Candidates: keyframes at least loop_min_travel back along the path and within
  // loop_search_radius in the graph, nearest first; at most loop_max_candidates, each outside the
  // submaps of those already chosen (so two candidates are two different views of the place).
  std::vector<std::pair<double, int>> near;
  for (int c = 0; c < j; ++c) {
    if (keyframes_[j].path_length - keyframes_[c].path_length < g.loop_min_travel) continue;
    const fl::Pose2 pc = graph_.pose(c);
    const double d = std::hypot(pc.x - pj.x, pc.y - pj.y);
    if (d < g.loop_search_radius) near.emplace_back(d, c);
  }
  std::sort(near.begin(), near.end());
  std::vector<int> chosen;
  for (const auto& [d, c] : near) {
    if (static_cast<int>(chosen.size()) >= g.loop_max_candidates) break;
    bool distinct = true;
    for (int o : chosen) distinct = distinct && std::abs(o - c) > 2 * g.loop_submap_half_width;
    if (distinct) chosen.push_back(c);
  }
  std::vector<std::pair<int, IcpResult>> added;  // (edge index, ICP) of the verified closures
  for (int cand : chosen) {
    ++stats_.loop_candidates;
    IcpResult icp;
    if (!VerifyLoopClosure(cand, j, &icp)) continue;
    PoseGraphEdge edge;
    edge.i = cand;
    edge.j = j;
    edge.T_i_j = icp.T_ref_query;
    edge.information = GraphEdgeInformation(icp);
    // Huber on the whitened residual: loop_huber_m in units of edge_sigma (as the internal edges
    // are weighted); with the calibrated information, at loop_huber_m along the best-known
    // translation.
    if (g.loop_huber_m <= 0.0) {
      edge.huber_scale = 0.0;
    } else if (g.edge_sigma > 0.0) {
      edge.huber_scale = g.loop_huber_m / g.edge_sigma;
    } else {
      const double info_xy_max =
          Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(edge.information.topLeftCorner<2, 2>())
              .eigenvalues()(1);
      edge.huber_scale = std::max(1.0, g.loop_huber_m * std::sqrt(info_xy_max));
    }
    edge.loop_closure = true;
    graph_.AddEdge(edge);
    added.emplace_back(graph_.num_edges() - 1, icp);
    ++graph_loop_edges_;
  }
  if (added.empty()) return;
  OptimizeAndFeedBack(res);
  for (const auto& [edge_index, icp] : added) {
    const PoseGraphEdge& e = graph_.edges()[edge_index];
    if (!e.enabled) continue;  // rejected by the residual check
    ++stats_.loop_closures;
    last_closure_keyframe_ = j;
    res->factors.push_back(Factor(e.i, e.j, icp, true));
  }
}

std::vector<PointNormal> RbpfSlam::LoopSubmap(int cand, double path_length) const {
  const GraphOptions& g = opt_.graph;
  std::vector<PointNormal> ref;
  const fl::Pose2 pc = graph_.pose(cand);
  const int n = static_cast<int>(keyframes_.size());
  for (int k = std::max(0, cand - g.loop_submap_half_width);
       k <= std::min(n - 1, cand + g.loop_submap_half_width); ++k) {
    if (path_length - keyframes_[k].path_length < g.loop_min_travel) continue;
    const fl::Pose2 T_c_k = pc.between(graph_.pose(k));
    const Eigen::Matrix2d R = T_c_k.rotation();
    for (const PointNormal& pn : keyframes_[k].normals_base) {
      PointNormal q;
      q.p = T_c_k * pn.p;
      q.n = R * pn.n;
      q.n_wide = R * pn.n_wide;
      ref.push_back(q);
    }
  }
  return ref;
}

bool RbpfSlam::VerifyLoopClosure(int cand, int j, IcpResult* icp) {
  const GraphOptions& g = opt_.graph;
  const std::vector<PointNormal> ref = LoopSubmap(cand, keyframes_[j].path_length);
  if (ref.empty()) return false;
  const fl::Pose2 pc = graph_.pose(cand);
  const fl::Pose2 prior = pc.between(graph_.pose(j));
  IcpOptions io = opt_.icp;
  io.min_inlier_fraction = g.loop_min_inlier_fraction;
  io.max_rms = g.loop_max_rms;
  io.max_correspondence_m = std::max(io.max_correspondence_m, 1.0);
  // ICP from the graph's relative pose first; when that fails (the drift since the candidate
  // is beyond ICP's basin, or the first pairs lock onto the wrong wall), the best pose of a
  // correlative search around it, then ICP from there.
  *icp = AlignPointToLine(ref, keyframes_[j].points_base, prior, io);
  if (icp->ok || !g.loop_search.enabled) return icp->ok;
  // Converged near the graph's pose, failed only on the inlier fraction: the start was inside
  // ICP's basin and a search for a better one cannot add overlap.
  const fl::Pose2 moved = prior.between(icp->T_ref_query);
  if (!g.loop_search_after_partial_overlap && icp->converged && icp->rms <= io.max_rms &&
      icp->inlier_fraction < io.min_inlier_fraction && Within(moved, 0.1, 0.05)) {
    ++stats_.loop_searches_skipped;
    return false;
  }
  ++stats_.loop_searches;
  std::vector<Eigen::Vector2d> ref_points(ref.size());
  for (size_t i = 0; i < ref.size(); ++i) ref_points[i] = ref[i].p;
  const CorrelativeResult cr =
      CorrelativeMatch(ref_points, keyframes_[j].points_base, prior, g.loop_search);
  if (!Usable(cr, g.loop_search)) return false;
  io.max_correspondence_m = opt_.icp.max_correspondence_m;
  *icp = AlignPointToLine(ref, keyframes_[j].points_base, cr.T_ref_query, io);
  return icp->ok;
}

bool RbpfSlam::OptimizeAndFeedBack(ScanResult* res) {
  if (graph_loop_edges_ == optimized_loop_edges_) return false;
  const GraphOptions& g = opt_.graph;
  const int last = anchor_.keyframe;  // where the particles are
  std::vector<fl::Pose2> before(graph_.num_nodes());
  for (int k = 0; k < graph_.num_nodes(); ++k) before[k] = graph_.pose(k);
  // Optimise; a loop edge the solution still disagrees with grossly is wrong: drop the worst
  // one and optimise again (from the original values).
  ++stats_.optimizations;
  for (int round = 0; round < 5; ++round) {
    graph_.Optimize(g.max_iterations, nullptr, g.function_tolerance);
    int worst = -1;
    double worst_score = 1.0;
    for (int k = 0; k < graph_.num_edges(); ++k) {
      const PoseGraphEdge& e = graph_.edges()[k];
      if (!e.enabled || !e.loop_closure) continue;
      const fl::Pose2 err = graph_.EdgeError(k);
      const double score = std::max(std::hypot(err.x, err.y) / g.loop_max_residual_m,
                                    std::abs(err.theta) / g.loop_max_residual_rad);
      if (score > worst_score) {
        worst_score = score;
        worst = k;
      }
    }
    if (worst < 0) break;
    graph_.DisableEdge(worst);
    ++stats_.loop_rejections;
    for (int k = 0; k < graph_.num_nodes(); ++k) graph_.set_pose(k, before[k]);
  }
  optimized_loop_edges_ = graph_loop_edges_;
  if (res) res->graph_changed = true;
  // Feed back only when the anchor keyframe (where the particles are) was corrected.
  const fl::Pose2 c = before[last].between(graph_.pose(last));
  if (!g.feed_back || Within(c, g.feedback_min_correction_m, 0.02)) {
    return true;
  }
  // Feed back: shift every particle by the correction of the anchor keyframe and give all of
  // them the map rebuilt from the corrected keyframes.
  const fl::Pose2 T_corr = graph_.pose(last) * before[last].inverse();
  for (Particle& p : particles_) p.pose = T_corr * p.pose;
  RebuildMaps();
  return true;
}

void RbpfSlam::RebuildMaps() {
  // The keyframes are integrated in order (clamped log-odds depend on the order). When the
  // first keyframes of the last rebuild kept their poses bit for bit (a divergence correction
  // moves only the newest node), that rebuild's map is continued with the keyframes after them:
  // the same updates in the same order, so the same map.
  const int n = graph_.num_nodes();
  const int cached = static_cast<int>(rebuild_poses_.size());  // nodes only grow: cached <= n
  bool reuse = cached > 0;
  for (int k = 0; k < cached && reuse; ++k) {
    const fl::Pose2 a = graph_.pose(k), b = rebuild_poses_[k];
    reuse = a.x == b.x && a.y == b.y && a.theta == b.theta;
  }
  TiledGrid map = reuse ? rebuild_map_ : TiledGrid(opt_.grid);
  map.BeginBatch();
  for (int k = reuse ? cached : 0; k < n; ++k) {
    IntegrateInto(&map, graph_.pose(k), keyframes_[k].points_base);
  }
  map.EndBatch();
  ++stats_.map_rebuilds;
  if (reuse) ++stats_.map_rebuilds_continued;
  rebuild_poses_.resize(n);
  for (int k = 0; k < n; ++k) rebuild_poses_[k] = graph_.pose(k);
  rebuild_map_ = map;
  for (Particle& p : particles_) p.map = map;
}

void RbpfSlam::Finish() {
  ScanResult last;
  FinishScan(&last);
  if (opt_.graph.enabled) OptimizeAndFeedBack(nullptr);
}

void RbpfSlam::SetKeepScanPath(bool keep) {
  keep_scan_path_ = keep;
  if (!keep) std::vector<PathRecord>().swap(path_);
}

void RbpfSlam::RecordScan(const PathRecord& record) {
  if (keep_scan_path_) path_.push_back(record);
  if (!(opt_.late_scan_max_age_s > 0.0) || record.keyframe < 0) return;
  recent_.push_back(
      {record.utime, record.keyframe, record.T_kf_base, record.odom, input_.odom_raw()});
  while (SecondsBetween(recent_.front().utime, record.utime) > opt_.late_scan_max_age_s) {
    recent_.pop_front();
  }
}

std::vector<StampedPose2> RbpfSlam::Trajectory() const {
  if (!keep_scan_path_) return KeyframePoses();
  std::vector<StampedPose2> out;
  out.reserve(path_.size());
  for (const PathRecord& r : path_) out.push_back({r.utime, graph_.pose(r.keyframe) * r.T_kf_base});
  // A scan the filter did not run on (too little motion, a fast turn) was placed by the
  // odometry from the filtered scan before it; the next filtered scan's correction of that
  // odometry is spread over the scans between them: each is blended, by time, from the pose
  // carried forward from the filtered scan before and back from the one after.
  size_t a = 0;
  while (a < path_.size()) {
    size_t b = a + 1;
    while (b < path_.size() && !path_[b].filtered) ++b;
    if (b >= path_.size()) break;  // scans after the last filtered one keep the forward pose
    const double span = static_cast<double>(path_[b].utime - path_[a].utime);
    for (size_t s = a + 1; s < b; ++s) {
      const fl::Pose2 back = out[b].T_world_base * path_[s].odom.between(path_[b].odom).inverse();
      const double alpha = static_cast<double>(path_[s].utime - path_[a].utime) / span;
      out[s].T_world_base = fl::Interpolate(out[s].T_world_base, back, alpha);
    }
    a = b;
  }
  return out;
}

std::vector<StampedPose2> RbpfSlam::KeyframePoses() const {
  std::vector<StampedPose2> out;
  for (int k = 0; k < graph_.num_nodes(); ++k) out.push_back({keyframes_[k].utime, graph_.pose(k)});
  return out;
}

}  // namespace fl::rbpf
