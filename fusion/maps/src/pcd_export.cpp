// The only file that includes PCL (slow to compile): binary PCD export.
#include <pcl/io/pcd_io.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <cstdio>
#include <filesystem>

#include "fusionloc/common/log.hpp"
#include "fusionloc/maps/map_export.hpp"

namespace fl::maps {
namespace {

// Why a write of about `needed` bytes to `path` may have failed.
std::string WriteFailureReason(const std::string& path, uintmax_t needed) {
  std::filesystem::path folder = std::filesystem::path(path).parent_path();
  if (folder.empty()) folder = ".";
  std::error_code ec;
  const std::filesystem::space_info space = std::filesystem::space(folder, ec);
  if (!ec && space.available < needed) {
    return "only " + std::to_string(space.available / 1024) + " kB free on its file system, " +
           "about " + std::to_string(needed / 1024 + 1) + " kB needed (disk full)";
  }
  return "does the folder exist and is it writable?";
}

template <class Cloud>
void WriteBinary(const Cloud& cloud, const std::string& path) {
  // PCL picks nothing from the extension, so a temporary name is safe.
  const std::string tmp = path + ".partial";
  pcl::PCDWriter writer;
  std::string pcl_error;
  int rc = -1;
  try {
    rc = writer.writeBinary(tmp, cloud);
  } catch (const std::exception& e) {  // PCL throws pcl::IOException on a failed allocation
    std::string what = e.what();
    if (what.rfind(": ", 0) == 0) what = what.substr(2);
    pcl_error = " (PCL: " + what + ")";
  }
  if (rc != 0) {
    std::remove(tmp.c_str());
    const uintmax_t needed = cloud.size() * sizeof(typename Cloud::PointType) + 1024;
    throw MapExportError("PCL could not write '" + path + "': " +
                         WriteFailureReason(path, needed) + pcl_error);
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    throw MapExportError("cannot rename '" + tmp + "' to '" + path + "'");
  }
}

}  // namespace

void SavePointCloudPcd(const std::vector<Eigen::Vector3f>& points,
                       const std::vector<float>& intensities, const std::string& path) {
  if (points.empty()) {
    throw MapExportError("point cloud for '" + path + "' is empty: nothing to export");
  }
  if (!intensities.empty() && intensities.size() != points.size()) {
    throw MapExportError("point cloud for '" + path + "': " + std::to_string(intensities.size()) +
                         " intensities for " + std::to_string(points.size()) +
                         " points; give one per point or none");
  }
  size_t non_finite = 0;
  for (const auto& p : points) non_finite += p.allFinite() ? 0 : 1;
  if (non_finite > 0) {
    FL_LOG(WARN) << "PCD '" << path << "': " << non_finite
                 << " non-finite point(s) kept as NaN (is_dense = false)";
  }
  if (intensities.empty()) {
    pcl::PointCloud<pcl::PointXYZ> cloud;
    cloud.reserve(points.size());
    for (const auto& p : points) cloud.push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
    cloud.width = static_cast<uint32_t>(points.size());
    cloud.height = 1;
    cloud.is_dense = non_finite == 0;
    WriteBinary(cloud, path);
  } else {
    pcl::PointCloud<pcl::PointXYZI> cloud;
    cloud.reserve(points.size());
    for (size_t i = 0; i < points.size(); ++i) {
      pcl::PointXYZI q;
      q.x = points[i].x();
      q.y = points[i].y();
      q.z = points[i].z();
      q.intensity = intensities[i];
      cloud.push_back(q);
    }
    cloud.width = static_cast<uint32_t>(points.size());
    cloud.height = 1;
    cloud.is_dense = non_finite == 0;
    WriteBinary(cloud, path);
  }
}

}  // namespace fl::maps
