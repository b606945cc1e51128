// Exporting maps to standard files:
//  - occupancy grids (fusionloc.occupancy_grid_t) to PGM + YAML in the ROS map_server
//    convention (loadable by map_server / nav2_map_server) and to a PNG for viewing;
//  - point clouds to binary PCD (PCL) and a PNG top view coloured by height.
// All functions validate their input and throw MapExportError with a clear message; files are
// written atomically (X.partial, then renamed), so a failure never leaves a file that looks whole.
// The reverse, a PGM + YAML grid back into a message: map_load.hpp (LoadOccupancyGrid).
#pragma once

#include <Eigen/Core>
#include <stdexcept>
#include <string>
#include <vector>

#include "fusionloc/occupancy_grid_t.hpp"
#include "fusionloc/point_cloud_t.hpp"

namespace fl::maps {

class MapExportError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// How occupancy percentages become the three map_server values (map_saver's defaults).
struct GridExportOptions {
  int occupied_min_percent = 65;  // cells >= this are occupied: PGM 0 (black)
  int free_max_percent = 25;      // cells in [0, this] are free: PGM 254 (white); others 205
  // Written to the YAML for map_server's reading of the trinary image.
  double occupied_thresh = 0.65;
  double free_thresh = 0.196;
};

// Throws MapExportError unless width, height > 0, num_cells == width * height == cells.size(),
// resolution > 0 and finite, origin finite, every cell in [-1, 100].
void ValidateGrid(const fusionloc::occupancy_grid_t& grid);

// Writes base.pgm (P5, row 0 = the top = largest y), base.yaml (image, mode trinary,
// resolution, origin [origin_x, origin_y, 0], negate 0, occupied_thresh, free_thresh) and
// base.png (gray levels 255 * (1 - p/100), unknown 205). Returns the written paths.
std::vector<std::string> SaveOccupancyGrid(const fusionloc::occupancy_grid_t& grid,
                                           const std::string& base_path,
                                           const GridExportOptions& options = {});

// Binary PCD via PCL: PointXYZ, or PointXYZI if `intensities` is not empty (then it must have
// one value per point). Non-finite points are kept (is_dense = false) and counted in a warning.
void SavePointCloudPcd(const std::vector<Eigen::Vector3f>& points,
                       const std::vector<float>& intensities, const std::string& path);

// PNG top view (x right, y up), `resolution_m` metres per pixel, each pixel coloured by the
// highest point in it (blue low .. yellow high), white where there is none, with a scale bar.
// Throws if there are no finite points or the image would exceed 8000 px a side.
void SavePointCloudTopView(const std::vector<Eigen::Vector3f>& points, const std::string& png_path,
                           double resolution_m);

// The points of a point_cloud_t (validated: num_points == points.size(), num_intensities 0 or
// num_points).
std::vector<Eigen::Vector3f> PointsFromMessage(const fusionloc::point_cloud_t& msg);

}  // namespace fl::maps
