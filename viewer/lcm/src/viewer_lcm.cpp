#include "fusionloc/viewer/viewer_lcm.hpp"

#include <chrono>
#include <cmath>
#include <sstream>
#include <thread>

#include "bot_core/planar_lidar_t.hpp"
#include "bot_core/pose_t.hpp"
#include "bot_core/rigid_transform_t.hpp"
#include "bot_procman/info2_t.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/json.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/common/robot_description_lcm.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/fused_pose_t.hpp"
#include "fusionloc/occupancy_grid_t.hpp"
#include "fusionloc/point_cloud_t.hpp"
#include "fusionloc/status_t.hpp"
#include "fusionloc/trajectory_t.hpp"
#include "fusionloc/wheel_odometry_t.hpp"

namespace fl::viewer {
namespace {

namespace ch = fl::channels;

double MonotonicSeconds() { return UtimeToSeconds(MonotonicUtime()); }

// The channels the viewer decodes, by their default names.
const std::vector<std::string>& DecodedChannels() {
  static const std::vector<std::string> kChannels = {
      ch::kRbpfMap,       ch::kLaser,        ch::kLaserToBase,     ch::kCameraToBase,
      ch::kRbpfPose,      ch::kVoPose,       ch::kFusedPose,       ch::kOdometry,
      ch::kGroundTruth,   ch::kRbpfTrajectory, ch::kFusedTrajectory, ch::kFusedMap,
      ch::kVoPoints,      ch::kPmdInfo};
  return kChannels;
}

bool IsStatus(const std::string& channel) { return channel.rfind(ch::kStatusPrefix, 0) == 0; }

template <class Msg>
bool Decode(const void* data, int size, Msg* msg) {
  return msg->decode(data, 0, size) == size;
}

ViewPose FromPose(const bot_core::pose_t& m) {
  const Eigen::Isometry3d T = IsometryFromArrays(m.pos, m.orientation);
  ViewPose p;
  p.utime = m.utime;
  p.x = m.pos[0];
  p.y = m.pos[1];
  p.z = m.pos[2];
  p.yaw = Pose2::FromIsometry3(T).theta;
  return p;
}

std::vector<ViewPose> FromTrajectory(const fusionloc::trajectory_t& m) {
  std::vector<ViewPose> out(static_cast<size_t>(m.num_poses));
  for (size_t i = 0; i < out.size(); ++i) {
    out[i] = {m.utimes[i], m.x[i], m.y[i], m.z[i], m.theta[i]};
  }
  return out;
}

}  // namespace

Status ViewerOptions::Validate() const {
  const Status s = scene.Validate();
  if (!s.ok()) return Status::Error("scene." + s.message());
  if (queue_frames < 8) return Status::Error("queue_frames must be >= 8");
  if (max_clients < 1 || max_clients > 64) return Status::Error("max_clients must be in [1, 64]");
  return Status::Ok();
}

// ---- MessageDecoder ----

MessageDecoder::MessageDecoder(const ChannelMap& channels) {
  for (const std::string& name : DecodedChannels()) role_[channels(name)] = name;
}

bool MessageDecoder::Decodes(const std::string& channel) const {
  return role_.count(channel) > 0 || IsStatus(channel);
}

void MessageDecoder::Dispatch(Scene* scene, const std::string& channel, const void* data,
                              int size, Utime utime) {
  scene->CountMessage(channel, utime, static_cast<size_t>(size));
  bool ok = true;
  if (IsStatus(channel)) {
    fusionloc::status_t m;
    if ((ok = Decode(data, size, &m))) {
      ProcessView p;
      p.channel = channel;
      p.process = m.process;
      p.utime = m.utime;
      p.level = m.level;
      p.message = m.message;
      p.messages_in = m.messages_in;
      p.messages_out = m.messages_out;
      p.messages_dropped = m.messages_dropped;
      p.cpu_ms_per_item = m.cpu_ms_per_item;
      for (int i = 0; i < m.num_keys; ++i) p.values.emplace_back(m.keys[i], m.values[i]);
      scene->SetProcess(std::move(p));
    }
  }
  const auto it = role_.find(channel);
  if (it != role_.end()) {
    const std::string& role = it->second;
    if (role == ch::kRbpfMap) {
      fusionloc::occupancy_grid_t m{};
      if ((ok = Decode(data, size, &m) && m.num_cells == m.width * m.height && m.width >= 0)) {
        GridView g;
        g.utime = m.utime;
        g.resolution = m.resolution;
        g.width = m.width;
        g.height = m.height;
        g.origin_x = m.origin_x;
        g.origin_y = m.origin_y;
        g.cells = std::move(m.cells);
        scene->SetGrid(std::move(g));
      }
    } else if (role == ch::kLaser) {
      bot_core::planar_lidar_t m;
      if ((ok = Decode(data, size, &m))) {
        ScanView s;
        s.utime = m.utime;
        s.ranges = std::move(m.ranges);
        s.rad0 = m.rad0;
        s.radstep = m.radstep;
        scene->SetScan(std::move(s));
      }
    } else if (role == ch::kLaserToBase || role == ch::kCameraToBase) {
      bot_core::rigid_transform_t m;
      if ((ok = Decode(data, size, &m))) {
        const Eigen::Isometry3d T = TransformFromLcm(m);
        if (role == ch::kLaserToBase) {
          scene->SetLaserToBase(Pose2::FromIsometry3(T));
        } else {
          scene->SetCameraToBase(T);
        }
      }
    } else if (role == ch::kRbpfPose || role == ch::kVoPose || role == ch::kGroundTruth) {
      bot_core::pose_t m;
      if ((ok = Decode(data, size, &m))) scene->AddPose(role, FromPose(m));
    } else if (role == ch::kFusedPose) {
      fusionloc::fused_pose_t m;
      if ((ok = Decode(data, size, &m))) scene->AddPose(role, {m.utime, m.x, m.y, 0.0, m.theta});
    } else if (role == ch::kOdometry) {
      fusionloc::wheel_odometry_t m;
      if ((ok = Decode(data, size, &m))) scene->AddPose(role, {m.utime, m.x, m.y, 0.0, m.theta});
    } else if (role == ch::kRbpfTrajectory || role == ch::kFusedTrajectory) {
      fusionloc::trajectory_t m;
      if ((ok = Decode(data, size, &m))) scene->SetTrajectory(role, m.utime, FromTrajectory(m));
    } else if (role == ch::kFusedMap || role == ch::kVoPoints) {
      fusionloc::point_cloud_t m;
      if ((ok = Decode(data, size, &m))) {
        std::vector<float> xyz;
        xyz.reserve(3 * m.points.size());
        for (const auto& p : m.points) xyz.insert(xyz.end(), {p[0], p[1], p[2]});
        if (role == ch::kVoPoints && m.frame == "camera") {
          scene->AddKeyframePoints(m.utime, xyz.data(), m.points.size());
        } else {
          scene->SetCloud(role, m.utime, xyz.data(), m.points.size());
        }
      }
    } else if (role == ch::kPmdInfo) {
      bot_procman::info2_t m;
      if ((ok = Decode(data, size, &m))) {
        DeputyView d;
        d.host = m.host;
        d.utime = m.utime;
        d.cpu_load = m.cpu_load;
        d.mem_total_bytes = m.phys_mem_total_bytes;
        d.mem_free_bytes = m.phys_mem_free_bytes;
        for (const auto& c : m.cmds) {
          DeputyCommandView v;
          v.name = c.cmd.command_name;
          v.group = c.cmd.group;
          v.exec = c.cmd.exec_str;
          v.pid = c.pid;
          v.runid = c.actual_runid;
          v.exit_code = c.exit_code;
          v.cpu = c.cpu_usage;
          v.rss_bytes = c.mem_rss_bytes;
          d.commands.push_back(std::move(v));
        }
        scene->SetDeputy(std::move(d));
      }
    }
  }
  if (!ok) ++decode_errors_;
}

// ---- live ----

std::vector<ChannelSpec> ViewerNode::Inputs() {
  return {{ch::kRbpfMap, "fusionloc.occupancy_grid_t", "the RBPF-SLAM's grid (drawn as a texture)"},
          {ch::kLaser, "bot_core.planar_lidar_t", "the latest scan, drawn at the robot's pose"},
          {ch::kLaserToBase, "bot_core.rigid_transform_t", "laser mounting (places the scan)"},
          {ch::kCameraToBase, "bot_core.rigid_transform_t", "camera mounting (places VO points)"},
          {ch::kRbpfPose, "bot_core.pose_t", "RBPF-SLAM poses (trail and arrow)"},
          {ch::kVoPose, "bot_core.pose_t", "stereo VO poses (trail and arrow)"},
          {ch::kFusedPose, "fusionloc.fused_pose_t", "fused poses (trail and arrow)"},
          {ch::kOdometry, "fusionloc.wheel_odometry_t", "wheel odometry (trail and arrow)"},
          {ch::kGroundTruth, "bot_core.pose_t", "reference poses when present"},
          {ch::kRbpfTrajectory, "fusionloc.trajectory_t", "the RBPF's keyframe trajectory"},
          {ch::kFusedTrajectory, "fusionloc.trajectory_t", "the fusion's trajectory"},
          {ch::kFusedMap, "fusionloc.point_cloud_t", "the fused 3D map (voxel-thinned)"},
          {ch::kVoPoints, "fusionloc.point_cloud_t", "VO keyframe points (voxel-thinned)"},
          {"STATUS_*", "fusionloc.status_t", "every process's health (and the fusion's solve)"},
          {ch::kPmdInfo, "bot_procman.info2_t", "procman deputies' process tables"},
          {"(all)", "-", "every other channel, counted for the rates"}};
}

std::vector<ChannelSpec> ViewerNode::Outputs() {
  return {{"STATUS_FL_VIEWER", "fusionloc.status_t", "browsers, frames sent and dropped"}};
}

Frame HelloFrame(const std::string& mode, const std::string& source) {
  return MakeFrame("hello", "{\"type\":\"hello\",\"program\":\"fl-viewer\",\"mode\":" +
                                JsonString(mode) + ",\"source\":" + JsonString(source) + "}");
}

ViewerNode::ViewerNode(const ViewerOptions& options, LcmInterface* lcm, const ChannelMap& channels,
                       WebServer* server)
    : lcm_(lcm),
      server_(server),
      scene_(options.scene),
      decoder_(channels),
      status_(lcm, kProgram) {
  lcm_->SubscribeRaw(".*", [this](const std::string& channel, const void* data, int size,
                                  Utime recv_utime) {
    if (channel == status_.channel()) return;  // our own
    const auto t0 = std::chrono::steady_clock::now();
    status_.CountIn();
    decoder_.Dispatch(&scene_, channel, data, size, recv_utime);
    status_.AddItemTime(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  });
  status_.SetState(fusionloc::status_t::LEVEL_OK, "serving " + server_->url());
}

void ViewerNode::Poll() {
  const ViewerStats stats = server_->stats();
  scene_.SetViewerStats(stats);
  const std::vector<Frame> frames = scene_.TakeChanges(MonotonicSeconds());
  server_->Broadcast(frames);
  for (const int id : server_->TakeNewClients()) {
    std::vector<Frame> snapshot = scene_.Snapshot();
    snapshot.insert(snapshot.begin(), HelloFrame("live", lcm_->url()));
    server_->Send(id, snapshot);
  }
  status_.Set("browsers", stats.clients);
  status_.Set("frames_sent", static_cast<double>(stats.frames_sent));
  status_.Set("frames_dropped", static_cast<double>(stats.frames_dropped));
  status_.Set("bytes_sent", static_cast<double>(stats.bytes_sent));
  status_.Set("decode_errors", static_cast<double>(decoder_.decode_errors()));
  status_.SetState(fusionloc::status_t::LEVEL_OK,
                   std::to_string(stats.clients) + " browser(s) on " + server_->url());
}

std::string ViewerNode::Summary() const {
  const ViewerStats s = server_->stats();
  return std::to_string(lcm_->messages_received()) + " messages seen, " +
         std::to_string(s.frames_sent) + " frames sent (" + std::to_string(s.bytes_sent) +
         " bytes), " + std::to_string(s.frames_dropped) + " dropped for slow browsers";
}

// ---- log mode ----


LogViewer::LogViewer(const ViewerOptions& options, const std::string& path,
                     const ChannelMap& channels, double speed, bool playing)
    : path_(path), scene_(options.scene), decoder_(channels), clock_(0, 0) {
  LcmLogReader reader(path);
  LcmLogEvent e;
  std::map<std::string, int> index;
  int64_t kept_bytes = 0;
  Utime start = 0, end = 0;
  while (reader.Next(&e)) {
    auto it = index.find(e.channel);
    if (it == index.end()) {
      it = index.emplace(e.channel, static_cast<int>(channels_.size())).first;
      channels_.push_back(e.channel);
    }
    Event ev{e.utime, it->second, {}, static_cast<int>(e.data.size())};
    if (decoder_.Decodes(e.channel)) {
      ev.data = std::move(e.data);
      kept_bytes += ev.size;
    }
    if (events_.empty()) start = e.utime;
    start = std::min(start, e.utime);
    end = std::max(end, e.utime);
    events_.push_back(std::move(ev));
  }
  if (events_.empty()) {
    const std::string problems = reader.ProblemSummary();
    throw std::runtime_error("'" + path + "' holds no LCM event" +
                             (problems.empty() ? " (is it an LCM log?)" : ": " + problems));
  }
  if (!reader.ProblemSummary().empty()) FL_LOG(WARN) << path << ": " << reader.ProblemSummary();
  // Time-stamp order (a log's order is nearly that already; stable for equal stamps).
  std::stable_sort(events_.begin(), events_.end(),
                   [](const Event& a, const Event& b) { return a.utime < b.utime; });
  clock_ = PlaybackClock(start, end, speed, playing);
  FL_LOG(INFO) << path << ": " << events_.size() << " events on " << channels_.size()
               << " channels over " << UtimeToSeconds(end - start) << " s; "
               << kept_bytes / 1048576 << " MiB kept for the view";
}

void LogViewer::Command(const std::string& text) {
  std::lock_guard<std::mutex> lock(mutex_);
  commands_.push_back(text);
}

void LogViewer::ApplyUntil(Utime t) {
  while (next_ < events_.size() && events_[next_].utime <= t) {
    const Event& e = events_[next_++];
    decoder_.Dispatch(&scene_, channels_[static_cast<size_t>(e.channel)],
                      e.data.empty() ? nullptr : e.data.data(), e.size, e.utime);
  }
}

std::vector<Frame> LogViewer::Step(double wall_s, double now_s) {
  std::deque<std::string> commands;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    commands.swap(commands_);
  }
  bool clock_changed = false;
  for (const std::string& text : commands) {
    PlaybackCommand c;
    std::string error;
    if (!ParsePlaybackCommand(text, &c, &error)) {
      FL_LOG(WARN) << "browser command " << error;
      continue;
    }
    clock_.Apply(c);
    clock_changed = true;
  }
  clock_.Advance(wall_s);
  std::vector<Frame> out;
  if (clock_.TakeSeek()) {
    scene_.Reset();
    next_ = 0;
    ApplyUntil(clock_.now());
    scene_.TakeChanges(now_s);  // marks everything as sent: the snapshot carries it
    out.push_back(MakeFrame("", "{\"type\":\"reset\"}"));
    for (Frame& f : scene_.Snapshot()) out.push_back(std::move(f));
  } else {
    ApplyUntil(clock_.now());
    out = scene_.TakeChanges(now_s);
  }
  if (clock_changed || now_s - clock_sent_s_ >= 0.1) {
    out.push_back(MakeFrame("clock", clock_.Json()));
    clock_sent_s_ = now_s;
  }
  return out;
}

std::vector<Frame> LogViewer::Snapshot() const {
  std::vector<Frame> out = scene_.Snapshot();
  out.insert(out.begin(), HelloFrame("log", path_));
  out.push_back(MakeFrame("clock", clock_.Json()));
  return out;
}

int LogViewer::Run(WebServer* server) {
  double last = MonotonicSeconds();
  while (!ShutdownRequested()) {
    const double now = MonotonicSeconds();
    scene_.SetViewerStats(server->stats());
    server->Broadcast(Step(now - last, now));
    last = now;
    for (const int id : server->TakeNewClients()) server->Send(id, Snapshot());
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return kExitOk;
}

}  // namespace fl::viewer
