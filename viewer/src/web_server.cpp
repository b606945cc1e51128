#include "fusionloc/viewer/web_server.hpp"

#include <civetweb.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "fusionloc/common/log.hpp"

namespace fl::viewer {
namespace {

constexpr const char* kCookie = "fl_viewer_token";

WebServer* Self(const mg_connection* conn) {
  return static_cast<WebServer*>(mg_get_user_data(mg_get_context(conn)));
}

int RequestTrampoline(mg_connection* conn, void*) { return Self(conn)->HandleRequest(conn); }
int WsConnectTrampoline(const mg_connection* conn, void*) {
  return Self(conn)->HandleWsConnect(conn);
}
void WsReadyTrampoline(mg_connection* conn, void*) { Self(conn)->HandleWsReady(conn); }
int WsDataTrampoline(mg_connection* conn, int bits, char* data, size_t len, void*) {
  return Self(conn)->HandleWsData(conn, bits, data, len);
}
void WsCloseTrampoline(const mg_connection* conn, void*) { Self(conn)->HandleWsClose(conn); }
int LogMessage(const mg_connection*, const char* message) {
  FL_LOG(DEBUG) << "civetweb: " << message;
  return 1;  // handled: civetweb prints nothing itself
}

// Compares without leaking where the first difference is.
bool SameSecret(const std::string& a, const std::string& b) {
  if (a.size() != b.size()) return false;
  unsigned char diff = 0;
  for (size_t i = 0; i < a.size(); ++i) diff |= static_cast<unsigned char>(a[i] ^ b[i]);
  return diff == 0;
}

bool ReadFile(const std::string& path, std::string* out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  std::ostringstream ss;
  ss << in.rdbuf();
  *out = ss.str();
  return true;
}

}  // namespace

bool TokenAccepted(const std::string& token, const char* query_string, const char* cookie_header) {
  if (token.empty()) return true;
  std::vector<char> buf(token.size() + 2);
  if (query_string &&
      mg_get_var(query_string, std::strlen(query_string), "token", buf.data(), buf.size()) >= 0 &&
      SameSecret(buf.data(), token)) {
    return true;
  }
  if (cookie_header && mg_get_cookie(cookie_header, kCookie, buf.data(), buf.size()) >= 0 &&
      SameSecret(buf.data(), token)) {
    return true;
  }
  return false;
}

WebServer::WebServer(ServerOptions options, CommandHandler on_command)
    : options_(std::move(options)), on_command_(std::move(on_command)) {}

WebServer::~WebServer() { Stop(); }

Status WebServer::Start() {
  namespace fs = std::filesystem;
  const std::string three = options_.three_dir;
  const std::string three_js =
      fs::exists(three + "/three.min.js") ? three + "/three.min.js" : three + "/build/three.min.js";
  files_ = {
      {"/", {options_.web_dir + "/index.html", "text/html; charset=utf-8"}},
      {"/index.html", {options_.web_dir + "/index.html", "text/html; charset=utf-8"}},
      {"/viewer.js", {options_.web_dir + "/viewer.js", "text/javascript; charset=utf-8"}},
      {"/viewer.css", {options_.web_dir + "/viewer.css", "text/css; charset=utf-8"}},
      {"/three/three.min.js", {three_js, "text/javascript; charset=utf-8"}},
      {"/three/OrbitControls.js",
       {three + "/examples/js/controls/OrbitControls.js", "text/javascript; charset=utf-8"}},
  };
  for (const auto& [url, file] : files_) {
    if (fs::exists(file.first)) continue;
    if (url.rfind("/three/", 0) == 0) {
      return Status::Error("three.js not found: no " + file.first +
                           "; install Debian's libjs-three (./fusionloc setup) or pass "
                           "--three-dir");
    }
    return Status::Error("the viewer's page is missing: no " + file.first +
                         "; pass --web-dir with the repository's viewer/web folder");
  }
  mg_init_library(MG_FEATURES_WEBSOCKET);
  if (!mg_check_feature(MG_FEATURES_WEBSOCKET)) {
    return Status::Error("this civetweb library has no WebSocket support");
  }
  const std::string ports = (options_.bind.find(':') != std::string::npos
                                 ? "[" + options_.bind + "]"
                                 : options_.bind) +
                            ":" + std::to_string(options_.port);
  const std::string threads = std::to_string(options_.max_clients + 4);
  const char* config[] = {"listening_ports", ports.c_str(), "num_threads", threads.c_str(),
                          "request_timeout_ms", "10000", "enable_keep_alive", "yes",
                          nullptr};
  mg_callbacks callbacks;
  std::memset(&callbacks, 0, sizeof(callbacks));
  callbacks.log_message = LogMessage;
  char error_text[256] = "";
  unsigned error_code = 0;
  mg_error_data error{&error_code, error_text, sizeof(error_text)};
  mg_init_data init{&callbacks, this, config};
  ctx_ = mg_start2(&init, &error);
  if (!ctx_) {
    return Status::Error("cannot listen on " + ports + ": " +
                         (error_text[0] ? error_text : "unknown error") +
                         " (is another fl-viewer running? choose another --port)");
  }
  mg_server_port server_ports[4];
  const int n = mg_get_server_ports(ctx_, 4, server_ports);
  port_ = n > 0 ? server_ports[0].port : options_.port;
  mg_set_request_handler(ctx_, "/", RequestTrampoline, nullptr);
  mg_set_websocket_handler(ctx_, "/ws", WsConnectTrampoline, WsReadyTrampoline, WsDataTrampoline,
                           WsCloseTrampoline, nullptr);
  return Status::Ok();
}

void WebServer::Stop() {
  if (!ctx_) return;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (auto& [conn, c] : clients_) c->queue.Close();
  }
  mg_stop(ctx_);  // closes the connections (HandleWsClose joins their senders)
  ctx_ = nullptr;
  std::map<const mg_connection*, std::unique_ptr<Client>> left;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    left.swap(clients_);
  }
  for (auto& [conn, c] : left) {
    c->queue.Close();
    if (c->sender.joinable()) c->sender.join();
  }
}

std::string WebServer::url() const {
  const std::string host = options_.bind == "0.0.0.0" || options_.bind == "::"
                               ? std::string("HOST")
                               : (options_.bind.find(':') != std::string::npos
                                      ? "[" + options_.bind + "]"
                                      : options_.bind);
  return "http://" + host + ":" + std::to_string(port_) + "/" +
         (options_.token.empty() ? "" : "?token=" + options_.token);
}

int WebServer::HandleRequest(mg_connection* conn) {
  const mg_request_info* info = mg_get_request_info(conn);
  const std::string uri = info->local_uri ? info->local_uri : "/";
  if (!TokenAccepted(options_.token, info->query_string, mg_get_header(conn, "Cookie"))) {
    mg_send_http_error(conn, 403, "%s",
                       "fl-viewer: this viewer needs its access token: open the address it "
                       "printed, with ?token=...\n");
    return 403;
  }
  const auto it = files_.find(uri);
  if (it == files_.end()) {
    mg_send_http_error(conn, 404, "fl-viewer: no %s here\n", uri.c_str());
    return 404;
  }
  std::string body;
  if (!ReadFile(it->second.first, &body)) {
    mg_send_http_error(conn, 500, "fl-viewer: cannot read %s\n", it->second.first.c_str());
    return 500;
  }
  std::string cookie;
  if (!options_.token.empty()) {
    cookie = std::string("Set-Cookie: ") + kCookie + "=" + options_.token +
             "; Path=/; HttpOnly; SameSite=Strict\r\n";
  }
  mg_printf(conn,
            "HTTP/1.1 200 OK\r\nContent-Type: %s\r\nContent-Length: %zu\r\n"
            "Cache-Control: no-cache\r\n%sConnection: close\r\n\r\n",
            it->second.second.c_str(), body.size(), cookie.c_str());
  mg_write(conn, body.data(), body.size());
  return 200;
}

int WebServer::HandleWsConnect(const mg_connection* conn) {
  const mg_request_info* info = mg_get_request_info(conn);
  if (!TokenAccepted(options_.token, info->query_string, mg_get_header(conn, "Cookie"))) {
    FL_LOG(WARN) << "refused a WebSocket without the access token";
    return 1;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  if (static_cast<int>(clients_.size()) + pending_ >= options_.max_clients) {
    FL_LOG(WARN) << "refused a browser: already " << options_.max_clients
                 << " connected (--max-clients)";
    return 1;
  }
  ++pending_;
  return 0;
}

void WebServer::HandleWsReady(mg_connection* conn) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (pending_ > 0) --pending_;
  auto client = std::make_unique<Client>(static_cast<size_t>(options_.queue_frames));
  client->id = next_id_++;
  client->conn = conn;
  Client* raw = client.get();
  client->sender = std::thread([this, raw] { SenderLoop(raw); });
  new_clients_.push_back(raw->id);
  clients_[conn] = std::move(client);
  const mg_request_info* info = mg_get_request_info(conn);
  FL_LOG(INFO) << "browser " << raw->id << " connected from "
               << (info ? info->remote_addr : "?");
}

int WebServer::HandleWsData(mg_connection*, int bits, char* data, size_t len) {
  const int opcode = bits & 0xf;
  if (opcode == MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE) return 0;
  if (opcode == MG_WEBSOCKET_OPCODE_TEXT && on_command_) on_command_(std::string(data, len));
  return 1;
}

void WebServer::HandleWsClose(const mg_connection* conn) {
  std::unique_ptr<Client> client;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto it = clients_.find(conn);
    if (it == clients_.end()) return;
    client = std::move(it->second);
    clients_.erase(it);
  }
  dropped_closed_ += client->queue.dropped();
  client->queue.Close();
  if (client->sender.joinable()) client->sender.join();
  FL_LOG(INFO) << "browser " << client->id << " disconnected";
}

void WebServer::SenderLoop(Client* client) {
  Frame frame;
  while (true) {
    if (!client->queue.Pop(&frame, 500)) {
      if (client->queue.closed()) return;
      continue;
    }
    const int n = mg_websocket_write(client->conn, MG_WEBSOCKET_OPCODE_BINARY, frame.bytes.data(),
                                     frame.bytes.size());
    if (n <= 0) return;  // the connection is gone; HandleWsClose cleans up
    ++frames_sent_;
    bytes_sent_ += static_cast<int64_t>(frame.bytes.size());
  }
}

void WebServer::Broadcast(const std::vector<Frame>& frames) {
  if (frames.empty()) return;
  std::lock_guard<std::mutex> lock(mutex_);
  for (auto& [conn, c] : clients_) {
    for (const Frame& f : frames) c->queue.Push(f);
  }
}

std::vector<int> WebServer::TakeNewClients() {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<int> out;
  out.swap(new_clients_);
  return out;
}

void WebServer::Send(int client, const std::vector<Frame>& frames) {
  std::lock_guard<std::mutex> lock(mutex_);
  for (auto& [conn, c] : clients_) {
    if (c->id != client) continue;
    for (const Frame& f : frames) c->queue.Push(f);
  }
}

ViewerStats WebServer::stats() const {
  ViewerStats s;
  std::lock_guard<std::mutex> lock(mutex_);
  s.clients = static_cast<int>(clients_.size());
  s.frames_dropped = dropped_closed_;
  for (const auto& [conn, c] : clients_) s.frames_dropped += c->queue.dropped();
  s.frames_sent = frames_sent_;
  s.bytes_sent = bytes_sent_;
  return s;
}

}  // namespace fl::viewer
