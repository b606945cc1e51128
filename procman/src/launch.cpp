#include "fusionloc/procman/launch.hpp"

#include <cctype>
#include <cstdlib>
#include <set>

#include "fusionloc/common/yaml_options.hpp"

namespace fl::procman {

Status ProcessSpec::Validate() const {
  if (name.empty()) return Status::Error("a process has no name; add 'name: ...'");
  for (char c : name) {
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '_' && c != '-') {
      return Status::Error("process name '" + name + "' may only use letters, digits, _ and -");
    }
  }
  if (command.empty()) return Status::Error("process '" + name + "' has no command");
  if (restart != "never" && restart != "on_failure" && restart != "always") {
    return Status::Error("process '" + name + "': restart '" + restart +
                         "' unknown; use never, on_failure or always");
  }
  if (on_exit != "continue" && on_exit != "stop_all") {
    return Status::Error("process '" + name + "': on_exit '" + on_exit +
                         "' unknown; use continue or stop_all");
  }
  if (max_restarts < 0) return Status::Error("process '" + name + "': max_restarts must be >= 0");
  if (!(restart_delay_s >= 0.0) || !(start_delay_s >= 0.0)) {
    return Status::Error("process '" + name + "': restart_delay_s and start_delay_s must be >= 0");
  }
  return Status::Ok();
}

Status LaunchFile::Validate() const {
  if (processes.empty()) return Status::Error("no processes; add a 'processes:' list");
  if (!(stop_timeout_s > 0.0)) return Status::Error("stop_timeout_s must be > 0");
  if (!(end_grace_s >= 0.0)) return Status::Error("end_grace_s must be >= 0");
  std::set<std::string> names;
  for (const ProcessSpec& p : processes) {
    const Status s = p.Validate();
    if (!s.ok()) return s;
    if (!names.insert(p.name).second) {
      return Status::Error("process name '" + p.name + "' is used twice; names must be unique");
    }
  }
  return Status::Ok();
}

LaunchFile LoadLaunchFile(const std::string& path) { return LoadYamlFile<LaunchFile>(path); }

bool ExpandVariables(const std::string& text, const std::map<std::string, std::string>& vars,
                     std::string* out, std::string* error) {
  std::string result;
  size_t i = 0;
  while (i < text.size()) {
    if (text.compare(i, 2, "${") != 0) {
      result += text[i++];
      continue;
    }
    const size_t end = text.find('}', i + 2);
    if (end == std::string::npos) {
      *error = "'${' without a closing '}' in: " + text;
      return false;
    }
    const std::string name = text.substr(i + 2, end - i - 2);
    const auto it = vars.find(name);
    if (it != vars.end()) {
      result += it->second;
    } else if (const char* env = std::getenv(name.c_str()); env != nullptr) {
      result += env;
    } else {
      *error = "variable ${" + name + "} is not set; pass --vars " + name +
               "=VALUE to fl-procman or export it";
      return false;
    }
    i = end + 1;
  }
  *out = result;
  return true;
}

bool SplitCommand(const std::string& command, std::vector<std::string>* argv, std::string* error) {
  argv->clear();
  std::string word;
  bool in_word = false, quoted = false;
  for (char c : command) {
    if (c == '"') {
      quoted = !quoted;
      in_word = true;
    } else if (!quoted && std::isspace(static_cast<unsigned char>(c))) {
      if (in_word) argv->push_back(word);
      word.clear();
      in_word = false;
    } else {
      word += c;
      in_word = true;
    }
  }
  if (quoted) {
    *error = "unclosed double quote in command: " + command;
    return false;
  }
  if (in_word) argv->push_back(word);
  if (argv->empty()) {
    *error = "empty command";
    return false;
  }
  return true;
}

}  // namespace fl::procman
