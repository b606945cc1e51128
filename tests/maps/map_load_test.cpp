// Loading the map_server PGM + YAML that SaveOccupancyGrid writes (map_load.hpp): the round trip,
// map_server's reading of other maps, and clear errors for bad files.
#include "fusionloc/maps/map_load.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <functional>

#include "fusionloc/maps/map_export.hpp"
#include "test_paths.hpp"

namespace fl::maps {
namespace {

// 5 x 3 cells at 5 cm, origin on the cell lattice, every kind of cell.
fusionloc::occupancy_grid_t MakeGrid() {
  fusionloc::occupancy_grid_t g{};
  g.utime = 1;
  g.resolution = 0.05;
  g.width = 5;
  g.height = 3;
  g.origin_x = -1.5;
  g.origin_y = 2.25;
  g.num_cells = 15;
  g.cells = {0, -1, 100, 50, 10, -1, -1, 70, 30, 25, 100, 0, 25, 65, 64};
  return g;
}

std::string LoadError(const std::string& yaml_path) {
  try {
    LoadOccupancyGrid(yaml_path);
  } catch (const MapLoadError& e) {
    return e.what();
  }
  return "(no MapLoadError thrown)";
}

void Write(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

const char* kYaml =
    "image: m.pgm\nresolution: 0.1\norigin: [1.0, -2.0, 0.0]\nnegate: 0\n"
    "occupied_thresh: 0.65\nfree_thresh: 0.196\n";

TEST(MapLoad, ExportThenLoadGivesTheSameOccupancy) {
  test::TempDir dir;
  const fusionloc::occupancy_grid_t g = MakeGrid();
  SaveOccupancyGrid(g, dir.file("map"));
  const fusionloc::occupancy_grid_t back = LoadOccupancyGrid(dir.file("map.yaml"));
  EXPECT_EQ(back.width, g.width);
  EXPECT_EQ(back.height, g.height);
  EXPECT_EQ(back.num_cells, g.num_cells);
  EXPECT_DOUBLE_EQ(back.resolution, g.resolution);
  EXPECT_DOUBLE_EQ(back.origin_x, g.origin_x);
  EXPECT_DOUBLE_EQ(back.origin_y, g.origin_y);
  // The PGM is trinary (GridExportOptions: occupied >= 65 %, free <= 25 %, else unknown): the
  // same occupancy comes back as 100, 0 or -1, cell by cell, rows in the same order.
  ASSERT_EQ(back.cells.size(), g.cells.size());
  const GridExportOptions o;
  for (size_t i = 0; i < g.cells.size(); ++i) {
    const int v = g.cells[i];
    const int expected = v < 0                         ? -1
                         : v >= o.occupied_min_percent ? 100
                         : v <= o.free_max_percent     ? 0
                                                       : -1;
    EXPECT_EQ(back.cells[i], expected) << "cell " << i << " (" << v << " %)";
  }
  // Loading is idempotent: exporting what was loaded writes the same files.
  SaveOccupancyGrid(back, dir.file("again"));
  EXPECT_EQ(test::ReadFile(dir.file("again.pgm")), test::ReadFile(dir.file("map.pgm")));
}

TEST(MapLoad, ReadsAsciiPgmNegateScaleAndRawLikeMapServer) {
  test::TempDir dir;
  // 3 x 2, top row first: black (occupied), white (free), mid gray (unknown) / 0, 254, 100.
  Write(dir.file("m.pgm"), "P2\n# a comment\n3 2\n255\n0 255 128\n0 254 100\n");
  Write(dir.file("m.yaml"), kYaml);
  fusionloc::occupancy_grid_t g = LoadOccupancyGrid(dir.file("m.yaml"));
  ASSERT_EQ(g.cells.size(), 6u);
  // Bottom row (the image's last) first.
  EXPECT_EQ(std::vector<int8_t>(g.cells.begin(), g.cells.end()),
            (std::vector<int8_t>{100, 0, -1, 100, 0, -1}));
  EXPECT_DOUBLE_EQ(g.origin_x, 1.0);
  EXPECT_DOUBLE_EQ(g.origin_y, -2.0);
  // negate: 1 swaps black and white.
  Write(dir.file("n.yaml"), "image: m.pgm\nresolution: 0.1\norigin: [1.0, -2.0, 0.0]\nnegate: 1\n");
  g = LoadOccupancyGrid(dir.file("n.yaml"));
  EXPECT_EQ(g.cells[0], 0);
  EXPECT_EQ(g.cells[1], 100);
  // scale: the gray in between gets 99 (p - free) / (occ - free): pixel 100 -> p 0.608 -> 90.
  Write(dir.file("s.yaml"), std::string(kYaml) + "mode: scale\n");
  g = LoadOccupancyGrid(dir.file("s.yaml"));
  EXPECT_EQ(g.cells[2], 90);
  // raw: the pixel value itself, unknown above 100.
  Write(dir.file("r.yaml"), std::string(kYaml) + "mode: raw\n");
  g = LoadOccupancyGrid(dir.file("r.yaml"));
  EXPECT_EQ(g.cells[0], 0);
  EXPECT_EQ(g.cells[1], -1);
  EXPECT_EQ(g.cells[2], 100);
}

TEST(MapLoad, BadFilesGiveErrorsNamingTheFileAndTheFix) {
  test::TempDir dir;
  Write(dir.file("m.pgm"), std::string("P5\n2 1\n255\n") + '\0' + '\xfe');
  // Missing YAML.
  std::string e = LoadError(dir.file("none.yaml"));
  EXPECT_NE(e.find("none.yaml' not found"), std::string::npos) << e;
  EXPECT_NE(e.find("fl-map-export"), std::string::npos) << e;
  // A typo in a key: named, with the line and the closest known key.
  Write(dir.file("typo.yaml"), "image: m.pgm\nresolutoin: 0.05\norigin: [0, 0, 0]\n");
  e = LoadError(dir.file("typo.yaml"));
  EXPECT_NE(e.find("typo.yaml:2"), std::string::npos) << e;
  EXPECT_NE(e.find("unknown key 'resolutoin'; did you mean 'resolution'?"), std::string::npos) << e;
  // Missing keys.
  Write(dir.file("nores.yaml"), "image: m.pgm\norigin: [0, 0, 0]\n");
  e = LoadError(dir.file("nores.yaml"));
  EXPECT_NE(e.find("missing key 'resolution'"), std::string::npos) << e;
  Write(dir.file("noimg.yaml"), "resolution: 0.05\norigin: [0, 0, 0]\n");
  EXPECT_NE(LoadError(dir.file("noimg.yaml")).find("missing key 'image'"), std::string::npos);
  Write(dir.file("org.yaml"), "image: m.pgm\nresolution: 0.05\norigin: [0, 0]\n");
  EXPECT_NE(LoadError(dir.file("org.yaml")).find("origin has 2 numbers"), std::string::npos);
  Write(dir.file("rot.yaml"), "image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0.3]\n");
  EXPECT_NE(LoadError(dir.file("rot.yaml")).find("rotated map is not supported"),
            std::string::npos);
  // A wrong type.
  Write(dir.file("type.yaml"), "image: m.pgm\nresolution: fine\norigin: [0, 0, 0]\n");
  e = LoadError(dir.file("type.yaml"));
  EXPECT_NE(e.find("'resolution' expects a number"), std::string::npos) << e;
  // Bad values.
  Write(dir.file("thr.yaml"),
        "image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nfree_thresh: 0.7\n");
  EXPECT_NE(LoadError(dir.file("thr.yaml")).find("free_thresh < occupied_thresh"),
            std::string::npos);
  Write(dir.file("mode.yaml"), "image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nmode: x\n");
  EXPECT_NE(LoadError(dir.file("mode.yaml")).find("mode 'x'"), std::string::npos);
  // The image: missing (named with the YAML that points to it), unsupported, truncated.
  Write(dir.file("gone.yaml"), "image: gone.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n");
  e = LoadError(dir.file("gone.yaml"));
  EXPECT_NE(e.find("gone.pgm"), std::string::npos) << e;
  EXPECT_NE(e.find("relative to the YAML's folder"), std::string::npos) << e;
  Write(dir.file("c.pgm"), "P6\n1 1\n255\nabc");
  Write(dir.file("ppm.yaml"), "image: c.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n");
  e = LoadError(dir.file("ppm.yaml"));
  EXPECT_NE(e.find("colour PPM"), std::string::npos) << e;
  EXPECT_NE(e.find("convert"), std::string::npos) << e;
  Write(dir.file("p.png"), "\x89PNG\r\n\x1a\n");
  Write(dir.file("png.yaml"), "image: p.png\nresolution: 0.05\norigin: [0, 0, 0]\n");
  EXPECT_NE(LoadError(dir.file("png.yaml")).find("not a PGM file"), std::string::npos);
  Write(dir.file("w.pgm"), "P5\n2 1\n65535\n");
  Write(dir.file("wide.yaml"), "image: w.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n");
  EXPECT_NE(LoadError(dir.file("wide.yaml")).find("maxval 65535"), std::string::npos);
  Write(dir.file("t.pgm"), "P5\n4 4\n255\nabc");
  Write(dir.file("trunc.yaml"), "image: t.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n");
  e = LoadError(dir.file("trunc.yaml"));
  EXPECT_NE(e.find("truncated: 4 x 4 needs 16 bytes of pixels, the file has 3"), std::string::npos)
      << e;
  Write(dir.file("h.pgm"), "P5\nfour 4\n255\n");
  Write(dir.file("head.yaml"), "image: h.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n");
  EXPECT_NE(LoadError(dir.file("head.yaml")).find("bad PGM header (width is 'four'"),
            std::string::npos);
  // And the good file loads.
  Write(dir.file("ok.yaml"), "image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n");
  const fusionloc::occupancy_grid_t g = LoadOccupancyGrid(dir.file("ok.yaml"));
  EXPECT_EQ(g.cells, (std::vector<int8_t>{100, 0}));
}

}  // namespace
}  // namespace fl::maps
