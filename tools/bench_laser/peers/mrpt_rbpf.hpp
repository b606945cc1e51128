// A peer laser SLAM for `fl-bench-laser --peers`: MRPT's `rbpf-slam` (Debian's mrpt-apps, its
// Rao-Blackwellized particle filter with occupancy grids), run as a separate process on the same
// CARMEN log as ours, its output converted into a trajectory with a pose for every scan so that
// the bench scores it with the same code as our runs.
//
// The pipeline (RunMrptRbpf):
//   1. fl-mrpt-rawlog (tools/bench_laser/peers/mrpt_rawlog_main.cpp, built only when CMake finds
//      MRPT) reads the CARMEN log with fl::importers::ReadCarmenLog and writes an MRPT rawlog in
//      the actions-observations format: per scan one CActionRobotMovement2D (the odometry
//      increment since the previous scan) and a CSensoryFrame with the CObservation2DRangeScan.
//      Beside it a steps file (WriteMrptSteps) lists per rawlog step the scan's time, the
//      increment and whether rbpf-slam runs its particle filter there (the rule of MRPT's
//      CMetricMapBuilderRBPF::processActionObservation, evaluated with MRPT's own pose classes).
//   2. rbpf-slam INI RAWLOG, with the INI (config/peers/mrpt_rbpf_slam.ini) plus the output
//      folder the bench chooses; its peak RSS (wait4 ru_maxrss) and CPU time are measured.
//   3. Its outputs are read: most_likely_path.txt (the most likely particle's path: the start
//      pose and one pose per particle-filter step), log_estimated_path.txt (per step the
//      particles' weighted mean pose: the online pose) and log_times.txt (per step the wall time
//      of CMetricMapBuilderRBPF::processActionObservation, the call that does the SLAM).
//
// Nothing here links MRPT: the conversion is plain text in, fl::eval::Trajectory out, and is
// unit-tested without MRPT (tests/bench_laser/mrpt_rbpf_test.cpp).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/time.hpp"
#include "fusionloc/eval/trajectory.hpp"

namespace fl::peers {

// One rawlog step (one scan) as fl-mrpt-rawlog wrote it.
struct MrptStep {
  fl::Utime utime = 0;  // [us] the scan's time (CARMEN ipc_timestamp)
  Pose2 increment;      // odometry increment since the previous step (first step: identity)
  bool filter = false;  // rbpf-slam runs its particle filter on this step (appends a path pose)
};

// Steps file: a '#' header, then one line per step "index utime_us filter dx dy dtheta".
void WriteMrptSteps(const std::vector<MrptStep>& steps, const std::string& path);
// Throws std::runtime_error "FILE:LINE: ..." on a malformed line or indices out of order.
std::vector<MrptStep> ReadMrptSteps(const std::string& path);

// most_likely_path.txt: one "x y yaw" line per path pose. Throws naming FILE:LINE.
std::vector<Pose2> ReadMrptPath(const std::string& path);
// log_estimated_path.txt: "step x y z yaw pitch roll timestamp" lines ('%' comments); returns
// the planar pose of each step in order. Throws if a step is missing or out of order.
std::vector<Pose2> ReadMrptStepPoses(const std::string& path);
// log_times.txt: "step ms map_size inserted" lines; returns the ms of each step in order.
std::vector<double> ReadMrptStepTimes(const std::string& path);

// The final trajectory, a pose for every step: a particle-filter step takes the path's next
// pose; any other step the last path pose composed with the odometry increments since then
// (what MRPT's own current-pose estimate does between filter steps). `path` must hold the start
// pose plus one pose per filter step, and the first step must be a filter step; otherwise
// std::runtime_error says which count does not match (the rawlog and the run disagree).
fl::eval::Trajectory MrptFinalTrajectory(const std::vector<MrptStep>& steps,
                                         const std::vector<Pose2>& path);
// The online trajectory: step k's pose (ReadMrptStepPoses) at step k's time. Counts must match.
fl::eval::Trajectory MrptOnlineTrajectory(const std::vector<MrptStep>& steps,
                                          const std::vector<Pose2>& step_poses);

struct MrptRbpfOptions {
  std::string ini;          // MRPT .ini (config/peers/mrpt_rbpf_slam.ini)
  std::string rawlog_tool;  // fl-mrpt-rawlog
  std::string rbpf_slam = "rbpf-slam";  // MRPT's program (PATH is searched)
  std::string work_dir;     // rawlog, steps, the run's ini and rbpf-slam's output go here
  std::string label;        // progress label, e.g. "[bench laser] mit-csail-raw/mrpt"
};

struct MrptRbpfRun {
  std::vector<MrptStep> steps;
  fl::eval::Trajectory final_trajectory;  // MrptFinalTrajectory
  fl::eval::Trajectory online;            // MrptOnlineTrajectory
  std::vector<double> ms_per_step;        // log_times.txt (wall ms of processActionObservation)
  int64_t filter_steps = 0;               // steps with a particle-filter update
  int64_t inserted_steps = 0;             // steps whose scan went into the maps
  double peak_rss_mb = 0.0;               // rbpf-slam's ru_maxrss [MiB]
  double cpu_s = 0.0;                     // rbpf-slam's user + system CPU time [s]
  double wall_s = 0.0;                    // rbpf-slam's wall time, start to exit [s]
  std::string output_dir;                 // rbpf-slam's logOutput_dir (finalMap*.png etc.)
};

// The run's ini: `ini_text` with logOutput_dir=OUTPUT_DIR added at the top of its
// [MappingApplication] section. Throws if that section is missing or the text already sets
// logOutput_dir or rawlog_file (the bench chooses both).
std::string MrptRunIni(const std::string& ini_text, const std::string& output_dir);

// Runs steps 1-3 above on `carmen_log`. Throws std::runtime_error naming the program, its exit
// status and the last lines of its log on any failure.
MrptRbpfRun RunMrptRbpf(const MrptRbpfOptions& options, const std::string& carmen_log);

}  // namespace fl::peers
