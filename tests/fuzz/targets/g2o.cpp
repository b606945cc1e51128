// g2o pose-graph reader (fl-bench-posegraph, the fusion's graph files): any text either reads
// or gives an error Status; a graph read has a pose for every edge's vertices, and a small one
// goes through the batch optimiser without crashing.
#include <sstream>

#include "../fuzz_entry.hpp"
#include "fusionloc/fusion/g2o_reader.hpp"
#include "fusionloc/fusion/pose_graph.hpp"

int Fuzz_g2o(const uint8_t* data, size_t size) {
  fl::fuzz::QuietLogs();
  std::istringstream in(std::string(reinterpret_cast<const char*>(data), size));
  fl::fusion::G2oGraph graph;
  if (!fl::fusion::ReadG2o(in, "fuzz.g2o", &graph).ok()) return 0;
  FL_FUZZ_CHECK(graph.num_poses() > 0);
  for (const auto& e : graph.edges2) {
    FL_FUZZ_CHECK(graph.poses2.count(e.id_i) && graph.poses2.count(e.id_j));
  }
  for (const auto& e : graph.edges3) {
    FL_FUZZ_CHECK(graph.poses3.count(e.id_i) && graph.poses3.count(e.id_j));
  }
  if (graph.num_poses() <= 20 && graph.num_edges() <= 40) {
    fl::fusion::PoseGraphSolveOptions options;
    options.max_iterations = 5;
    fl::fusion::PoseGraphResult result;
    (void)fl::fusion::OptimizePoseGraph(&graph, options, &result);
  }
  return 0;
}
