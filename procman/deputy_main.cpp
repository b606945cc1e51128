// fl-procman-deputy: runs the commands a sheriff orders on this host (fl::procman::Deputy on
// LCM through DeputyNode, procman/lcm/).
#include <unistd.h>

#include <iostream>
#include <memory>

#include "fusionloc/common/lcm_process.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/procman/deputy_cli.hpp"
#include "fusionloc/procman/procman_lcm.hpp"

int main(int argc, char** argv) {
  fl::Program program(
      "fl-procman-deputy",
      "The process manager's deputy (libbot2 bot-procman compatible): one per host; starts, "
      "stops and restarts the commands a sheriff orders, each in its own process group, "
      "forwards their output (PMD_PRINTF, and LOG_DIR/<command>.log), respawns them with a "
      "back-off when auto_respawn is set, and publishes its status at 1 Hz (PMD_INFO2: pid, "
      "state, run id, exit code, CPU, memory per command; host load and memory). No command "
      "outlives it, even if it is killed with SIGKILL.");
  fl::procman::DeputyOptions options;
  fl::procman::DeputyCli cli(&program, &options);
  fl::LcmProcess process(&program, fl::procman::DeputyInputs(), fl::procman::DeputyOutputs());
  program.cli().AddEpilog(
      "\nExamples:\n"
      "  fl-procman-deputy --insecure --lcm-url 'udpm://239.255.76.67:7667?ttl=1'\n");
  if (!program.Parse(argc, argv)) return program.exit_code();
  return program.Run([&] {
    auto lcm = process.Open();
    fl::procman::Deputy deputy(options, nullptr);
    auto node = cli.MakeNode(&deputy, lcm.get(), process.channels());
    // Status and output are published at once (a sheriff then knows this deputy).
    FL_LOG(INFO) << "deputy '" << deputy.name() << "' on " << lcm->url() << ", "
                 << cli.SecurityLine() << "; logs in " << options.log_dir;
    while (!fl::ShutdownRequested()) {
      if (lcm->HandleSubscriptions(10) < 0) break;
      node->Poll();
    }
    FL_LOG(INFO) << "stopping every command";
    deputy.StopAll();
    node->PublishStatus();
    return fl::kExitOk;
  });
}
