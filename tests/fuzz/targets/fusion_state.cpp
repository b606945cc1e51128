// The fusion's saved state (fl-fusion's journal snapshot: FactorGraphFusion::LoadState, then
// PointMap::LoadState, from one buffer as the node reads it). Input: [mode byte][rest].
//  mode even: the rest is the state itself;
//  mode odd:  the rest is edits [offset u16 LE][byte] applied to a valid state made by a small
//             deterministic run (a fusion with retired and map nodes, odometry, a pending
//             factor and a 3D map), so that the search starts from bytes that load.
// The valid state's retired trajectory is spilled (all but its newest 3 poses) to a file; each
// input's fusion is bound to a fresh copy of that file, so that the spilled count and stamp the
// state names are checked against it (and the copy is spilled into as the loaded fusion goes on).
// Any bytes either load or throw StateError; a fusion and a map that load take new inputs,
// solve, and give finite poses without crashing.
#include <fcntl.h>
#include <stdlib.h>
#include <unistd.h>

#include <cerrno>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "../fuzz_entry.hpp"
#include "fusionloc/fusion/factor_graph_fusion.hpp"
#include "fusionloc/fusion/point_map.hpp"

namespace {

using fl::Pose2;
using fl::Utime;
using fl::fusion::FactorGraphFusion;
using fl::fusion::FusionOptions;
using fl::fusion::PointMap;
using fl::fusion::PointMapOptions;
using fl::fusion::RelativePoseFactor;
using fl::fusion::RetiredSpillFile;

constexpr Utime kStepUs = 500000;  // [us] between laser nodes

FusionOptions Options() {
  FusionOptions o;
  o.active_window_s = 10.0;  // the shortest: nodes retire within the 30 s run
  o.window_size = 5;
  o.max_window_nodes = 10;
  o.full_solve_every_n_nodes = 10;
  return o;
}

constexpr size_t kKeepInMemory = 3;  // retired poses; the rest spilled,
constexpr size_t kSpillBatch = 2;    // this many at a time

// The valid state's spill file and the working copy the inputs load with; removed at exit.
struct SpillFiles {
  SpillFiles() {
    char pattern[] = "/tmp/fl_fuzz_fusion_state_XXXXXX";
    const char* made = mkdtemp(pattern);
    FL_FUZZ_CHECK(made != nullptr);
    dir = made;
    original = dir + "/valid.retired";
    work = dir + "/work.retired";
  }
  ~SpillFiles() {
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
  }
  std::string dir, original, work;
};

SpillFiles& Files() {
  static SpillFiles files;
  return files;
}

// Copies `from` to `to` (replaced), retrying reads and writes interrupted by libFuzzer's timer
// signal (std::filesystem::copy_file gives up on EINTR).
void CopyFile(const std::string& from, const std::string& to) {
  const int in = ::open(from.c_str(), O_RDONLY | O_CLOEXEC);
  const int out = ::open(to.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  FL_FUZZ_CHECK(in >= 0 && out >= 0);
  char buffer[65536];
  for (;;) {
    const ssize_t n = ::read(in, buffer, sizeof(buffer));
    if (n < 0 && errno == EINTR) continue;
    FL_FUZZ_CHECK(n >= 0);
    if (n == 0) break;
    for (ssize_t done = 0; done < n;) {
      const ssize_t w = ::write(out, buffer + done, static_cast<size_t>(n - done));
      if (w < 0 && errno == EINTR) continue;
      FL_FUZZ_CHECK(w > 0);
      done += w;
    }
  }
  ::close(in);
  ::close(out);
}

Pose2 Truth(int k) { return Pose2(0.1 * k, 0.3 * std::sin(0.05 * k), 0.05 * std::sin(0.03 * k)); }

// A valid state: 60 laser nodes at 2 Hz with odometry, laser factors, a factor still pending
// (ahead of the newest node) and a 3D map keyframe every 10 nodes.
const std::vector<uint8_t>& ValidState() {
  static const std::vector<uint8_t> bytes = [] {
    FactorGraphFusion fusion(Options());
    fusion.SpillRetiredTrajectory(std::make_shared<RetiredSpillFile>(Files().original),
                                  kKeepInMemory, kSpillBatch);
    PointMap map((PointMapOptions()));
    for (int k = 0; k < 60; ++k) {
      const Utime t = 1000000 + kStepUs * static_cast<Utime>(k);
      (void)fusion.AddOdometry(t, Truth(k));
      (void)fusion.AddLaserPose(t, Truth(k) * Pose2(0.001 * k, 0.0, 0.0005 * k));
      if (k > 0) {
        RelativePoseFactor f;
        f.utime_i = t - kStepUs;
        f.utime_j = t;
        f.T_i_j = Truth(k - 1).between(Truth(k)).ToIsometry3();
        f.information.diagonal() << 1e4, 1e4, 0, 0, 0, 1e5;
        (void)fusion.AddFactor(f);
      }
      if (k % 10 == 0) {
        (void)map.AddKeyframe(t, {Eigen::Vector3f(1.0f, 0.1f * k, 0.5f),
                                  Eigen::Vector3f(2.0f, -0.2f, 0.3f)});
      }
      fusion.Update();
      if (fusion.full_solve_requested()) fusion.FullSolve();
    }
    RelativePoseFactor ahead;
    ahead.utime_i = 1000000 + kStepUs * 59;
    ahead.utime_j = ahead.utime_i + 2 * kStepUs;
    ahead.information.diagonal() << 1e4, 1e4, 0, 0, 0, 1e5;
    (void)fusion.AddFactor(ahead);
    FL_FUZZ_CHECK(fusion.retired_trajectory().spilled() > 0 && fusion.num_map_nodes() > 0 &&
                  fusion.num_pending_factors() == 1 && map.num_keyframes() > 0);
    fl::StateWriter w;
    fusion.SaveState(&w);
    map.SaveState(&w);
    return w.Release();
  }();
  return bytes;
}

}  // namespace

int Fuzz_fusion_state(const uint8_t* data, size_t size) {
  fl::fuzz::QuietLogs();
  fl::fuzz::Input in(data, size);
  const std::vector<uint8_t>& valid = ValidState();  // also writes the spill file
  const uint8_t mode = in.Byte();
  std::vector<uint8_t> state;
  const bool unedited = mode % 2 == 1 && in.empty();  // must load
  if (mode % 2 == 0) {
    const std::string_view rest = in.Rest();
    state.assign(rest.begin(), rest.end());
  } else {
    state = valid;
    while (!in.empty()) {
      const size_t at = in.U16();
      const uint8_t value = in.Byte();
      if (!state.empty()) state[at % state.size()] = value;
    }
  }
  FactorGraphFusion fusion(Options());
  CopyFile(Files().original, Files().work);
  fusion.SpillRetiredTrajectory(std::make_shared<RetiredSpillFile>(Files().work), kKeepInMemory,
                                kSpillBatch);
  PointMap map((PointMapOptions()));
  fl::StateReader r(state.data(), state.size());
  try {
    fusion.LoadState(&r);
  } catch (const fl::StateError&) {
    FL_FUZZ_CHECK(!unedited);
    FL_FUZZ_CHECK(fusion.num_nodes() == 0 && fusion.num_factors() == 0);  // left unchanged
    return 0;
  }
  try {
    map.LoadState(&r);
    r.End("fuzz state");
  } catch (const fl::StateError&) {
    FL_FUZZ_CHECK(!unedited);
  }
  // Loaded: it goes on.
  const Utime newest = fusion.newest_node_utime();
  if (newest < (Utime{1} << 60)) {
    for (int k = 1; k <= 3; ++k) {
      const Utime t = newest + kStepUs * k;
      (void)fusion.AddOdometry(t, Pose2(0.1 * k, 0.0, 0.0));
      (void)fusion.AddLaserPose(t, Pose2(0.1 * k, 0.0, 0.0));
      fusion.Update();
    }
  }
  fusion.FullSolve();
  // Trajectory(): one pose per scan, in time order.
  const auto trajectory = fusion.Trajectory();
  FL_FUZZ_CHECK(std::adjacent_find(trajectory.begin(), trajectory.end(),
                                   [](const auto& a, const auto& b) {
                                     return a.utime >= b.utime;
                                   }) == trajectory.end());
  fl::fusion::TrajectoryPoint latest;
  (void)fusion.Latest(&latest);
  (void)map.MergeFinalKeyframes([&](Utime t, Pose2* p) { return fusion.PoseAt(t, p); },
                                fusion.final_until());
  (void)map.Build([&](Utime t, Pose2* p) { return fusion.PoseAt(t, p); });
  return 0;
}
