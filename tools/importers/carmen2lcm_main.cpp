// fl-carmen2lcm: a CARMEN laser log (.clf / .log / .log.gz) into an LCM log with LASER,
// ODOMETRY and (corrected logs) GROUND_TRUTH. Thin adapter over fl::importers::ConvertCarmen.
#include <exception>
#include <filesystem>
#include <iostream>

#include "fusionloc/common/log.hpp"
#include "fusionloc/common/program.hpp"
#include "fusionloc/common/yaml_options.hpp"
#include "fusionloc/importers/carmen.hpp"

namespace {

// "dir/intel-corrected.log.gz" -> "intel-corrected.lcmlog" (in the current folder).
std::string DefaultOutput(const std::string& in) {
  std::string name = std::filesystem::path(in).filename().string();
  for (const char* ext : {".gz", ".clf", ".log"}) {
    const std::string e(ext);
    if (name.size() > e.size() && name.compare(name.size() - e.size(), e.size(), e) == 0) {
      name.resize(name.size() - e.size());
    }
  }
  return name + ".lcmlog";
}

}  // namespace

int main(int argc, char** argv) {
  fl::Program program("fl-carmen2lcm",
                      "Converts a CARMEN laser log (.clf, .log, .log.gz) into an LCM log:\n"
                      "LASER (planar_lidar_t), ODOMETRY (wheel_odometry_t) and, for corrected\n"
                      "logs, GROUND_TRUTH (pose_t, the corrected poses). Corrected logs get\n"
                      "seeded synthetic noisy odometry (see docs/IMPORTERS.md).");
  fl::CommandLine& cli = program.cli();
  std::string in, out, noisy, timestamp, timestamps_from, ground_truth_from, repeated_stamps;
  int64_t seed = -1;
  fl::importers::CarmenOptions options;
  program.AddOptions(&options, "a CarmenOptions file, see docs/IMPORTERS.md");
  cli.AddPositional("IN", &in, "CARMEN log to read", /*required=*/false);
  cli.AddPositional("OUT", &out, "LCM log to write (default: IN's name with .lcmlog, here)",
                    /*required=*/false);
  cli.AddFlag("noisy-odometry", &noisy,
              "auto (corrected logs by file name), true or false (overrides the config)");
  cli.AddFlag("seed", &seed, "seed of the odometry noise (overrides the config; -1 = config)");
  cli.AddFlag("timestamp", &timestamp, "ipc or logger: which CARMEN time stamp becomes utime");
  cli.AddFlag("timestamps-from", &timestamps_from,
              "raw log of the same run: take each scan's time stamp from the raw scan with the "
              "same ranges (e.g. mit-csail.clf for csail-corrected.log.gz)");
  cli.AddFlag("repeated-stamps", &repeated_stamps,
              "auto, keep or by_order: scans that repeat the stamp before them (too few "
              "digits) kept, or every scan stamped by its order (auto: by_order when more "
              "than a quarter repeat); overrides the config");
  cli.AddFlag("ground-truth-from", &ground_truth_from,
              "raw logs: corrected log of the same run; its poses go to GROUND_TRUTH for the "
              "raw scans with the same ranges (e.g. csail-corrected.log.gz for mit-csail.clf)");
  cli.AddEpilog(
      "\nExamples:\n"
      "  fl-carmen2lcm ../shared/data/laser/mit-csail.clf csail-raw.lcmlog\n"
      "  fl-carmen2lcm ../shared/data/laser/intel-corrected.log.gz intel.lcmlog --seed 7\n"
      "  fl-carmen2lcm ../shared/data/laser/csail-corrected.log.gz csail.lcmlog \\\n"
      "      --timestamps-from ../shared/data/laser/mit-csail.clf\n"
      "  fl-carmen2lcm ../shared/data/laser/mit-csail.clf csail-raw.lcmlog \\\n"
      "      --ground-truth-from ../shared/data/laser/csail-corrected.log.gz\n"
      "Exit status: 0 done, 1 conversion failed (nothing written), 2 usage or\n"
      "configuration error.\n");
  cli.AddCheck([&]() -> std::string {  // the flags override the options file
    if (!noisy.empty()) options.noisy_odometry = noisy;
    if (seed >= 0) options.seed = static_cast<uint64_t>(seed);
    if (!timestamp.empty()) options.timestamp = timestamp;
    if (!timestamps_from.empty()) options.timestamps_from = timestamps_from;
    if (!ground_truth_from.empty()) options.ground_truth_from = ground_truth_from;
    if (!repeated_stamps.empty()) options.repeated_stamps = repeated_stamps;
    const fl::Status valid = options.Validate();
    return valid.ok() ? "" : "invalid options: " + valid.message();
  });
  if (!program.Parse(argc, argv)) return program.exit_code();
  return program.Run([&] {
    if (in.empty()) throw fl::UsageError("missing IN (the CARMEN log to convert)");
    if (out.empty()) out = DefaultOutput(in);
    const auto summary = fl::importers::ConvertCarmen(options, in, out);
    std::cout << summary.ToString();
    return fl::kExitOk;
  });
}
