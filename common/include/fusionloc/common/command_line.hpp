// Small command-line parser shared by every fl-* program, so that all of them answer --help,
// --print-config and --log-level the same way and reject unknown or malformed flags with a
// clear message and exit code 2 (the exit-code policy is in fusionloc/common/program.hpp).
//
//   fl::CommandLine cli("fl-sim", "Simulated robot: publishes laser, stereo, odometry.");
//   std::string url = fl::kDefaultLcmUrl;
//   cli.AddFlag("lcm-url", &url, "LCM URL to publish on");
//   cli.AddPositional("LOG", &log, "input log");       // required positional
//   if (!cli.Parse(argc, argv)) return cli.exit_code(); // printed help (0) or an error (2)
//
// Built in: --help (-h); --log-level debug|info|warn|error (sets fl::SetLogLevel);
// --print-config, which prints the program's options as YAML and exits 0: by default the
// flags' effective values, or what SetConfigPrinter() gives (an Options struct, see
// fl::Program::AddOptions).
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace fl {

class CommandLine {
 public:
  CommandLine(std::string program, std::string description);

  void AddFlag(const std::string& name, std::string* value, const std::string& help);
  void AddFlag(const std::string& name, double* value, const std::string& help);
  void AddFlag(const std::string& name, int* value, const std::string& help);
  void AddFlag(const std::string& name, int64_t* value, const std::string& help);
  void AddFlag(const std::string& name, uint64_t* value, const std::string& help);
  // A switch: present = true ("--name"), or "--name=false".
  void AddFlag(const std::string& name, bool* value, const std::string& help);
  // A flag that may be given several times; each value is appended ("--channel A=B").
  void AddRepeatedFlag(const std::string& name, std::vector<std::string>* values,
                       const std::string& help);
  void AddPositional(const std::string& name, std::string* value, const std::string& help,
                     bool required = true);
  // Free-form text appended to --help (examples, channel lists).
  void AddEpilog(const std::string& text) { epilog_ += text; }
  // What --print-config prints (after every flag has been parsed; flags given before it apply).
  void SetConfigPrinter(std::function<std::string()> printer) { printer_ = std::move(printer); }
  // Runs after a successful parse (and before --print-config prints): checks the flags'
  // values together. Returns "" if fine, else the message of a usage error (exit code 2).
  void AddCheck(std::function<std::string()> check) { checks_.push_back(std::move(check)); }

  // Returns true if the program should run. Otherwise help, the configuration or an error has
  // been printed and exit_code() is 0 (help, --print-config) or 2 (usage error).
  bool Parse(int argc, char** argv);
  int exit_code() const { return exit_code_; }
  std::string Help() const;
  // The flags' current values as a YAML map (what --print-config prints by default).
  std::string FlagsAsYaml() const;
  const std::string& program() const { return program_; }

 private:
  struct Flag {
    std::string name;
    std::string help;
    std::string default_text;
    bool is_switch = false;
    bool repeated = false;
    std::function<bool(const std::string&)> set;
    std::function<std::string()> get;  // current value as YAML text
  };
  struct Positional {
    std::string name;
    std::string help;
    bool required;
    std::string* value;
  };
  void Add(Flag flag);
  bool Fail(const std::string& message);

  std::string program_;
  std::string description_;
  std::string epilog_;
  std::vector<Flag> flags_;
  std::vector<Positional> positionals_;
  std::function<std::string()> printer_;
  std::vector<std::function<std::string()>> checks_;
  bool print_config_ = false;
  std::string log_level_ = "info";
  int exit_code_ = 0;
};

}  // namespace fl
