// fl-log-info: a headless summary of any LCM log (channels, types, counts, rates, time span,
// bytes, decode errors, time going backwards, truncation). Thin adapter over InspectLcmLog.
#include <exception>
#include <iostream>

#include "fusionloc/common/log.hpp"
#include "fusionloc/common/program.hpp"
#include "fusionloc/importers/log_info.hpp"

int main(int argc, char** argv) {
  fl::Program program("fl-log-info",
                      "Summarises an LCM log: per channel the message type (by fingerprint,\n"
                      "matched against every fusionloc/bot_core type; others show as\n"
                      "'unknown (0x...)'), count, rate, bytes, first/last time, messages that do\n"
                      "not decode as their type and time going backwards; plus the log's time\n"
                      "span and any truncated or corrupt bytes.");
  fl::CommandLine& cli = program.cli();
  std::string path;
  bool json = false, strict = false, types = false;
  cli.AddPositional("LOG", &path, "LCM log file", /*required=*/false);
  cli.AddFlag("json", &json, "print one JSON object instead of the table");
  cli.AddFlag("strict", &strict, "exit with status 3 if the log has any problem");
  cli.AddFlag("types", &types, "list the known message types and their fingerprints, and exit");
  cli.AddEpilog(
      "\nExample:\n"
      "  fl-log-info kitti0001.lcmlog\n"
      "Exit status: 0 read (problems are listed), 1 cannot read or not an LCM log,\n"
      "2 usage error, "
      "3 problems found (with --strict).\n");
  if (!program.Parse(argc, argv)) return program.exit_code();
  if (types) {
    for (const auto& t : fl::importers::KnownLcmTypes()) {
      std::printf("0x%016llx  %s\n", static_cast<unsigned long long>(t.fingerprint),
                  t.name.c_str());
    }
    return 0;
  }
  if (path.empty()) {
    std::cerr << "fl-log-info: missing LOG (the LCM log to summarise); see --help\n";
    return 2;
  }
  try {
    const fl::importers::LogInfo info = fl::importers::InspectLcmLog(path);
    std::cout << (json ? info.ToJson() : info.ToText());
    if (info.events == 0 && info.file_bytes > 0) {
      std::cerr << "fl-log-info: error: " << path
                << ": no LCM event found: not an LCM log (convert it first, e.g. with "
                   "fl-carmen2lcm or fl-kitti2lcm)\n";
      return 1;
    }
    return (strict && info.has_problems()) ? 3 : 0;
  } catch (const std::exception& e) {
    std::cerr << "fl-log-info: error: " << e.what() << "\n";
    return 1;
  }
}
