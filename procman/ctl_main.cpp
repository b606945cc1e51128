// fl-procman-ctl: sends one order to a running fl-procman-sheriff over LCM (PMD_SHERIFF_CTL)
// and prints its answer (PMD_SHERIFF_CTL_REPLY).
#include <unistd.h>

#include <memory>

#include <chrono>
#include <iostream>
#include <random>

#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/lcm_process.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/procman/order_auth.hpp"
#include "fusionloc/procman/procman_lcm.hpp"
#include "fusionloc/procman/sheriff_lcm.hpp"

int main(int argc, char** argv) {
  fl::Program program("fl-procman-ctl",
                      "Sends one order to the fl-procman-sheriff on the LCM network and prints "
                      "its answer: start|stop|restart NAME|GROUP|everything, run SCRIPT, "
                      "status, quit. Exit status 1 if the sheriff refused the order or none "
                      "answered. The order is signed with --key FILE (default: the procman key "
                      "at its default place, if there is one), as a sheriff that signs its "
                      "orders requires; --insecure sends it plain.");
  std::string verb, target;
  double timeout_s = 3.0;
  program.cli().AddPositional("ORDER", &verb, "start, stop, restart, run, status or quit");
  program.cli().AddPositional("NAME", &target, "command, group, 'everything' or script", false);
  program.cli().AddFlag("timeout", &timeout_s, "[s] wait this long for the sheriff's answer");
  std::string key_path;
  bool insecure = false;
  program.cli().AddFlag("key", &key_path,
                        "sign the order with this procman key (default: the default key file, "
                        "docs/PROCMAN_SECURITY.md, if it exists)");
  program.cli().AddFlag("insecure", &insecure, "send the order unsigned");
  fl::LcmProcess process(&program,
                         {{fl::procman::kCtlReplyChannel, "bot_procman.printf_t", "the answer"}},
                         {{fl::channels::kPmdSheriffCtl, "bot_procman.printf_t", "the order (--insecure)"},
                          {fl::channels::kPmdSheriffCtlSigned, "fusionloc.procman_signed_orders_t",
                           "the order, signed"}});
  program.cli().AddEpilog(
      "\nExamples:\n  fl-procman-ctl restart fusion\n  fl-procman-ctl stop estimators\n"
      "  fl-procman-ctl status\n");
  if (!program.Parse(argc, argv)) return program.exit_code();
  return program.Run([&] {
    if (insecure && !key_path.empty()) throw fl::UsageError("--key and --insecure exclude each other");
    std::string path = key_path;
    if (path.empty() && !insecure) {
      path = fl::procman::ExistingDefaultKeyPath();
    }
    std::unique_ptr<fl::procman::Key> key;
    if (!path.empty()) {
      try {
        key = std::make_unique<fl::procman::Key>(fl::procman::LoadKey(path));
      } catch (const fl::procman::KeyError& e) {
        throw fl::UsageError(e.what());
      }
    }
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
    if (key) {
      std::vector<uint8_t> bytes(static_cast<size_t>(order.getEncodedSize()));
      order.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
      fl::procman::OrderSigner signer(*key, id);
      lcm->Publish(process.channels()(fl::channels::kPmdSheriffCtlSigned),
                   signer.Sign(bytes, fl::procman::WallClockUs()));
    } else {
      lcm->Publish(process.channels()(fl::channels::kPmdSheriffCtl), order);
    }
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
    const bool refused = answer.rfind("error:", 0) == 0 || answer.rfind("refused:", 0) == 0;
    return refused ? fl::kExitFailure : fl::kExitOk;
  });
}
