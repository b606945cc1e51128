// The only translation unit of fl_fusion that includes PCL (slow to compile).
#include "fusionloc/fusion/point_map.hpp"

#include <pcl/filters/voxel_grid.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <cmath>
#include <map>

namespace fl::fusion {
namespace {

// VoxelGrid indexes voxels with 32-bit integers: split big clouds into tiles whose voxel
// count fits, filter each tile, and concatenate (voxels never straddle tiles: tiles are
// aligned to the voxel grid).
pcl::PointCloud<pcl::PointXYZ>::Ptr VoxelFilter(const pcl::PointCloud<pcl::PointXYZ>::Ptr& in,
                                                double voxel) {
  auto out = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  if (in->empty()) return out;
  const double tile = voxel * 1000.0;  // 1000^3 voxels < 2^31
  std::map<std::tuple<int64_t, int64_t, int64_t>, pcl::PointCloud<pcl::PointXYZ>::Ptr> tiles;
  for (const auto& p : in->points) {
    const auto key = std::make_tuple(static_cast<int64_t>(std::floor(p.x / tile)),
                                     static_cast<int64_t>(std::floor(p.y / tile)),
                                     static_cast<int64_t>(std::floor(p.z / tile)));
    auto& cloud = tiles[key];
    if (!cloud) cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
    cloud->points.push_back(p);
  }
  pcl::VoxelGrid<pcl::PointXYZ> grid;
  grid.setLeafSize(static_cast<float>(voxel), static_cast<float>(voxel), static_cast<float>(voxel));
  for (auto& [key, cloud] : tiles) {
    cloud->width = static_cast<uint32_t>(cloud->points.size());
    cloud->height = 1;
    cloud->is_dense = true;
    pcl::PointCloud<pcl::PointXYZ> filtered;
    grid.setInputCloud(cloud);
    grid.filter(filtered);
    *out += filtered;
  }
  return out;
}

}  // namespace

struct PointMap::Impl {
  std::map<Utime, pcl::PointCloud<pcl::PointXYZ>::Ptr> keyframes;  // base frame
  std::map<Utime, Pose2> final_poses;  // kept keyframes whose pose is final
  int64_t points = 0;
};

Status PointMapOptions::Validate() const {
  if (!(voxel_size_m >= 0.005 && voxel_size_m <= 10.0)) {
    return Status::Error("voxel_size_m must be in [0.005, 10] m");
  }
  if (!(max_range_m > 0.0)) return Status::Error("max_range_m must be > 0");
  if (max_points < 1) return Status::Error("max_points must be >= 1");
  if (!(merge_spacing_m >= 0.0) || !(merge_spacing_rad > 0.0 && merge_spacing_rad <= M_PI)) {
    return Status::Error("merge_spacing_m must be >= 0 m and merge_spacing_rad in (0, pi] rad");
  }
  return Status::Ok();
}

PointMap::PointMap(const PointMapOptions& options) : impl_(new Impl), options_(options) {
  const Status s = options_.Validate();
  if (!s.ok()) throw std::invalid_argument("PointMapOptions: " + s.message());
}

PointMap::~PointMap() = default;
PointMap::PointMap(PointMap&&) noexcept = default;
PointMap& PointMap::operator=(PointMap&&) noexcept = default;

Status PointMap::AddKeyframe(Utime utime, const std::vector<Eigen::Vector3f>& points_base) {
  if (impl_->keyframes.count(utime)) {
    return Status::Error("point map: a keyframe at utime " + std::to_string(utime) +
                         " is already stored; duplicate dropped");
  }
  auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  cloud->points.reserve(points_base.size());
  const float max_range = static_cast<float>(options_.max_range_m);
  for (const Eigen::Vector3f& p : points_base) {
    if (!p.allFinite() || p.norm() > max_range) {
      ++dropped_points_;
      continue;
    }
    cloud->points.emplace_back(p.x(), p.y(), p.z());
  }
  cloud->width = static_cast<uint32_t>(cloud->points.size());
  cloud->height = 1;
  auto filtered = VoxelFilter(cloud, options_.voxel_size_m);
  impl_->points += static_cast<int64_t>(filtered->size());
  impl_->keyframes[utime] = filtered;
  return Status::Ok();
}

std::vector<Eigen::Vector3f> PointMap::Build(const std::function<bool(Utime, Pose2*)>& pose_at,
                                             int* skipped) const {
  if (skipped) *skipped = 0;
  auto all = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  all->points.reserve(static_cast<size_t>(std::min<int64_t>(impl_->points, options_.max_points)));
  for (const auto& [utime, cloud] : impl_->keyframes) {
    Pose2 T_map_base;
    // A pose beyond kMaxMapExtentM (or not finite) comes from a corrupt input upstream: its
    // points would not even be finite floats; the keyframe is skipped.
    if (!pose_at(utime, &T_map_base) || !(std::abs(T_map_base.x) <= kMaxMapExtentM) ||
        !(std::abs(T_map_base.y) <= kMaxMapExtentM) || !std::isfinite(T_map_base.theta)) {
      if (skipped) ++*skipped;
      continue;
    }
    const Eigen::Isometry3f T = T_map_base.ToIsometry3().cast<float>();
    for (const auto& p : cloud->points) {
      if (static_cast<int64_t>(all->points.size()) >= options_.max_points) break;
      const Eigen::Vector3f q = T * Eigen::Vector3f(p.x, p.y, p.z);
      all->points.emplace_back(q.x(), q.y(), q.z());
    }
  }
  all->width = static_cast<uint32_t>(all->points.size());
  all->height = 1;
  const auto filtered = VoxelFilter(all, options_.voxel_size_m);
  std::vector<Eigen::Vector3f> out;
  out.reserve(filtered->size());
  for (const auto& p : filtered->points) out.emplace_back(p.x, p.y, p.z);
  return out;
}

int PointMap::MergeFinalKeyframes(const std::function<bool(Utime, Pose2*)>& pose_at,
                                  Utime final_until) {
  if (options_.merge_spacing_m <= 0.0) return 0;
  int merged = 0;
  for (auto it = impl_->keyframes.begin();
       it != impl_->keyframes.end() && it->first <= final_until;) {
    if (impl_->final_poses.count(it->first)) {
      ++it;
      continue;
    }
    Pose2 T_map_k;
    if (!pose_at(it->first, &T_map_k) || !std::isfinite(T_map_k.x) || !std::isfinite(T_map_k.y) ||
        !std::isfinite(T_map_k.theta)) {
      ++it;  // no pose (yet): left as it is
      continue;
    }
    bool found = false;
    for (const auto& [utime, T_map_m] : impl_->final_poses) {
      if (std::hypot(T_map_m.x - T_map_k.x, T_map_m.y - T_map_k.y) <= options_.merge_spacing_m &&
          std::fabs(WrapAngle(T_map_m.theta - T_map_k.theta)) <= options_.merge_spacing_rad) {
        found = true;
        break;
      }
    }
    if (!found) {
      impl_->final_poses.emplace(it->first, T_map_k);
      ++it;
      continue;
    }
    // The kept keyframe already holds this view. (Moving k's points into it instead made the
    // map grow by ~20k points a minute in a looping soak: stereo noise fills new voxels.)
    impl_->points -= static_cast<int64_t>(it->second->size());
    it = impl_->keyframes.erase(it);
    ++merged;
  }
  merged_keyframes_ += merged;
  return merged;
}

int PointMap::num_keyframes() const { return static_cast<int>(impl_->keyframes.size()); }
int64_t PointMap::stored_points() const { return impl_->points; }

namespace {
constexpr char kMapStateMagic[] = "FLPTMAP_";
constexpr uint32_t kMapStateVersion = 1;
}  // namespace

void PointMap::SaveState(StateWriter* w) const {
  w->Begin(kMapStateMagic, kMapStateVersion);
  w->PutCount(impl_->keyframes.size());
  for (const auto& [utime, cloud] : impl_->keyframes) {
    w->Put(utime);
    w->PutCount(cloud->size());
    for (const auto& p : cloud->points) {
      w->Put(p.x);
      w->Put(p.y);
      w->Put(p.z);
    }
  }
  w->PutCount(impl_->final_poses.size());
  for (const auto& [utime, pose] : impl_->final_poses) {
    w->Put(utime);
    w->Put(pose);
  }
  w->Put(dropped_points_);
  w->Put(merged_keyframes_);
}

void PointMap::LoadState(StateReader* r) {
  r->Begin(kMapStateMagic, kMapStateVersion);
  auto impl = std::make_unique<Impl>();
  const size_t num_keyframes = r->Count(16, "map keyframes");
  for (size_t k = 0; k < num_keyframes; ++k) {
    const Utime utime = r->Get<int64_t>("map keyframe utime");
    const size_t n = r->Count(12, "map keyframe points");
    auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
    cloud->points.reserve(n);
    const float max_range = static_cast<float>(options_.max_range_m);
    for (size_t i = 0; i < n; ++i) {
      const float x = r->Get<float>("point"), y = r->Get<float>("point"), z = r->Get<float>("point");
      // What AddKeyframe keeps (finite, within max_range_m), as the voxel filter assumes.
      if (!(Eigen::Vector3f(x, y, z).norm() <= max_range)) {
        r->Fail("map keyframe at utime " + std::to_string(utime) + ": a point is not finite or " +
                "beyond max_range_m");
      }
      cloud->points.emplace_back(x, y, z);
    }
    cloud->width = static_cast<uint32_t>(cloud->points.size());
    cloud->height = 1;
    if (!impl->keyframes.emplace(utime, cloud).second) {
      r->Fail("two map keyframes at utime " + std::to_string(utime));
    }
    impl->points += static_cast<int64_t>(n);
  }
  const size_t num_final = r->Count(32, "final map keyframe poses");
  for (size_t k = 0; k < num_final; ++k) {
    const Utime utime = r->Get<int64_t>("final pose utime");
    const Pose2 pose = r->GetPose2("final pose");
    if (!std::isfinite(pose.x) || !std::isfinite(pose.y) || !std::isfinite(pose.theta)) {
      r->Fail("final pose of the map keyframe at utime " + std::to_string(utime) +
              " is not finite");
    }
    impl->final_poses[utime] = pose;
  }
  const int64_t dropped = r->Get<int64_t>("dropped points");
  const int64_t merged = r->Get<int64_t>("merged keyframes");
  impl_ = std::move(impl);
  dropped_points_ = dropped;
  merged_keyframes_ = merged;
}

}  // namespace fl::fusion
