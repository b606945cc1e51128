#include "fusionloc/eval/metrics.hpp"

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <limits>
#include <map>
#include <numeric>
#include <sstream>

#include "fusionloc/common/geometry.hpp"
#include "text_parse.hpp"

namespace fl::eval {

using namespace internal;  // NOLINT: parsing helpers

namespace {

constexpr double kRadToDeg = 180.0 / M_PI;

std::string Fmt(double v, int digits = 3) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(digits) << v;
  return s.str();
}

// The associated poses, in time order.
struct Matched {
  std::vector<StampedPose> est, ref;
};

Matched Match(const Trajectory& est, const Trajectory& ref, Utime max_dt_us) {
  CheckTrajectory(est, "estimated trajectory");
  CheckTrajectory(ref, "reference trajectory");
  Matched m;
  for (const auto& [i, j] : Associate(est, ref, max_dt_us)) {
    m.est.push_back(est[i]);
    m.ref.push_back(ref[j]);
  }
  return m;
}

// Rotation angle [rad] via the quaternion, 2 atan2(|v|, |w|): accurate near 0, where
// acos((trace - 1) / 2) loses half the digits.
double AngleRad(const Eigen::Matrix3d& r) {
  const Eigen::Quaterniond q(r);
  return 2.0 * std::atan2(q.vec().norm(), std::fabs(q.w()));
}
double AngleDeg(const Eigen::Matrix3d& r) { return AngleRad(r) * kRadToDeg; }

// Nearest pose of `traj` to `t` within max_dt, or -1.
long Nearest(const Trajectory& traj, Utime t, Utime max_dt_us) {
  auto it = std::lower_bound(traj.begin(), traj.end(), t,
                             [](const StampedPose& p, Utime v) { return p.utime < v; });
  long best = -1;
  Utime best_dt = 0;
  if (it != traj.end()) {
    best = static_cast<long>(it - traj.begin());
    best_dt = it->utime - t;
  }
  if (it != traj.begin()) {
    const long j = static_cast<long>(it - traj.begin()) - 1;
    const Utime dt = t - traj[static_cast<size_t>(j)].utime;
    if (best < 0 || dt <= best_dt) {
      best = j;
      best_dt = dt;
    }
  }
  return (best >= 0 && best_dt <= max_dt_us) ? best : -1;
}

}  // namespace

Alignment ParseAlignment(const std::string& text) {
  const std::string t = Lower(text);
  if (t == "none") return Alignment::kNone;
  if (t == "se2") return Alignment::kSE2;
  if (t == "se3") return Alignment::kSE3;
  if (t == "sim3") return Alignment::kSim3;
  throw EvalError("unknown alignment '" + text + "'; use one of: none, se2, se3, sim3");
}

std::string AlignmentName(Alignment alignment) {
  switch (alignment) {
    case Alignment::kNone:
      return "none";
    case Alignment::kSE2:
      return "se2";
    case Alignment::kSE3:
      return "se3";
    case Alignment::kSim3:
      return "sim3";
  }
  return "?";
}

DeltaUnit ParseDeltaUnit(const std::string& text) {
  const std::string t = Lower(text);
  if (t == "frames" || t == "frame" || t == "f") return DeltaUnit::kFrames;
  if (t == "m" || t == "meters" || t == "metres") return DeltaUnit::kMeters;
  if (t == "s" || t == "seconds" || t == "sec") return DeltaUnit::kSeconds;
  throw EvalError("unknown RPE step unit '" + text + "'; use one of: frames, m, s");
}

ErrorStats ComputeErrorStats(std::vector<double> values) {
  ErrorStats s;
  s.count = values.size();
  if (values.empty()) return s;
  double sum = 0, sum_sq = 0;
  for (double v : values) {
    sum += v;
    sum_sq += v * v;
    s.max = std::max(s.max, v);
  }
  const double n = static_cast<double>(values.size());
  s.mean = sum / n;
  s.rmse = std::sqrt(sum_sq / n);
  double var = 0;
  for (double v : values) var += (v - s.mean) * (v - s.mean);
  s.std = std::sqrt(var / n);
  std::sort(values.begin(), values.end());
  const size_t mid = values.size() / 2;
  s.median = values.size() % 2 ? values[mid] : 0.5 * (values[mid - 1] + values[mid]);
  return s;
}

Eigen::Isometry3d AlignPoints(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& dst,
                              Alignment alignment, double* scale) {
  if (src.cols() != dst.cols()) throw EvalError("AlignPoints: point sets differ in size");
  const long n = src.cols();
  const long needed = alignment == Alignment::kNone ? 1 : alignment == Alignment::kSE2 ? 2 : 3;
  if (n < needed) {
    throw EvalError(AlignmentName(alignment) + " alignment needs at least " +
                    std::to_string(needed) + " associated poses, found " + std::to_string(n) +
                    "; check the time overlap or raise --max-dt");
  }
  *scale = 1.0;
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  if (alignment == Alignment::kNone) return T;
  const Eigen::Vector3d mu_src = src.rowwise().mean();
  const Eigen::Vector3d mu_dst = dst.rowwise().mean();
  if (alignment == Alignment::kSE2) {
    // Planar Horn: theta = atan2(sum (a x b)_z, sum a . b) over centred xy points a (src), b (dst).
    double s_cross = 0, s_dot = 0;
    for (long k = 0; k < n; ++k) {
      const Eigen::Vector2d a = (src.col(k) - mu_src).head<2>();
      const Eigen::Vector2d b = (dst.col(k) - mu_dst).head<2>();
      s_cross += a.x() * b.y() - a.y() * b.x();
      s_dot += a.dot(b);
    }
    const double theta = std::atan2(s_cross, s_dot);
    T.linear() = Eigen::AngleAxisd(theta, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    Eigen::Vector3d t = mu_dst - T.linear() * mu_src;
    t.z() = 0.0;
    T.translation() = t;
    return T;
  }
  const double src_var = (src.colwise() - mu_src).squaredNorm() / static_cast<double>(n);
  if (src_var < 1e-18) {
    throw EvalError("the estimated positions do not move (all at one point): " +
                    AlignmentName(alignment) + " alignment is undefined");
  }
  const bool with_scale = alignment == Alignment::kSim3;
  const Eigen::Matrix4d M = Eigen::umeyama(src, dst, with_scale);
  const Eigen::Matrix3d sR = M.topLeftCorner<3, 3>();
  const double s = with_scale ? std::cbrt(sR.determinant()) : 1.0;
  if (!(s > 0) || !std::isfinite(s)) {
    throw EvalError("Sim(3) alignment failed (scale " + Fmt(s) +
                    "); is the trajectory degenerate?");
  }
  *scale = s;
  T.linear() = Eigen::Quaterniond(sR / s).normalized().toRotationMatrix();
  T.translation() = M.topRightCorner<3, 1>();
  return T;
}

AteResult ComputeAte(const Trajectory& est, const Trajectory& ref, Alignment alignment,
                     Utime max_dt_us) {
  const Matched m = Match(est, ref, max_dt_us);
  const long n = static_cast<long>(m.est.size());
  Eigen::Matrix3Xd src(3, n), dst(3, n);
  for (long k = 0; k < n; ++k) {
    src.col(k) = m.est[static_cast<size_t>(k)].T_world_base.translation();
    dst.col(k) = m.ref[static_cast<size_t>(k)].T_world_base.translation();
  }
  AteResult r;
  r.T_ref_est = AlignPoints(src, dst, alignment, &r.scale);
  if ((alignment == Alignment::kSE3 || alignment == Alignment::kSim3) && n >= 3) {
    const Eigen::Matrix3Xd centred = src.colwise() - src.rowwise().mean();
    const Eigen::Vector3d sv =
        Eigen::JacobiSVD<Eigen::Matrix3d>(centred * centred.transpose()).singularValues();
    if (sv(1) <= 1e-8 * sv(0)) {
      r.warning =
          "the estimated positions lie on a straight line: the rotation about that line "
          "is not determined by " +
          AlignmentName(alignment) +
          " alignment (rotation errors are then arbitrary); use se2 for ground robots";
    }
  }
  const Eigen::Matrix3d R = r.T_ref_est.linear();
  const Eigen::Vector3d t = r.T_ref_est.translation();
  for (long k = 0; k < n; ++k) {
    const auto& pe = m.est[static_cast<size_t>(k)];
    const auto& pr = m.ref[static_cast<size_t>(k)];
    StampedPose aligned;
    aligned.utime = pe.utime;
    aligned.T_world_base.linear() = R * pe.T_world_base.linear();
    aligned.T_world_base.translation() = r.scale * R * pe.T_world_base.translation() + t;
    const Eigen::Vector3d d = aligned.T_world_base.translation() - pr.T_world_base.translation();
    r.utimes.push_back(pe.utime);
    r.trans_errors_m.push_back(d.norm());
    r.rot_errors_deg.push_back(
        AngleDeg(pr.T_world_base.linear().transpose() * aligned.T_world_base.linear()));
    r.err_x_m.push_back(d.x());
    r.err_y_m.push_back(d.y());
    r.err_z_m.push_back(d.z());
    r.err_yaw_deg.push_back(WrapAngle(Yaw(aligned.T_world_base) - Yaw(pr.T_world_base)) *
                            kRadToDeg);
    r.est_aligned.push_back(aligned);
    r.ref_matched.push_back(pr);
  }
  r.trans_m = ComputeErrorStats(r.trans_errors_m);
  r.rot_deg = ComputeErrorStats(r.rot_errors_deg);
  return r;
}

RunSpreadResult ComputeRunSpread(const std::vector<Trajectory>& runs, Alignment alignment,
                                 Utime max_dt_us) {
  if (runs.size() < 2) {
    throw EvalError("run spread needs at least 2 runs of the same input, got " +
                    std::to_string(runs.size()));
  }
  RunSpreadResult r;
  r.min_m = std::numeric_limits<double>::infinity();
  double sum = 0.0;
  for (size_t a = 0; a < runs.size(); ++a) {
    for (size_t b = a + 1; b < runs.size(); ++b) {
      double ate = 0.0;
      try {
        ate = ComputeAte(runs[b], runs[a], alignment, max_dt_us).trans_m.rmse;
      } catch (const EvalError& e) {
        throw EvalError("run spread, run " + std::to_string(b) + " against run " +
                        std::to_string(a) + ": " + e.what());
      }
      sum += ate;
      r.min_m = std::min(r.min_m, ate);
      r.max_m = std::max(r.max_m, ate);
      ++r.pairs;
    }
  }
  r.mean_m = sum / static_cast<double>(r.pairs);
  return r;
}

Trajectory AverageRuns(const std::vector<Trajectory>& runs, Alignment alignment, Utime max_dt_us) {
  if (runs.empty()) throw EvalError("average of runs: no runs");
  const Trajectory& first = runs.front();
  // Per time stamp of the first run: sums of the aligned positions and rotations, and how many
  // runs have a pose there.
  std::map<Utime, size_t> index;
  for (size_t k = 0; k < first.size(); ++k) index.emplace(first[k].utime, k);
  std::vector<Eigen::Vector3d> sum_p(first.size(), Eigen::Vector3d::Zero());
  std::vector<Eigen::Matrix3d> sum_R(first.size(), Eigen::Matrix3d::Zero());
  std::vector<size_t> count(first.size(), 0);
  for (size_t r = 0; r < runs.size(); ++r) {
    AteResult a;
    try {
      a = ComputeAte(runs[r], first, alignment, max_dt_us);
    } catch (const EvalError& e) {
      throw EvalError("average of runs, run " + std::to_string(r) + " against run 0: " + e.what());
    }
    for (size_t m = 0; m < a.ref_matched.size(); ++m) {
      const size_t k = index.at(a.ref_matched[m].utime);
      sum_p[k] += a.est_aligned[m].T_world_base.translation();
      sum_R[k] += a.est_aligned[m].T_world_base.linear();
      ++count[k];
    }
  }
  Trajectory out;
  for (size_t k = 0; k < first.size(); ++k) {
    if (count[k] != runs.size()) continue;
    StampedPose p;
    p.utime = first[k].utime;
    p.T_world_base.linear() = NearestRotation(sum_R[k]);  // chordal mean
    p.T_world_base.translation() = sum_p[k] / static_cast<double>(runs.size());
    out.push_back(p);
  }
  if (out.empty()) throw EvalError("average of runs: no time stamp of run 0 is in every run");
  return out;
}

RpeResult ComputeRpe(const Trajectory& est, const Trajectory& ref, double delta, DeltaUnit unit,
                     Utime max_dt_us) {
  if (!(delta > 0) || !std::isfinite(delta)) {
    throw EvalError("RPE step must be a positive number, got " + Fmt(delta));
  }
  if (unit == DeltaUnit::kFrames && std::fabs(delta - std::round(delta)) > 1e-9) {
    throw EvalError("RPE step in frames must be a whole number, got " + Fmt(delta));
  }
  const Matched m = Match(est, ref, max_dt_us);
  const size_t n = m.est.size();
  std::vector<double> dist(n, 0.0);
  for (size_t k = 1; k < n; ++k) {
    dist[k] =
        dist[k - 1] +
        (m.ref[k].T_world_base.translation() - m.ref[k - 1].T_world_base.translation()).norm();
  }
  RpeResult r;
  size_t j = 0;
  for (size_t i = 0; i < n; ++i) {
    if (unit == DeltaUnit::kFrames) {
      j = i + static_cast<size_t>(std::llround(delta));
    } else {
      j = std::max(j, i + 1);
      while (j < n && (unit == DeltaUnit::kMeters
                           ? dist[j] - dist[i] < delta
                           : UtimeToSeconds(m.ref[j].utime - m.ref[i].utime) < delta)) {
        ++j;
      }
    }
    if (j >= n) break;
    const Eigen::Isometry3d d_ref = m.ref[i].T_world_base.inverse() * m.ref[j].T_world_base;
    const Eigen::Isometry3d d_est = m.est[i].T_world_base.inverse() * m.est[j].T_world_base;
    const Eigen::Isometry3d e = d_ref.inverse() * d_est;
    r.utimes.push_back(m.est[i].utime);
    r.trans_errors_m.push_back(e.translation().norm());
    r.rot_errors_deg.push_back(AngleDeg(e.linear()));
  }
  if (r.trans_errors_m.empty()) {
    const std::string unit_name = unit == DeltaUnit::kFrames   ? "frames"
                                  : unit == DeltaUnit::kMeters ? "m"
                                                               : "s";
    throw EvalError("RPE step " + Fmt(delta) + " " + unit_name +
                    " is longer than the associated trajectory (" + std::to_string(n) + " poses, " +
                    Fmt(dist.back()) + " m, " +
                    Fmt(UtimeToSeconds(m.ref.back().utime - m.ref.front().utime)) +
                    " s); choose a smaller --rpe-delta");
  }
  r.trans_m = ComputeErrorStats(r.trans_errors_m);
  r.rot_deg = ComputeErrorStats(r.rot_errors_deg);
  return r;
}

DriftResult ComputeKittiDrift(const Trajectory& est, const Trajectory& ref,
                              const std::vector<double>& lengths_m, Utime max_dt_us,
                              int step_frames) {
  if (step_frames < 1) throw EvalError("KITTI drift step must be >= 1 frame");
  if (lengths_m.empty()) throw EvalError("KITTI drift needs at least one segment length");
  for (double len : lengths_m) {
    if (!(len > 0) || !std::isfinite(len)) {
      throw EvalError("KITTI segment lengths must be positive, got " + Fmt(len));
    }
  }
  const Matched m = Match(est, ref, max_dt_us);
  const size_t n = m.est.size();
  // Devkit trajectoryDistances(): cumulative path length of the ground truth.
  std::vector<double> dist(n, 0.0);
  for (size_t k = 1; k < n; ++k) {
    dist[k] =
        dist[k - 1] +
        (m.ref[k].T_world_base.translation() - m.ref[k - 1].T_world_base.translation()).norm();
  }
  DriftResult r;
  std::vector<double> t_sum(lengths_m.size(), 0.0), r_sum(lengths_m.size(), 0.0);
  std::vector<size_t> count(lengths_m.size(), 0);
  double t_total = 0, r_total = 0;
  for (size_t first = 0; first < n; first += static_cast<size_t>(step_frames)) {
    for (size_t li = 0; li < lengths_m.size(); ++li) {
      const double len = lengths_m[li];
      // Devkit lastFrameFromSegmentLength(): first frame with dist > dist[first] + len
      // (dist never decreases, so a binary search finds the same frame).
      const size_t last = static_cast<size_t>(
          std::upper_bound(dist.begin() + static_cast<long>(first), dist.end(), dist[first] + len) -
          dist.begin());
      if (last >= n) continue;
      const Eigen::Isometry3d d_gt = m.ref[first].T_world_base.inverse() * m.ref[last].T_world_base;
      const Eigen::Isometry3d d_res =
          m.est[first].T_world_base.inverse() * m.est[last].T_world_base;
      const Eigen::Isometry3d err = d_res.inverse() * d_gt;
      const double t_err = err.translation().norm() / len;  // [m/m]
      const double r_err = AngleRad(err.linear()) / len;    // [rad/m]
      t_sum[li] += t_err;
      r_sum[li] += r_err;
      ++count[li];
      t_total += t_err;
      r_total += r_err;
      ++r.segments;
    }
  }
  if (r.segments == 0) {
    std::string list;
    for (double len : lengths_m) list += (list.empty() ? "" : ",") + Fmt(len, 0);
    throw EvalError("no KITTI segment fits: the associated reference path is " + Fmt(dist.back()) +
                    " m long but the shortest segment length is " +
                    Fmt(*std::min_element(lengths_m.begin(), lengths_m.end())) + " m (lengths " +
                    list + "); give shorter --kitti-lengths");
  }
  r.trans_pct = 100.0 * t_total / static_cast<double>(r.segments);
  r.rot_deg_per_100m = 100.0 * kRadToDeg * r_total / static_cast<double>(r.segments);
  for (size_t li = 0; li < lengths_m.size(); ++li) {
    if (count[li] == 0) continue;
    r.lengths_m.push_back(lengths_m[li]);
    r.trans_pct_per_length.push_back(100.0 * t_sum[li] / static_cast<double>(count[li]));
    r.rot_deg_per_100m_per_length.push_back(100.0 * kRadToDeg * r_sum[li] /
                                            static_cast<double>(count[li]));
    r.segments_per_length.push_back(count[li]);
  }
  return r;
}

std::vector<double> DefaultKittiLengths(double path_length_m) {
  if (!(path_length_m >= 0.1) || !std::isfinite(path_length_m)) {
    throw EvalError("path length " + Fmt(path_length_m) +
                    " m is too short for segment drift (needs >= 0.1 m); the robot did not move");
  }
  std::vector<double> lengths;
  if (path_length_m >= 200.0) {
    for (int k = 1; k <= 8; ++k) {
      if (100.0 * k < path_length_m) lengths.push_back(100.0 * k);
    }
    return lengths;
  }
  const double target = 0.8 * path_length_m / 8.0;
  double step = std::pow(10.0, std::floor(std::log10(target)));
  if (5.0 * step <= target) {
    step *= 5.0;
  } else if (2.0 * step <= target) {
    step *= 2.0;
  }
  for (int k = 1; k <= 8; ++k) lengths.push_back(step * k);
  return lengths;
}

std::vector<Relation> ReadRelations(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw EvalError("cannot open relations file '" + path + "'");
  std::vector<Relation> relations;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    const std::string trimmed = Trim(line);
    if (trimmed.empty() || trimmed[0] == '#') continue;
    const std::string where = Where(path, line_no);
    const auto tokens = SplitTokens(trimmed);
    if (tokens.size() != 8) {
      throw EvalError(where +
                      ": a relation line has 8 values (t1 t2 x y z roll pitch yaw), found " +
                      std::to_string(tokens.size()));
    }
    Relation rel;
    rel.utime1 = ParseSecondsUtime(tokens[0], where);
    rel.utime2 = ParseSecondsUtime(tokens[1], where);
    double v[6];
    for (int k = 0; k < 6; ++k) v[k] = ParseNumber(tokens[k + 2], where);
    rel.T_1_2.linear() = RotationFromRollPitchYaw(v[3], v[4], v[5]);
    rel.T_1_2.translation() = Eigen::Vector3d(v[0], v[1], v[2]);
    relations.push_back(rel);
  }
  if (relations.empty()) throw EvalError("relations file '" + path + "' has no relations");
  return relations;
}

void WriteRelations(const std::vector<Relation>& relations, const std::string& path) {
  const std::string tmp = path + ".partial";
  {
    std::ofstream out(tmp);
    if (!out) throw EvalError("cannot write '" + tmp + "'");
    out << "# t1 t2 x y z roll pitch yaw (s, s, m, m, m, rad, rad, rad): pose at t2 in the frame "
           "of the pose at t1\n";
    out << std::setprecision(10);
    for (const auto& rel : relations) {
      const Eigen::Vector3d rpy = RollPitchYaw(rel.T_1_2.linear());
      const auto& t = rel.T_1_2.translation();
      out << std::fixed << std::setprecision(6) << UtimeToSeconds(rel.utime1) << ' '
          << UtimeToSeconds(rel.utime2) << ' ' << std::setprecision(9) << t.x() << ' ' << t.y()
          << ' ' << t.z() << ' ' << rpy.x() << ' ' << rpy.y() << ' ' << rpy.z() << '\n';
    }
    if (!out.good()) throw EvalError("error writing '" + tmp + "'");
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    throw EvalError("cannot rename '" + tmp + "' to '" + path + "'");
  }
}

std::vector<Relation> RelationsFromTrajectory(const Trajectory& ref, size_t step_frames) {
  CheckTrajectory(ref, "reference trajectory");
  if (step_frames < 1) throw EvalError("relations need a step of at least 1 frame");
  if (ref.size() <= step_frames) {
    throw EvalError("reference has " + std::to_string(ref.size()) +
                    " poses: too few for relations " + std::to_string(step_frames) +
                    " frame(s) apart");
  }
  std::vector<Relation> relations;
  for (size_t i = 0; i + step_frames < ref.size(); ++i) {
    const auto& a = ref[i];
    const auto& b = ref[i + step_frames];
    relations.push_back({a.utime, b.utime, a.T_world_base.inverse() * b.T_world_base});
  }
  return relations;
}

RelationResult ComputeRelationError(const Trajectory& est, const std::vector<Relation>& relations,
                                    Utime max_dt_us) {
  CheckTrajectory(est, "estimated trajectory");
  if (relations.empty()) throw EvalError("no relations to evaluate");
  RelationResult r;
  std::vector<double> t_err, r_err;
  for (const auto& rel : relations) {
    const long a = Nearest(est, rel.utime1, max_dt_us);
    const long b = Nearest(est, rel.utime2, max_dt_us);
    if (a < 0 || b < 0) {
      ++r.skipped;
      continue;
    }
    const Eigen::Isometry3d d_est = est[static_cast<size_t>(a)].T_world_base.inverse() *
                                    est[static_cast<size_t>(b)].T_world_base;
    const Eigen::Isometry3d e = rel.T_1_2.inverse() * d_est;
    t_err.push_back(e.translation().norm());
    r_err.push_back(AngleDeg(e.linear()));
  }
  r.used = t_err.size();
  if (r.used == 0) {
    throw EvalError("none of the " + std::to_string(relations.size()) +
                    " relations could be evaluated: their times (first t1 = " +
                    Fmt(UtimeToSeconds(relations.front().utime1)) + " s) are not within " +
                    Fmt(max_dt_us / 1000.0, 1) + " ms of an estimated pose (est covers [" +
                    Fmt(UtimeToSeconds(est.front().utime)) + ", " +
                    Fmt(UtimeToSeconds(est.back().utime)) + "] s); check the clocks or --max-dt");
  }
  for (double v : t_err) r.trans_sq_mean_m2 += v * v;
  for (double v : r_err) r.rot_sq_mean_deg2 += v * v;
  r.trans_sq_mean_m2 /= static_cast<double>(r.used);
  r.rot_sq_mean_deg2 /= static_cast<double>(r.used);
  r.trans_m = ComputeErrorStats(t_err);
  r.rot_deg = ComputeErrorStats(r_err);
  return r;
}

RelationResult ComputeRelationError(const Trajectory& est, const std::string& relations_file,
                                    Utime max_dt_us) {
  return ComputeRelationError(est, ReadRelations(relations_file), max_dt_us);
}

}  // namespace fl::eval
