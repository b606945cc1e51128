// Configuration of the fl-fusion process: config/fusion.yaml.
#pragma once

#include "fusionloc/fusion/factor_graph_fusion.hpp"
#include "fusionloc/fusion/point_map.hpp"

namespace fl::fusion {

struct FusionProcessConfig {
  FusionOptions graph;                 // the factor graph (see factor_graph_fusion.hpp)
  PointMapOptions map;                 // the 3D point map (see point_map.hpp)
  double trajectory_period_s = 1.0;    // [s of data time] FUSED_TRAJECTORY at least this often
                                       // while the window changes it; always after a full solve
  // [s] Each FUSED_TRAJECTORY but the last one carries the poses that can still change (the
  // active window) and the final (retired) ones of this many seconds before them; a consumer
  // keeps its poses older than a message's first and takes the message's (trajectory_t.lcm).
  // A final pose is so sent in about trajectory_overlap_s / trajectory_period_s messages. The
  // last message (the end of a log, a shutdown) is the whole trajectory. 0 = the whole
  // trajectory every time (its size, and the fusion's memory, grow with the run).
  double trajectory_overlap_s = 30.0;
  double map_png_resolution_m = 0.05;  // [m/pixel] of the saved top-view PNG

  template <class A>
  void Serialize(A* a) {
    a->Visit("graph", &graph);
    a->Visit("map", &map);
    a->Visit("trajectory_period_s", &trajectory_period_s);
    a->Visit("trajectory_overlap_s", &trajectory_overlap_s);
    a->Visit("map_png_resolution_m", &map_png_resolution_m);
  }
  Status Validate() const {
    Status s = graph.Validate();
    if (!s.ok()) return Status::Error("graph." + s.message());
    s = map.Validate();
    if (!s.ok()) return Status::Error("map." + s.message());
    if (!(trajectory_period_s > 0.0)) return Status::Error("trajectory_period_s must be > 0");
    if (!(trajectory_overlap_s >= 0.0))
      return Status::Error("trajectory_overlap_s must be >= 0 (0: the whole trajectory always)");
    if (!(map_png_resolution_m > 0.0)) return Status::Error("map_png_resolution_m must be > 0");
    return Status::Ok();
  }
};

}  // namespace fl::fusion
