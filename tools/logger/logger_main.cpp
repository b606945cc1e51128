// fl-logger: records LCM traffic into an LCM log, as lcm-logger does, but never leaves a log
// that looks complete when it is not (logger.hpp).
#include <cmath>
#include <cstdio>

#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/program.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "logger.hpp"

int main(int argc, char** argv) {
  fl::Program program(
      "fl-logger",
      "Records LCM messages into an LCM log (lcm-logger's format; read by lcm-logplayer, "
      "fl-log-info, fl-replay and every process's --lcm-url=log:). While it records, the "
      "events go to OUTPUT.partial, handed to the kernel every --flush-interval-ms; on "
      "SIGINT or SIGTERM it is closed and renamed to OUTPUT. A write error (disk full, I/O "
      "error) stops it with exit code 1 and a message naming the file, the reason and what was "
      "recorded: OUTPUT.partial keeps the events written until then and is not renamed; a "
      "killed logger leaves OUTPUT.partial only. So an OUTPUT that exists is a whole "
      "recording.");
  fl::CommandLine& cli = program.cli();
  fl::logger::LoggerOptions options;
  std::string url = fl::kDefaultLcmUrl;
  cli.AddPositional("OUTPUT", &options.output, "the LCM log to write (e.g. run.lcmlog)");
  cli.AddFlag("lcm-url", &url,
              "LCM URL to record from (udpm://... live; log:IN.lcmlog copies a log, then "
              "exits)");
  cli.AddFlag("channel", &options.channel_regex,
              "channels to record: LCM's regular expression, anchored ('LASER|ODOMETRY', "
              "'STATUS_.*')");
  cli.AddFlag("force", &options.force,
              "overwrite an existing OUTPUT (removed at the start) or OUTPUT.partial");
  cli.AddFlag("flush-interval-ms", &options.flush_interval_ms,
              "[ms] hand what was recorded to the kernel this often (a kill -9 keeps it); 0: "
              "after every message");
  cli.AddFlag("progress-interval-s", &options.progress_interval_s,
              "[s] a progress line (events, MB, rates) on stderr this often; 0: none");
  cli.AddEpilog(
      "\nExamples:\n"
      "  fl-logger run.lcmlog                                 # everything, until Ctrl-C\n"
      "  fl-logger --channel 'LASER|ODOMETRY' --force laser.lcmlog\n"
      "  fl-logger --lcm-url=log:run.lcmlog --channel 'FUSED_.*' fused.lcmlog   # a copy\n"
      "Exit status: 0 recorded and renamed to OUTPUT; 1 OUTPUT exists (without --force), "
      "cannot be written, a write error, or LCM that cannot be opened; 2 usage error.\n");
  cli.AddCheck([&] { return options.Check(); });
  if (!program.Parse(argc, argv)) return program.exit_code();
  return program.Run([&] {
    fl::InstallShutdownHandlers();
    auto lcm = fl::MakeLcm(url);
    fl::logger::Logger logger(lcm.get(), options);
    FL_LOG(INFO) << "recording '" << options.channel_regex << "' from " << url << " into "
                 << logger.partial_path() << " (renamed to " << options.output << " when stopped)";
    const fl::logger::LoggerReport r = logger.Run([] { return fl::ShutdownRequested(); });
    char size[64];
    std::snprintf(size, sizeof(size), "%.1f", static_cast<double>(r.bytes) / 1e6);
    FL_LOG(INFO) << "recorded " << r.events << " events (" << size << " MB) in "
                 << std::lround(r.wall_s) << " s into " << options.output
                 << (r.input_ended ? " (end of the input log)" : "");
    return fl::kExitOk;
  });
}
