// fl-rbpf-slam: the laser RBPF-SLAM process: RbpfSlamNode (rbpf_slam_lcm.hpp) on the process
// edge (fusionloc/common/lcm_process.hpp). With --localize MAP.yaml it localizes on a saved map
// instead: LocalizerNode (localizer_lcm.hpp), with its own options file (config/localizer.yaml).
#include <cstring>
#include <memory>

#include "fusionloc/maps/map_load.hpp"
#include "fusionloc/rbpf_slam/localizer_lcm.hpp"
#include "fusionloc/rbpf_slam/rbpf_slam_lcm.hpp"

namespace {

constexpr const char* kLocalizeHelp =
    "MAP.yaml: localize on this saved map (map_server PGM + YAML, as fl-map-export writes it) "
    "instead of mapping: Monte Carlo localization with the SLAM's likelihood field and "
    "scan-matching proposal; --config then takes a localizer options file "
    "(config/localizer.yaml). `fl-rbpf-slam --localize MAP.yaml --help` lists its channels";

// Whether the command line asks for --localize (its options and channels differ from the
// SLAM's, so the choice is made before the flags are declared).
bool LocalizeRequested(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--") == 0) break;
    if (std::strcmp(argv[i], "--localize") == 0 || std::strncmp(argv[i], "--localize=", 11) == 0) {
      return true;
    }
  }
  return false;
}

int LocalizeMain(int argc, char** argv) {
  using fl::rbpf::LocalizerNode;
  fl::Program program(LocalizerNode::kProgram,
                      "Laser RBPF-SLAM, localization mode (--localize MAP.yaml): Monte Carlo "
                      "localization on a saved map with the SLAM's likelihood field and "
                      "scan-matching proposal, KLD-adaptive particle count, an initial pose from "
                      "INITIAL_POSE or global initialisation, and relocalization when lost.");
  fl::rbpf::LocalizerOptions options;
  program.AddOptions(&options, "config/localizer.yaml");
  std::string map_path;
  program.cli().AddFlag("localize", &map_path, kLocalizeHelp);
  program.cli().AddCheck([&map_path]() -> std::string {
    return map_path.empty() ? "--localize needs the map's YAML file: --localize MAP.yaml" : "";
  });
  fl::rbpf::RbpfSlamNodeOptions node_options;
  node_options.AddFlags(&program.cli());
  program.cli().AddCheck([&node_options]() -> std::string {
    return node_options.no_odometry ? "--no-odometry cannot be used with --localize: the "
                                      "localizer runs its filter on the odometry's motion"
                                    : "";
  });
  fl::LcmProcess process(&program, LocalizerNode::Inputs(), LocalizerNode::Outputs());
  program.cli().AddEpilog(
      "\nExamples:\n"
      "  fl-map-export slam.lcmlog --channel RBPF_MAP --out out/map   # a map from a SLAM run\n"
      "  fl-rbpf-slam --localize out/map.yaml --config config/localizer.yaml\n"
      "  fl-rbpf-slam --localize out/map.yaml --lcm-url log:run.lcmlog,loc.lcmlog\n"
      "Status keys and the method: docs/RBPF_SLAM.md, \"Localization on a saved map\".\n");
  if (!program.Parse(argc, argv)) return program.exit_code();
  return program.Run([&] {
    // A bad map file is bad data (exit 1): MapLoadError names the file and the fix.
    const fusionloc::occupancy_grid_t grid = fl::maps::LoadOccupancyGrid(map_path);
    fl::rbpf::OccupancyMap map;
    try {
      map = fl::rbpf::OccupancyMapFromLcm(grid);
    } catch (const std::invalid_argument& e) {
      throw fl::maps::MapLoadError("map '" + map_path + "': " + e.what());
    }
    FL_LOG(INFO) << "map " << map_path << ": " << map.width << " x " << map.height << " cells at "
                 << map.resolution << " m";
    return process.Run([&](fl::LcmInterface* lcm, const fl::ChannelMap& channels) {
      try {
        return std::make_unique<LocalizerNode>(options, node_options, map, map_path, lcm, channels);
      } catch (const std::invalid_argument& e) {
        throw fl::maps::MapLoadError("map '" + map_path + "': " + e.what());
      }
    });
  });
}

}  // namespace

int main(int argc, char** argv) {
  if (LocalizeRequested(argc, argv)) return LocalizeMain(argc, argv);
  using fl::rbpf::RbpfSlamNode;
  fl::Program program(RbpfSlamNode::kProgram,
                      "Laser RBPF-SLAM (GMapping-style particle filter with a scan-matching "
                      "proposal and likelihood-field weights, refined by ICP keyframe factors and "
                      "a Ceres pose graph with loop closures).");
  fl::rbpf::RbpfSlamOptions options;
  program.AddOptions(&options, "config/rbpf_slam.yaml");
  std::string map_path;  // set only in LocalizeMain; declared here for --help
  program.cli().AddFlag("localize", &map_path, kLocalizeHelp);
  fl::rbpf::RbpfSlamNodeOptions node_options;
  node_options.AddFlags(&program.cli());
  fl::LcmProcess process(&program, RbpfSlamNode::Inputs(), RbpfSlamNode::Outputs());
  program.cli().AddEpilog(
      "\nExamples:\n"
      "  fl-rbpf-slam --config config/rbpf_slam.yaml\n"
      "  fl-rbpf-slam --lcm-url log:carmen.lcmlog,rbpf.lcmlog   # replay, outputs to rbpf.lcmlog\n"
      "  fl-rbpf-slam --localize out/map.yaml                     # localize on a saved map\n"
      "Design: docs/RBPF_SLAM.md.\n");
  if (!program.Parse(argc, argv)) return program.exit_code();
  return program.Run([&] {
    return process.Run([&](fl::LcmInterface* lcm, const fl::ChannelMap& channels) {
      return std::make_unique<RbpfSlamNode>(options, node_options, lcm, channels);
    });
  });
}
