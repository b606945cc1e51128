// Map loader (fl-rbpf-slam --localize MAP.yaml): a map_server YAML and its PGM image. Input:
// [YAML length, u16 LE][YAML text][PGM bytes]; "@IMAGE@" in the YAML stands for the image's
// path. Any bytes either load or throw MapLoadError; a loaded grid is consistent.
#include <string>

#include "../fuzz_entry.hpp"
#include "fusionloc/maps/map_load.hpp"

int Fuzz_map_load(const uint8_t* data, size_t size) {
  fl::fuzz::QuietLogs();
  fl::fuzz::Input in(data, size);
  std::string yaml(in.Bytes(in.U16()));
  const std::string_view pgm = in.Rest();
  fl::fuzz::MemFile image(pgm.data(), pgm.size());
  for (size_t at = yaml.find("@IMAGE@"); at != std::string::npos; at = yaml.find("@IMAGE@")) {
    yaml.replace(at, 7, image.path());
  }
  fl::fuzz::MemFile file(yaml.data(), yaml.size());
  try {
    const fusionloc::occupancy_grid_t g = fl::maps::LoadOccupancyGrid(file.path());
    FL_FUZZ_CHECK(g.width > 0 && g.height > 0);
    FL_FUZZ_CHECK(g.resolution > 0.0);
    FL_FUZZ_CHECK(static_cast<int64_t>(g.cells.size()) ==
                  static_cast<int64_t>(g.width) * g.height);
    for (int8_t c : g.cells) FL_FUZZ_CHECK(c == -1 || (c >= 0 && c <= 100));
  } catch (const fl::maps::MapLoadError&) {
  }
  return 0;
}
