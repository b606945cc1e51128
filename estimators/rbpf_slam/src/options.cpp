#include "fusionloc/rbpf_slam/options.hpp"

#include <algorithm>
#include <cmath>
#include <string>

namespace fl::rbpf {

namespace {
std::string Num(double v) {
  std::string s = std::to_string(v);
  while (s.size() > 1 && s.back() == '0') s.pop_back();
  if (!s.empty() && s.back() == '.') s.pop_back();
  return s;
}
Status Positive(const std::string& key, double v) {
  if (!(v > 0.0) || !std::isfinite(v)) {
    return Status::Error(key + " = " + Num(v) + " must be a positive number");
  }
  return Status::Ok();
}
Status NonNegative(const std::string& key, double v) {
  if (!(v >= 0.0) || !std::isfinite(v)) {
    return Status::Error(key + " = " + Num(v) + " must be >= 0");
  }
  return Status::Ok();
}
#define FL_RETURN_IF_ERROR(expr) \
  do {                           \
    const Status _s = (expr);    \
    if (!_s.ok()) return _s;     \
  } while (0)
}  // namespace

Status GridOptions::Validate() const {
  FL_RETURN_IF_ERROR(Positive("grid.resolution", resolution));
  FL_RETURN_IF_ERROR(Positive("grid.max_range", max_range));
  FL_RETURN_IF_ERROR(Positive("grid.field_max_distance", field_max_distance));
  if (field_max_distance / resolution > 15.0 + 1e-9) {
    return Status::Error("grid.field_max_distance = " + Num(field_max_distance) +
                         " m is more than 15 cells of grid.resolution = " + Num(resolution) +
                         " m; use at most " + Num(15 * resolution) + " m");
  }
  if (!(log_odds_hit > 0.0)) return Status::Error("grid.log_odds_hit must be > 0 (e.g. 0.9)");
  if (!(log_odds_miss < 0.0)) return Status::Error("grid.log_odds_miss must be < 0 (e.g. -0.3)");
  if (!(log_odds_clamp > log_odds_occupied) || log_odds_clamp > 300.0) {
    return Status::Error("grid.log_odds_clamp must be > grid.log_odds_occupied and <= 300");
  }
  FL_RETURN_IF_ERROR(NonNegative("grid.log_odds_occupied", log_odds_occupied));
  if (!(log_odds_free < log_odds_occupied) || !(log_odds_free > -log_odds_clamp)) {
    return Status::Error(
        "grid.log_odds_free must be below grid.log_odds_occupied and above "
        "-grid.log_odds_clamp (e.g. 0.0)");
  }
  if (free_space_beam_step < 1) return Status::Error("grid.free_space_beam_step must be >= 1");
  if (free_space_margin < 0 || free_space_margin > 10) {
    return Status::Error("grid.free_space_margin must be in [0, 10] cells");
  }
  if (!(max_size_m >= 10.0) || !(max_size_m / resolution <= 1048576.0)) {
    return Status::Error("grid.max_size_m = " + Num(max_size_m) +
                         " m must be at least 10 m and at most 2^20 cells of grid.resolution "
                         "(e.g. 2000)");
  }
  return Status::Ok();
}

Status MotionOptions::Validate() const {
  FL_RETURN_IF_ERROR(NonNegative("motion.srr", srr));
  FL_RETURN_IF_ERROR(NonNegative("motion.srt", srt));
  FL_RETURN_IF_ERROR(NonNegative("motion.str", str));
  FL_RETURN_IF_ERROR(NonNegative("motion.stt", stt));
  FL_RETURN_IF_ERROR(Positive("motion.max_odometry_jump_m", max_odometry_jump_m));
  FL_RETURN_IF_ERROR(Positive("motion.max_odometry_jump_rad", max_odometry_jump_rad));
  FL_RETURN_IF_ERROR(NonNegative("motion.max_odometry_speed_mps", max_odometry_speed_mps));
  FL_RETURN_IF_ERROR(NonNegative("motion.max_odometry_yaw_rate_rps", max_odometry_yaw_rate_rps));
  FL_RETURN_IF_ERROR(NonNegative("motion.jump_sigma_m", jump_sigma_m));
  FL_RETURN_IF_ERROR(NonNegative("motion.jump_sigma_rad", jump_sigma_rad));
  return Status::Ok();
}

bool MotionOptions::IsOdometryJump(const fl::Pose2& step, double dt_s) const {
  const double dt = std::max(0.0, dt_s);
  return std::hypot(step.x, step.y) > std::max(max_odometry_jump_m, max_odometry_speed_mps * dt) ||
         std::abs(step.theta) > std::max(max_odometry_jump_rad, max_odometry_yaw_rate_rps * dt);
}

Status MatcherOptions::Validate() const {
  if (beam_step < 1) return Status::Error("matcher.beam_step must be >= 1");
  if (max_iterations < 0) return Status::Error("matcher.max_iterations must be >= 0");
  FL_RETURN_IF_ERROR(Positive("matcher.converged_step", converged_step));
  FL_RETURN_IF_ERROR(NonNegative("matcher.function_tolerance", function_tolerance));
  if (function_tolerance >= 1.0) {
    return Status::Error("matcher.function_tolerance must be below 1 (a fraction of the cost)");
  }
  FL_RETURN_IF_ERROR(Positive("matcher.sigma", sigma));
  FL_RETURN_IF_ERROR(Positive("matcher.z_hit", z_hit));
  FL_RETURN_IF_ERROR(Positive("matcher.z_rand", z_rand));
  FL_RETURN_IF_ERROR(Positive("matcher.likelihood_gain", likelihood_gain));
  if (!(min_inlier_fraction >= 0.0 && min_inlier_fraction <= 1.0)) {
    return Status::Error("matcher.min_inlier_fraction must be in [0, 1]");
  }
  FL_RETURN_IF_ERROR(Positive("matcher.max_correction_m", max_correction_m));
  FL_RETURN_IF_ERROR(Positive("matcher.max_correction_rad", max_correction_rad));
  FL_RETURN_IF_ERROR(NonNegative("matcher.unexplored_margin", unexplored_margin));
  if (!(degeneracy_ratio >= 0.0 && degeneracy_ratio < 1.0)) {
    return Status::Error(
        "matcher.degeneracy_ratio must be in [0, 1) (0 turns the degeneracy "
        "treatment off; 0.1 is the default)");
  }
  return Status::Ok();
}

Status IcpOptions::Validate() const {
  if (max_iterations < 1) return Status::Error("icp.max_iterations must be >= 1");
  FL_RETURN_IF_ERROR(Positive("icp.max_correspondence_m", max_correspondence_m));
  FL_RETURN_IF_ERROR(Positive("icp.final_correspondence_m", final_correspondence_m));
  if (final_correspondence_m > max_correspondence_m) {
    return Status::Error("icp.final_correspondence_m must be <= icp.max_correspondence_m");
  }
  FL_RETURN_IF_ERROR(Positive("icp.normal_radius", normal_radius));
  FL_RETURN_IF_ERROR(Positive("icp.normal_max_gap", normal_max_gap));
  if (!(normal_radius_per_noise >= 0.0) || !(normal_gap_per_noise >= 0.0)) {
    return Status::Error(
        "icp.normal_radius_per_noise and icp.normal_gap_per_noise must be >= 0 (0 = fixed "
        "icp.normal_radius / icp.normal_max_gap; defaults 10 and 6)");
  }
  if (!(normal_max_eigen_ratio > 0.0 && normal_max_eigen_ratio <= 1.0)) {
    return Status::Error("icp.normal_max_eigen_ratio must be in (0, 1]");
  }
  FL_RETURN_IF_ERROR(Positive("icp.min_sigma", min_sigma));
  FL_RETURN_IF_ERROR(Positive("icp.floor_sigma_xy", floor_sigma_xy));
  FL_RETURN_IF_ERROR(Positive("icp.floor_sigma_theta", floor_sigma_theta));
  FL_RETURN_IF_ERROR(Positive("icp.max_sigma_xy", max_sigma_xy));
  if (!(degeneracy_ratio >= 0.0 && degeneracy_ratio < 1.0)) {
    return Status::Error("icp.degeneracy_ratio must be in [0, 1) (0.05 is the default)");
  }
  if (max_sigma_xy <= floor_sigma_xy) {
    return Status::Error("icp.max_sigma_xy must be larger than icp.floor_sigma_xy");
  }
  if (min_points < 3) return Status::Error("icp.min_points must be >= 3");
  if (!(min_inlier_fraction >= 0.0 && min_inlier_fraction <= 1.0)) {
    return Status::Error("icp.min_inlier_fraction must be in [0, 1]");
  }
  FL_RETURN_IF_ERROR(Positive("icp.max_rms", max_rms));
  return Status::Ok();
}

Status CorrelativeOptions::Validate(const std::string& key) const {
  FL_RETURN_IF_ERROR(Positive(key + ".linear_window", linear_window));
  FL_RETURN_IF_ERROR(NonNegative(key + ".angular_window", angular_window));
  FL_RETURN_IF_ERROR(NonNegative(key + ".angular_step", angular_step));
  FL_RETURN_IF_ERROR(Positive(key + ".resolution", resolution));
  FL_RETURN_IF_ERROR(Positive(key + ".sigma", sigma));
  if (linear_window / resolution > 200.0) {
    return Status::Error(
        key + ".linear_window / resolution = " + Num(linear_window / resolution) +
        " translation steps per side is too many (max 200): widen the "
        "resolution or narrow the window");
  }
  if (coarse_factor < 1 || coarse_factor > 16) {
    return Status::Error(key + ".coarse_factor = " + std::to_string(coarse_factor) +
                         " must be in [1, 16]");
  }
  if (max_points < 0) return Status::Error(key + ".max_points must be >= 0");
  if (!(min_score >= 0.0 && min_score <= 1.0)) {
    return Status::Error(key + ".min_score = " + Num(min_score) + " must be in [0, 1]");
  }
  return Status::Ok();
}

Status GraphOptions::Validate() const {
  FL_RETURN_IF_ERROR(loop_search.Validate());
  FL_RETURN_IF_ERROR(recovery_search.Validate("graph.recovery_search"));
  FL_RETURN_IF_ERROR(NonNegative("graph.recovery_min_gain", recovery_min_gain));
  FL_RETURN_IF_ERROR(NonNegative("graph.reuse_distance", reuse_distance));
  FL_RETURN_IF_ERROR(NonNegative("graph.reuse_angle", reuse_angle));
  FL_RETURN_IF_ERROR(Positive("graph.reuse_max_correction_m", reuse_max_correction_m));
  FL_RETURN_IF_ERROR(Positive("graph.reuse_max_correction_rad", reuse_max_correction_rad));
  FL_RETURN_IF_ERROR(NonNegative("graph.max_keyframes_per_place", max_keyframes_per_place));
  if (loop_max_candidates < 1) return Status::Error("graph.loop_max_candidates must be >= 1");
  if (loop_closure_spacing < 1) {
    return Status::Error(
        "graph.loop_closure_spacing must be >= 1 (keyframes; 1 = search at every one)");
  }
  if (!(divergence_min_gain >= 0.0 && divergence_min_gain <= 1.0)) {
    return Status::Error("graph.divergence_min_gain = " + Num(divergence_min_gain) +
                         " must be in [0, 1] (an inlier-fraction difference)");
  }
  FL_RETURN_IF_ERROR(NonNegative("graph.divergence_odometry_chi2", divergence_odometry_chi2));
  FL_RETURN_IF_ERROR(
      Positive("graph.divergence_odometry_rms_ratio", divergence_odometry_rms_ratio));
  FL_RETURN_IF_ERROR(NonNegative("graph.edge_sigma", edge_sigma));
  FL_RETURN_IF_ERROR(NonNegative("graph.noisy_factor_rms_per_noise", noisy_factor_rms_per_noise));
  FL_RETURN_IF_ERROR(Positive("graph.filter_edge_sigma_scale", filter_edge_sigma_scale));
  FL_RETURN_IF_ERROR(Positive("graph.filter_edge_min_sigma_m", filter_edge_min_sigma_m));
  FL_RETURN_IF_ERROR(Positive("graph.filter_edge_min_sigma_rad", filter_edge_min_sigma_rad));
  FL_RETURN_IF_ERROR(NonNegative("graph.filter_edge_huber", filter_edge_huber));
  FL_RETURN_IF_ERROR(Positive("graph.keyframe_distance", keyframe_distance));
  FL_RETURN_IF_ERROR(Positive("graph.keyframe_angle", keyframe_angle));
  FL_RETURN_IF_ERROR(Positive("graph.loop_search_radius", loop_search_radius));
  FL_RETURN_IF_ERROR(NonNegative("graph.loop_min_travel", loop_min_travel));
  if (loop_submap_half_width < 0) return Status::Error("graph.loop_submap_half_width must be >= 0");
  if (!(loop_min_inlier_fraction >= 0.0 && loop_min_inlier_fraction <= 1.0)) {
    return Status::Error("graph.loop_min_inlier_fraction must be in [0, 1]");
  }
  FL_RETURN_IF_ERROR(Positive("graph.loop_max_rms", loop_max_rms));
  FL_RETURN_IF_ERROR(NonNegative("graph.loop_huber_m", loop_huber_m));
  FL_RETURN_IF_ERROR(Positive("graph.loop_max_residual_m", loop_max_residual_m));
  FL_RETURN_IF_ERROR(Positive("graph.loop_max_residual_rad", loop_max_residual_rad));
  if (max_iterations < 1) return Status::Error("graph.max_iterations must be >= 1");
  if (!(function_tolerance >= 0.0 && function_tolerance < 1.0)) {
    return Status::Error("graph.function_tolerance must be in [0, 1) (default 1e-6), got " +
                         std::to_string(function_tolerance));
  }
  FL_RETURN_IF_ERROR(NonNegative("graph.feedback_min_correction_m", feedback_min_correction_m));
  return Status::Ok();
}

Status RbpfSlamOptions::Validate() const {
  if (particles < 1 || particles > 10000) {
    return Status::Error("particles = " + std::to_string(particles) + " must be in [1, 10000]");
  }
  if (!(neff_threshold >= 0.0 && neff_threshold <= 1.0)) {
    return Status::Error("neff_threshold = " + Num(neff_threshold) +
                         " must be in [0, 1] (a fraction of the particle count; 0.5 = N/2)");
  }
  FL_RETURN_IF_ERROR(NonNegative("linear_update", linear_update));
  FL_RETURN_IF_ERROR(NonNegative("angular_update", angular_update));
  FL_RETURN_IF_ERROR(NonNegative("max_turn_rate", max_turn_rate));
  FL_RETURN_IF_ERROR(NonNegative("turn_skip_max_gap", turn_skip_max_gap));
  FL_RETURN_IF_ERROR(NonNegative("refine_max_correction_m", refine_max_correction_m));
  FL_RETURN_IF_ERROR(NonNegative("refine_max_correction_rad", refine_max_correction_rad));
  FL_RETURN_IF_ERROR(turn_search.Validate("turn_search"));
  FL_RETURN_IF_ERROR(NonNegative("turn_search_after_s", turn_search_after_s));
  FL_RETURN_IF_ERROR(NonNegative("late_scan_max_age_s", late_scan_max_age_s));
  FL_RETURN_IF_ERROR(grid.Validate());
  FL_RETURN_IF_ERROR(motion.Validate());
  FL_RETURN_IF_ERROR(matcher.Validate());
  FL_RETURN_IF_ERROR(icp.Validate());
  FL_RETURN_IF_ERROR(graph.Validate());
  return Status::Ok();
}

}  // namespace fl::rbpf
