#include "fusionloc/procman/deputy_cli.hpp"

#include "fusionloc/common/channels.hpp"

namespace fl::procman {

std::vector<ChannelSpec> DeputyInputs() {
  return {{channels::kPmdOrders, "bot_procman.orders2_t", "the sheriff's orders (libbot2)"},
          {channels::kPmdDiscover, "bot_procman.discovery_t", "a sheriff or deputy starting"}};
}

std::vector<ChannelSpec> DeputyOutputs() {
  return {{channels::kPmdInfo, "bot_procman.info2_t", "status of the host and each command, 1 Hz"},
          {channels::kPmdPrintf, "bot_procman.printf_t", "output of the commands"},
          {channels::kPmdDiscover, "bot_procman.discovery_t", "once at start"}};
}

DeputyCli::DeputyCli(Program* program, DeputyOptions* options) : options_(options) {
  CommandLine& cli = program->cli();
  cli.AddFlag("name", &options->name,
              "this deputy's name, the host of its commands in the .cfg "
              "(default: the hostname)");
  cli.AddFlag("log-dir", &options->log_dir, "folder for <command>.log (created)");
  cli.AddRepeatedFlag("var", &vars_,
                      "NAME=VALUE for ${NAME} in the commands' exec (repeatable; names not "
                      "given are looked up in the environment)");
  cli.AddFlag("insecure", &insecure_,
              "act on unsigned PMD_ORDERS2 (libbot2's orders): anyone on the network can then "
              "make this deputy run anything; the status says so");
  cli.AddCheck([this]() -> std::string {
    for (const std::string& v : vars_) {
      const size_t eq = v.find('=');
      if (eq == std::string::npos || eq == 0) {
        return "--var '" + v + "' is not NAME=VALUE";
      }
      options_->vars[v.substr(0, eq)] = v.substr(eq + 1);
    }
    const Status s = options_->Validate();
    return s.ok() ? "" : "invalid deputy options: " + s.message();
  });
}

std::unique_ptr<DeputyNode> DeputyCli::MakeNode(Deputy* deputy, LcmInterface* lcm,
                                                const ChannelMap& channels) const {
  if (!insecure_) {
    throw UsageError(
        "orders are not signed in this build: start the deputy with --insecure to act on "
        "plain libbot2 PMD_ORDERS2 (see docs/PROCMAN.md)");
  }
  DeputyNodeOptions o;
  o.accept_unsigned = insecure_;
  return std::make_unique<DeputyNode>(deputy, lcm, channels, o);
}

std::string DeputyCli::SecurityLine() const {
  return insecure_ ? "INSECURE: acts on unsigned PMD_ORDERS2 from anyone on the network"
                   : "signed orders only";
}

}  // namespace fl::procman
