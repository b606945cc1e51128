// fl-procman-sheriff: commands the deputies of a libbot2 .cfg (fl::procman::Sheriff on LCM
// through SheriffNode, procman/lcm/), headless; --lone-ranger runs a deputy in-process.
#include <poll.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <iostream>
#include <memory>

#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/lcm_process.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/procman/deputy_cli.hpp"
#include "fusionloc/procman/sheriff_lcm.hpp"

namespace {

double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// Reads complete lines from stdin without blocking; false once stdin has ended.
bool ReadStdinLines(std::string* pending, std::vector<std::string>* lines) {
  pollfd p{0, POLLIN, 0};
  if (poll(&p, 1, 0) <= 0 || (p.revents & (POLLIN | POLLHUP)) == 0) return true;
  char buf[1024];
  const ssize_t n = read(0, buf, sizeof(buf));
  if (n <= 0) return false;
  pending->append(buf, static_cast<size_t>(n));
  size_t nl;
  while ((nl = pending->find('\n')) != std::string::npos) {
    lines->push_back(pending->substr(0, nl));
    pending->erase(0, nl + 1);
  }
  return true;
}

// A command that ended other than by its stop signal, or with a non-zero exit code.
bool EndedBadly(const fl::procman::CommandStatus& r, const fl::procman::CommandConfig& c) {
  if (!r.exited) return !r.error.empty();
  if (WIFEXITED(r.exit_status)) return WEXITSTATUS(r.exit_status) != 0;
  return !(WIFSIGNALED(r.exit_status) && WTERMSIG(r.exit_status) == c.stop_signal);
}

}  // namespace

int main(int argc, char** argv) {
  fl::Program program(
      "fl-procman-sheriff",
      "The process manager's sheriff (libbot2 bot-procman compatible), headless: reads a .cfg, "
      "sends each deputy its desired state (PMD_ORDERS2), prints a live status table, runs "
      "SCRIPT (if given) and takes orders on its terminal and from fl-procman-ctl: "
      "start|stop|restart NAME|GROUP|everything, run SCRIPT, status, quit. The sheriff keeps "
      "no state of its own: quit it and the deputies run on; a new sheriff picks up their "
      "state. Exit status 1 with --quit-after-script when a command failed.");
  fl::CommandLine& cli = program.cli();
  std::string cfg_path, script, report_path, new_key;
  bool lone_ranger = false, observer = false, quit_after_script = false, show_output = false;
  double status_period_s = 10.0;
  fl::procman::SheriffOptions sheriff_options;
  cli.AddPositional("CFG", &cfg_path, "procman config (libbot2 .cfg), e.g. config/procman/sim.cfg",
                    false);
  cli.AddPositional("SCRIPT", &script, "script of the .cfg to run at start", false);
  cli.AddFlag("lone-ranger", &lone_ranger,
              "also run a deputy in this process (its orders come straight from this sheriff, "
              "never from the network): one command for a single-computer robot");
  cli.AddFlag("new-key", &new_key,
              "write a new random key to this file (mode 0600; refuses to overwrite) and exit; "
              "copy it to every deputy's computer");
  cli.AddFlag("observer", &observer, "only watch and print the status; send no orders");
  cli.AddFlag("quit-after-script", &quit_after_script,
              "quit when SCRIPT is done (with --lone-ranger its commands are stopped)");
  cli.AddFlag("status-period", &status_period_s,
              "[s] print the status table this often (0: never)");
  cli.AddFlag("report", &report_path, "write the process table to this file when quitting");
  cli.AddFlag("show-output", &show_output, "print the commands' output (PMD_PRINTF)");
  cli.AddFlag("sheriff-name", &sheriff_options.name, "sheriff_name in the orders");
  cli.AddFlag("adopt-wait", &sheriff_options.adopt_wait_s,
              "[s] wait this long for a deputy's status before ordering it");
  fl::procman::DeputyOptions deputy_options;
  fl::procman::DeputyCli deputy_cli(&program, &deputy_options);
  std::vector<fl::ChannelSpec> inputs = {
      {fl::channels::kPmdInfo, "bot_procman.info2_t", "the deputies' status"},
      {fl::channels::kPmdPrintf, "bot_procman.printf_t", "the commands' output (--show-output)"},
      {fl::channels::kPmdSheriffCtl, "bot_procman.printf_t",
       "orders from fl-procman-ctl (refused when this sheriff signs its orders)"},
      {fl::channels::kPmdSheriffCtlSigned, "fusionloc.procman_signed_orders_t",
       "orders from fl-procman-ctl signed with the key"}};
  std::vector<fl::ChannelSpec> outputs = {
      {fl::channels::kPmdOrders, "bot_procman.orders2_t", "orders to the deputies"},
      {fl::procman::kCtlReplyChannel, "bot_procman.printf_t", "answers to fl-procman-ctl"}};
  fl::LcmProcess process(&program, inputs, outputs);
  cli.AddEpilog(
      "\nOrders are signed (PMD_ORDERS2_SIGNED) with --key FILE, or with the default key file "
      "if it exists; --insecure (or no key file) sends plain libbot2 PMD_ORDERS2, which only "
      "deputies started with --insecure obey. --name, --log-dir and --var are for the "
      "--lone-ranger deputy (its --name defaults to the one host of the .cfg), which takes "
      "its orders from this sheriff directly.\n"
      "\nExamples:\n"
      "  fl-procman-sheriff --lone-ranger config/procman/sim.cfg demo --var BIN=build/bin\n"
      "  fl-procman-sheriff config/procman/robot.cfg bringup   # deputies on sensors, compute\n"
      "  fl-procman-sheriff --observer config/procman/robot.cfg\n");
  cli.AddCheck([&]() -> std::string {
    if (!new_key.empty()) return "";
    if (lone_ranger && observer) return "--lone-ranger and --observer exclude each other";
    if (observer && !script.empty()) return "an --observer runs no SCRIPT";
    if (quit_after_script && script.empty()) return "--quit-after-script needs a SCRIPT";
    if (status_period_s < 0) return "--status-period must be >= 0";
    return "";
  });
  if (!program.Parse(argc, argv)) return program.exit_code();
  sheriff_options.observer = observer;
  return program.Run([&] {
    if (!new_key.empty()) {
      try {
        fl::procman::WriteNewKey(new_key);
        const fl::procman::Key key = fl::procman::LoadKey(new_key);
        std::cout << "new key " << key.id << " in " << new_key
                  << "; copy it (mode 0600) to every deputy's computer\n";
        return fl::kExitOk;
      } catch (const fl::procman::KeyError& e) {
        throw fl::UsageError(e.what());
      }
    }
    if (cfg_path.empty()) throw fl::UsageError("missing CFG (a procman .cfg)");
    fl::procman::ProcmanConfig config = fl::procman::LoadProcmanConfig(cfg_path);
    if (!script.empty() && config.FindScript(script) == nullptr) {
      std::string known;
      for (const auto& s : config.scripts) known += (known.empty() ? "" : ", ") + s.name;
      throw fl::UsageError("no script '" + script + "' in " + cfg_path +
                           (known.empty() ? " (it has none)" : " (it has: " + known + ")"));
    }
    fl::procman::Sheriff sheriff(config, sheriff_options);
    auto lcm = process.Open();
    fl::procman::SheriffNode node(&sheriff, lcm.get(), process.channels(), {show_output},
                                  &std::cout);
    // Signing: --key, else the default key file if there is one, unless --insecure.
    std::unique_ptr<fl::procman::OrderSigner> signer;
    if (!observer && !deputy_cli.insecure()) {
      std::string path = deputy_cli.key_path();
      if (path.empty()) {
        path = fl::procman::ExistingDefaultKeyPath();
      }
      if (!path.empty()) {
        try {
          char host[256] = {0};
          gethostname(host, sizeof(host) - 1);
          fl::procman::Key key = fl::procman::LoadKey(path);
          node.RequireSignedCtl({key});
          signer = std::make_unique<fl::procman::OrderSigner>(std::move(key),
                                                              sheriff_options.name + "@" + host);
        } catch (const fl::procman::KeyError& e) {
          throw fl::UsageError(e.what());
        }
        std::cout << "orders signed with key " << signer->key_id() << " (" << path << ") on "
                  << process.channels()(fl::channels::kPmdOrdersSigned)
                  << "; fl-procman-ctl orders only when signed with it (--key)\n";
        const std::string signed_channel = process.channels()(fl::channels::kPmdOrdersSigned);
        node.set_orders_sink([&, signed_channel](const bot_procman::orders2_t& o) {
          std::vector<uint8_t> bytes(static_cast<size_t>(o.getEncodedSize()));
          o.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
          lcm->Publish(signed_channel, signer->Sign(bytes, fl::procman::WallClockUs()));
        });
      } else if (!lone_ranger) {
        std::cout << "orders NOT signed (no --key and no key file at the default place): only "
                     "deputies started with --insecure obey them\n";
      }
    }
    std::unique_ptr<fl::procman::Deputy> deputy;
    std::unique_ptr<fl::procman::DeputyNode> deputy_node;
    if (lone_ranger) {
      if (deputy_options.name.empty() && sheriff.Hosts().size() == 1) {
        deputy_options.name = *sheriff.Hosts().begin();
      }
      deputy = std::make_unique<fl::procman::Deputy>(deputy_options, nullptr);
      fl::procman::DeputyNodeOptions dn;
      dn.subscribe_orders = false;
      dn.program = "fl-procman-sheriff";
      deputy_node = std::make_unique<fl::procman::DeputyNode>(deputy.get(), lcm.get(),
                                                              process.channels(), dn);
      deputy_node->SetStatusOption("security", "in-process: orders from its own sheriff only");
      // Straight to the in-process deputy; other deputies (if the .cfg names other hosts)
      // get them over LCM, signed or plain as above.
      node.set_orders_sink([&, sink = node.orders_sink()](const bot_procman::orders2_t& o) {
        if (o.host == deputy->name()) {
          deputy_node->HandleOrders(fl::procman::FromLcm(o), "its sheriff");
        } else {
          sink(o);
        }
      });
      // Its status straight to the sheriff as well (not only through LCM).
      sheriff.HandleStatus(deputy->MeasureStatus(fl::procman::WallClockUs()), Now());
      std::cout << "lone ranger: deputy '" << deputy->name() << "' in this process, logs in "
                << deputy_options.log_dir << "\n";
    }
    std::cout << "sheriff on " << lcm->url() << ": " << config.commands.size() << " commands on "
              << sheriff.Hosts().size() << " hosts from " << cfg_path
              << (observer ? " (observer)" : "") << "\n";
    std::string error;
    if (!script.empty()) sheriff.RunScript(script, &error);
    bool stdin_open = true;
    std::string pending;
    double next_table = Now() + status_period_s;
    bool script_seen_running = false;
    while (!fl::ShutdownRequested() && !node.quit_requested()) {
      if (lcm->HandleSubscriptions(10) < 0) break;
      if (deputy_node) {
        deputy_node->Poll();
        sheriff.HandleStatus(
            fl::procman::HostStatus{0, deputy->name(), 0, 0, 0, 0, 0, deputy->Commands(), {}},
            Now());
      }
      node.Poll();
      std::vector<std::string> lines;
      if (stdin_open) stdin_open = ReadStdinLines(&pending, &lines);
      for (const std::string& l : lines) {
        const std::string reply = node.Execute(l);
        if (!reply.empty()) std::cout << reply << (reply.back() == '\n' ? "" : "\n");
      }
      if (status_period_s > 0 && Now() >= next_table) {
        next_table = Now() + status_period_s;
        std::cout << sheriff.StatusTable() << std::flush;
      }
      script_seen_running = script_seen_running || sheriff.ScriptRunning();
      if (quit_after_script && script_seen_running && !sheriff.ScriptRunning()) break;
    }
    if (deputy) {
      std::cout << "stopping the lone ranger's commands\n";
      deputy->StopAll();
      sheriff.HandleStatus(deputy->MeasureStatus(fl::procman::WallClockUs()), Now());
      deputy_node->PublishStatus();
    }
    bool failed = false;
    std::string failures;
    for (size_t i = 0; i < config.commands.size(); ++i) {
      if (EndedBadly(sheriff.Reported(i), config.commands[i])) {
        failed = true;
        failures += " " + config.commands[i].path();
      }
    }
    const std::string table = sheriff.ReportTable();
    std::cout << table;
    if (!report_path.empty()) {
      std::ofstream out(report_path);
      out << table;
      if (!out) throw std::runtime_error("cannot write the report '" + report_path + "'");
    }
    if (quit_after_script && failed) {
      std::cerr << "fl-procman-sheriff: failed:" << failures
                << " (see their logs in the deputies' --log-dir)\n";
      return fl::kExitFailure;
    }
    return fl::kExitOk;
  });
}
