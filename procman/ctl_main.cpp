// fl-procman-ctl: sends one order to a running fl-procman-sheriff over LCM (PMD_SHERIFF_CTL)
// and prints its answer (PMD_SHERIFF_CTL_REPLY).
#include <unistd.h>

#include <chrono>
#include <iostream>
#include <random>

#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/lcm_process.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/procman/procman_lcm.hpp"
#include "fusionloc/procman/sheriff_lcm.hpp"

int main(int argc, char** argv) {
  fl::Program program("fl-procman-ctl",
                      "Sends one order to the fl-procman-sheriff on the LCM network and prints "
                      "its answer: start|stop|restart NAME|GROUP|everything, run SCRIPT, "
                      "status, quit. Exit status 1 if the sheriff refused the order or none "
                      "answered.");
  std::string verb, target;
  double timeout_s = 3.0;
  program.cli().AddPositional("ORDER", &verb, "start, stop, restart, run, status or quit");
  program.cli().AddPositional("NAME", &target, "command, group, 'everything' or script", false);
  program.cli().AddFlag("timeout", &timeout_s, "[s] wait this long for the sheriff's answer");
  fl::LcmProcess process(&program,
                         {{fl::procman::kCtlReplyChannel, "bot_procman.printf_t", "the answer"}},
                         {{fl::channels::kPmdSheriffCtl, "bot_procman.printf_t", "the order"}});
  program.cli().AddEpilog(
      "\nExamples:\n  fl-procman-ctl restart fusion\n  fl-procman-ctl stop estimators\n"
      "  fl-procman-ctl status\n");
  if (!program.Parse(argc, argv)) return program.exit_code();
  return program.Run([&] {
    auto lcm = process.Open();
    std::random_device rd;
    const std::string id = "ctl-" + std::to_string(getpid()) + "-" + std::to_string(rd());
    bool answered = false;
    std::string answer;
    lcm->Subscribe<bot_procman::printf_t>(
        process.channels()(fl::procman::kCtlReplyChannel),
        [&](const bot_procman::printf_t& msg, const std::string&) {
          if (msg.deputy_name != id) return;
          answered = true;
          answer = msg.text;
        });
    bot_procman::printf_t order;
    order.utime = fl::procman::WallClockUs();
    order.deputy_name = id;
    order.sheriff_id = 0;
    order.text = verb + (target.empty() ? "" : " " + target);
    lcm->Publish(process.channels()(fl::channels::kPmdSheriffCtl), order);
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    while (!answered && !fl::ShutdownRequested() && std::chrono::steady_clock::now() < end) {
      lcm->HandleSubscriptions(50);
    }
    if (!answered) {
      std::cerr << "fl-procman-ctl: no sheriff answered on " << lcm->url() << " within "
                << timeout_s << " s; is fl-procman-sheriff running with the same --lcm-url?\n";
      return fl::kExitFailure;
    }
    std::cout << answer << (answer.empty() || answer.back() == '\n' ? "" : "\n");
    return answer.rfind("error:", 0) == 0 ? fl::kExitFailure : fl::kExitOk;
  });
}
