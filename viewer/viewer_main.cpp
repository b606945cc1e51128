// fl-viewer: the live view of the system in a browser (map, scan, trajectories, 3D cloud,
// process health), or of a log with a time slider: ViewerNode / LogViewer (viewer_lcm.hpp)
// on the process edge (fusionloc/common/lcm_process.hpp). docs/VIEWER.md.
#include <memory>

#include "fusionloc/common/log.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/viewer/viewer_lcm.hpp"

#ifndef FL_VIEWER_WEB_DIR
#define FL_VIEWER_WEB_DIR "viewer/web"
#endif

int main(int argc, char** argv) {
  using fl::viewer::ViewerNode;
  fl::Program program(ViewerNode::kProgram,
                      "The system in a browser: occupancy grid, latest scan, trajectories, 3D "
                      "cloud, process health and channel rates, live or from a log (--log).");
  fl::viewer::ViewerOptions options;
  program.AddOptions(&options, "config/viewer.yaml");
  fl::viewer::ServerOptions server_options;
  server_options.web_dir = FL_VIEWER_WEB_DIR;
  std::string log_path;
  double speed = 1.0;
  bool paused = false;
  auto& cli = program.cli();
  cli.AddFlag("port", &server_options.port, "TCP port of the page (0: any free port)");
  cli.AddFlag("bind", &server_options.bind,
              "address to listen on; 127.0.0.1 is this computer only. 0.0.0.0 exposes "
              "everything the robot publishes to the network: set --token with it");
  cli.AddFlag("token", &server_options.token,
              "access token (letters, digits, '-', '_'; 8 or more) required by the page and its "
              "WebSocket as ?token=...; empty: none");
  cli.AddFlag("web-dir", &server_options.web_dir, "folder of the page (the repository's viewer/web)");
  cli.AddFlag("three-dir", &server_options.three_dir, "three.js folder (Debian's libjs-three)");
  cli.AddFlag("log", &log_path, "show this LCM log with a time slider instead of live LCM");
  cli.AddFlag("speed", &speed, "log mode: initial playback speed (times real time)");
  cli.AddFlag("paused", &paused, "log mode: start paused at the beginning");
  cli.AddCheck([&]() -> std::string {
    if (server_options.port < 0 || server_options.port > 65535) return "--port must be in [0, 65535]";
    const std::string& t = server_options.token;
    if (!t.empty()) {
      if (t.size() < 8) return "--token must have 8 characters or more";
      for (const char c : t) {
        if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_') {
          return "--token may hold letters, digits, '-' and '_' only";
        }
      }
    }
    if (!(speed > 0 && speed <= 1000)) return "--speed must be in (0, 1000]";
    return "";
  });
  fl::LcmProcess process(&program, ViewerNode::Inputs(), ViewerNode::Outputs());
  cli.AddEpilog(
      "\nExamples:\n"
      "  fl-viewer                          # live: open http://127.0.0.1:8765/\n"
      "  fl-viewer --log out/demo/paper-.../run.lcmlog   # a log, with a time slider\n"
      "  fl-viewer --bind 0.0.0.0 --token $(head -c 12 /dev/urandom | base64 | tr +/ -_)\n"
      "Design and frames: docs/VIEWER.md.\n");
  if (!program.Parse(argc, argv)) return program.exit_code();
  server_options.max_clients = options.max_clients;
  server_options.queue_frames = options.queue_frames;
  return program.Run([&] {
    if (!log_path.empty()) {
      fl::viewer::LogViewer viewer(options, log_path, process.channels(), speed, !paused);
      fl::viewer::WebServer server(server_options,
                                   [&viewer](const std::string& c) { viewer.Command(c); });
      const fl::Status s = server.Start();
      if (!s.ok()) throw std::runtime_error(s.message());
      fl::InstallShutdownHandlers();
      FL_LOG(INFO) << "open " << server.url() << " (log " << log_path << ")";
      return viewer.Run(&server);
    }
    fl::viewer::WebServer server(server_options, [](const std::string& c) {
      FL_LOG(DEBUG) << "browser command ignored live: " << c;
    });
    const fl::Status s = server.Start();
    if (!s.ok()) throw std::runtime_error(s.message());
    FL_LOG(INFO) << "open " << server.url();
    return process.Run([&](fl::LcmInterface* lcm, const fl::ChannelMap& channels) {
      return std::make_unique<ViewerNode>(options, lcm, channels, &server);
    });
  });
}
