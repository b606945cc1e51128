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
  double map_png_resolution_m = 0.05;  // [m/pixel] of the saved top-view PNG

  template <class A>
  void Serialize(A* a) {
    a->Visit("graph", &graph);
    a->Visit("map", &map);
    a->Visit("trajectory_period_s", &trajectory_period_s);
    a->Visit("map_png_resolution_m", &map_png_resolution_m);
  }
  Status Validate() const {
    Status s = graph.Validate();
    if (!s.ok()) return Status::Error("graph." + s.message());
    s = map.Validate();
    if (!s.ok()) return Status::Error("map." + s.message());
    if (!(trajectory_period_s > 0.0)) return Status::Error("trajectory_period_s must be > 0");
    if (!(map_png_resolution_m > 0.0)) return Status::Error("map_png_resolution_m must be > 0");
    return Status::Ok();
  }
};

}  // namespace fl::fusion
