// PNG plots for evaluation and benchmarks, drawn with OpenCV (no OpenCV in this header):
//  - PlotTrajectoriesTopView: several trajectories from above (x right, y up), equal axes,
//    ticks in metres, grid, legend, start/end markers, optional occupancy-grid background;
//  - PlotSeries: stacked panels sharing an x axis (e.g. x, y, heading error over time);
//  - PlotAteErrors: the x, y and heading errors of an AteResult over time (MSIF Fig. 6 style).
// Every function writes the file atomically and throws EvalError if it cannot, or if there is
// nothing finite to draw.
//
//   fl::eval::PlotTrajectoriesTopView("out/run_traj.png",
//       {{"ground truth", ref, fl::eval::kPlotBlack}, {"fused", est, fl::eval::kPlotBlue}});
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "fusionloc/eval/metrics.hpp"
#include "fusionloc/eval/trajectory.hpp"
#include "fusionloc/occupancy_grid_t.hpp"

namespace fl::eval {

struct Color {
  uint8_t r = 0, g = 0, b = 0;
};
constexpr Color kPlotBlack{0, 0, 0};
constexpr Color kPlotBlue{31, 119, 180};
constexpr Color kPlotOrange{255, 127, 14};
constexpr Color kPlotGreen{44, 160, 44};
constexpr Color kPlotRed{214, 39, 40};
constexpr Color kPlotPurple{148, 103, 189};
constexpr Color kPlotGray{127, 127, 127};
// A distinct colour for curve `index` (the ones above, cycling).
Color PlotColor(size_t index);

struct TrajectoryCurve {
  std::string name;
  Trajectory trajectory;
  Color color = kPlotBlue;
};

// An occupancy grid drawn under the trajectories, same convention as fusionloc.occupancy_grid_t:
// cell (row r, col c) covers x in [origin_x + c res, ...), y in [origin_y + r res, ...);
// cells row-major, 0..100 occupancy percent, -1 unknown.
struct BackgroundGrid {
  double resolution = 0;              // [m]
  double origin_x = 0, origin_y = 0;  // [m]
  int width = 0, height = 0;          // [cells]
  std::vector<int8_t> cells;
};

// Validated copy of an occupancy grid message; throws EvalError if inconsistent.
BackgroundGrid BackgroundFromGrid(const fusionloc::occupancy_grid_t& grid);
// The last fusionloc.occupancy_grid_t on `channel` of an LCM log (e.g. RBPF_MAP); throws
// EvalError if the log or channel is missing or carries another type.
BackgroundGrid ReadBackgroundGridLcm(const std::string& log_path, const std::string& channel);

struct TopViewOptions {
  std::string title;
  int width_px = 1000;
  int height_px = 850;
  const BackgroundGrid* background = nullptr;  // optional, not owned (plane "xy" only)
  // "xy": world x right, y up (ground robots, z up). "xz": x right, z up — the top view of
  // camera-frame trajectories such as KITTI's (x right, y down, z forward).
  std::string plane = "xy";
};

void PlotTrajectoriesTopView(const std::string& png_path,
                             const std::vector<TrajectoryCurve>& curves,
                             const TopViewOptions& options = {});

struct SeriesCurve {
  std::string name;
  std::vector<double> x, y;  // same length; non-finite points break the line
  Color color = kPlotBlue;
};
struct Panel {
  std::string y_label;  // e.g. "x error [m]"
  std::vector<SeriesCurve> curves;
};
// Stacked panels with a shared x range; a legend in each panel with more than one curve.
void PlotSeries(const std::string& png_path, const std::string& title, const std::string& x_label,
                const std::vector<Panel>& panels, int width_px = 1000, int panel_height_px = 240);

// x, y error [m] and heading error [deg] of the aligned estimate against time since the first
// pair [s], three stacked panels. plane "xz": x, z errors and the heading of the z axis in the
// x-z plane (camera frames).
void PlotAteErrors(const std::string& png_path, const AteResult& ate, const std::string& title,
                   const std::string& est_name = "estimate", const std::string& plane = "xy");

}  // namespace fl::eval
