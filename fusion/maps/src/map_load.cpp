#include "fusionloc/maps/map_load.hpp"

#include <cctype>
#include <cmath>
#include <fstream>
#include <iterator>
#include <limits>
#include <vector>

#include "fusionloc/common/number_format.hpp"
#include "fusionloc/common/yaml_options.hpp"

namespace fl::maps {
namespace {

// The map_server YAML, read by the options loader (unknown keys and wrong types are errors
// naming the file, line and key).
struct MapYaml {
  std::string image;
  double resolution = std::numeric_limits<double>::quiet_NaN();
  std::vector<double> origin;
  int negate = 0;
  double occupied_thresh = 0.65;
  double free_thresh = 0.196;
  std::string mode = "trinary";

  template <class A>
  void Serialize(A* a) {
    a->Visit("image", &image);
    a->Visit("mode", &mode);
    a->Visit("resolution", &resolution);
    a->Visit("origin", &origin);
    a->Visit("negate", &negate);
    a->Visit("occupied_thresh", &occupied_thresh);
    a->Visit("free_thresh", &free_thresh);
  }
};

std::string Folder(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  return slash == std::string::npos ? std::string() : path.substr(0, slash + 1);
}

// An 8-bit PGM (P5 or P2): width x height gray values, row 0 at the top, scaled to 0..255.
struct Pgm {
  int width = 0, height = 0;
  std::vector<uint8_t> pixels;
};

Pgm ReadPgm(const std::string& path, const std::string& yaml_path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    throw MapLoadError("map image '" + path + "' (the 'image' of '" + yaml_path +
                       "') not found or unreadable; the path is relative to the YAML's folder");
  }
  const std::string data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  size_t pos = 0;
  const auto unsupported = [&](const std::string& why) {
    return MapLoadError("map image '" + path + "': " + why +
                        "; only 8-bit PGM (P5 binary or P2 ASCII, maxval <= 255) is read: "
                        "convert it, e.g. `convert IMAGE -depth 8 map.pgm` (ImageMagick), and "
                        "set 'image' in '" +
                        yaml_path + "'");
  };
  // Header tokens, skipping white space and '#' comments.
  const auto token = [&]() -> std::string {
    while (pos < data.size()) {
      if (std::isspace(static_cast<unsigned char>(data[pos]))) {
        ++pos;
      } else if (data[pos] == '#') {
        while (pos < data.size() && data[pos] != '\n') ++pos;
      } else {
        break;
      }
    }
    const size_t start = pos;
    while (pos < data.size() && !std::isspace(static_cast<unsigned char>(data[pos]))) ++pos;
    return data.substr(start, pos - start);
  };
  const auto number = [&](const char* what) {
    const std::string t = token();
    if (t.empty() || t.size() > 9 || t.find_first_not_of("0123456789") != std::string::npos) {
      throw MapLoadError("map image '" + path + "': bad PGM header (" + what + " is '" + t +
                         "', expected a positive integer): the file is damaged or not a PGM");
    }
    return std::stoi(t);
  };
  if (data.size() < 2 || data[0] != 'P') throw unsupported("not a PGM file");
  const std::string magic = token();
  if (magic != "P5" && magic != "P2") {
    throw unsupported("format '" + magic.substr(0, 2) + "' (" +
                      (magic == "P6" || magic == "P3" ? "a colour PPM" : "not a gray PGM") + ")");
  }
  Pgm pgm;
  pgm.width = number("width");
  pgm.height = number("height");
  const int maxval = number("maxval");
  if (pgm.width <= 0 || pgm.height <= 0) {
    throw MapLoadError("map image '" + path + "' has size " + std::to_string(pgm.width) + " x " +
                       std::to_string(pgm.height) + "; both must be > 0");
  }
  if (maxval <= 0 || maxval > 255) throw unsupported("maxval " + std::to_string(maxval));
  const size_t n = static_cast<size_t>(pgm.width) * static_cast<size_t>(pgm.height);
  if (n > 400000000u) {
    throw MapLoadError("map image '" + path + "' is " + std::to_string(pgm.width) + " x " +
                       std::to_string(pgm.height) + " pixels (over 400 million): not a map");
  }
  pgm.pixels.resize(n);
  const auto scaled = [&](int v) {
    return static_cast<uint8_t>(maxval == 255 ? v : (v * 255 + maxval / 2) / maxval);
  };
  if (magic == "P5") {
    ++pos;  // the single white-space byte after maxval
    if (data.size() < pos + n) {
      throw MapLoadError("map image '" + path + "' is truncated: " + std::to_string(pgm.width) +
                         " x " + std::to_string(pgm.height) + " needs " + std::to_string(n) +
                         " bytes of pixels, the file has " +
                         std::to_string(data.size() > pos ? data.size() - pos : 0) +
                         "; export the map again");
    }
    for (size_t i = 0; i < n; ++i) {
      const int v = static_cast<unsigned char>(data[pos + i]);
      if (v > maxval) {
        throw MapLoadError("map image '" + path + "': pixel " + std::to_string(i) + " is " +
                           std::to_string(v) + ", above maxval " + std::to_string(maxval));
      }
      pgm.pixels[i] = scaled(v);
    }
  } else {
    for (size_t i = 0; i < n; ++i) {
      const std::string t = token();
      if (t.empty()) {
        throw MapLoadError("map image '" + path + "' is truncated: " + std::to_string(n) +
                           " pixels expected, " + std::to_string(i) + " found");
      }
      if (t.size() > 3 || t.find_first_not_of("0123456789") != std::string::npos ||
          std::stoi(t) > maxval) {
        throw MapLoadError("map image '" + path + "': pixel " + std::to_string(i) + " is '" + t +
                           "', not a number in 0.." + std::to_string(maxval));
      }
      pgm.pixels[i] = scaled(std::stoi(t));
    }
  }
  return pgm;
}

}  // namespace

fusionloc::occupancy_grid_t LoadOccupancyGrid(const std::string& yaml_path) {
  {
    std::ifstream probe(yaml_path);
    if (!probe) {
      throw MapLoadError("map file '" + yaml_path +
                         "' not found or unreadable; pass the .yaml that fl-map-export wrote "
                         "(fl-map-export LOG --channel RBPF_MAP --out PREFIX)");
    }
  }
  MapYaml y;
  try {
    y = LoadYamlFile<MapYaml>(yaml_path);
  } catch (const ConfigError& e) {
    throw MapLoadError(std::string("map file: ") + e.what() +
                       " (a map_server YAML has image, resolution, origin, negate, "
                       "occupied_thresh, free_thresh and optionally mode)");
  }
  const auto bad = [&](const std::string& what) {
    return MapLoadError("map file '" + yaml_path + "': " + what);
  };
  if (y.image.empty()) {
    throw bad("missing key 'image' (the PGM file, relative to the YAML's folder)");
  }
  if (std::isnan(y.resolution)) throw bad("missing key 'resolution' (metres per cell)");
  if (!(y.resolution > 0.0) || !std::isfinite(y.resolution)) {
    throw bad("resolution = " + FormatDouble(y.resolution) +
              " must be a positive number of metres");
  }
  if (y.origin.size() != 3) {
    throw bad(y.origin.empty() ? "missing key 'origin' ([x, y, yaw] of the lower-left corner)"
                               : "origin has " + std::to_string(y.origin.size()) +
                                     " numbers; write [x, y, yaw]");
  }
  if (!std::isfinite(y.origin[0]) || !std::isfinite(y.origin[1]) || !std::isfinite(y.origin[2])) {
    throw bad("origin must be finite numbers");
  }
  if (std::abs(y.origin[2]) > 1e-9) {
    throw bad("origin yaw = " + FormatDouble(y.origin[2]) +
              " rad: a rotated map is not supported; rotate the image instead and set yaw 0");
  }
  if (y.negate != 0 && y.negate != 1) throw bad("negate must be 0 or 1");
  if (!(y.free_thresh >= 0.0 && y.free_thresh < y.occupied_thresh && y.occupied_thresh <= 1.0)) {
    throw bad("thresholds must satisfy 0 <= free_thresh < occupied_thresh <= 1 (got free_thresh " +
              FormatDouble(y.free_thresh) + ", occupied_thresh " + FormatDouble(y.occupied_thresh) +
              ")");
  }
  if (y.mode != "trinary" && y.mode != "scale" && y.mode != "raw") {
    throw bad("mode '" + y.mode + "' is not one of trinary, scale, raw");
  }
  const std::string image_path = y.image[0] == '/' ? y.image : Folder(yaml_path) + y.image;
  const Pgm pgm = ReadPgm(image_path, yaml_path);

  fusionloc::occupancy_grid_t g{};
  g.utime = 0;
  g.resolution = y.resolution;
  g.origin_x = y.origin[0];
  g.origin_y = y.origin[1];
  g.width = pgm.width;
  g.height = pgm.height;
  g.num_cells = g.width * g.height;
  g.cells.resize(static_cast<size_t>(g.num_cells));
  for (int r = 0; r < pgm.height; ++r) {
    const uint8_t* row = &pgm.pixels[static_cast<size_t>(r) * static_cast<size_t>(pgm.width)];
    int8_t* out = &g.cells[static_cast<size_t>(pgm.height - 1 - r) * static_cast<size_t>(g.width)];
    for (int c = 0; c < pgm.width; ++c) {
      const int v = row[c];
      if (y.mode == "raw") {
        out[c] = static_cast<int8_t>(v <= 100 ? v : -1);
        continue;
      }
      const double p = y.negate ? v / 255.0 : (255.0 - v) / 255.0;
      if (p > y.occupied_thresh) {
        out[c] = 100;
      } else if (p < y.free_thresh) {
        out[c] = 0;
      } else if (y.mode == "scale") {
        out[c] = static_cast<int8_t>(
            std::lround(99.0 * (p - y.free_thresh) / (y.occupied_thresh - y.free_thresh)));
      } else {
        out[c] = -1;
      }
    }
  }
  return g;
}

}  // namespace fl::maps
