// Loading occupancy grids from the files SaveOccupancyGrid (map_export.hpp) writes: the ROS
// map_server PGM + YAML pair, read the way map_server reads it, so that maps saved by ROS
// (map_saver, nav2_map_server) load too. The format's one place: this loader beside the writer.
//
// YAML keys (map_server's): image (required; relative to the YAML's folder), resolution
// (required, m/cell), origin (required, [x, y, yaw]: the map-frame pose of the lower-left
// corner of the image; yaw must be 0), negate (0), occupied_thresh (0.65), free_thresh (0.196),
// mode (trinary, scale or raw; trinary). Any other key is an error (a typo would otherwise be
// silently ignored). Image: 8-bit PGM, binary (P5) or ASCII (P2), maxval <= 255.
// Cell value of a pixel v (map_server): p = (255 - v) / 255, or v / 255 with negate;
//   trinary: p > occupied_thresh -> 100, p < free_thresh -> 0, else -1 (unknown);
//   scale:   as trinary, but a p in between gets 99 * (p - free) / (occ - free) (rounded);
//   raw:     v itself if v <= 100, else -1.
// Image row 0 is the top of the map (largest y), as the writer stores it.
#pragma once

#include <stdexcept>
#include <string>

#include "fusionloc/occupancy_grid_t.hpp"

namespace fl::maps {

// Every bad-input error of the loader; the message names the file and says what to fix.
class MapLoadError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Loads a map_server YAML and its image into a grid message (cells -1, 0..100; utime 0).
// Throws MapLoadError for a missing or unreadable file, a bad or unknown YAML key, an
// unsupported image or one whose size does not match its header.
fusionloc::occupancy_grid_t LoadOccupancyGrid(const std::string& yaml_path);

}  // namespace fl::maps
