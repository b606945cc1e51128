#include "fusionloc/common/command_line.hpp"

#include <cerrno>
#include <cstdlib>
#include <iostream>
#include <sstream>

namespace fl {
namespace {

template <class T>
std::string ToText(const T& v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

bool ParseDouble(const std::string& s, double* out) {
  if (s.empty()) return false;
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(s.c_str(), &end);
  if (errno != 0 || *end != '\0') return false;
  *out = v;
  return true;
}

bool ParseInt64(const std::string& s, int64_t* out) {
  if (s.empty()) return false;
  char* end = nullptr;
  errno = 0;
  const long long v = std::strtoll(s.c_str(), &end, 0);
  if (errno != 0 || *end != '\0') return false;
  *out = v;
  return true;
}

}  // namespace

CommandLine::CommandLine(std::string program, std::string description)
    : program_(std::move(program)), description_(std::move(description)) {}

void CommandLine::Add(const std::string& name, const std::string& help, std::string default_text,
                      bool is_switch, std::function<bool(const std::string&)> set) {
  flags_.push_back({name, help, std::move(default_text), is_switch, std::move(set)});
}

void CommandLine::AddFlag(const std::string& name, std::string* value, const std::string& help) {
  Add(name, help, *value, false, [value](const std::string& s) {
    *value = s;
    return true;
  });
}
void CommandLine::AddFlag(const std::string& name, double* value, const std::string& help) {
  Add(name, help, ToText(*value), false,
      [value](const std::string& s) { return ParseDouble(s, value); });
}
void CommandLine::AddFlag(const std::string& name, int* value, const std::string& help) {
  Add(name, help, ToText(*value), false, [value](const std::string& s) {
    int64_t v;
    if (!ParseInt64(s, &v) || v < INT32_MIN || v > INT32_MAX) return false;
    *value = static_cast<int>(v);
    return true;
  });
}
void CommandLine::AddFlag(const std::string& name, int64_t* value, const std::string& help) {
  Add(name, help, ToText(*value), false,
      [value](const std::string& s) { return ParseInt64(s, value); });
}
void CommandLine::AddFlag(const std::string& name, uint64_t* value, const std::string& help) {
  Add(name, help, ToText(*value), false, [value](const std::string& s) {
    int64_t v;
    if (!ParseInt64(s, &v) || v < 0) return false;
    *value = static_cast<uint64_t>(v);
    return true;
  });
}
void CommandLine::AddFlag(const std::string& name, bool* value, const std::string& help) {
  Add(name, help, *value ? "true" : "false", true, [value](const std::string& s) {
    if (s.empty() || s == "true" || s == "1" || s == "yes") {
      *value = true;
    } else if (s == "false" || s == "0" || s == "no") {
      *value = false;
    } else {
      return false;
    }
    return true;
  });
}

void CommandLine::AddPositional(const std::string& name, std::string* value,
                                const std::string& help, bool required) {
  positionals_.push_back({name, help, required, value});
}

std::string CommandLine::Help() const {
  std::ostringstream s;
  s << "Usage: " << program_ << " [options]";
  for (const auto& p : positionals_)
    s << (p.required ? " " : " [") << p.name << (p.required ? "" : "]");
  s << "\n\n" << description_ << "\n";
  if (!positionals_.empty()) {
    s << "\nArguments:\n";
    for (const auto& p : positionals_) s << "  " << p.name << "\n      " << p.help << "\n";
  }
  s << "\nOptions:\n";
  for (const auto& f : flags_) {
    s << "  --" << f.name << (f.is_switch ? "" : "=VALUE") << "\n      " << f.help;
    if (!f.default_text.empty()) s << " (default: " << f.default_text << ")";
    s << "\n";
  }
  s << "  --help\n      print this help and exit\n";
  if (!epilog_.empty()) s << "\n" << epilog_ << "\n";
  return s.str();
}

bool CommandLine::Parse(int argc, char** argv) {
  size_t next_positional = 0;
  for (int i = 1; i < argc; ++i) {
    std::string arg = argv[i];
    if (arg == "--help" || arg == "-h") {
      std::cout << Help();
      exit_code_ = 0;
      return false;
    }
    if (arg.rfind("--", 0) == 0 && arg.size() > 2) {
      std::string name = arg.substr(2), value;
      bool has_value = false;
      const size_t eq = name.find('=');
      if (eq != std::string::npos) {
        value = name.substr(eq + 1);
        name = name.substr(0, eq);
        has_value = true;
      }
      const Flag* flag = nullptr;
      for (const auto& f : flags_) {
        if (f.name == name) flag = &f;
      }
      if (!flag) {
        std::cerr << program_ << ": unknown option '--" << name << "'; see " << program_
                  << " --help\n";
        exit_code_ = 2;
        return false;
      }
      if (!has_value && !flag->is_switch) {
        if (i + 1 >= argc) {
          std::cerr << program_ << ": option '--" << name << "' needs a value\n";
          exit_code_ = 2;
          return false;
        }
        value = argv[++i];
      }
      if (!flag->set(value)) {
        std::cerr << program_ << ": bad value '" << value << "' for option '--" << name << "' ("
                  << flag->help << ")\n";
        exit_code_ = 2;
        return false;
      }
      continue;
    }
    if (next_positional >= positionals_.size()) {
      std::cerr << program_ << ": unexpected argument '" << arg << "'; see " << program_
                << " --help\n";
      exit_code_ = 2;
      return false;
    }
    *positionals_[next_positional++].value = arg;
  }
  for (size_t p = next_positional; p < positionals_.size(); ++p) {
    if (positionals_[p].required) {
      std::cerr << program_ << ": missing argument " << positionals_[p].name << " ("
                << positionals_[p].help << "); see " << program_ << " --help\n";
      exit_code_ = 2;
      return false;
    }
  }
  return true;
}

}  // namespace fl
