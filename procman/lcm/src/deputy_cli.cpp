#include "fusionloc/procman/deputy_cli.hpp"

#include "fusionloc/common/channels.hpp"
#include "fusionloc/procman/order_auth.hpp"

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
  cli.AddFlag("key", &key_path_,
              "key file of the signed orders (mode 0600; made by fl-procman-sheriff --new-key); "
              "default: $FUSIONLOC_PROCMAN_KEY, /etc/fusionloc/procman.key as root, else "
              "$XDG_CONFIG_HOME/fusionloc/procman.key (~/.config/...)");
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
  std::string path = key_path_;
  if (path.empty() && !insecure_) {
    try {
      path = DefaultKeyPath();
    } catch (const KeyError& e) {
      throw UsageError(std::string(e.what()) + "; give --key FILE, or --insecure");
    }
  }
  std::unique_ptr<OrderVerifier> verifier;
  std::string key_id;
  if (!path.empty()) {
    try {
      Key key = LoadKey(path);
      key_id = key.id;
      verifier = std::make_unique<OrderVerifier>(std::vector<Key>{key}, OrderVerifier::Options());
    } catch (const KeyError& e) {
      throw UsageError(std::string(e.what()) +
                       (key_path_.empty() ? " (the default key file; make one with "
                                            "fl-procman-sheriff --new-key FILE, give --key "
                                            "FILE, or start with --insecure)"
                                          : ""));
    }
  }
  DeputyNodeOptions o;
  o.accept_unsigned = insecure_;
  auto node = std::make_unique<DeputyNode>(deputy, lcm, channels, o);
  if (verifier) node->EnableSignedOrders(std::move(verifier), channels);
  if (insecure_) {
    security_ =
        key_id.empty()
            ? "INSECURE: acts on unsigned PMD_ORDERS2 from anyone on the network"
            : "INSECURE: acts on unsigned PMD_ORDERS2 and on orders signed with key " + key_id;
  } else {
    security_ = "signed orders only (key " + key_id + " from " + path + ")";
  }
  node->SetStatusOption("security", security_);
  return node;
}

}  // namespace fl::procman
