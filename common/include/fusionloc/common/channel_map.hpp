// Channel renaming, the same for every process: `--channel LASER=FRONT_LASER` makes the process
// use FRONT_LASER wherever it would use LASER (inputs and outputs alike).
#pragma once

#include <map>
#include <string>
#include <vector>

namespace fl {

class ChannelMap {
 public:
  // Adds "NAME=OTHER". Returns "" or the error (not NAME=OTHER, NAME not in `known`, renamed
  // twice). `known` lists the channels the process uses; empty accepts any name.
  std::string Add(const std::string& spec, const std::vector<std::string>& known = {});
  // The channel to use for `name` (itself unless renamed).
  std::string operator()(const std::string& name) const;
  const std::map<std::string, std::string>& renames() const { return renames_; }

 private:
  std::map<std::string, std::string> renames_;
};

}  // namespace fl
