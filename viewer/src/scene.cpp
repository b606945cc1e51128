#include "fusionloc/viewer/scene.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "fusionloc/common/json.hpp"
#include "fusionloc/common/trajectory_merge.hpp"

namespace fl::viewer {
namespace {

std::string Num(double v) { return JsonNumber(v, 10); }

void AppendPose(std::vector<float>* out, const ViewPose& p) {
  out->insert(out->end(), {static_cast<float>(p.x), static_cast<float>(p.y),
                           static_cast<float>(p.z), static_cast<float>(p.yaw)});
}

std::string PoseJson(const ViewPose& p) {
  return "[" + Num(p.x) + "," + Num(p.y) + "," + Num(p.z) + "," + Num(p.yaw) + "," +
         std::to_string(p.utime) + "]";
}

// A source whose latest pose is older than this (data time) gives way to the next one.
constexpr double kRecentPoseS = 2.0;

}  // namespace

Status SceneOptions::Validate() const {
  auto positive = [](double v) { return v > 0 && std::isfinite(v); };
  auto non_negative = [](double v) { return v >= 0 && std::isfinite(v); };
  if (!non_negative(grid_period_s)) return Status::Error("grid_period_s must be >= 0");
  if (!non_negative(scan_period_s)) return Status::Error("scan_period_s must be >= 0");
  if (!non_negative(trail_period_s)) return Status::Error("trail_period_s must be >= 0");
  if (!non_negative(trail_min_distance_m)) return Status::Error("trail_min_distance_m must be >= 0");
  if (!non_negative(trail_min_turn_rad)) return Status::Error("trail_min_turn_rad must be >= 0");
  if (!non_negative(trajectory_min_distance_m)) {
    return Status::Error("trajectory_min_distance_m must be >= 0");
  }
  if (!(cloud_voxel_m >= 0.005 && cloud_voxel_m <= 10)) {
    return Status::Error("cloud_voxel_m must be in [0.005, 10] m");
  }
  if (!non_negative(cloud_period_s)) return Status::Error("cloud_period_s must be >= 0");
  if (max_trail_poses < 2) return Status::Error("max_trail_poses must be >= 2");
  if (max_cloud_points < 1) return Status::Error("max_cloud_points must be >= 1");
  if (!positive(rates_window_s)) return Status::Error("rates_window_s must be > 0");
  if (!positive(status_period_s)) return Status::Error("status_period_s must be > 0");
  return Status::Ok();
}

const std::vector<std::string>& Scene::PoseSources() {
  static const std::vector<std::string> kSources = {"FUSED_POSE", "RBPF_POSE", "VO_POSE",
                                                    "ODOMETRY", "GROUND_TRUTH"};
  return kSources;
}

Scene::Scene(const SceneOptions& options) : options_(options) {}

void Scene::Reset() {
  const ViewerStats stats = viewer_stats_;
  *this = Scene(options_);
  viewer_stats_ = stats;
}

void Scene::SetGrid(GridView grid) {
  clock_ = std::max(clock_, grid.utime);
  const bool same = grid.width == grid_.width && grid.height == grid_.height &&
                    grid.resolution == grid_.resolution && grid.origin_x == grid_.origin_x &&
                    grid.origin_y == grid_.origin_y && grid.cells == grid_.cells;
  const bool was_pending = grid_changed_;
  grid_ = std::move(grid);
  grid_changed_ = was_pending || !same;
}

void Scene::SetScan(ScanView scan) {
  clock_ = std::max(clock_, scan.utime);
  scan_ = std::move(scan);
  scan_changed_ = true;
}

void Scene::SetLaserToBase(const Pose2& T_base_laser) { T_base_laser_ = T_base_laser; }
void Scene::SetCameraToBase(const Eigen::Isometry3d& T_base_camera) {
  T_base_camera_ = T_base_camera;
}

Scene::Trail& Scene::TrailOf(const std::string& source) {
  auto it = trails_.find(source);
  if (it == trails_.end()) {
    it = trails_
             .emplace(source, Trail{TrailDecimator(options_.trail_period_s,
                                                   options_.trail_min_distance_m,
                                                   options_.trail_min_turn_rad),
                                    {}, 0, false, {}, false, true})
             .first;
  }
  return it->second;
}

Scene::Cloud& Scene::CloudOf(const std::string& source) {
  auto it = clouds_.find(source);
  if (it == clouds_.end()) it = clouds_.emplace(source, Cloud(options_.cloud_voxel_m)).first;
  return it->second;
}

void Scene::AddPose(const std::string& source, const ViewPose& pose) {
  if (!std::isfinite(pose.x) || !std::isfinite(pose.y) || !std::isfinite(pose.yaw)) return;
  clock_ = std::max(clock_, pose.utime);
  Trail& t = TrailOf(source);
  t.last = pose;
  t.have_last = true;
  t.last_sent = false;
  bool restart = false;
  if (!t.decimator.Accept(pose, &restart)) return;
  if (restart) {
    t.poses.clear();
    t.restart = true;
  }
  if (t.poses.size() >= static_cast<size_t>(options_.max_trail_poses)) {
    t.poses.erase(t.poses.begin(), t.poses.begin() + static_cast<long>(t.poses.size() / 2));
    t.restart = true;
  }
  t.poses.push_back(pose);
}

void Scene::SetTrajectory(const std::string& source, Utime utime,
                          const std::vector<ViewPose>& poses) {
  clock_ = std::max(clock_, utime);
  // A message may carry only the trajectory's latest part (trajectory_t.lcm).
  MergeTrajectoryTail(
      &trajectories_[source],
      DecimateTrajectory(poses, options_.trajectory_min_distance_m, options_.trail_min_turn_rad),
      [](const ViewPose& p) { return p.utime; });
  trajectory_changed_[source] = true;
}

void Scene::SetCloud(const std::string& source, Utime utime, const float* xyz, size_t n) {
  clock_ = std::max(clock_, utime);
  Cloud& c = CloudOf(source);
  c.voxels.Clear();
  c.points.clear();
  c.voxels.Add(xyz, std::min(n, static_cast<size_t>(options_.max_cloud_points) * 8), &c.points);
  if (c.points.size() / 3 > static_cast<size_t>(options_.max_cloud_points)) {
    c.points.resize(static_cast<size_t>(options_.max_cloud_points) * 3);
  }
  c.whole = true;
  c.sent = 0;
  c.utime = utime;
}

void Scene::AddKeyframePoints(Utime utime, const float* xyz_camera, size_t n) {
  clock_ = std::max(clock_, utime);
  ViewPose robot;
  std::string source;
  if (!RobotPose(&robot, &source)) return;  // nowhere to put them yet
  Cloud& c = CloudOf("VO_POINTS");
  if (c.points.size() / 3 >= static_cast<size_t>(options_.max_cloud_points)) return;
  // Placed in the plane (x, y, yaw) at the pose's height.
  Eigen::Isometry3d T_world_base = Pose2(robot.x, robot.y, robot.yaw).ToIsometry3();
  T_world_base.translation().z() = robot.z;
  const Eigen::Isometry3f T = (T_world_base * T_base_camera_).cast<float>();
  std::vector<float> world;
  world.reserve(3 * n);
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3f p =
        T * Eigen::Vector3f(xyz_camera[3 * i], xyz_camera[3 * i + 1], xyz_camera[3 * i + 2]);
    world.insert(world.end(), {p.x(), p.y(), p.z()});
  }
  c.voxels.Add(world.data(), n, &c.points);
  c.utime = utime;
}

void Scene::SetProcess(ProcessView process) {
  clock_ = std::max(clock_, process.utime);
  const std::string key = process.channel;
  processes_[key] = std::move(process);
  processes_changed_ = true;
}

void Scene::SetDeputy(DeputyView deputy) {
  clock_ = std::max(clock_, deputy.utime);
  const std::string key = deputy.host;
  deputies_[key] = std::move(deputy);
  processes_changed_ = true;
}

void Scene::CountMessage(const std::string& channel, Utime utime, size_t bytes) {
  Rate& r = rates_[channel];
  ++r.count;
  r.bytes += static_cast<int64_t>(bytes);
  if (!r.recent.empty() && utime < r.recent.back()) r.recent.clear();  // time went back
  r.recent.push_back(utime);
  while (r.recent.size() > 2000) r.recent.pop_front();
  clock_ = std::max(clock_, utime);
}

size_t Scene::trail_size(const std::string& source) const {
  const auto it = trails_.find(source);
  return it == trails_.end() ? 0 : it->second.poses.size();
}

size_t Scene::cloud_size(const std::string& source) const {
  const auto it = clouds_.find(source);
  return it == clouds_.end() ? 0 : it->second.points.size() / 3;
}

bool Scene::RobotPose(ViewPose* pose, std::string* source) const {
  const Trail* fallback = nullptr;
  std::string fallback_source;
  for (const std::string& s : PoseSources()) {
    const auto it = trails_.find(s);
    if (it == trails_.end() || !it->second.have_last) continue;
    if (UtimeToSeconds(clock_ - it->second.last.utime) <= kRecentPoseS) {
      *pose = it->second.last;
      *source = s;
      return true;
    }
    if (!fallback) {
      fallback = &it->second;
      fallback_source = s;
    }
  }
  if (!fallback) return false;
  *pose = fallback->last;
  *source = fallback_source;
  return true;
}

// ---- frames ----

Frame Scene::GridFrame() const {
  std::ostringstream h;
  h << "{\"type\":\"grid\",\"utime\":" << grid_.utime << ",\"resolution\":" << Num(grid_.resolution)
    << ",\"width\":" << grid_.width << ",\"height\":" << grid_.height
    << ",\"origin_x\":" << Num(grid_.origin_x) << ",\"origin_y\":" << Num(grid_.origin_y) << "}";
  return MakeFrame("grid", h.str(), grid_.cells.data(), grid_.cells.size());
}

Frame Scene::ScanFrame() const {
  std::vector<float> xy;
  xy.reserve(2 * scan_.ranges.size());
  for (size_t i = 0; i < scan_.ranges.size(); ++i) {
    const double r = scan_.ranges[i];
    if (!(r > 0) || !std::isfinite(r)) continue;
    const double a = scan_.rad0 + static_cast<double>(i) * scan_.radstep;
    const Eigen::Vector2d p = T_base_laser_ * Eigen::Vector2d(r * std::cos(a), r * std::sin(a));
    xy.push_back(static_cast<float>(p.x()));
    xy.push_back(static_cast<float>(p.y()));
  }
  ViewPose robot;
  std::string source;
  const bool placed = RobotPose(&robot, &source);
  std::ostringstream h;
  h << "{\"type\":\"scan\",\"utime\":" << scan_.utime << ",\"count\":" << xy.size() / 2
    << ",\"source\":" << JsonString(placed ? source : "") << ",\"pose\":"
    << (placed ? PoseJson(robot) : "null") << "}";
  return MakeFrame("scan", h.str(), xy.data(), xy.size() * sizeof(float));
}

Frame Scene::TrailFrame(const std::string& source, const Trail& t, size_t from,
                        bool replace) const {
  std::vector<float> data;
  data.reserve(4 * (t.poses.size() - from));
  for (size_t i = from; i < t.poses.size(); ++i) AppendPose(&data, t.poses[i]);
  std::ostringstream h;
  h << "{\"type\":\"trail\",\"source\":" << JsonString(source)
    << ",\"replace\":" << (replace ? "true" : "false") << ",\"count\":" << data.size() / 4 << "}";
  // Appends must all arrive: no key. A whole trail replaces any queued one.
  return MakeFrame(replace ? "trail:" + source : "", h.str(), data.data(),
                   data.size() * sizeof(float));
}

Frame Scene::PoseFrame() const {
  std::ostringstream h;
  h << "{\"type\":\"poses\",\"poses\":{";
  bool first = true;
  for (const auto& [source, t] : trails_) {
    if (!t.have_last) continue;
    h << (first ? "" : ",") << JsonString(source) << ":" << PoseJson(t.last);
    first = false;
  }
  ViewPose robot;
  std::string source;
  const bool placed = RobotPose(&robot, &source);
  h << "},\"robot\":" << (placed ? JsonString(source) : "null") << ",\"clock\":" << clock_ << "}";
  return MakeFrame("poses", h.str());
}

Frame Scene::TrajectoryFrame(const std::string& source) const {
  const std::vector<ViewPose>& poses = trajectories_.at(source);
  std::vector<float> data;
  data.reserve(4 * poses.size());
  for (const ViewPose& p : poses) AppendPose(&data, p);
  std::ostringstream h;
  h << "{\"type\":\"trajectory\",\"source\":" << JsonString(source)
    << ",\"count\":" << poses.size() << "}";
  return MakeFrame("trajectory:" + source, h.str(), data.data(), data.size() * sizeof(float));
}

Frame Scene::CloudFrame(const std::string& source, const Cloud& c, size_t from, size_t to,
                        bool replace) const {
  const size_t n = to - from;
  std::ostringstream h;
  h << "{\"type\":\"cloud\",\"source\":" << JsonString(source)
    << ",\"replace\":" << (replace ? "true" : "false") << ",\"count\":" << n
    << ",\"total\":" << to << ",\"voxel\":" << Num(c.voxels.voxel())
    << ",\"utime\":" << c.utime << "}";
  return MakeFrame(replace ? "cloud:" + source : "", h.str(), c.points.data() + 3 * from,
                   n * 3 * sizeof(float));
}

Frame Scene::ProcessesFrame() const {
  std::ostringstream h;
  h << "{\"type\":\"processes\",\"processes\":[";
  bool first = true;
  for (const auto& [channel, p] : processes_) {
    h << (first ? "" : ",") << "{\"channel\":" << JsonString(channel)
      << ",\"process\":" << JsonString(p.process) << ",\"utime\":" << p.utime
      << ",\"level\":" << p.level << ",\"message\":" << JsonString(p.message)
      << ",\"in\":" << p.messages_in << ",\"out\":" << p.messages_out
      << ",\"dropped\":" << p.messages_dropped << ",\"cpu_ms_per_item\":" << Num(p.cpu_ms_per_item)
      << ",\"values\":{";
    for (size_t i = 0; i < p.values.size(); ++i) {
      h << (i ? "," : "") << JsonString(p.values[i].first) << ":" << Num(p.values[i].second);
    }
    h << "}}";
    first = false;
  }
  h << "],\"deputies\":[";
  first = true;
  for (const auto& [host, d] : deputies_) {
    h << (first ? "" : ",") << "{\"host\":" << JsonString(host) << ",\"utime\":" << d.utime
      << ",\"cpu_load\":" << Num(d.cpu_load) << ",\"mem_total\":" << d.mem_total_bytes
      << ",\"mem_free\":" << d.mem_free_bytes << ",\"commands\":[";
    for (size_t i = 0; i < d.commands.size(); ++i) {
      const DeputyCommandView& c = d.commands[i];
      h << (i ? "," : "") << "{\"name\":" << JsonString(c.name) << ",\"group\":"
        << JsonString(c.group) << ",\"exec\":" << JsonString(c.exec) << ",\"pid\":" << c.pid
        << ",\"runid\":" << c.runid << ",\"exit_code\":" << c.exit_code
        << ",\"cpu\":" << Num(c.cpu) << ",\"rss\":" << c.rss_bytes << "}";
    }
    h << "]}";
    first = false;
  }
  h << "]}";
  return MakeFrame("processes", h.str());
}

Frame Scene::RatesFrame() const {
  std::ostringstream h;
  h << "{\"type\":\"rates\",\"clock\":" << clock_ << ",\"channels\":[";
  bool first = true;
  const Utime window = SecondsToUtime(options_.rates_window_s);
  for (const auto& [channel, r] : rates_) {
    // Messages in the window ending at the latest data time.
    size_t n = 0;
    for (auto it = r.recent.rbegin(); it != r.recent.rend() && clock_ - *it <= window; ++it) ++n;
    const double hz = static_cast<double>(n) / options_.rates_window_s;
    h << (first ? "" : ",") << "{\"name\":" << JsonString(channel) << ",\"count\":" << r.count
      << ",\"bytes\":" << r.bytes << ",\"hz\":" << JsonNumber(hz, 4) << "}";
    first = false;
  }
  h << "],\"viewer\":{\"clients\":" << viewer_stats_.clients
    << ",\"frames_sent\":" << viewer_stats_.frames_sent
    << ",\"frames_dropped\":" << viewer_stats_.frames_dropped
    << ",\"bytes_sent\":" << viewer_stats_.bytes_sent << "}}";
  return MakeFrame("rates", h.str());
}

std::vector<Frame> Scene::TakeChanges(double now_s) {
  std::vector<Frame> out;
  if (grid_changed_ && !grid_.cells.empty() && now_s - grid_sent_s_ >= options_.grid_period_s) {
    out.push_back(GridFrame());
    grid_changed_ = false;
    grid_sent_s_ = now_s;
  }
  for (auto& [source, changed] : trajectory_changed_) {
    if (!changed) continue;
    out.push_back(TrajectoryFrame(source));
    changed = false;
  }
  for (auto& [source, t] : trails_) {
    if (t.restart) {
      out.push_back(TrailFrame(source, t, 0, true));
      t.restart = false;
    } else if (t.sent < t.poses.size()) {
      out.push_back(TrailFrame(source, t, t.sent, false));
    }
    t.sent = t.poses.size();
  }
  const bool scan_due = now_s - scan_sent_s_ >= options_.scan_period_s;
  bool poses_changed = false;
  for (auto& [source, t] : trails_) {
    if (!t.last_sent) poses_changed = true;
  }
  if (scan_due && (poses_changed || scan_changed_)) {
    if (scan_changed_ && !scan_.ranges.empty()) out.push_back(ScanFrame());
    if (poses_changed) out.push_back(PoseFrame());
    for (auto& [source, t] : trails_) t.last_sent = true;
    scan_changed_ = false;
    scan_sent_s_ = now_s;
  }
  if (now_s - cloud_sent_s_ >= options_.cloud_period_s) {
    bool any = false;
    for (auto& [source, c] : clouds_) {
      if (c.whole) {
        out.push_back(CloudFrame(source, c, 0, c.points.size() / 3, true));
        any = true;
      } else if (c.sent < c.points.size() / 3) {
        out.push_back(CloudFrame(source, c, c.sent, c.points.size() / 3, false));
        any = true;
      }
      c.whole = false;
      c.sent = c.points.size() / 3;
    }
    if (any) cloud_sent_s_ = now_s;
  }
  if (now_s - status_sent_s_ >= options_.status_period_s) {
    if (processes_changed_) out.push_back(ProcessesFrame());
    processes_changed_ = false;
    out.push_back(RatesFrame());
    status_sent_s_ = now_s;
  }
  frames_made_ += static_cast<int64_t>(out.size());
  return out;
}

std::vector<Frame> Scene::Snapshot() const {
  std::vector<Frame> out;
  if (!grid_.cells.empty()) out.push_back(GridFrame());
  for (const auto& [source, poses] : trajectories_) out.push_back(TrajectoryFrame(source));
  for (const auto& [source, t] : trails_) out.push_back(TrailFrame(source, t, 0, true));
  if (!scan_.ranges.empty()) out.push_back(ScanFrame());
  if (!trails_.empty()) out.push_back(PoseFrame());
  // What TakeChanges has sent so far: later changes reach every client alike.
  for (const auto& [source, c] : clouds_) {
    if (!c.whole) out.push_back(CloudFrame(source, c, 0, c.sent, true));
  }
  out.push_back(ProcessesFrame());
  out.push_back(RatesFrame());
  return out;
}

}  // namespace fl::viewer
