// Small command-line parser shared by every fl-* program, so that all of them answer --help
// the same way and reject unknown or malformed flags with a clear message.
//
//   fl::CommandLine cli("fl-sim", "Simulated robot: publishes laser, stereo, odometry.");
//   std::string url = fl::kDefaultLcmUrl;
//   cli.AddFlag("lcm-url", &url, "LCM URL to publish on");
//   cli.AddPositional("LOG", &log, "input log");       // required positional
//   if (!cli.Parse(argc, argv)) return cli.exit_code(); // printed help (0) or an error (2)
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
  void AddPositional(const std::string& name, std::string* value, const std::string& help,
                     bool required = true);
  // Free-form text appended to --help (examples, channel lists).
  void AddEpilog(const std::string& text) { epilog_ += text; }

  // Returns true if the program should run. Otherwise help or an error has been printed and
  // exit_code() is 0 (help) or 2 (usage error).
  bool Parse(int argc, char** argv);
  int exit_code() const { return exit_code_; }
  std::string Help() const;

 private:
  struct Flag {
    std::string name;
    std::string help;
    std::string default_text;
    bool is_switch = false;
    std::function<bool(const std::string&)> set;
  };
  struct Positional {
    std::string name;
    std::string help;
    bool required;
    std::string* value;
  };
  void Add(const std::string& name, const std::string& help, std::string default_text,
           bool is_switch, std::function<bool(const std::string&)> set);

  std::string program_;
  std::string description_;
  std::string epilog_;
  std::vector<Flag> flags_;
  std::vector<Positional> positionals_;
  int exit_code_ = 0;
};

}  // namespace fl
