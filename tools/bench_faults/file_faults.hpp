// The file faults of fl-bench-faults: damaged logs replayed with fl-replay, and full disks
// under the writers of logs and maps.
//
//   log_truncated         a simulated sensor log cut at 60 % of its bytes (inside an event), as
//                         a killed logger leaves it: the replay must name the byte offset where
//                         the incomplete event starts and keep every event before it.
//   log_corrupted         512 random bytes written over the end of one event and the header of
//                         the next, at 40 % of the log: the replay must name the damage's byte
//                         offset, resynchronise at the next event and lose only the damaged one.
//   disk_full_replay_log  fl-replay --out onto a 2 MB file system: a clear error, a non-zero
//                         exit, and no output log under its final name.
//   disk_full_map_save    fl-replay --map-out onto a 64 kB file system: the same for the map.
//   disk_full_logger      fl-logger recording the live simulator onto a 1 MB file system:
//                         the same; what it recorded stays readable in LOG.partial.
// The disk-full runs mount a tmpfs in a private mount namespace (unshare -m), which needs root;
// without it they are skipped with a warning.
#pragma once

#include <string>
#include <vector>

#include "fusionloc/bench/bench.hpp"

namespace fl::bench_faults {

struct FileFaultSetup {
  std::string bin;         // folder of the fl-* programs
  std::string config_dir;  // rbpf_slam.yaml, stereo_vo.yaml, fusion.yaml, robot/sim.yaml
  std::string out_dir;     // each run's files go to OUT/<run>/
  std::string world = "paper";
  double duration_s = 60.0;  // [s] of simulated data in the sensor log
  int seed = 1;
  int port = 7700;  // UDP port of the live bus of disk_full_logger (loopback, ttl=0)
};

// Names of the file-fault runs, in order.
std::vector<std::string> FileFaultNames();

// Runs the named file faults (all if `only` is empty); one Run each, with the metrics crashes,
// fused_ate_m, fused_ate_ratio (over the undamaged replay's), messages_lost, recovery_s and the
// fault's own checks.
std::vector<fl::bench::Run> RunFileFaults(const FileFaultSetup& setup,
                                          const std::vector<std::string>& only);

// A run's note without its trailing "; " separators.
std::string TrimNote(std::string note);

// The RMSE [m] of FUSED_TRAJECTORY against GROUND_TRUTH in an LCM log (SE(2) alignment, as the
// demo); -1 with a reason appended to `note` if it cannot be computed.
double FusedAte(const std::string& log, std::string* note);

}  // namespace fl::bench_faults
