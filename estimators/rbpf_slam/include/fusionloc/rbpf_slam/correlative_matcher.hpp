// Correlative scan matching: an exhaustive search over a window of poses for loop-closure
// candidates (Olson, "Real-Time Correlative Scan Matching", ICRA 2009), so that a loop closes
// even when the drift since the candidate keyframe is larger than ICP's basin of convergence.
//
// The reference points (a submap of keyframe scans, in the reference frame) are rasterised into
// a lookup grid L of cell size `resolution`: L(c) = exp(-d²/2σ²), d the distance from the centre
// of cell c to the nearest reference point (σ = `sigma`, cut at 3σ). The score of a pose T is the
// mean over the query points q_i of L(cell(T q_i)), in [0, 1].
// Search: every heading θ in initial.θ ± angular_window at steps of `angular_step` (0 = the
// resolution over the query's 95th-percentile range, so the farthest points move by about one
// cell per step), and every translation in initial ± linear_window at steps of one cell. It is
// done on two levels: a coarse grid C(c) = max of L over the k×k block of cells starting at c
// (k = coarse_factor) bounds the score of k×k translations from above with one lookup per point,
// and only the coarse translations whose bound can beat the best exact score found so far are
// expanded to full resolution (branch and bound with one level). The result equals the full
// exhaustive search.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/rbpf_slam/options.hpp"

namespace fl::rbpf {

struct CorrelativeResult {
  bool ok = false;              // a pose was found (false only for empty inputs)
  fl::Pose2 T_ref_query;        // best pose
  double score = 0.0;           // [-] mean lookup value of the query points at the best pose
  int evaluated = 0;            // exact pose evaluations (for tests and tuning)
  bool at_window_edge = false;  // the best pose is on the window's border: the true optimum
                                // may lie outside, so the match is not trustworthy
};

// Whether a search result can be used: a pose was found, not on the window's border, with a
// score of at least options.min_score.
inline bool Usable(const CorrelativeResult& r, const CorrelativeOptions& options) {
  return r.ok && !r.at_window_edge && r.score >= options.min_score;
}

// Best pose of `query` (points in its own frame) against `reference` (points in the reference
// frame) within the window around `initial`.
CorrelativeResult CorrelativeMatch(const std::vector<Eigen::Vector2d>& reference,
                                   const std::vector<Eigen::Vector2d>& query,
                                   const fl::Pose2& initial, const CorrelativeOptions& options);

}  // namespace fl::rbpf
