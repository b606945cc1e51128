// fl-viewer's LCM side (target fl_viewer_lcm): the messages of the system into the Scene
// (MessageDecoder), the live node on the process edge (ViewerNode) and log mode (LogViewer).
//
// In:  every channel (for the rates); decoded: RBPF_MAP, LASER, LASER_TO_BASE, CAMERA_TO_BASE,
//      RBPF_POSE, VO_POSE, FUSED_POSE, ODOMETRY, GROUND_TRUTH, RBPF_TRAJECTORY,
//      FUSED_TRAJECTORY, FUSED_MAP, VO_POINTS, STATUS_* and PMD_INFO2.
// Out: STATUS_FL_VIEWER; to browsers, the frames of viewer/include/fusionloc/viewer/frame.hpp.
#pragma once

#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "fusionloc/common/channel_map.hpp"
#include "fusionloc/common/lcm_process.hpp"
#include "fusionloc/viewer/playback.hpp"
#include "fusionloc/viewer/scene.hpp"
#include "fusionloc/viewer/web_server.hpp"

namespace fl::viewer {

// The options file (config/viewer.yaml). Where it listens is on the command line.
struct ViewerOptions {
  SceneOptions scene;
  int queue_frames = 256;  // frames queued per browser before its oldest are dropped
  int max_clients = 8;     // browsers at once

  template <class A>
  void Serialize(A* a) {
    a->Visit("scene", &scene);
    a->Visit("queue_frames", &queue_frames);
    a->Visit("max_clients", &max_clients);
  }
  Status Validate() const;
};

// Decodes a message of any channel into the scene: the one code path of live and log mode.
class MessageDecoder {
 public:
  explicit MessageDecoder(const ChannelMap& channels);
  // Counts the message and, if the viewer shows its channel, decodes it. A message that does
  // not decode as its channel's type is counted in decode_errors() and skipped.
  void Dispatch(Scene* scene, const std::string& channel, const void* data, int size,
                Utime utime);
  // True if Dispatch decodes this channel (log mode keeps only those messages' bytes).
  bool Decodes(const std::string& channel) const;
  int64_t decode_errors() const { return decode_errors_; }

 private:
  std::map<std::string, std::string> role_;  // channel as used -> default name
  int64_t decode_errors_ = 0;
};

class ViewerNode : public LcmNode {
 public:
  static constexpr const char* kProgram = "fl-viewer";
  static std::vector<ChannelSpec> Inputs();
  static std::vector<ChannelSpec> Outputs();

  // `server` is started by the caller and outlives the node.
  ViewerNode(const ViewerOptions& options, LcmInterface* lcm, const ChannelMap& channels,
             WebServer* server);

  StatusReporter& status() override { return status_; }
  std::vector<std::string> RequiredInputs() const override { return {}; }
  void Poll() override;
  std::string Summary() const override;
  const Scene& scene() const { return scene_; }

 private:
  LcmInterface* lcm_;
  WebServer* server_;
  Scene scene_;
  MessageDecoder decoder_;
  StatusReporter status_;
  std::string hello_;
};

// The frame a browser gets first: {"type":"hello", "mode": "live"|"log", "source": URL or log}.
Frame HelloFrame(const std::string& mode, const std::string& source);

// Log mode: the log's messages in memory (the bytes of the channels the viewer decodes, and
// the time and channel of every other, for the rates), played on a PlaybackClock.
class LogViewer {
 public:
  // Reads the log (LcmLogReader). Throws std::runtime_error naming the file if it cannot be
  // read or holds no event.
  LogViewer(const ViewerOptions& options, const std::string& path, const ChannelMap& channels,
            double speed, bool playing);

  // The browser commands (thread-safe; from the server's threads).
  void Command(const std::string& text);
  // One step: applies commands, moves the clock by `wall_s`, feeds the scene, and returns the
  // frames for every browser (after a seek: a reset and the whole view).
  std::vector<Frame> Step(double wall_s, double now_s);
  // What a browser that has just connected gets.
  std::vector<Frame> Snapshot() const;
  // Runs until shutdown: Step every 20 ms, sending to `server`.
  int Run(WebServer* server);

  const PlaybackClock& clock() const { return clock_; }
  const Scene& scene() const { return scene_; }
  size_t events() const { return events_.size(); }

 private:
  struct Event {
    Utime utime;
    int channel;               // index into channels_
    std::vector<uint8_t> data;  // empty unless the viewer decodes the channel
    int size;                   // bytes in the log
  };
  void ApplyUntil(Utime t);

  std::string path_;
  Scene scene_;
  MessageDecoder decoder_;
  std::vector<std::string> channels_;
  std::vector<Event> events_;
  size_t next_ = 0;
  PlaybackClock clock_;
  std::mutex mutex_;
  std::deque<std::string> commands_;
  double clock_sent_s_ = -1e9;
};

}  // namespace fl::viewer
