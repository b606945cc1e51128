// The viewer's HTTP and WebSocket server (civetweb, Debian's libcivetweb-dev).
//
// Serves the page (viewer/web/), three.js from Debian's libjs-three, and /ws: a WebSocket per
// browser that receives the viewer's frames (frame.hpp) and may send one-line commands back
// ("seek 12.5", "play", "pause", "speed 2" in log mode).
//
// Every client has its own bounded FrameQueue and sender thread, so a slow or stalled browser
// costs its own queue only: Broadcast() never blocks, and a full queue drops its oldest
// frames (counted in stats()).
//
// Security: binds 127.0.0.1 unless told otherwise. With a token, every request must carry it,
// as ?token=T in the URL (the page then keeps it in a cookie for its scripts and WebSocket);
// without one, anyone who can reach the port sees everything the robot publishes.
#pragma once

#include <atomic>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "fusionloc/common/status.hpp"
#include "fusionloc/viewer/frame.hpp"
#include "fusionloc/viewer/scene.hpp"

struct mg_context;
struct mg_connection;

namespace fl::viewer {

struct ServerOptions {
  std::string bind = "127.0.0.1";  // address to listen on
  int port = 8765;                 // TCP port (0: any free port, see port())
  std::string token;               // "" = no access token
  std::string web_dir;             // folder with index.html, viewer.js, viewer.css
  std::string three_dir = "/usr/share/javascript/three";  // Debian's libjs-three
  int max_clients = 8;             // browsers at once (each holds a server thread)
  int queue_frames = 256;          // frames queued per browser before the oldest are dropped
};

// True if `token` is empty, or the query string (`token=...`) or the Cookie header
// (`fl_viewer_token=...`) carries it. Either may be null.
bool TokenAccepted(const std::string& token, const char* query_string, const char* cookie_header);

class WebServer {
 public:
  // Called from the server's threads with each text message of a browser.
  using CommandHandler = std::function<void(const std::string& command)>;

  WebServer(ServerOptions options, CommandHandler on_command);
  ~WebServer();
  WebServer(const WebServer&) = delete;
  WebServer& operator=(const WebServer&) = delete;

  // Checks the files and starts listening. Error naming the address, or the missing file and
  // its package.
  Status Start();
  void Stop();
  int port() const { return port_; }
  // The address to open (with ?token= when there is one).
  std::string url() const;

  // Queues frames for every browser (never blocks).
  void Broadcast(const std::vector<Frame>& frames);
  // The ids of browsers that connected since the last call (they need a snapshot).
  std::vector<int> TakeNewClients();
  // Queues frames for one browser (unknown id: nothing).
  void Send(int client, const std::vector<Frame>& frames);
  ViewerStats stats() const;

  // civetweb callbacks (public for the C trampolines only).
  int HandleRequest(mg_connection* conn);
  int HandleWsConnect(const mg_connection* conn);
  void HandleWsReady(mg_connection* conn);
  int HandleWsData(mg_connection* conn, int bits, char* data, size_t len);
  void HandleWsClose(const mg_connection* conn);

 private:
  struct Client {
    explicit Client(size_t capacity) : queue(capacity) {}
    int id = 0;
    mg_connection* conn = nullptr;
    FrameQueue queue;
    std::thread sender;
  };
  void SenderLoop(Client* client);

  ServerOptions options_;
  CommandHandler on_command_;
  mg_context* ctx_ = nullptr;
  int port_ = 0;
  std::map<std::string, std::pair<std::string, std::string>> files_;  // url -> (file, mime)
  mutable std::mutex mutex_;
  std::map<const mg_connection*, std::unique_ptr<Client>> clients_;
  std::vector<int> new_clients_;
  int next_id_ = 1;
  int pending_ = 0;  // accepted connections not yet ready
  std::atomic<int64_t> frames_sent_{0}, bytes_sent_{0}, dropped_closed_{0};
};

}  // namespace fl::viewer
