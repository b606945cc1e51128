// fl-procman: runs a launch file (config/launch/*.yaml) and supervises its processes.
#include <fstream>
#include <iostream>

#include "fusionloc/common/program.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/common/yaml_options.hpp"
#include "fusionloc/procman/launch.hpp"
#include "fusionloc/procman/supervisor.hpp"

namespace {

// "A=1,B=x" -> {A: 1, B: x}
bool ParseVars(const std::string& text, std::map<std::string, std::string>* vars,
               std::string* error) {
  size_t start = 0;
  while (start < text.size()) {
    size_t end = text.find(',', start);
    if (end == std::string::npos) end = text.size();
    const std::string item = text.substr(start, end - start);
    const size_t eq = item.find('=');
    if (eq == std::string::npos || eq == 0) {
      *error = "--vars item '" + item + "' is not NAME=VALUE";
      return false;
    }
    (*vars)[item.substr(0, eq)] = item.substr(eq + 1);
    start = end + 1;
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  fl::Program program(
      "fl-procman",
      "Starts the processes of a launch file, restarts them by their policy (never, "
      "on_failure, always; max_restarts), writes each one's output to LOG_DIR/<name>.log and "
      "stops them all cleanly (SIGTERM, then SIGKILL) when the run ends: a process marked "
      "on_exit: stop_all exits, a required process fails for good, or Ctrl-C. Exit status: 0 "
      "the run ended cleanly, 1 it failed, 2 bad usage or launch file.");
  fl::CommandLine& cli = program.cli();
  std::string launch_path, log_dir = "out/procman", vars_text, report_path;
  double status_period_s = 10.0;
  cli.AddPositional("LAUNCH", &launch_path, "launch file (YAML), e.g. config/launch/sim_demo.yaml");
  cli.AddFlag("log-dir", &log_dir, "folder for <process>.log files (created)");
  cli.AddFlag("vars", &vars_text,
              "values for ${NAME} in the commands: NAME=VALUE[,NAME=VALUE...] (the environment "
              "is used for names not given here)");
  cli.AddFlag("status-period", &status_period_s, "[s] print a status line this often (0: never)");
  cli.AddFlag("report", &report_path, "also write the final process table to this file");
  cli.AddEpilog(
      "\nExample:\n  fl-procman config/launch/sim_demo.yaml --log-dir out/demo/run1 \\\n"
      "      --vars BIN=build/bin,LCM_URL=udpm://239.255.76.67:7667?ttl=0\n");
  if (!program.Parse(argc, argv)) return program.exit_code();
  std::map<std::string, std::string> vars;
  std::string error;
  if (!ParseVars(vars_text, &vars, &error)) {
    std::cerr << "fl-procman: " << error << "\n";
    return 2;
  }
  fl::procman::LaunchFile launch;
  try {
    launch = fl::procman::LoadLaunchFile(launch_path);
  } catch (const std::exception& e) {
    std::cerr << "fl-procman: " << e.what() << "\n";
    return 2;
  }
  vars.emplace("RUN_DIR", log_dir);
  fl::procman::SupervisorOptions options;
  options.log_dir = log_dir;
  options.vars = vars;
  options.status_period_s = status_period_s;
  fl::InstallShutdownHandlers();
  try {
    fl::procman::Supervisor supervisor(launch, options);
    const fl::procman::RunResult result = supervisor.Run();
    const std::string table = supervisor.ReportTable();
    std::cout << "[procman " << launch.name << "] run " << (result.ok ? "ended" : "FAILED") << ": "
              << result.reason << "\n"
              << table;
    if (!report_path.empty()) {
      std::ofstream out(report_path);
      out << "run " << (result.ok ? "ended" : "FAILED") << ": " << result.reason << "\n" << table;
      if (!out) std::cerr << "fl-procman: cannot write " << report_path << "\n";
    }
    return result.ok ? 0 : 1;
  } catch (const std::exception& e) {
    std::cerr << "fl-procman: " << e.what() << "\n";
    return 2;
  }
}
