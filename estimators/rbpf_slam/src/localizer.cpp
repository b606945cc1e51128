#include "fusionloc/rbpf_slam/localizer.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <queue>
#include <stdexcept>
#include <unordered_set>
#include <utility>

#include "fusionloc/common/number_format.hpp"
#include "fusionloc/rbpf_slam/rbpf_slam.hpp"
#include "fusionloc/rbpf_slam/scan_matcher.hpp"

namespace fl::rbpf {

namespace {
Status Positive(const std::string& key, double v) {
  if (!(v > 0.0) || !std::isfinite(v)) {
    return Status::Error(key + " = " + FormatDouble(v) + " must be a positive number");
  }
  return Status::Ok();
}
#define FL_LOC_RETURN_IF_ERROR(expr) \
  do {                               \
    const Status _s = (expr);        \
    if (!_s.ok()) return _s;         \
  } while (0)

// The grid options of the likelihood field of a map at `resolution`.
GridOptions FieldOptions(const LocalizerOptions& o, double resolution) {
  GridOptions g;
  g.resolution = resolution;
  g.max_range = o.max_range;
  // The field stores at most 15 cells (GridOptions::Validate): a fine map gets a shorter reach.
  g.field_max_distance = std::min(o.field_max_distance, 15.0 * resolution);
  return g;
}
}  // namespace

const char* LocalizerStateName(LocalizerState s) {
  switch (s) {
    case LocalizerState::kWaiting:
      return "waiting";
    case LocalizerState::kConverging:
      return "converging";
    case LocalizerState::kLocalized:
      return "localized";
    case LocalizerState::kLost:
      return "lost";
  }
  return "?";
}

Status LocalizerOptions::Validate() const {
  if (min_particles < 1 || min_particles > 100000) {
    return Status::Error("min_particles = " + std::to_string(min_particles) +
                         " must be in [1, 100000]");
  }
  if (max_particles < min_particles || max_particles > 100000) {
    return Status::Error("max_particles = " + std::to_string(max_particles) +
                         " must be in [min_particles, 100000]");
  }
  if (!(kld_epsilon > 0.0 && kld_epsilon < 1.0)) {
    return Status::Error("kld_epsilon = " + FormatDouble(kld_epsilon) + " must be in (0, 1)");
  }
  FL_LOC_RETURN_IF_ERROR(Positive("kld_z", kld_z));
  FL_LOC_RETURN_IF_ERROR(Positive("kld_bin_xy", kld_bin_xy));
  FL_LOC_RETURN_IF_ERROR(Positive("kld_bin_theta", kld_bin_theta));
  if (!(neff_threshold >= 0.0 && neff_threshold <= 1.0)) {
    return Status::Error("neff_threshold = " + FormatDouble(neff_threshold) +
                         " must be in [0, 1] (a fraction of the particle count)");
  }
  if (!(linear_update >= 0.0) || !(angular_update >= 0.0)) {
    return Status::Error("linear_update and angular_update must be >= 0");
  }
  if (!(initial_sigma_xy >= 0.0) || !(initial_sigma_theta >= 0.0) ||
      !std::isfinite(initial_sigma_xy) || !std::isfinite(initial_sigma_theta)) {
    return Status::Error("initial_sigma_xy and initial_sigma_theta must be >= 0");
  }
  FL_LOC_RETURN_IF_ERROR(Positive("global_step_m", global_step_m));
  FL_LOC_RETURN_IF_ERROR(Positive("global_step_rad", global_step_rad));
  if (global_step_rad > M_PI) return Status::Error("global_step_rad must be at most pi");
  if (global_beams < 3) return Status::Error("global_beams must be >= 3");
  FL_LOC_RETURN_IF_ERROR(Positive("global_sigma", global_sigma));
  if (global_hypotheses < 1 || global_hypotheses > max_particles) {
    return Status::Error("global_hypotheses = " + std::to_string(global_hypotheses) +
                         " must be in [1, max_particles]");
  }
  if (!(lost_log_likelihood < 0.0) || !std::isfinite(lost_log_likelihood)) {
    return Status::Error("lost_log_likelihood = " + FormatDouble(lost_log_likelihood) +
                         " must be a negative number (a mean log-likelihood per beam, e.g. -1.6)");
  }
  if (lost_updates < 1) return Status::Error("lost_updates must be >= 1");
  if (!(relocalize_min_gain >= 0.0) || !std::isfinite(relocalize_min_gain)) {
    return Status::Error("relocalize_min_gain = " + FormatDouble(relocalize_min_gain) +
                         " must be >= 0 (a mean log-likelihood per beam, e.g. 0.2)");
  }
  FL_LOC_RETURN_IF_ERROR(Positive("cluster_radius_m", cluster_radius_m));
  FL_LOC_RETURN_IF_ERROR(Positive("cluster_radius_rad", cluster_radius_rad));
  FL_LOC_RETURN_IF_ERROR(Positive("keyframe_distance", keyframe_distance));
  FL_LOC_RETURN_IF_ERROR(Positive("keyframe_angle", keyframe_angle));
  FL_LOC_RETURN_IF_ERROR(Positive("factor_floor_sigma_xy", factor_floor_sigma_xy));
  FL_LOC_RETURN_IF_ERROR(Positive("factor_floor_sigma_theta", factor_floor_sigma_theta));
  FL_LOC_RETURN_IF_ERROR(Positive("max_range", max_range));
  FL_LOC_RETURN_IF_ERROR(Positive("field_max_distance", field_max_distance));
  FL_LOC_RETURN_IF_ERROR(motion.Validate());
  FL_LOC_RETURN_IF_ERROR(matcher.Validate());
  return Status::Ok();
}

TiledGrid GridFromOccupancyMap(const OccupancyMap& map, const GridOptions& grid_options,
                               Eigen::Vector2d* offset, int occupied_percent, int free_percent) {
  if (map.width <= 0 || map.height <= 0 ||
      map.cells.size() != static_cast<size_t>(map.width) * static_cast<size_t>(map.height)) {
    throw std::invalid_argument("occupancy map of " + std::to_string(map.width) + " x " +
                                std::to_string(map.height) + " cells holds " +
                                std::to_string(map.cells.size()) + " cells");
  }
  if (!(map.resolution > 0.0) || !std::isfinite(map.resolution) || !std::isfinite(map.origin_x) ||
      !std::isfinite(map.origin_y)) {
    throw std::invalid_argument("occupancy map resolution must be > 0 and its origin finite");
  }
  GridOptions g = grid_options;
  g.resolution = map.resolution;
  g.field_max_distance = std::min(g.field_max_distance, 15.0 * map.resolution);
  const double ox = std::round(map.origin_x / map.resolution);
  const double oy = std::round(map.origin_y / map.resolution);
  if (std::abs(ox) + map.width >= TiledGrid::kMaxCellIndex ||
      std::abs(oy) + map.height >= TiledGrid::kMaxCellIndex) {
    throw std::invalid_argument("occupancy map origin is too far from the frame's origin");
  }
  if (offset) {
    *offset =
        Eigen::Vector2d(map.origin_x - ox * map.resolution, map.origin_y - oy * map.resolution);
  }
  TiledGrid grid(g);
  const int full = static_cast<int>(std::lround(g.log_odds_clamp * kLogOddsScale));
  const int cx0 = static_cast<int>(ox), cy0 = static_cast<int>(oy);
  grid.BeginBatch();
  for (int j = 0; j < map.height; ++j) {
    const int8_t* row = &map.cells[static_cast<size_t>(j) * static_cast<size_t>(map.width)];
    for (int i = 0; i < map.width; ++i) {
      const int v = row[i];
      if (v >= occupied_percent) {
        grid.UpdateCell(cx0 + i, cy0 + j, full);
      } else if (v >= 0 && v <= free_percent) {
        grid.UpdateCell(cx0 + i, cy0 + j, -full);
      }
    }
  }
  grid.EndBatch();
  return grid;
}

MonteCarloLocalizer::MonteCarloLocalizer(const LocalizerOptions& options, const OccupancyMap& map)
    : opt_(options),
      grid_(GridFromOccupancyMap(map, FieldOptions(options, map.resolution), &offset_)),
      rng_(static_cast<uint32_t>(options.seed)) {
  const Status s = options.Validate();
  if (!s.ok()) throw std::invalid_argument("LocalizerOptions: " + s.message());
  bool any_obstacle = false;
  const int step =
      std::max(1, static_cast<int>(std::lround(options.global_step_m / map.resolution)));
  const double ox = std::round(map.origin_x / map.resolution);
  const double oy = std::round(map.origin_y / map.resolution);
  for (int j = 0; j < map.height; ++j) {
    for (int i = 0; i < map.width; ++i) {
      const int v = map.cells[static_cast<size_t>(j) * static_cast<size_t>(map.width) + i];
      if (v >= 65) any_obstacle = true;
      if (v >= 0 && v <= 25 && i % step == 0 && j % step == 0) {
        free_cells_.emplace_back((ox + i + 0.5) * map.resolution, (oy + j + 0.5) * map.resolution);
      }
    }
  }
  if (!any_obstacle) {
    throw std::invalid_argument("the map has no occupied cell: nothing to localize against");
  }
}

Status MonteCarloLocalizer::SetBaseLaser(const fl::Pose2& T) {
  if (!std::isfinite(T.x) || !std::isfinite(T.y) || !std::isfinite(T.theta)) {
    return Status::Error("T_base_laser is not finite");
  }
  if (input_.initialized())
    return Status::Error("T_base_laser can only be set before the first scan");
  T_base_laser_ = T;
  return Status::Ok();
}

Status MonteCarloLocalizer::SetInitialPose(const fl::Pose2& T_map_base) {
  if (!std::isfinite(T_map_base.x) || !std::isfinite(T_map_base.y) ||
      !std::isfinite(T_map_base.theta)) {
    return Status::Error("initial pose is not finite; ignored");
  }
  int x0, y0, x1, y1;
  grid_.Bounds(&x0, &y0, &x1, &y1);
  const fl::Pose2 g = ToGrid(T_map_base);
  const double r = grid_.resolution();
  if (g.x < x0 * r || g.x >= x1 * r || g.y < y0 * r || g.y >= y1 * r) {
    return Status::Error(
        "initial pose (" + FormatDouble(T_map_base.x) + ", " + FormatDouble(T_map_base.y) +
        ") is outside the map (x " + FormatDouble(x0 * r + offset_.x()) + " .. " +
        FormatDouble(x1 * r + offset_.x()) + ", y " + FormatDouble(y0 * r + offset_.y()) + " .. " +
        FormatDouble(y1 * r + offset_.y()) + "); ignored");
  }
  pending_initial_pose_ = fl::Pose2(T_map_base.x, T_map_base.y, WrapAngle(T_map_base.theta));
  return Status::Ok();
}

std::vector<Eigen::Vector2d> MonteCarloLocalizer::GlobalCandidates() const {
  std::vector<Eigen::Vector2d> out;
  out.reserve(free_cells_.size());
  for (const auto& c : free_cells_) out.push_back(c + offset_);
  return out;
}

std::vector<fl::Pose2> MonteCarloLocalizer::ParticlePoses() const {
  std::vector<fl::Pose2> out;
  out.reserve(particles_.size());
  for (const auto& p : particles_) out.push_back(ToMap(p.pose));
  return out;
}

std::vector<double> MonteCarloLocalizer::NormalizedWeights() const {
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

int MonteCarloLocalizer::BestIndex() const {
  int best = 0;
  for (size_t i = 1; i < particles_.size(); ++i) {
    if (particles_[i].log_w > particles_[best].log_w) best = static_cast<int>(i);
  }
  return best;
}

void MonteCarloLocalizer::ConvertScan(const LaserScan& scan, LocalizationResult* result) {
  stats_.invalid_beams += ScanToBasePoints(scan, T_base_laser_, opt_.max_range, &hits_base_);
  match_base_.clear();
  for (size_t k = 0; k < hits_base_.size(); k += opt_.matcher.beam_step) {
    match_base_.push_back(hits_base_[k]);
  }
  result->valid_beams = static_cast<int>(hits_base_.size());
}

void MonteCarloLocalizer::InitializeAround(const fl::Pose2& T_map_base) {
  std::normal_distribution<double> n01(0.0, 1.0);
  const fl::Pose2 g = ToGrid(T_map_base);
  particles_.clear();
  for (int i = 0; i < opt_.min_particles; ++i) {
    particles_.push_back(
        {fl::Pose2(g.x + opt_.initial_sigma_xy * n01(rng_), g.y + opt_.initial_sigma_xy * n01(rng_),
                   WrapAngle(g.theta + opt_.initial_sigma_theta * n01(rng_))),
         0.0});
  }
  estimate_ = g;
  state_ = LocalizerState::kConverging;
  from_initial_pose_ = true;
  fitted_since_init_ = false;
  bad_in_a_row_ = 0;
  have_keyframe_ = false;
  ++stats_.initial_poses;
}

double MonteCarloLocalizer::InitializeGlobal(const std::vector<Eigen::Vector2d>& points) {
  ++stats_.global_initializations;
  state_ = LocalizerState::kConverging;
  from_initial_pose_ = false;
  fitted_since_init_ = false;
  bad_in_a_row_ = 0;
  have_keyframe_ = false;
  if (points.empty() || free_cells_.empty()) {  // nothing to score with: keep the particles
    return -std::numeric_limits<double>::infinity();
  }
  // The scoring beams, evenly spread over the scan.
  std::vector<Eigen::Vector2d> sub;
  const size_t n = std::min(points.size(), static_cast<size_t>(opt_.global_beams));
  for (size_t k = 0; k < n; ++k) sub.push_back(points[k * points.size() / n]);
  const int headings = static_cast<int>(std::ceil(2.0 * M_PI / opt_.global_step_rad - 1e-9));
  // The best global_hypotheses candidates (a min-heap on the score).
  using Candidate = std::pair<double, fl::Pose2>;
  const auto worse = [](const Candidate& a, const Candidate& b) { return a.first > b.first; };
  std::priority_queue<Candidate, std::vector<Candidate>, decltype(worse)> best(worse);
  const size_t keep = static_cast<size_t>(opt_.global_hypotheses);
  MatcherOptions scoring = opt_.matcher;
  scoring.sigma = opt_.global_sigma;
  for (int h = 0; h < headings; ++h) {
    const double theta = -M_PI + 2.0 * M_PI * h / headings;
    for (const Eigen::Vector2d& c : free_cells_) {
      const fl::Pose2 pose(c.x(), c.y(), theta);
      const double score = ScanLogLikelihood(grid_, sub, pose, scoring);
      if (best.size() < keep) {
        best.emplace(score, pose);
      } else if (score > best.top().first) {
        best.pop();
        best.emplace(score, pose);
      }
    }
  }
  particles_.clear();
  double best_ll = -std::numeric_limits<double>::infinity();
  while (!best.empty()) {
    const MatchResult mr = MatchScan(grid_, points, best.top().second, opt_.matcher);
    best.pop();
    particles_.push_back({mr.T_world_base, mr.log_likelihood / opt_.matcher.likelihood_gain});
    best_ll = std::max(best_ll, mr.log_likelihood);
  }
  double mx = -std::numeric_limits<double>::infinity();
  for (const auto& p : particles_) mx = std::max(mx, p.log_w);
  for (auto& p : particles_) p.log_w -= mx;
  estimate_ = particles_[BestIndex()].pose;
  return best_ll / static_cast<double>(points.size());
}

void MonteCarloLocalizer::Predict(const fl::Pose2& delta, bool jump) {
  // The SLAM's motion model (RbpfSlam::ProcessFilter): GMapping's srr/srt/str/stt.
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
  for (Particle& p : particles_) {
    const fl::Pose2 noisy(delta.x + sx * n01(rng_), delta.y + sy * n01(rng_),
                          delta.theta + st * n01(rng_));
    p.pose = p.pose * noisy;
  }
}

double MonteCarloLocalizer::Correct(const std::vector<Eigen::Vector2d>& points) {
  if (points.empty()) return -std::numeric_limits<double>::infinity();
  MatcherOptions mo = opt_.matcher;
  if (pending_jump_) {
    mo.max_correction_m = std::max(mo.max_correction_m, 3.0 * opt_.motion.jump_sigma_m);
    mo.max_correction_rad = std::max(mo.max_correction_rad, 3.0 * opt_.motion.jump_sigma_rad);
  }
  double best_ll = -std::numeric_limits<double>::infinity();
  for (Particle& p : particles_) {
    const MatchResult mr = MatchScan(grid_, points, p.pose, mo);
    if (!mr.ok) ++stats_.match_failures;
    p.pose = mr.T_world_base;
    p.log_w += mr.log_likelihood / opt_.matcher.likelihood_gain;
    best_ll = std::max(best_ll, mr.log_likelihood);
  }
  double mx = -std::numeric_limits<double>::infinity();
  for (const auto& p : particles_) mx = std::max(mx, p.log_w);
  for (auto& p : particles_) p.log_w -= mx;
  return best_ll / static_cast<double>(points.size());
}

int MonteCarloLocalizer::KldParticleCount(int bins, double epsilon, double z) {
  if (bins <= 1) return 1;
  const double k = bins - 1;
  const double a = 2.0 / (9.0 * k);
  const double b = 1.0 - a + std::sqrt(a) * z;
  return static_cast<int>(std::ceil(k / (2.0 * epsilon) * b * b * b));
}

int MonteCarloLocalizer::ResampleKld() {
  ++stats_.resamples;
  const std::vector<double> w = NormalizedWeights();
  std::vector<double> cumulative(w.size());
  double c = 0.0;
  for (size_t i = 0; i < w.size(); ++i) cumulative[i] = (c += w[i]);
  std::uniform_real_distribution<double> u(0.0, c);
  struct BinHash {
    size_t operator()(const std::array<int64_t, 3>& b) const {
      return std::hash<int64_t>()(b[0] * 73856093 ^ b[1] * 19349663 ^ b[2] * 83492791);
    }
  };
  std::unordered_set<std::array<int64_t, 3>, BinHash> bins;
  std::vector<Particle> next;
  while (static_cast<int>(next.size()) < opt_.max_particles) {
    const size_t i = std::min<size_t>(
        w.size() - 1,
        static_cast<size_t>(std::lower_bound(cumulative.begin(), cumulative.end(), u(rng_)) -
                            cumulative.begin()));
    next.push_back({particles_[i].pose, 0.0});
    const fl::Pose2& p = particles_[i].pose;
    bins.insert({static_cast<int64_t>(std::floor(p.x / opt_.kld_bin_xy)),
                 static_cast<int64_t>(std::floor(p.y / opt_.kld_bin_xy)),
                 static_cast<int64_t>(std::floor((p.theta + M_PI) / opt_.kld_bin_theta))});
    const int needed = std::max(opt_.min_particles, KldParticleCount(static_cast<int>(bins.size()),
                                                                     opt_.kld_epsilon, opt_.kld_z));
    if (static_cast<int>(next.size()) >= needed) break;
  }
  particles_ = std::move(next);
  return static_cast<int>(particles_.size());
}

fl::Pose2 MonteCarloLocalizer::ClusterMean(Eigen::Matrix3d* covariance) const {
  if (particles_.empty()) {
    if (covariance) covariance->setZero();
    return ToMap(estimate_);
  }
  const std::vector<double> w = NormalizedWeights();
  const fl::Pose2 best = particles_[BestIndex()].pose;
  double sw = 0.0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();  // (x, y, dθ from the best)
  std::vector<std::pair<double, Eigen::Vector3d>> members;
  for (size_t i = 0; i < particles_.size(); ++i) {
    const fl::Pose2& p = particles_[i].pose;
    const double dth = WrapAngle(p.theta - best.theta);
    if (std::hypot(p.x - best.x, p.y - best.y) > opt_.cluster_radius_m ||
        std::abs(dth) > opt_.cluster_radius_rad) {
      continue;
    }
    const Eigen::Vector3d v(p.x, p.y, dth);
    members.emplace_back(w[i], v);
    mean += w[i] * v;
    sw += w[i];
  }
  mean /= sw;
  if (covariance) {
    covariance->setZero();
    for (const auto& [wi, v] : members) {
      const Eigen::Vector3d d = v - mean;
      *covariance += wi * d * d.transpose();
    }
    *covariance /= sw;
  }
  return ToMap(fl::Pose2(mean.x(), mean.y(), WrapAngle(best.theta + mean.z())));
}

fl::Pose2 MonteCarloLocalizer::CurrentPose() const {
  return ToMap(estimate_) * odom_at_processed_.between(input_.odom());
}

Status MonteCarloLocalizer::AddScan(const LaserScan& scan, const fl::Pose2& odom_pose,
                                    LocalizationResult* result) {
  LocalizationResult local;
  LocalizationResult* res = result ? result : &local;
  *res = LocalizationResult();
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

  bool run = false;
  fl::Pose2 delta;
  if (in.first) {
    odom_at_processed_ = odom_pose;
    run = true;
  } else {
    if (in.odometry_jump) {
      ++stats_.odometry_jumps;
      pending_jump_ = true;
      res->odometry_jump = true;
    }
    delta = odom_at_processed_.between(input_.odom());
    run = std::hypot(delta.x, delta.y) >= opt_.linear_update ||
          std::abs(delta.theta) >= opt_.angular_update || pending_jump_ ||
          pending_initial_pose_.has_value();
  }
  if (!run) {
    res->T_map_base = CurrentPose();
    res->state = state_;
    res->particles = num_particles();
    res->bad_updates = bad_in_a_row_;
    return Status::Ok();
  }

  // --- One filter update.
  ++stats_.processed;
  res->processed = true;
  double fit;
  if (pending_initial_pose_) {
    InitializeAround(*pending_initial_pose_);
    pending_initial_pose_.reset();
    res->initialized_from_pose = true;
    fit = Correct(match_base_);
  } else if (particles_.empty()) {
    fit = InitializeGlobal(match_base_);
    res->global_initialization = true;
  } else {
    Predict(delta, pending_jump_);
    fit = Correct(match_base_);
  }
  pending_jump_ = false;
  odom_at_processed_ = input_.odom();
  res->fit = fit;

  // --- Does the scan fit the map?
  const bool good = fit >= opt_.lost_log_likelihood;
  if (good) {
    bad_in_a_row_ = 0;
    fitted_since_init_ = true;
    from_initial_pose_ = false;
    state_ = LocalizerState::kLocalized;
  } else {
    ++bad_in_a_row_;
    ++stats_.bad_updates;
    if (bad_in_a_row_ >= opt_.lost_updates) {
      // With relocalize, the verdict needs a better place: the whole map is searched, and the
      // filter moves there only if the scan fits there by relocalize_min_gain per beam better
      // than where it is (a map that is wrong here, or people around the robot, make poor fits
      // too, and a search of a map with look-alike places would then jump to one of them).
      const bool was_from_initial_pose = from_initial_pose_, had_fitted = fitted_since_init_;
      bool moved = !opt_.relocalize;
      if (opt_.relocalize) {
        const std::vector<Particle> kept = particles_;
        const fl::Pose2 kept_estimate = estimate_;
        const LocalizerState kept_state = state_;
        const bool kept_keyframe = have_keyframe_;
        res->search_fit = InitializeGlobal(match_base_);
        moved = res->search_fit >= fit + opt_.relocalize_min_gain;
        if (moved) {
          res->global_initialization = true;
        } else {
          --stats_.global_initializations;
          ++stats_.relocalizations_refused;
          res->relocalization_refused = true;
          particles_ = kept;
          estimate_ = kept_estimate;
          state_ = kept_state;
          from_initial_pose_ = was_from_initial_pose;
          fitted_since_init_ = had_fitted;
          have_keyframe_ = kept_keyframe;
          bad_in_a_row_ = 0;  // searched again after lost_updates more bad updates
        }
      }
      if (moved && was_from_initial_pose && !had_fitted) {
        res->initial_pose_rejected = true;
        ++stats_.initial_pose_rejections;
      } else if (moved && had_fitted) {
        res->lost = true;
        ++stats_.lost_detections;
      }
      if (!opt_.relocalize) {
        state_ = LocalizerState::kLost;
        bad_in_a_row_ = 0;
        from_initial_pose_ = false;
        fitted_since_init_ = false;
        have_keyframe_ = false;
      }
    }
  }
  res->bad_updates = bad_in_a_row_;

  // --- Resample (KLD sampling decides the count). Not on a global initialisation's scan: its
  // hypotheses all meet the next scan before the weights of one decide.
  if (!particles_.empty() && !res->global_initialization) {
    const std::vector<double> w = NormalizedWeights();
    double s2 = 0.0;
    for (double x : w) s2 += x * x;
    res->neff = s2 > 0.0 ? 1.0 / s2 : 0.0;
    if (res->neff < opt_.neff_threshold * static_cast<double>(particles_.size())) {
      ResampleKld();
      res->resampled = true;
    }
  }
  Eigen::Matrix3d cov;
  const fl::Pose2 mean = ClusterMean(&cov);
  estimate_ = ToGrid(mean);
  stats_.max_particles_used = std::max(stats_.max_particles_used, num_particles());
  res->T_map_base = mean;
  res->covariance = cov;
  res->state = state_;
  res->particles = num_particles();
  if (good && state_ == LocalizerState::kLocalized) {
    MaybeAddFactor(scan.utime, mean, cov, res);
  }
  return Status::Ok();
}

void MonteCarloLocalizer::MaybeAddFactor(fl::Utime utime, const fl::Pose2& pose,
                                         const Eigen::Matrix3d& cluster_cov,
                                         LocalizationResult* res) {
  Eigen::Matrix3d cov = cluster_cov;
  cov(0, 0) += opt_.factor_floor_sigma_xy * opt_.factor_floor_sigma_xy;
  cov(1, 1) += opt_.factor_floor_sigma_xy * opt_.factor_floor_sigma_xy;
  cov(2, 2) += opt_.factor_floor_sigma_theta * opt_.factor_floor_sigma_theta;
  if (have_keyframe_) {
    const fl::Pose2 d = keyframe_pose_.between(pose);
    if (std::hypot(d.x, d.y) < opt_.keyframe_distance && std::abs(d.theta) < opt_.keyframe_angle) {
      return;
    }
    // Covariance of T_i_j = T_i^-1 T_j from the two poses' (independent) covariances, in the
    // world frame: δt_ij = R_iᵀ(δt_j - δt_i) - J t_ij δθ_i, δθ_ij = δθ_j - δθ_i, J = [0 -1; 1 0].
    const Eigen::Matrix2d Rt = keyframe_pose_.rotation().transpose();
    Eigen::Matrix3d Ai = Eigen::Matrix3d::Zero(), Aj = Eigen::Matrix3d::Zero();
    Ai.topLeftCorner<2, 2>() = -Rt;
    Ai(0, 2) = d.y;  // -J t_ij = (t_y, -t_x)
    Ai(1, 2) = -d.x;
    Ai(2, 2) = -1.0;
    Aj.topLeftCorner<2, 2>() = Rt;
    Aj(2, 2) = 1.0;
    Eigen::Matrix3d rel = Ai * keyframe_cov_ * Ai.transpose() + Aj * cov * Aj.transpose();
    rel = 0.5 * (rel + rel.transpose());
    KeyframeFactor f;
    f.keyframe_i = keyframe_id_;
    f.keyframe_j = keyframe_id_ + 1;
    f.utime_i = keyframe_utime_;
    f.utime_j = utime;
    f.T_i_j = d;
    f.information = rel.inverse();
    f.information = 0.5 * (f.information + f.information.transpose());
    f.is_loop_closure = false;
    res->factors.push_back(f);
    ++stats_.factors;
  }
  have_keyframe_ = true;
  ++keyframe_id_;
  keyframe_utime_ = utime;
  keyframe_pose_ = pose;
  keyframe_cov_ = cov;
}

}  // namespace fl::rbpf
