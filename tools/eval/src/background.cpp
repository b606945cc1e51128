// Occupancy-grid backgrounds for top-view plots, from messages or LCM logs.
#include <cmath>
#include <map>

#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/eval/plot.hpp"

namespace fl::eval {

BackgroundGrid BackgroundFromGrid(const fusionloc::occupancy_grid_t& g) {
  const int64_t n = static_cast<int64_t>(g.width) * g.height;
  if (g.width <= 0 || g.height <= 0 || g.num_cells != n ||
      static_cast<int64_t>(g.cells.size()) != n || !(g.resolution > 0) ||
      !std::isfinite(g.resolution) || !std::isfinite(g.origin_x) || !std::isfinite(g.origin_y)) {
    throw EvalError("occupancy grid is inconsistent (" + std::to_string(g.width) + " x " +
                    std::to_string(g.height) + " cells, num_cells " + std::to_string(g.num_cells) +
                    ", " + std::to_string(g.cells.size()) + " values, resolution " +
                    std::to_string(g.resolution) + ")");
  }
  BackgroundGrid b;
  b.resolution = g.resolution;
  b.origin_x = g.origin_x;
  b.origin_y = g.origin_y;
  b.width = g.width;
  b.height = g.height;
  b.cells = g.cells;
  return b;
}

BackgroundGrid ReadBackgroundGridLcm(const std::string& log_path, const std::string& channel) {
  if (!IsLcmLog(log_path)) {
    throw EvalError("map source '" + log_path + "' is not an LCM log (or cannot be opened)");
  }
  LcmLogReader reader(log_path);
  LcmLogEvent ev, last;
  bool found = false;
  std::map<std::string, int64_t> counts;
  while (reader.Next(&ev)) {
    ++counts[ev.channel];
    if (ev.channel == channel) {
      last = ev;
      found = true;
    }
  }
  if (!found) {
    std::string list;
    for (const auto& [name, count] : counts) {
      list += (list.empty() ? "" : ", ") + name + " (" + std::to_string(count) + ")";
    }
    throw EvalError("map channel '" + channel + "' not found in '" + log_path +
                    "'; channels present: " + (list.empty() ? "none" : list));
  }
  fusionloc::occupancy_grid_t grid;
  const int size = static_cast<int>(last.data.size());
  if (grid.decode(last.data.data(), 0, size) != size) {
    throw EvalError("the last message on '" + channel + "' in '" + log_path +
                    "' is not a fusionloc.occupancy_grid_t (wrong channel or truncated)");
  }
  return BackgroundFromGrid(grid);
}

}  // namespace fl::eval
