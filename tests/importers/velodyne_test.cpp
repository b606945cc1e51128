// KITTI Velodyne scans: the .bin reader, the `Tr` parse and the scan list of a folder.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <vector>

#include "bot_core/rigid_transform_t.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/geometry.hpp"
#include "fusionloc/importers/kitti.hpp"
#include "fusionloc/laser_scan_3d_t.hpp"
#include "importer_fixtures.hpp"
#include "test_paths.hpp"

namespace fl::importers {
namespace {

namespace fs = std::filesystem;
using fl::test::TempDir;

void WriteFloats(const std::string& path, const std::vector<float>& v) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(v.data()),
            static_cast<std::streamsize>(v.size() * sizeof(float)));
}

std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  ADD_FAILURE() << "expected an error";
  return "";
}

TEST(KittiVelodyneTest, ReadsPointsAndDropsNonFinite) {
  TempDir dir;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  WriteFloats(dir.file("s.bin"), {1.f,  2.f,  3.f,  0.5f,  //
                                  nan,  0.f,  0.f,  0.1f,  //
                                  -4.f, 5.5f, -6.f, 0.f,   //
                                  0.f,  inf,  0.f,  0.2f,  //
                                  7.f,  8.f,  9.f,  nan});
  const VelodyneScan s = ReadVelodyneBin(dir.file("s.bin"));
  ASSERT_EQ(s.points.size(), 2u);
  ASSERT_EQ(s.intensities.size(), 2u);
  EXPECT_EQ(s.dropped_non_finite, 3);
  EXPECT_EQ(s.points[0], Eigen::Vector3f(1.f, 2.f, 3.f));
  EXPECT_FLOAT_EQ(s.intensities[0], 0.5f);
  EXPECT_EQ(s.points[1], Eigen::Vector3f(-4.f, 5.5f, -6.f));
  EXPECT_FLOAT_EQ(s.intensities[1], 0.f);
}

TEST(KittiVelodyneTest, EmptyFileIsAnEmptyScan) {
  TempDir dir;
  WriteFloats(dir.file("e.bin"), {});
  const VelodyneScan s = ReadVelodyneBin(dir.file("e.bin"));
  EXPECT_TRUE(s.points.empty());
  EXPECT_EQ(s.dropped_non_finite, 0);
}

TEST(KittiVelodyneBadInputTest, SizeNotAMultipleOf16NamesTheFile) {
  TempDir dir;
  WriteFloats(dir.file("t.bin"), {1.f, 2.f, 3.f, 0.5f, 1.f, 2.f});  // 24 bytes
  const std::string e = ErrorOf([&] { ReadVelodyneBin(dir.file("t.bin")); });
  EXPECT_NE(e.find(dir.file("t.bin")), std::string::npos) << e;
  EXPECT_NE(e.find("24 bytes"), std::string::npos) << e;
  EXPECT_NE(e.find("multiple of 16"), std::string::npos) << e;
  const std::string m = ErrorOf([&] { ReadVelodyneBin(dir.file("missing.bin")); });
  EXPECT_NE(m.find("missing.bin"), std::string::npos) << m;
}

TEST(KittiVelodyneTest, ParsesTr) {
  const std::string calib =
      "P0: 50 0 5 0 0 50 3 0 0 0 1 0\n"
      "Tr: 0 -1 0 0.1 0 0 -1 -0.2 1 0 0 -0.3\n";
  const Eigen::Isometry3d T = ParseKittiVelodyneToCamera(calib, "calib.txt");
  // Velodyne x forward -> camera z forward; Velodyne y left -> camera -x.
  EXPECT_TRUE((T.linear() * Eigen::Vector3d::UnitX()).isApprox(Eigen::Vector3d::UnitZ()));
  EXPECT_TRUE((T.linear() * Eigen::Vector3d::UnitY()).isApprox(-Eigen::Vector3d::UnitX()));
  EXPECT_TRUE(T.translation().isApprox(Eigen::Vector3d(0.1, -0.2, -0.3)));
}

TEST(KittiVelodyneBadInputTest, MissingOrBadTrNamesTheFile) {
  const std::string missing =
      ErrorOf([] { ParseKittiVelodyneToCamera("P0: 1 0 0 0 0 1 0 0 0 0 1 0\n", "seq/calib.txt"); });
  EXPECT_NE(missing.find("seq/calib.txt"), std::string::npos) << missing;
  EXPECT_NE(missing.find("Tr"), std::string::npos) << missing;
  const std::string shortrow =
      ErrorOf([] { ParseKittiVelodyneToCamera("Tr: 1 0 0 0 0 1 0 0 0 0 1\n", "seq/calib.txt"); });
  EXPECT_NE(shortrow.find("seq/calib.txt:1"), std::string::npos) << shortrow;
  const std::string notrot =
      ErrorOf([] { ParseKittiVelodyneToCamera("Tr: 2 0 0 0 0 1 0 0 0 0 1 0\n", "seq/calib.txt"); });
  EXPECT_NE(notrot.find("rotation"), std::string::npos) << notrot;
}

// A minimal odometry folder with `scans` Velodyne files and the given calib.txt.
std::string OdometryFolder(const TempDir& dir, int frames, int scans, const std::string& calib) {
  const std::string root = dir.file("seq");
  fs::create_directories(root + "/image_0");
  fs::create_directories(root + "/image_1");
  fs::create_directories(root + "/velodyne");
  std::string times;
  for (int i = 0; i < frames; ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "%06d", i);
    cv::imwrite(root + "/image_0/" + name + ".png", cv::Mat(6, 10, CV_8UC1, cv::Scalar(100)));
    cv::imwrite(root + "/image_1/" + name + ".png", cv::Mat(6, 10, CV_8UC1, cv::Scalar(100)));
    if (i < scans) WriteFloats(root + "/velodyne/" + name + ".bin", {1.f, 0.f, 0.f, 0.3f});
    times += std::to_string(0.1 * i) + "\n";
  }
  fl::test::WriteText(root + "/times.txt", times);
  fl::test::WriteText(root + "/calib.txt", calib);
  return root;
}

const char* kCalibWithTr =
    "P0: 50 0 5 0 0 50 3 0 0 0 1 0\nP1: 50 0 5 -25 0 50 3 0 0 0 1 0\n"
    "Tr: 0 -1 0 0 0 0 -1 0 1 0 0 0\n";

TEST(KittiVelodyneTest, FolderListsOneScanPerFrameWithTheTransform) {
  TempDir dir;
  const std::string root = OdometryFolder(dir, 3, 3, kCalibWithTr);
  KittiOptions opts;
  opts.allow_no_ground_truth = true;
  const KittiSequence seq = ScanKittiFolder(opts, root);
  ASSERT_EQ(seq.velodyne_scans.size(), 3u);
  EXPECT_EQ(fs::path(seq.velodyne_scans[2]).filename().string(), "000002.bin");
  EXPECT_TRUE((seq.T_cam0_velo * Eigen::Vector3d::UnitX()).isApprox(Eigen::Vector3d::UnitZ()));
}

TEST(KittiVelodyneBadInputTest, FolderWithScansButNoTrOrTooFewScans) {
  TempDir a, b;
  KittiOptions opts;
  opts.allow_no_ground_truth = true;
  const std::string no_tr =
      OdometryFolder(a, 2, 2, "P0: 50 0 5 0 0 50 3 0 0 0 1 0\nP1: 50 0 5 -25 0 50 3 0 0 0 1 0\n");
  const std::string e1 = ErrorOf([&] { ScanKittiFolder(opts, no_tr); });
  EXPECT_NE(e1.find(no_tr + "/calib.txt"), std::string::npos) << e1;
  EXPECT_NE(e1.find("'Tr:'"), std::string::npos) << e1;
  const std::string few = OdometryFolder(b, 3, 2, kCalibWithTr);
  const std::string e2 = ErrorOf([&] { ScanKittiFolder(opts, few); });
  EXPECT_NE(e2.find("2 .bin scans for 3 images"), std::string::npos) << e2;
}

TEST(KittiVelodyneTest, ConversionWritesLaser3dAndItsMounting) {
  TempDir dir;
  const std::string root = OdometryFolder(dir, 3, 3, kCalibWithTr);
  // Frame 1's scan: two points and a NaN one.
  WriteFloats(root + "/velodyne/000001.bin",
              {5.f, 1.f, -1.5f, 0.25f, std::numeric_limits<float>::quiet_NaN(), 0.f, 0.f, 0.f, -2.f,
               3.f, 0.5f, 0.75f});
  KittiOptions opts;
  opts.allow_no_ground_truth = true;
  const ConvertSummary s = ConvertKitti(opts, root, dir.file("o.lcmlog"));
  EXPECT_EQ(s.messages.at(channels::kLaser3d), 3);
  const auto log = fl::test::ReadLog(dir.file("o.lcmlog"));
  const auto scan = log.Decode<fusionloc::laser_scan_3d_t>(channels::kLaser3d, 1);
  EXPECT_EQ(scan.frame, "velodyne");
  EXPECT_EQ(scan.utime, kKittiOdometryEpochUtime + 100000);
  ASSERT_EQ(scan.num_points, 2);
  EXPECT_FLOAT_EQ(scan.x[0], 5.f);
  EXPECT_FLOAT_EQ(scan.y[0], 1.f);
  EXPECT_FLOAT_EQ(scan.z[0], -1.5f);
  EXPECT_FLOAT_EQ(scan.intensity[0], 0.25f);
  EXPECT_FLOAT_EQ(scan.x[1], -2.f);
  EXPECT_FLOAT_EQ(scan.intensity[1], 0.75f);
  bool warned = false;
  for (const auto& w : s.warnings)
    warned |= w.find("1 non-finite points dropped") != std::string::npos;
  EXPECT_TRUE(warned);
  // Each scan comes just before its frame's images (a subscriber has it for the frame).
  for (size_t k = 0; k < 3; ++k) {
    EXPECT_LT(log.IndexOf(channels::kLaser3d, k), log.IndexOf(channels::kStereo, k)) << k;
    if (k > 0) {
      EXPECT_GT(log.IndexOf(channels::kLaser3d, k), log.IndexOf(channels::kStereo, k - 1)) << k;
    }
  }
  // The fixture's Tr turns Velodyne axes (x forward, y left, z up) into the optical frame, and
  // the base has the same axes as the Velodyne: T_base_velodyne = identity.
  ASSERT_GE(log.IndexOf(channels::kLaser3dToBase, 0), 0);
  const auto m = log.Decode<bot_core::rigid_transform_t>(channels::kLaser3dToBase, 0);
  const Eigen::Isometry3d T = IsometryFromArrays(m.trans, m.quat);
  EXPECT_TRUE(T.isApprox(Eigen::Isometry3d::Identity(), 1e-12));

  // Without laser_3d: no LASER_3D.
  opts.laser_3d = false;
  const ConvertSummary none = ConvertKitti(opts, root, dir.file("n.lcmlog"));
  EXPECT_EQ(none.messages.count(channels::kLaser3d), 0u);
  EXPECT_EQ(none.messages.count(channels::kLaser3dToBase), 0u);
}

TEST(KittiVelodyneTest, RealSnippetHasScansInFrontOfTheCamera) {
  const std::string folder = fl::test::SharedDataDir() + "/lidar_stereo/kitti_odometry_04_f000-050";
  FL_REQUIRE_SHARED_FILE(folder + "/velodyne/000000.bin");
  KittiOptions opts;
  opts.poses_file = folder + "/poses.txt";
  const KittiSequence seq = ScanKittiFolder(opts, folder);
  ASSERT_EQ(seq.velodyne_scans.size(), seq.left_images.size());
  const VelodyneScan s = ReadVelodyneBin(seq.velodyne_scans[0]);
  EXPECT_GT(s.points.size(), 100000u);
  // The HDL-64E sees all around: about a quarter of the points lie in the camera's view cone.
  int in_front = 0;
  for (const auto& p : s.points) {
    const Eigen::Vector3d c = seq.T_cam0_velo * p.cast<double>();
    if (c.z() > 1.0 && std::abs(c.x()) < c.z()) ++in_front;
  }
  EXPECT_GT(in_front, static_cast<int>(s.points.size()) / 8);
  EXPECT_LT(in_front, static_cast<int>(s.points.size()) / 2);
}

}  // namespace
}  // namespace fl::importers
