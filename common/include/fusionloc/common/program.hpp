// The edge every fl-* program stands on: command line, options file, log level and one
// exit-code policy. LCM processes add fusionloc/common/lcm_process.hpp on top.
//
//   int main(int argc, char** argv) {
//     fl::Program program("fl-foo", "What it does.");
//     FooOptions options;                       // Serialize() + optional Validate()
//     program.AddOptions(&options, "config/foo.yaml");
//     std::string in;
//     program.cli().AddPositional("IN", &in, "input file");
//     if (!program.Parse(argc, argv)) return program.exit_code();
//     return program.Run([&] { return RunFoo(options, in); });
//   }
//
// Exit codes, the same for every program (README "Exit codes"):
//   0  success; also --help and --print-config
//   1  bad data or a runtime failure: an input that is missing, unreadable or not what it
//      should be, LCM that cannot be opened, a failed write
//   2  bad usage or bad configuration: an unknown option or bad value, an options file that is
//      missing, malformed, has an unknown key or an invalid value
#pragma once

#include <functional>
#include <stdexcept>
#include <string>

#include "fusionloc/common/command_line.hpp"
#include "fusionloc/common/yaml_options.hpp"

namespace fl {

constexpr int kExitOk = 0;
constexpr int kExitFailure = 1;
constexpr int kExitUsage = 2;

// Thrown for a wrong command line or a wrong combination of options: exit code 2.
// (fl::ConfigError, for options files, is exit code 2 too; anything else is 1.)
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class Program {
 public:
  // Sets the name printed in log lines.
  Program(std::string name, std::string description);

  CommandLine& cli() { return cli_; }
  const std::string& name() const { return name_; }

  // Adds --config FILE for an Options struct (with Serialize and optionally Validate): the file
  // is loaded over the defaults once the flags are parsed, and --print-config prints the result.
  // `example` names the usual file in --help ("config/rbpf_slam.yaml").
  template <class Options>
  void AddOptions(Options* options, const std::string& example) {
    cli_.AddFlag("config", &config_path_,
                 "options YAML (e.g. " + example + "); empty: the built-in defaults");
    cli_.AddCheck([this, options]() -> std::string {
      try {
        if (!config_path_.empty()) *options = LoadYamlFile<Options>(config_path_);
        if constexpr (internal::HasValidate<Options>::value) {
          const Status s = options->Validate();
          if (!s.ok()) throw ConfigError("invalid options: " + s.message());
        }
      } catch (const ConfigError& e) {
        return e.what();
      }
      return "";
    });
    cli_.SetConfigPrinter([options] { return SaveYamlString(*options); });
  }
  const std::string& config_path() const { return config_path_; }

  // Parses the command line (and loads the options). False: help, the configuration or a
  // usage error was printed; exit with exit_code().
  bool Parse(int argc, char** argv);
  int exit_code() const { return parse_failure_ >= 0 ? parse_failure_ : cli_.exit_code(); }

  // Runs `body` and turns what it throws into "name: message" on stderr and an exit code:
  // UsageError and ConfigError 2, any other exception 1.
  int Run(const std::function<int()>& body) const;

 private:
  std::string name_;
  CommandLine cli_;
  std::string config_path_;
  int parse_failure_ = -1;
};

}  // namespace fl
