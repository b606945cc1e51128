#include "fusionloc/common/channel_map.hpp"

#include <algorithm>

namespace fl {

std::string ChannelMap::Add(const std::string& spec, const std::vector<std::string>& known) {
  const size_t eq = spec.find('=');
  if (eq == std::string::npos || eq == 0 || eq + 1 == spec.size()) {
    return "--channel '" + spec + "' is not NAME=OTHER (e.g. --channel LASER=FRONT_LASER)";
  }
  const std::string name = spec.substr(0, eq), other = spec.substr(eq + 1);
  if (!known.empty() && std::find(known.begin(), known.end(), name) == known.end()) {
    std::string list;
    for (const auto& k : known) list += (list.empty() ? "" : ", ") + k;
    return "--channel " + spec + ": this process uses no channel '" + name +
           "'; its channels: " + list;
  }
  if (renames_.count(name)) return "--channel renames '" + name + "' twice";
  renames_[name] = other;
  return "";
}

std::string ChannelMap::operator()(const std::string& name) const {
  const auto it = renames_.find(name);
  return it == renames_.end() ? name : it->second;
}

}  // namespace fl
