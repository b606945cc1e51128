// The deputy's command-line flags, shared by fl-procman-deputy and the in-process deputy of
// fl-procman-sheriff --lone-ranger: --name, --log-dir, --var NAME=VALUE, --key, --insecure.
//
// Order policy: with a key (--key FILE, else the default key file, DefaultKeyPath() in
// order_auth.hpp) the deputy acts on signed orders (PMD_ORDERS2_SIGNED) only; --insecure
// also accepts plain libbot2 PMD_ORDERS2 (alone: plain orders only). Neither, and no key
// file: a usage error naming both ways.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "fusionloc/common/lcm_process.hpp"
#include "fusionloc/procman/procman_lcm.hpp"

namespace fl::procman {

std::vector<ChannelSpec> DeputyInputs();
std::vector<ChannelSpec> DeputyOutputs();

class DeputyCli {
 public:
  // Adds the flags to `program`; they fill `options` once parsed.
  DeputyCli(Program* program, DeputyOptions* options);
  // The node for `deputy`, with the order policy the flags chose.
  std::unique_ptr<DeputyNode> MakeNode(Deputy* deputy, LcmInterface* lcm,
                                       const ChannelMap& channels) const;
  const std::string& key_path() const { return key_path_; }
  bool insecure() const { return insecure_; }
  // "signed orders only (key ...)" or "INSECURE: ...", for the log (after MakeNode).
  std::string SecurityLine() const { return security_; }

 private:
  DeputyOptions* options_;
  std::vector<std::string> vars_;
  std::string key_path_;
  bool insecure_ = false;
  mutable std::string security_;
};

}  // namespace fl::procman
