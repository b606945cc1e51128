// Known scenes for the viewer's tests: an occupancy grid whose cells say where they are (an
// occupied block, a half-occupied block, an unknown band, free elsewhere: no symmetry, so a
// flip or a shift shows), a straight trajectory, and a robot driving along x.
#pragma once

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/time.hpp"
#include "fusionloc/fused_pose_t.hpp"
#include "fusionloc/occupancy_grid_t.hpp"
#include "fusionloc/status_t.hpp"
#include "fusionloc/trajectory_t.hpp"

namespace fl::test {

struct ViewerGridFixture {
  double resolution = 0.5;  // [m]
  int width = 24, height = 16;
  double origin_x = -3.0, origin_y = -2.0;  // [m]

  // [%] of cell (row, col): 100 in rows 2-4 x cols 4-7, 50 in rows 6-9 x cols 16-19, unknown
  // (-1) from row 12 up, 0 elsewhere.
  int8_t Cell(int row, int col) const {
    if (row >= 12) return -1;
    if (row >= 2 && row <= 4 && col >= 4 && col <= 7) return 100;
    if (row >= 6 && row <= 9 && col >= 16 && col <= 19) return 50;
    return 0;
  }
  std::vector<int8_t> Cells() const {
    std::vector<int8_t> cells(static_cast<size_t>(width * height));
    for (int r = 0; r < height; ++r) {
      for (int c = 0; c < width; ++c) cells[static_cast<size_t>(r * width + c)] = Cell(r, c);
    }
    return cells;
  }
  // Map-frame centre of a cell.
  double CellX(int col) const { return origin_x + (col + 0.5) * resolution; }
  double CellY(int row) const { return origin_y + (row + 0.5) * resolution; }
};

// A straight trajectory from (-2, -1) to (8, 5), `n` poses 0.1 s apart.
struct ViewerTrajectoryFixture {
  int n = 50;
  double x0 = -2, y0 = -1, x1 = 8, y1 = 5;
  double X(int i) const { return x0 + (x1 - x0) * i / (n - 1); }
  double Y(int i) const { return y0 + (y1 - y0) * i / (n - 1); }
  double Yaw() const { return std::atan2(y1 - y0, x1 - x0); }
};

// A robot driving along x at 1 m/s from x = 0 for `duration_s`, poses at `rate_hz`.
struct ViewerDriveFixture {
  double duration_s = 10.0;
  double rate_hz = 10.0;
  Utime start = 1700000000000000;
  double X(double t_s) const { return t_s; }
};

// ---- the same as LCM messages ----

inline fusionloc::occupancy_grid_t ViewerGridMsg(Utime utime) {
  const ViewerGridFixture g;
  fusionloc::occupancy_grid_t m{};
  m.utime = utime;
  m.resolution = g.resolution;
  m.width = g.width;
  m.height = g.height;
  m.origin_x = g.origin_x;
  m.origin_y = g.origin_y;
  m.cells = g.Cells();
  m.num_cells = static_cast<int32_t>(m.cells.size());
  return m;
}

inline fusionloc::trajectory_t ViewerTrajectoryMsg(Utime utime) {
  const ViewerTrajectoryFixture t;
  fusionloc::trajectory_t m{};
  m.utime = utime;
  m.num_poses = t.n;
  for (int i = 0; i < t.n; ++i) {
    m.utimes.push_back(utime - (t.n - i) * 100000);
    m.x.push_back(t.X(i));
    m.y.push_back(t.Y(i));
    m.z.push_back(0);
    m.theta.push_back(t.Yaw());
  }
  return m;
}

inline fusionloc::status_t ViewerStatusMsg(Utime utime, const std::string& process) {
  fusionloc::status_t m{};
  m.utime = utime;
  m.process = process;
  m.level = fusionloc::status_t::LEVEL_OK;
  m.message = "fixture";
  m.num_keys = 1;
  m.keys = {"nodes"};
  m.values = {42};
  return m;
}

inline fusionloc::fused_pose_t ViewerFusedPoseMsg(Utime utime, double x) {
  fusionloc::fused_pose_t m{};
  m.utime = utime;
  m.x = x;
  return m;
}

// The drive as a log: the grid first, FUSED_POSE at rate_hz, STATUS_FL_FUSION every 1 s.
inline void WriteViewerDriveLog(const std::string& out) {
  const ViewerDriveFixture d;
  LcmLogWriter log(out);
  log.Write(channels::kRbpfMap, ViewerGridMsg(d.start), d.start);
  const int n = static_cast<int>(d.duration_s * d.rate_hz);
  for (int i = 0; i <= n; ++i) {
    const double t = i / d.rate_hz;
    const Utime u = d.start + SecondsToUtime(t);
    log.Write(channels::kFusedPose, ViewerFusedPoseMsg(u, d.X(t)), u);
    if (i % 10 == 0) log.Write("STATUS_FL_FUSION", ViewerStatusMsg(u, "fl-fusion"), u);
  }
  log.Close();
}

}  // namespace fl::test
