#include "fusionloc/common/yaml_options.hpp"

#include <algorithm>
#include <fstream>

namespace fl {
namespace internal {

std::string ClosestKey(const std::string& key, const std::vector<std::string>& known) {
  std::string best;
  size_t best_d = 3;  // suggest only keys within two edits
  for (const auto& k : known) {
    std::vector<size_t> prev(k.size() + 1), cur(k.size() + 1);
    for (size_t j = 0; j <= k.size(); ++j) prev[j] = j;
    for (size_t i = 1; i <= key.size(); ++i) {
      cur[0] = i;
      for (size_t j = 1; j <= k.size(); ++j) {
        cur[j] =
            std::min({prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (key[i - 1] == k[j - 1] ? 0 : 1)});
      }
      std::swap(prev, cur);
    }
    if (prev[k.size()] < best_d) {
      best_d = prev[k.size()];
      best = k;
    }
  }
  return best;
}

}  // namespace internal

std::string YamlReadArchive::Where(const YAML::Node& n) const {
  const YAML::Mark m = n.Mark();
  if (m.line < 0) return file_ + ": ";
  return file_ + ":" + std::to_string(m.line + 1) + ":" + std::to_string(m.column + 1) + ": ";
}

void YamlReadArchive::TypeError(const YAML::Node& n, const std::string& key,
                                const char* expected) const {
  std::string got;
  if (n.IsScalar()) {
    got = "'" + n.Scalar() + "'";
  } else if (n.IsSequence()) {
    got = "a list";
  } else if (n.IsMap()) {
    got = "a map";
  } else {
    got = "nothing";
  }
  throw ConfigError(Where(n) + "key '" + key + "' expects " + expected + ", got " + got);
}

void YamlReadArchive::CheckNoUnknownKeys() const {
  for (const auto& kv : node_) {
    if (!kv.first.IsScalar()) {
      throw ConfigError(Where(kv.first) + "a key " +
                        (prefix_.empty() ? std::string() : "of '" + prefix_ + "' ") +
                        "is a list or a map; option keys are plain names");
    }
    const std::string key = kv.first.as<std::string>();
    if (std::find(known_.begin(), known_.end(), key) != known_.end()) continue;
    std::string msg = Where(kv.first) + "unknown key '" + Qualified(key) + "'";
    const std::string hint = internal::ClosestKey(key, known_);
    if (!hint.empty()) msg += "; did you mean '" + hint + "'?";
    msg += " Known keys" + (prefix_.empty() ? std::string() : " of '" + prefix_ + "'") + ":";
    for (const auto& k : known_) msg += " " + k;
    throw ConfigError(msg);
  }
}

YAML::Node ParseYamlString(const std::string& text, const std::string& name) {
  try {
    return YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw ConfigError(name + ":" + std::to_string(e.mark.line + 1) + ":" +
                      std::to_string(e.mark.column + 1) + ": YAML syntax error: " + e.msg);
  }
}

YAML::Node ParseYamlFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) {
    throw ConfigError("config file '" + path +
                      "' not found or unreadable; pass an existing file (see config/)");
  }
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  return ParseYamlString(text, path);
}

}  // namespace fl
