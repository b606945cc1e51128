// fl-map-export: writes the last map message of a channel in an LCM log to standard files.
#include <iostream>
#include <map>
#include <sstream>

#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/common/program.hpp"
#include "fusionloc/maps/map_export.hpp"

namespace {

int Run(const std::string& log_path, const std::string& channel, const std::string& out,
        double resolution) {
  if (out.empty()) throw fl::maps::MapExportError("--out PREFIX is required");
  std::unique_ptr<fl::LcmLogReader> reader;
  try {
    reader = std::make_unique<fl::LcmLogReader>(log_path);
  } catch (const std::exception& e) {
    throw fl::maps::MapExportError(std::string("cannot open LCM log: ") + e.what());
  }
  const int64_t kGridHash = fusionloc::occupancy_grid_t::getHash();
  const int64_t kCloudHash = fusionloc::point_cloud_t::getHash();
  std::map<std::string, int64_t> counts;
  fl::LcmLogEvent ev, last;
  bool found = false;
  int64_t on_channel = 0;
  while (reader->Next(&ev)) {
    ++counts[ev.channel];
    if (ev.channel != channel) continue;
    ++on_channel;
    last = ev;
    found = true;
  }
  if (!reader->ProblemSummary().empty()) FL_LOG(WARN) << reader->ProblemSummary();
  if (!found) {
    std::string list;
    for (const auto& [name, n] : counts) {
      list += (list.empty() ? "" : ", ") + name + " (" + std::to_string(n) + ")";
    }
    throw fl::maps::MapExportError("channel '" + channel + "' not found in '" + log_path +
                                   "'; channels present: " + (list.empty() ? "none" : list));
  }
  const int size = static_cast<int>(last.data.size());
  int64_t hash = 0;
  for (int k = 0; k < 8 && k < size; ++k) {
    hash = static_cast<int64_t>((static_cast<uint64_t>(hash) << 8) | last.data[k]);
  }
  if (hash == kGridHash) {
    fusionloc::occupancy_grid_t grid;
    if (size < 8 || grid.decode(last.data.data(), 0, size) != size) {
      throw fl::maps::MapExportError(
          "the last message on '" + channel +
          "' does not decode as fusionloc.occupancy_grid_t (truncated?)");
    }
    const auto files = fl::maps::SaveOccupancyGrid(grid, out);
    std::cout << "occupancy grid " << grid.width << " x " << grid.height << " cells at "
              << grid.resolution << " m (message " << on_channel << " of " << on_channel << " on "
              << channel << ") -> ";
    for (const auto& f : files) std::cout << f << " ";
    std::cout << "\n";
    return 0;
  }
  if (hash == kCloudHash) {
    fusionloc::point_cloud_t cloud;
    if (size < 8 || cloud.decode(last.data.data(), 0, size) != size) {
      throw fl::maps::MapExportError("the last message on '" + channel +
                                     "' does not decode as fusionloc.point_cloud_t (truncated?)");
    }
    const auto points = fl::maps::PointsFromMessage(cloud);
    fl::maps::SavePointCloudPcd(points, cloud.intensities, out + ".pcd");
    fl::maps::SavePointCloudTopView(points, out + "_top.png", resolution);
    std::cout << "point cloud of " << points.size() << " points in frame '" << cloud.frame
              << "' (message " << on_channel << " of " << on_channel << " on " << channel << ") -> "
              << out << ".pcd " << out << "_top.png\n";
    return 0;
  }
  throw fl::maps::MapExportError("channel '" + channel +
                                 "' does not carry a map: expected fusionloc.occupancy_grid_t or "
                                 "fusionloc.point_cloud_t (e.g. RBPF_MAP, FUSED_MAP, VO_POINTS)");
}

}  // namespace

int main(int argc, char** argv) {
  std::string log_path, channel = "RBPF_MAP", out;
  double resolution = 0.05;
  fl::Program program("fl-map-export",
                      "Exports the last map message of a channel in an LCM log: an occupancy grid "
                      "(fusionloc.occupancy_grid_t) to PREFIX.pgm + PREFIX.yaml (ROS map_server) "
                      "+ PREFIX.png, or a point cloud (fusionloc.point_cloud_t) to PREFIX.pcd "
                      "(binary) + PREFIX_top.png. Exit status: 0 ok, 1 bad input, 2 bad usage.");
  fl::CommandLine& cli = program.cli();
  cli.AddPositional("LOG", &log_path, "LCM log with the map channel");
  cli.AddFlag("channel", &channel, "map channel: RBPF_MAP, FUSED_MAP, VO_POINTS, ...");
  cli.AddFlag("out", &out, "output prefix (folder must exist), e.g. out/intel_map");
  cli.AddFlag("resolution", &resolution, "point-cloud top view: metres per pixel");
  cli.AddEpilog(
      "\nExample:\n  fl-map-export slam.lcmlog --channel RBPF_MAP --out out/map\n"
      "  (then: ros2 run nav2_map_server map_server --ros-args -p "
      "yaml_filename:=out/map.yaml)\n");
  if (!program.Parse(argc, argv)) return program.exit_code();
  try {
    return Run(log_path, channel, out, resolution);
  } catch (const std::exception& e) {
    std::cerr << "fl-map-export: error: " << e.what() << "\n";
    return 1;
  }
}
