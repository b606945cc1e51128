#include "fusionloc/common/program.hpp"

#include <iostream>

#include "fusionloc/common/log.hpp"

namespace fl {

Program::Program(std::string name, std::string description)
    : name_(std::move(name)), cli_(name_, std::move(description)) {
  SetLogProcessName(name_);
}

bool Program::Parse(int argc, char** argv) {
  try {
    return cli_.Parse(argc, argv);
  } catch (const std::exception& e) {
    // A check or the config printer failed in a way it did not report itself.
    std::cerr << name_ << ": " << e.what() << "\n";
    parse_failure_ = kExitUsage;
    return false;
  }
}

int Program::Run(const std::function<int()>& body) const {
  try {
    return body();
  } catch (const UsageError& e) {
    std::cerr << name_ << ": " << e.what() << " (see " << name_ << " --help)\n";
    return kExitUsage;
  } catch (const ConfigError& e) {
    std::cerr << name_ << ": " << e.what() << "\n";
    return kExitUsage;
  } catch (const std::exception& e) {
    std::cerr << name_ << ": " << e.what() << "\n";
    return kExitFailure;
  }
}

}  // namespace fl
