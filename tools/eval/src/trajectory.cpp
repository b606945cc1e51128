#include "fusionloc/eval/trajectory.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <iomanip>
#include <map>
#include <set>
#include <sstream>

#include "bot_core/image_metadata_t.hpp"
#include "bot_core/image_t.hpp"
#include "bot_core/images_t.hpp"
#include "bot_core/planar_lidar_t.hpp"
#include "bot_core/pose_t.hpp"
#include "bot_core/rigid_transform_t.hpp"
#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/common/trajectory_merge.hpp"
#include "fusionloc/fused_pose_t.hpp"
#include "fusionloc/occupancy_grid_t.hpp"
#include "fusionloc/point_cloud_t.hpp"
#include "fusionloc/relative_pose_factor_t.hpp"
#include "fusionloc/status_t.hpp"
#include "fusionloc/stereo_calibration_t.hpp"
#include "fusionloc/trajectory_t.hpp"
#include "fusionloc/wheel_odometry_t.hpp"
#include "text_parse.hpp"

namespace fl::eval {

using namespace internal;  // NOLINT: parsing helpers

namespace {

// A planar (x, y, theta) message as a pose; non-finite values become a NaN translation so that
// the trajectory check reports them with the message's time.
StampedPose PlanarPose(Utime utime, double x, double y, double theta) {
  StampedPose p;
  p.utime = utime;
  p.T_world_base = Pose2(x, y, theta).ToIsometry3();
  if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(theta)) {
    p.T_world_base.translation().setConstant(std::nan(""));
  }
  return p;
}

// Name of a project message type by fingerprint, for error messages ("" if unknown).
std::string TypeNameOfHash(int64_t hash) {
  static const std::map<int64_t, std::string> kNames = {
      {bot_core::image_metadata_t::getHash(), "bot_core.image_metadata_t"},
      {bot_core::image_t::getHash(), "bot_core.image_t"},
      {bot_core::images_t::getHash(), "bot_core.images_t"},
      {bot_core::planar_lidar_t::getHash(), "bot_core.planar_lidar_t"},
      {bot_core::pose_t::getHash(), "bot_core.pose_t"},
      {bot_core::rigid_transform_t::getHash(), "bot_core.rigid_transform_t"},
      {fusionloc::fused_pose_t::getHash(), "fusionloc.fused_pose_t"},
      {fusionloc::occupancy_grid_t::getHash(), "fusionloc.occupancy_grid_t"},
      {fusionloc::point_cloud_t::getHash(), "fusionloc.point_cloud_t"},
      {fusionloc::relative_pose_factor_t::getHash(), "fusionloc.relative_pose_factor_t"},
      {fusionloc::status_t::getHash(), "fusionloc.status_t"},
      {fusionloc::stereo_calibration_t::getHash(), "fusionloc.stereo_calibration_t"},
      {fusionloc::trajectory_t::getHash(), "fusionloc.trajectory_t"},
      {fusionloc::wheel_odometry_t::getHash(), "fusionloc.wheel_odometry_t"}};
  const auto it = kNames.find(hash);
  return it == kNames.end() ? "" : it->second;
}

// KITTI raw "YYYY-MM-DD HH:MM:SS.fffffffff" (UTC) or plain seconds.
Utime ParseTimesLine(const std::string& line, const std::string& where) {
  int year, month, day, hour, minute;
  char sec_text[64] = {0};
  if (std::sscanf(line.c_str(), "%4d-%2d-%2d %2d:%2d:%63s", &year, &month, &day, &hour, &minute,
                  sec_text) == 6) {
    std::tm tm{};
    tm.tm_year = year - 1900;
    tm.tm_mon = month - 1;
    tm.tm_mday = day;
    tm.tm_hour = hour;
    tm.tm_min = minute;
    tm.tm_sec = 0;
    const time_t epoch = timegm(&tm);
    if (epoch == static_cast<time_t>(-1)) throw EvalError(where + ": bad date '" + line + "'");
    const Utime sec = ParseSecondsUtime(sec_text, where);
    return static_cast<Utime>(epoch) * kUtimePerSecond + sec;
  }
  const auto tokens = SplitTokens(line);
  if (tokens.size() != 1) {
    throw EvalError(where +
                    ": expected one time a line (seconds, or 'YYYY-MM-DD HH:MM:SS.f'), got '" +
                    line + "'");
  }
  return ParseSecondsUtime(tokens[0], where);
}

Eigen::Isometry3d FromRotationChecked(const Eigen::Matrix3d& r, const Eigen::Vector3d& t,
                                      const std::string& where) {
  const double ortho_err = (r.transpose() * r - Eigen::Matrix3d::Identity()).norm();
  if (ortho_err > 1e-2 || r.determinant() < 0) {
    throw EvalError(where + ": the 3x3 rotation is not a rotation (|R^T R - I| = " +
                    std::to_string(ortho_err) + ", det = " + std::to_string(r.determinant()) +
                    "); is this really a KITTI pose file (row-major 3x4 [R|t])?");
  }
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::Quaterniond(r).normalized().toRotationMatrix();  // re-orthonormalise
  T.translation() = t;
  return T;
}

std::string FormatSeconds(Utime t) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(3) << UtimeToSeconds(t);
  return s.str();
}

}  // namespace

double Yaw(const Eigen::Isometry3d& T) { return std::atan2(T.linear()(1, 0), T.linear()(0, 0)); }

void CheckTrajectory(const Trajectory& trajectory, const std::string& what) {
  if (trajectory.empty()) {
    throw EvalError(what +
                    " is empty: no poses; check the file/channel name and that the "
                    "estimator produced output");
  }
  for (size_t i = 0; i < trajectory.size(); ++i) {
    const auto& T = trajectory[i].T_world_base;
    if (!T.matrix().allFinite()) {
      throw EvalError(what + ": pose " + std::to_string(i) +
                      " (t=" + FormatSeconds(trajectory[i].utime) + " s) contains NaN or infinity");
    }
    if (i > 0 && trajectory[i].utime <= trajectory[i - 1].utime) {
      throw EvalError(what + ": time does not increase at pose " + std::to_string(i) +
                      " (t=" + FormatSeconds(trajectory[i].utime) + " s after " +
                      FormatSeconds(trajectory[i - 1].utime) +
                      " s); sort the poses by time and remove duplicates");
    }
  }
}

Trajectory ReadTrajectoryText(const std::string& path, const std::string& format) {
  return ReadTrajectoryText(path, format, "");
}

Trajectory ReadTrajectoryText(const std::string& path, const std::string& format_in,
                              const std::string& kitti_times_path) {
  std::string format = Lower(format_in);
  if (format != "auto" && format != "tum" && format != "kitti" && format != "2d") {
    throw EvalError("unknown trajectory format '" + format_in +
                    "'; use one of: auto, tum, kitti, 2d");
  }
  std::ifstream in(path);
  if (!in) throw EvalError("cannot open trajectory file '" + path + "'");
  if (IsLcmLog(path)) {
    throw EvalError("'" + path +
                    "' is an LCM log, not a text trajectory; read it with a channel "
                    "(fl-eval --est-channel/--ref-channel)");
  }

  Trajectory traj;
  std::string line;
  int line_no = 0;
  size_t expected = 0;
  while (std::getline(in, line)) {
    ++line_no;
    const std::string trimmed = Trim(line);
    if (trimmed.empty() || trimmed[0] == '#' || trimmed[0] == '%') continue;
    const auto tokens = SplitTokens(trimmed);
    const std::string where = Where(path, line_no);
    if (format == "auto") {
      if (tokens.size() == 8) {
        format = "tum";
      } else if (tokens.size() == 12) {
        format = "kitti";
      } else if (tokens.size() == 4) {
        format = "2d";
      } else {
        throw EvalError(where + ": cannot tell the trajectory format from a line of " +
                        std::to_string(tokens.size()) +
                        " values; expected 8 (TUM: t x y z qx qy qz qw), 12 (KITTI: 3x4 [R|t]) "
                        "or 4 (2D: t x y theta); pass --format if the file is one of these");
      }
    }
    expected = format == "tum" ? 8 : format == "kitti" ? 12 : 4;
    if (tokens.size() != expected) {
      throw EvalError(where + ": expected " + std::to_string(expected) + " values for format '" +
                      format + "', found " + std::to_string(tokens.size()));
    }
    StampedPose pose;
    if (format == "tum") {
      pose.utime = ParseSecondsUtime(tokens[0], where);
      double v[7];
      for (int k = 0; k < 7; ++k) v[k] = ParseNumber(tokens[k + 1], where);
      Eigen::Quaterniond q(v[6], v[3], v[4], v[5]);
      const double n = q.norm();
      if (n < 1e-6) throw EvalError(where + ": quaternion (qx qy qz qw) has zero length");
      if (std::fabs(n - 1.0) > 1e-2) {
        throw EvalError(where + ": quaternion length is " + std::to_string(n) +
                        ", not 1; is the column order t x y z qx qy qz qw (TUM)?");
      }
      pose.T_world_base.linear() = q.normalized().toRotationMatrix();
      pose.T_world_base.translation() = Eigen::Vector3d(v[0], v[1], v[2]);
    } else if (format == "2d") {
      pose.utime = ParseSecondsUtime(tokens[0], where);
      const double x = ParseNumber(tokens[1], where);
      const double y = ParseNumber(tokens[2], where);
      const double th = ParseNumber(tokens[3], where);
      pose.T_world_base = Pose2(x, y, th).ToIsometry3();
    } else {
      double v[12];
      for (int k = 0; k < 12; ++k) v[k] = ParseNumber(tokens[k], where);
      Eigen::Matrix3d r;
      r << v[0], v[1], v[2], v[4], v[5], v[6], v[8], v[9], v[10];
      pose.T_world_base = FromRotationChecked(r, Eigen::Vector3d(v[3], v[7], v[11]), where);
      pose.utime = static_cast<Utime>(traj.size()) * kKittiDefaultFramePeriodUs;
    }
    if (!traj.empty() && pose.utime <= traj.back().utime) {
      throw EvalError(where + ": time " + tokens[0] + " s is not after the previous pose's (" +
                      FormatSeconds(traj.back().utime) +
                      " s); poses must be sorted by time without duplicates");
    }
    traj.push_back(pose);
  }
  if (traj.empty()) {
    throw EvalError("trajectory file '" + path + "' has no poses (only blank or comment lines)");
  }

  if (format == "kitti" && !kitti_times_path.empty()) {
    std::ifstream tin(kitti_times_path);
    if (!tin) throw EvalError("cannot open KITTI times file '" + kitti_times_path + "'");
    std::vector<Utime> times;
    int tno = 0;
    while (std::getline(tin, line)) {
      ++tno;
      const std::string trimmed = Trim(line);
      if (trimmed.empty() || trimmed[0] == '#') continue;
      const std::string where = Where(kitti_times_path, tno);
      const Utime t = ParseTimesLine(trimmed, where);
      if (!times.empty() && t <= times.back()) {
        throw EvalError(where + ": time does not increase; times must be sorted");
      }
      times.push_back(t);
    }
    if (times.size() != traj.size()) {
      throw EvalError("KITTI times file '" + kitti_times_path + "' has " +
                      std::to_string(times.size()) + " times but '" + path + "' has " +
                      std::to_string(traj.size()) + " poses; they must match one to one");
    }
    for (size_t i = 0; i < traj.size(); ++i) traj[i].utime = times[i];
  }
  CheckTrajectory(traj, "trajectory file '" + path + "'");
  return traj;
}

bool IsLcmLog(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  unsigned char b[4];
  if (!in.read(reinterpret_cast<char*>(b), 4)) return false;
  return b[0] == 0xED && b[1] == 0xA1 && b[2] == 0xDA && b[3] == 0x01;
}

Trajectory ReadTrajectoryLcm(const std::string& log_path, const std::string& channel) {
  if (!IsLcmLog(log_path)) {
    std::ifstream probe(log_path);
    if (!probe) throw EvalError("cannot open LCM log '" + log_path + "'");
    throw EvalError("'" + log_path + "' is not an LCM log (no LCM sync word at the start)");
  }
  std::unique_ptr<LcmLogReader> reader;
  try {
    reader = std::make_unique<LcmLogReader>(log_path);
  } catch (const std::exception& e) {
    throw EvalError(std::string("cannot open LCM log: ") + e.what());
  }
  const int64_t kPoseHash = bot_core::pose_t::getHash();
  const int64_t kFusedHash = fusionloc::fused_pose_t::getHash();
  const int64_t kTrajHash = fusionloc::trajectory_t::getHash();
  const int64_t kOdomHash = fusionloc::wheel_odometry_t::getHash();

  std::map<std::string, int64_t> channel_counts;
  std::vector<StampedPose> poses;
  Trajectory traj_merged;  // trajectory_t messages, merged (MergeTrajectoryTail)
  bool have_traj = false;
  int64_t kind = 0;  // hash of the channel's type once known
  int64_t decode_failures = 0;
  LcmLogEvent ev;
  while (reader->Next(&ev)) {
    ++channel_counts[ev.channel];
    if (ev.channel != channel) continue;
    const int size = static_cast<int>(ev.data.size());
    if (size < 8) {
      ++decode_failures;
      continue;
    }
    int64_t hash = 0;
    for (int k = 0; k < 8; ++k)
      hash = static_cast<int64_t>((static_cast<uint64_t>(hash) << 8) | ev.data[k]);
    if (hash != kPoseHash && hash != kFusedHash && hash != kTrajHash && hash != kOdomHash) {
      std::ostringstream h;
      h << std::hex << static_cast<uint64_t>(hash);
      const std::string type = TypeNameOfHash(hash);
      throw EvalError("channel '" + channel + "' in '" + log_path + "' carries " +
                      (type.empty() ? "a message type with fingerprint 0x" + h.str() : type) +
                      ", not a pose type; use a channel of type bot_core.pose_t, "
                      "fusionloc.fused_pose_t, fusionloc.wheel_odometry_t or "
                      "fusionloc.trajectory_t");
    }
    if (kind != 0 && hash != kind) {
      throw EvalError("channel '" + channel + "' in '" + log_path +
                      "' mixes message types; one channel must carry one type");
    }
    kind = hash;
    if (hash == kPoseHash) {
      bot_core::pose_t msg{};
      if (msg.decode(ev.data.data(), 0, size) != size) {
        ++decode_failures;
        continue;
      }
      StampedPose p;
      p.utime = msg.utime;
      p.T_world_base = IsometryFromArrays(msg.pos, msg.orientation);
      const double qn = std::sqrt(
          msg.orientation[0] * msg.orientation[0] + msg.orientation[1] * msg.orientation[1] +
          msg.orientation[2] * msg.orientation[2] + msg.orientation[3] * msg.orientation[3]);
      if (!(qn > 1e-6)) {
        throw EvalError("channel '" + channel + "' in '" + log_path + "': pose at utime " +
                        std::to_string(msg.utime) + " has a zero or NaN orientation quaternion");
      }
      poses.push_back(p);
    } else if (hash == kOdomHash) {
      fusionloc::wheel_odometry_t msg{};
      if (msg.decode(ev.data.data(), 0, size) != size) {
        ++decode_failures;
        continue;
      }
      poses.push_back(PlanarPose(msg.utime, msg.x, msg.y, msg.theta));
    } else if (hash == kFusedHash) {
      fusionloc::fused_pose_t msg{};
      if (msg.decode(ev.data.data(), 0, size) != size) {
        ++decode_failures;
        continue;
      }
      poses.push_back(PlanarPose(msg.utime, msg.x, msg.y, msg.theta));
    } else {
      fusionloc::trajectory_t msg{};
      if (msg.decode(ev.data.data(), 0, size) != size) {
        ++decode_failures;
        continue;
      }
      const size_t n = static_cast<size_t>(std::max(0, msg.num_poses));
      if (msg.utimes.size() != n || msg.x.size() != n || msg.y.size() != n ||
          msg.z.size() != n || msg.theta.size() != n) {
        throw EvalError("channel '" + channel + "' of '" + log_path +
                        "': trajectory_t arrays do not match num_poses");
      }
      Trajectory latest;
      latest.reserve(n);
      for (size_t i = 0; i < n; ++i) {
        StampedPose p;
        p.utime = msg.utimes[i];
        p.T_world_base = Pose2(msg.x[i], msg.y[i], msg.theta[i]).ToIsometry3();
        p.T_world_base.translation().z() = msg.z[i];
        if (!std::isfinite(msg.theta[i])) p.T_world_base.translation().setConstant(std::nan(""));
        latest.push_back(p);
      }
      // A message may carry only the trajectory's latest part (trajectory_t.lcm).
      MergeTrajectoryTail(&traj_merged, std::move(latest),
                          [](const StampedPose& p) { return p.utime; });
      have_traj = true;
    }
  }
  if (!reader->ProblemSummary().empty()) {
    FL_LOG(WARN) << "LCM log '" << log_path << "': " << reader->ProblemSummary();
  }
  if (decode_failures > 0) {
    FL_LOG(WARN) << "channel '" << channel << "' in '" << log_path << "': " << decode_failures
                 << " message(s) did not decode (truncated or corrupt) and were skipped";
  }
  if (channel_counts.find(channel) == channel_counts.end()) {
    std::string list;
    for (const auto& [name, count] : channel_counts) {
      list += (list.empty() ? "" : ", ") + name + " (" + std::to_string(count) + ")";
    }
    if (channel.empty()) {
      throw EvalError("'" + log_path +
                      "' is an LCM log: name the pose channel to read; channels "
                      "present: " +
                      (list.empty() ? "none (empty log)" : list));
    }
    throw EvalError("channel '" + channel + "' not found in LCM log '" + log_path +
                    "'; channels present: " + (list.empty() ? "none (empty log)" : list));
  }

  const std::string what = "channel '" + channel + "' of '" + log_path + "'";
  Trajectory traj;
  if (have_traj) {
    CheckTrajectory(traj_merged, what + " (its trajectory_t messages, merged)");
    return traj_merged;
  }

  std::stable_sort(poses.begin(), poses.end(),
                   [](const StampedPose& a, const StampedPose& b) { return a.utime < b.utime; });
  int64_t duplicates = 0;
  for (const auto& p : poses) {
    if (!traj.empty() && traj.back().utime == p.utime) {
      traj.back() = p;  // keep the latest estimate for this time
      ++duplicates;
    } else {
      traj.push_back(p);
    }
  }
  if (duplicates > 0) {
    FL_LOG(WARN) << what << ": " << duplicates
                 << " pose(s) repeated an earlier time stamp; kept the latest of each";
  }
  CheckTrajectory(traj, what);
  return traj;
}

Trajectory ReadTrajectory(const std::string& path, const std::string& channel,
                          const std::string& format, const std::string& kitti_times_path) {
  if (IsLcmLog(path)) return ReadTrajectoryLcm(path, channel);
  return ReadTrajectoryText(path, format, kitti_times_path);
}

void WriteTrajectoryTum(const Trajectory& trajectory, const std::string& path) {
  const std::string tmp = path + ".partial";
  {
    std::ofstream out(tmp);
    if (!out) throw EvalError("cannot write '" + tmp + "'");
    out << "# t x y z qx qy qz qw\n" << std::setprecision(9);
    for (const auto& p : trajectory) {
      const Eigen::Quaterniond q(p.T_world_base.linear());
      const auto& t = p.T_world_base.translation();
      const Utime s = p.utime / kUtimePerSecond, us = p.utime % kUtimePerSecond;
      char stamp[48];
      if (p.utime >= 0) {
        std::snprintf(stamp, sizeof(stamp), "%lld.%06lld", static_cast<long long>(s),
                      static_cast<long long>(us));
      } else {
        std::snprintf(stamp, sizeof(stamp), "%.6f", UtimeToSeconds(p.utime));
      }
      out << stamp << ' ' << t.x() << ' ' << t.y() << ' ' << t.z() << ' ' << q.x() << ' ' << q.y()
          << ' ' << q.z() << ' ' << q.w() << '\n';
    }
    if (!out.good()) throw EvalError("error writing '" + tmp + "'");
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    throw EvalError("cannot rename '" + tmp + "' to '" + path + "'");
  }
}

std::vector<std::pair<size_t, size_t>> Associate(const Trajectory& est, const Trajectory& ref,
                                                 Utime max_dt_us) {
  if (est.empty()) throw EvalError("estimated trajectory is empty: nothing to evaluate");
  if (ref.empty()) throw EvalError("reference trajectory is empty: nothing to compare with");
  if (max_dt_us < 0) throw EvalError("association tolerance max_dt must be >= 0");
  // Candidate: nearest ref for each est.
  std::vector<std::pair<size_t, size_t>> pairs;
  std::vector<Utime> pair_dt;
  for (size_t i = 0; i < est.size(); ++i) {
    const Utime t = est[i].utime;
    auto it = std::lower_bound(ref.begin(), ref.end(), t,
                               [](const StampedPose& p, Utime v) { return p.utime < v; });
    size_t best = ref.size();
    Utime best_dt = 0;
    if (it != ref.end()) {
      best = static_cast<size_t>(it - ref.begin());
      best_dt = it->utime - t;
    }
    if (it != ref.begin()) {
      const size_t j = static_cast<size_t>(it - ref.begin()) - 1;
      const Utime dt = t - ref[j].utime;
      if (best == ref.size() || dt <= best_dt) {
        best = j;
        best_dt = dt;
      }
    }
    if (best == ref.size() || best_dt > max_dt_us) continue;
    if (!pairs.empty() && pairs.back().second >= best) {
      // Same ref pose claimed again (est sorted => best never decreases): keep the nearer.
      if (best_dt < pair_dt.back()) {
        pairs.back() = {i, best};
        pair_dt.back() = best_dt;
      }
      continue;
    }
    pairs.emplace_back(i, best);
    pair_dt.push_back(best_dt);
  }
  if (pairs.empty()) {
    std::ostringstream msg;
    msg << std::fixed << std::setprecision(3) << "est covers t=["
        << UtimeToSeconds(est.front().utime) << ", " << UtimeToSeconds(est.back().utime)
        << "] s, ref covers [" << UtimeToSeconds(ref.front().utime) << ", "
        << UtimeToSeconds(ref.back().utime) << "] s; no pair within " << std::defaultfloat
        << max_dt_us / 1000.0 << " ms: check the channels/files (same clock?) or --max-dt";
    throw EvalError(msg.str());
  }
  return pairs;
}

double PathLength(const Trajectory& trajectory) {
  double length = 0;
  for (size_t i = 1; i < trajectory.size(); ++i) {
    length +=
        (trajectory[i].T_world_base.translation() - trajectory[i - 1].T_world_base.translation())
            .norm();
  }
  return length;
}

}  // namespace fl::eval
