// The deputy's command-line flags, shared by fl-procman-deputy and the in-process deputy of
// fl-procman-sheriff --lone-ranger: --name, --log-dir, --var NAME=VALUE, --insecure.
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
  // "signed orders only (key ...)" or "INSECURE: ...", for the log.
  std::string SecurityLine() const;

 private:
  DeputyOptions* options_;
  std::vector<std::string> vars_;
  bool insecure_ = false;
};

}  // namespace fl::procman
