// fl-replay: the whole pipeline (RBPF-SLAM, stereo VO, fusion) over a recorded log in one
// process, as fast as the CPU allows (replay.hpp).
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <opencv2/core/utility.hpp>
#include <sstream>

#include "fusionloc/common/lcm_process.hpp"
#include "fusionloc/common/number_format.hpp"
#include "fusionloc/common/program.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "replay.hpp"

namespace {

std::vector<std::string> SplitComma(const std::string& text) {
  std::vector<std::string> out;
  std::stringstream s(text);
  std::string item;
  while (std::getline(s, item, ',')) {
    if (!item.empty()) out.push_back(item);
  }
  return out;
}

// A progress bar on stderr: redrawn in place on a terminal, a line every 10 % otherwise.
class ProgressBar {
 public:
  ProgressBar() : tty_(isatty(STDERR_FILENO) == 1), start_(std::chrono::steady_clock::now()) {}
  void Update(double fraction, double data_s) {
    fraction = std::clamp(fraction, 0.0, 1.0);
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    const int decile = static_cast<int>(fraction * 10);
    if (done_ || (!tty_ && decile <= last_decile_ && fraction < 1.0)) return;
    last_decile_ = decile;
    done_ = fraction >= 1.0;
    const int width = 30, filled = static_cast<int>(std::lround(fraction * width));
    const double eta = fraction > 0.01 ? elapsed * (1.0 - fraction) / fraction : 0.0;
    char line[200];
    std::snprintf(line, sizeof(line),
                  "[fl-replay] %3d%% |%s%s| %.1f s of data, %.1fx real time, ETA %.0f s",
                  static_cast<int>(std::lround(fraction * 100)), std::string(filled, '#').c_str(),
                  std::string(width - filled, ' ').c_str(), data_s,
                  elapsed > 0 ? data_s / elapsed : 0.0, eta);
    std::fprintf(stderr, tty_ ? "\r%s" : "%s\n", line);
    if (tty_ && fraction >= 1.0) std::fprintf(stderr, "\n");
    std::fflush(stderr);
  }

 private:
  bool tty_;
  std::chrono::steady_clock::time_point start_;
  int last_decile_ = -1;
  bool done_ = false;
};

// ./config if it is there, else the source tree's config/ beside build/bin/fl-replay.
std::string DefaultConfigDir() {
  namespace fs = std::filesystem;
  if (fs::exists("config/rbpf_slam.yaml")) return "config";
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    const fs::path beside = exe.parent_path().parent_path().parent_path() / "config";
    if (fs::exists(beside / "rbpf_slam.yaml")) return beside.string();
  }
  return "config";
}

}  // namespace

int main(int argc, char** argv) {
  fl::Program program(
      "fl-replay",
      "Runs the RBPF-SLAM, the stereo VO and the fusion over a recorded LCM log in one process, "
      "through the same adapters as the live processes, as fast as the CPU allows. Input "
      "events are delivered in time order; each stage's outputs reach the next stages as over "
      "live LCM, stamped with the data time of the input that caused them. Recorded outputs "
      "of the stages that run (RBPF_*, VO_*, FUSED_*, their STATUS_*) are replaced. The output "
      "log holds the inputs and every output; the same log and configuration give a "
      "byte-identical output.");
  fl::CommandLine& cli = program.cli();
  fl::replay::ReplayOptions options;
  std::string stages = "rbpf,vo,fusion";
  bool quiet = false;
  int threads = 1;
  options.config_dir = DefaultConfigDir();
  cli.AddPositional("LOG", &options.in_path,
                    "LCM log to replay (fl-sim --log, lcm-logger, "
                    "fl-carmen2lcm, fl-kitti2lcm, a demo's run.lcmlog)");
  cli.AddFlag("out", &options.out_path, "output LCM log: the inputs and every output");
  cli.AddFlag(
      "config-dir", &options.config_dir,
      "folder with rbpf_slam.yaml, stereo_vo.yaml and fusion.yaml ('' = built-in defaults)");
  cli.AddFlag("map-out", &options.map_out,
              "prefix of the fusion's 3D map: PREFIX.pcd and PREFIX_top.png ('' = not saved)");
  cli.AddFlag("stages", &stages, "comma-separated stages to run, in order: rbpf, vo, fusion");
  cli.AddFlag("reorder-window-s", &options.reorder_window_s,
              "[s] of log time within which input events are put in time-stamp order");
  cli.AddFlag("threads", &threads, "OpenCV worker threads of the VO");
  cli.AddFlag("quiet", &quiet, "no progress bar");
  cli.AddEpilog(
      "\nExamples:\n"
      "  fl-sim --log paper.lcmlog && fl-replay paper.lcmlog --out paper_out.lcmlog\n"
      "  fl-replay out/demo/paper-*/run.lcmlog --out again.lcmlog --stages fusion\n"
      "  ./fusionloc replay paper.lcmlog      # the same, then the report of ./fusionloc demo\n"
      "Exit status: 0 done; 1 the log is unreadable, not an LCM log, or has no stage's inputs;\n"
      "2 usage or configuration error.\n");
  cli.AddCheck([&]() -> std::string {
    options.stages = SplitComma(stages);
    if (!(options.reorder_window_s >= 0)) return "--reorder-window-s must be >= 0";
    if (threads < 1) return "--threads must be >= 1";
    return "";
  });
  if (!program.Parse(argc, argv)) return program.exit_code();
  cv::setNumThreads(threads);
  return program.Run([&] {
    fl::InstallShutdownHandlers();
    ProgressBar bar;
    const fl::replay::ReplayReport r = fl::replay::RunReplay(options, [&](double f, double data_s) {
      if (!quiet) bar.Update(f, data_s);
    });
    std::ostringstream s;
    s << "replayed " << fl::FormatDouble(std::round(r.data_s * 10) / 10) << " s of data in "
      << fl::FormatDouble(std::round(r.wall_s * 10) / 10) << " s ("
      << fl::FormatDouble(std::round(r.data_s / std::max(r.wall_s, 1e-9) * 10) / 10)
      << "x real time); input: " << fl::DescribeLogChannels(r.input_channels);
    FL_LOG(INFO) << s.str();
    if (!r.replaced.empty()) {
      FL_LOG(INFO) << "recorded outputs replaced by this replay's: "
                   << fl::DescribeLogChannels(r.replaced);
    }
    for (const auto& st : r.stages) {
      if (!st.missing.empty()) {
        std::string m;
        for (const auto& c : st.missing) m += (m.empty() ? "" : ", ") + c;
        FL_LOG(WARN) << st.program << ": no " << m << " in the log; this stage produced nothing";
      } else {
        FL_LOG(INFO) << st.program << ": " << st.summary;
      }
    }
    if (!options.out_path.empty()) {
      FL_LOG(INFO) << "wrote " << options.out_path << " (" << r.events_out << " events)";
    }
    bool failed = false;
    for (const auto& st : r.stages) {
      if (st.failure.empty()) continue;
      FL_LOG(ERROR) << st.program << ": " << st.failure;
      failed = true;
    }
    if (failed) return fl::kExitFailure;
    if (fl::ShutdownRequested()) {
      FL_LOG(WARN) << "interrupted: the output holds what was replayed until then";
      return fl::kExitFailure;
    }
    return fl::kExitOk;
  });
}
