#include "fusionloc/common/command_line.hpp"

#include <yaml-cpp/yaml.h>

#include <cerrno>
#include <cstdlib>
#include <iostream>
#include <sstream>
#include <stdexcept>

#include "fusionloc/common/log.hpp"
#include "fusionloc/common/number_format.hpp"

namespace fl {
namespace {

template <class T>
std::string ToText(const T& v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

// A string as a YAML scalar (quoted when YAML would read it as something else).
std::string YamlScalar(const std::string& s) {
  YAML::Emitter e;
  e << s;
  return e.c_str();
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
    : program_(std::move(program)), description_(std::move(description)) {
  Flag print;
  print.name = "print-config";
  print.help = "print the effective configuration as YAML and exit";
  print.is_switch = true;
  print.set = [this](const std::string& s) {
    print_config_ = s.empty() || s == "true" || s == "1" || s == "yes";
    return print_config_ || s == "false" || s == "0" || s == "no";
  };
  Add(std::move(print));
  Flag level;
  level.name = "log-level";
  level.help = "messages on stderr from this level up: debug, info, warn or error";
  level.default_text = log_level_;
  level.set = [this](const std::string& s) {
    LogLevel l;
    if (!ParseLogLevel(s, &l)) return false;
    log_level_ = s;
    SetLogLevel(l);
    return true;
  };
  level.get = [this] { return log_level_; };
  Add(std::move(level));
}

void CommandLine::Add(Flag flag) {
  for (const auto& f : flags_) {
    if (f.name == flag.name) {
      throw std::logic_error(program_ + ": option --" + flag.name + " is declared twice");
    }
  }
  flags_.push_back(std::move(flag));
}

void CommandLine::AddFlag(const std::string& name, std::string* value, const std::string& help) {
  Add({name, help, *value, false, false,
       [value](const std::string& s) {
         *value = s;
         return true;
       },
       [value] { return YamlScalar(*value); }});
}
void CommandLine::AddFlag(const std::string& name, double* value, const std::string& help) {
  Add({name, help, FormatDouble(*value), false, false,
       [value](const std::string& s) { return ParseDouble(s, value); },
       [value] { return FormatDouble(*value); }});
}
void CommandLine::AddFlag(const std::string& name, int* value, const std::string& help) {
  Add({name, help, ToText(*value), false, false,
       [value](const std::string& s) {
         int64_t v;
         if (!ParseInt64(s, &v) || v < INT32_MIN || v > INT32_MAX) return false;
         *value = static_cast<int>(v);
         return true;
       },
       [value] { return ToText(*value); }});
}
void CommandLine::AddFlag(const std::string& name, int64_t* value, const std::string& help) {
  Add({name, help, ToText(*value), false, false,
       [value](const std::string& s) { return ParseInt64(s, value); },
       [value] { return ToText(*value); }});
}
void CommandLine::AddFlag(const std::string& name, uint64_t* value, const std::string& help) {
  Add({name, help, ToText(*value), false, false,
       [value](const std::string& s) {
         int64_t v;
         if (!ParseInt64(s, &v) || v < 0) return false;
         *value = static_cast<uint64_t>(v);
         return true;
       },
       [value] { return ToText(*value); }});
}
void CommandLine::AddFlag(const std::string& name, bool* value, const std::string& help) {
  Add({name, help, *value ? "true" : "false", true, false,
       [value](const std::string& s) {
         if (s.empty() || s == "true" || s == "1" || s == "yes") {
           *value = true;
         } else if (s == "false" || s == "0" || s == "no") {
           *value = false;
         } else {
           return false;
         }
         return true;
       },
       [value] { return std::string(*value ? "true" : "false"); }});
}
void CommandLine::AddRepeatedFlag(const std::string& name, std::vector<std::string>* values,
                                  const std::string& help) {
  Add({name, help + " (may be repeated)", "", false, true,
       [values](const std::string& s) {
         values->push_back(s);
         return true;
       },
       [values] {
         std::string out = "[";
         for (size_t i = 0; i < values->size(); ++i) {
           out += (i ? ", " : "") + YamlScalar((*values)[i]);
         }
         return out + "]";
       }});
}

void CommandLine::AddPositional(const std::string& name, std::string* value,
                                const std::string& help, bool required) {
  positionals_.push_back({name, help, required, value});
}

std::string CommandLine::FlagsAsYaml() const {
  std::ostringstream s;
  s << "# " << program_ << ": effective flags (this program has no options file)\n";
  for (const auto& p : positionals_) s << p.name << ": " << YamlScalar(*p.value) << "\n";
  for (const auto& f : flags_) {
    if (f.get) s << f.name << ": " << f.get() << "\n";
  }
  return s.str();
}

bool CommandLine::Fail(const std::string& message) {
  std::cerr << program_ << ": " << message << "\n";
  exit_code_ = 2;
  return false;
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
  exit_code_ = 0;
  print_config_ = false;
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
      if (!flag) return Fail("unknown option '--" + name + "'; see " + program_ + " --help");
      if (!has_value && !flag->is_switch) {
        if (i + 1 >= argc) return Fail("option '--" + name + "' needs a value");
        value = argv[++i];
      }
      if (!flag->set(value)) {
        return Fail("bad value '" + value + "' for option '--" + name + "' (" + flag->help + ")");
      }
      continue;
    }
    if (next_positional >= positionals_.size()) {
      return Fail("unexpected argument '" + arg + "'; see " + program_ + " --help");
    }
    *positionals_[next_positional++].value = arg;
  }
  // --print-config needs no positional: it shows what the program would run with.
  if (!print_config_) {
    for (size_t p = next_positional; p < positionals_.size(); ++p) {
      if (positionals_[p].required) {
        return Fail("missing argument " + positionals_[p].name + " (" + positionals_[p].help +
                    "); see " + program_ + " --help");
      }
    }
  }
  for (const auto& check : checks_) {
    const std::string error = check();
    if (!error.empty()) return Fail(error);
  }
  if (print_config_) {
    std::cout << (printer_ ? printer_() : FlagsAsYaml());
    exit_code_ = 0;
    return false;
  }
  return true;
}

}  // namespace fl
