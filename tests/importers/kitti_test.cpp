#include "fusionloc/importers/kitti.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "bot_core/images_t.hpp"
#include "bot_core/pose_t.hpp"
#include "bot_core/rigid_transform_t.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/geometry.hpp"
#include "fusionloc/stereo_calibration_t.hpp"
#include "importer_fixtures.hpp"
#include "test_paths.hpp"

namespace fl::importers {
namespace {

namespace fs = std::filesystem;
using fl::test::TempDir;

std::string ExpectConvertError(const KittiOptions& opts, const std::string& folder,
                               const std::string& out) {
  std::string message;
  try {
    ConvertKitti(opts, folder, out);
    ADD_FAILURE() << "conversion of " << folder << " should have failed";
  } catch (const std::exception& e) {
    message = e.what();
  }
  EXPECT_FALSE(fs::exists(out)) << "half-written output left at " << out;
  EXPECT_FALSE(fs::exists(out + ".partial")) << "partial output left at " << out;
  return message;
}

Eigen::Isometry3d PoseOf(const bot_core::pose_t& p) {
  return IsometryFromArrays(p.pos, p.orientation);
}

TEST(KittiTest, ParsesTimestamps) {
  Utime t = 0;
  ASSERT_TRUE(ParseKittiTimestamp("2011-09-26 13:02:25.967790592", &t));
  EXPECT_EQ(t, 1317042145967791);  // rounded to the microsecond
  ASSERT_TRUE(ParseKittiTimestamp("1970-01-01 00:00:01.5", &t));
  EXPECT_EQ(t, 1500000);
  ASSERT_TRUE(ParseKittiTimestamp("1970-01-01 00:00:02", &t));
  EXPECT_EQ(t, 2000000);
  EXPECT_FALSE(ParseKittiTimestamp("2011-09-26", &t));
  EXPECT_FALSE(ParseKittiTimestamp("2011-09-26 13:02:25.96x", &t));
  EXPECT_FALSE(ParseKittiTimestamp("2011-13-26 13:02:25.9", &t));
}

TEST(KittiTest, RotationBaseCameraMapsOpticalAxes) {
  const Eigen::Matrix3d R = RotationBaseCamera();
  EXPECT_TRUE((R * Eigen::Vector3d::UnitZ()).isApprox(Eigen::Vector3d::UnitX()));   // forward
  EXPECT_TRUE((R * Eigen::Vector3d::UnitX()).isApprox(-Eigen::Vector3d::UnitY()));  // right
  EXPECT_TRUE((R * Eigen::Vector3d::UnitY()).isApprox(-Eigen::Vector3d::UnitZ()));  // down
  EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
}

TEST(KittiTest, ConvertsTheRealDrive) {
  const std::string folder = fl::test::SharedDataDir() + "/stereo/kitti_raw_2011_09_26_drive_0001";
  FL_REQUIRE_SHARED_FILE(folder + "/calib_cam_to_cam.txt");
  TempDir dir;
  const std::string out = dir.file("k.lcmlog");
  const ConvertSummary s = ConvertKitti(KittiOptions{}, folder, out);
  EXPECT_EQ(s.messages.at(channels::kStereo), 108);
  EXPECT_EQ(s.messages.at(channels::kGroundTruth), 108);
  EXPECT_GE(s.messages.at(channels::kStereoCalibration), 1);
  EXPECT_TRUE(s.warnings.empty());
  const auto log = fl::test::ReadLog(out);
  EXPECT_EQ(log.channel_order[0], channels::kCameraToBase);  // the mounting, then the intrinsics
  EXPECT_EQ(log.channel_order[1], channels::kStereoCalibration);
  const auto cal = log.Decode<fusionloc::stereo_calibration_t>(channels::kStereoCalibration, 0);
  EXPECT_EQ(cal.width, 1242);
  EXPECT_EQ(cal.height, 375);
  EXPECT_DOUBLE_EQ(cal.fx, 721.5377);
  EXPECT_DOUBLE_EQ(cal.cx, 609.5593);
  EXPECT_DOUBLE_EQ(cal.cy, 172.854);
  EXPECT_NEAR(cal.baseline, 387.5744 / 721.5377, 1e-9);
  EXPECT_TRUE(cal.rectified);
  const auto pair = log.Decode<bot_core::images_t>(channels::kStereo, 0);
  ASSERT_EQ(pair.n_images, 2);
  EXPECT_EQ(pair.image_types[0], 0);
  EXPECT_EQ(pair.image_types[1], 1);
  EXPECT_EQ(pair.utime, 1317042145967791);  // image_00/timestamps.txt line 1
  const int32_t gray = bot_core::image_t::PIXEL_FORMAT_GRAY;
  EXPECT_EQ(pair.images[0].pixelformat, gray);
  EXPECT_EQ(pair.images[1].width, 1242);
  EXPECT_EQ(pair.images[1].row_stride, 1242);
  EXPECT_EQ(pair.images[1].size, 1242 * 375);
  const cv::Mat png = cv::imread(folder + "/image_01/data/0000000000.png", cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(png.empty());
  EXPECT_EQ(0, std::memcmp(png.data, pair.images[1].data.data(), 1242 * 375));
  // Ground truth: identity at frame 0; the car drives forward (base +x), about 107 m in all.
  const auto gt0 = log.Decode<bot_core::pose_t>(channels::kGroundTruth, 0);
  EXPECT_TRUE(PoseOf(gt0).isApprox(Eigen::Isometry3d::Identity(), 1e-6));
  double length = 0;
  Eigen::Vector3d prev = Eigen::Vector3d::Zero();
  for (size_t i = 1; i < 108; ++i) {
    const Eigen::Vector3d p =
        PoseOf(log.Decode<bot_core::pose_t>(channels::kGroundTruth, i)).translation();
    length += (p - prev).norm();
    prev = p;
  }
  EXPECT_NEAR(length, 107.0, 3.0);
  const auto gt1 = log.Decode<bot_core::pose_t>(channels::kGroundTruth, 1);
  EXPECT_GT(gt1.pos[0], 0.5);                         // forward
  EXPECT_LT(std::abs(gt1.pos[2]), 0.1 * gt1.pos[0]);  // on the ground
  const auto& t = log.utimes.at(channels::kStereo);
  for (size_t i = 1; i < t.size(); ++i) ASSERT_GT(t[i], t[i - 1]);
}

TEST(KittiTest, GroundTruthIsTheBaseFramePose) {
  TempDir dir;
  fl::test::KittiRawFixture fx;
  fx.frames = 4;
  fx.Write(dir.file("drive"));
  KittiOptions opts;
  opts.start_frame = 1;
  const ConvertSummary s = ConvertKitti(opts, dir.file("drive"), dir.file("o.lcmlog"));
  EXPECT_EQ(s.messages.at(channels::kStereo), 3);
  const auto log = fl::test::ReadLog(dir.file("o.lcmlog"));
  // The camera moves 1 m along its optical z per frame: the base moves 1 m along x, and world
  // is the base at the first converted frame.
  for (size_t i = 0; i < 3; ++i) {
    const auto gt = log.Decode<bot_core::pose_t>(channels::kGroundTruth, i);
    EXPECT_NEAR(gt.pos[0], static_cast<double>(i), 1e-9);
    EXPECT_NEAR(gt.pos[1], 0.0, 1e-9);
    EXPECT_NEAR(gt.pos[2], 0.0, 1e-9);
    EXPECT_NEAR(gt.orientation[0], 1.0, 1e-9);
  }
  const auto pair = log.Decode<bot_core::images_t>(channels::kStereo, 0);
  EXPECT_EQ(pair.utime, 1317042145100000);  // frame 1: 13:02:25.100000005
  EXPECT_EQ(pair.images[0].data[0], 1);     // left pixel (0,0) of frame 1 = 0 + 1
  EXPECT_EQ(pair.images[1].data[0], 3);     // right = 0 + 2 * 1 + 1
  const auto cal = log.Decode<fusionloc::stereo_calibration_t>(channels::kStereoCalibration, 0);
  EXPECT_DOUBLE_EQ(cal.baseline, 0.5);
  // CAMERA_TO_BASE (T_base_camera) comes first: rotation optical -> base, no translation for
  // cam0.
  ASSERT_LT(log.IndexOf(channels::kCameraToBase, 0), log.IndexOf(channels::kStereoCalibration, 0));
  const auto mount = log.Decode<bot_core::rigid_transform_t>(channels::kCameraToBase, 0);
  const Eigen::Isometry3d T_bc = IsometryFromArrays(mount.trans, mount.quat);
  EXPECT_TRUE(T_bc.linear().isApprox(RotationBaseCamera(), 1e-12));
  EXPECT_NEAR(T_bc.translation().norm(), 0.0, 1e-12);
}

// `count` pairs 000000.png ... of `image` in root/left and root/right (odometry layout).
void WriteOdometryPairs(const std::string& root, const std::string& left, const std::string& right,
                        int count, const cv::Mat& image) {
  fs::create_directories(root + "/" + left);
  fs::create_directories(root + "/" + right);
  for (int i = 0; i < count; ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "%06d.png", i);
    cv::imwrite(root + "/" + left + "/" + name, image);
    cv::imwrite(root + "/" + right + "/" + name, image);
  }
}

TEST(KittiTest, OdometryLayoutColourToGrayAndEpoch) {
  TempDir dir;
  const std::string root = dir.file("seq");
  WriteOdometryPairs(root, "image_2", "image_3", 2, cv::Mat(6, 10, CV_8UC3, cv::Scalar(0, 0, 255)));  // red
  fl::test::WriteText(root + "/times.txt", "0.000000e+00\n1.036594e-01\n");
  fl::test::WriteText(root + "/calib.txt",
                      "P0: 50 0 5 0 0 50 3 0 0 0 1 0\nP1: 50 0 5 -25 0 50 3 0 0 0 1 0\n"
                      "P2: 50 0 5 5 0 50 3 0 0 0 1 0\nP3: 50 0 5 -20 0 50 3 0 0 0 1 0\n");
  KittiOptions opts;
  opts.allow_no_ground_truth = true;
  const ConvertSummary s = ConvertKitti(opts, root, dir.file("o.lcmlog"));
  EXPECT_EQ(s.messages.at(channels::kStereo), 2);
  EXPECT_EQ(s.messages.count(channels::kGroundTruth), 0u);
  ASSERT_EQ(s.warnings.size(), 1u);
  const auto log = fl::test::ReadLog(dir.file("o.lcmlog"));
  const auto pair = log.Decode<bot_core::images_t>(channels::kStereo, 1);
  EXPECT_EQ(pair.utime, kKittiOdometryEpochUtime + 103659);
  EXPECT_EQ(pair.images[0].width, 10);
  EXPECT_EQ(pair.images[0].height, 6);
  EXPECT_EQ(pair.images[0].data[0], 76);  // OpenCV gray of pure red: 0.299 * 255
  const auto cal = log.Decode<fusionloc::stereo_calibration_t>(channels::kStereoCalibration, 0);
  EXPECT_DOUBLE_EQ(cal.baseline, 0.5);  // (5 - (-20)) / 50
  // The left colour camera sits 0.1 m to the left of cam0 (P2 tx = 5 / 50): +y in base.
  EXPECT_NEAR(log.Decode<bot_core::rigid_transform_t>(channels::kCameraToBase, 0).trans[1], 0.1,
              1e-12);
}

TEST(KittiTest, OxtsPosesReproduceThePoseFile) {
  const std::string folder = fl::test::SharedDataDir() + "/stereo/kitti_raw_2011_09_26_drive_0001";
  FL_REQUIRE_SHARED_FILE(folder + "/poses_cam0_from_oxts.txt");
  FL_REQUIRE_SHARED_FILE(folder + "/oxts/data");
  const std::vector<Eigen::Isometry3d> oxts = PosesFromOxts(folder);
  KittiOptions opts;
  const KittiSequence seq = ScanKittiFolder(opts, folder);
  ASSERT_EQ(oxts.size(), seq.T_cam0start_cam0.size());
  ASSERT_EQ(oxts.size(), 108u);
  for (size_t i = 0; i < oxts.size(); ++i) {
    EXPECT_LT((oxts[i].translation() - seq.T_cam0start_cam0[i].translation()).norm(), 1e-5) << i;
    const Eigen::Matrix3d dR = oxts[i].linear().transpose() * seq.T_cam0start_cam0[i].linear();
    EXPECT_LT(Eigen::AngleAxisd(dR).angle(), 1e-6) << i;
  }
}

TEST(KittiTest, GroundTruthFromOxtsWhenNoPoseFile) {
  TempDir dir;
  fl::test::KittiRawFixture fx;
  fx.write_poses = false;
  fx.write_oxts = true;
  fx.Write(dir.file("d"));
  const ConvertSummary s = ConvertKitti(KittiOptions{}, dir.file("d"), dir.file("o.lcmlog"));
  ASSERT_EQ(s.messages.at(channels::kGroundTruth), 3);
  EXPECT_TRUE(s.warnings.empty());
  ASSERT_EQ(s.notes.size(), 1u);
  EXPECT_NE(s.notes[0].find("computed from"), std::string::npos);
  const auto log = fl::test::ReadLog(dir.file("o.lcmlog"));
  for (size_t i = 0; i < 3; ++i) {
    const auto gt = log.Decode<bot_core::pose_t>(channels::kGroundTruth, i);
    EXPECT_NEAR(gt.pos[0], static_cast<double>(i), 1e-6);  // 1 m east = 1 m forward
    EXPECT_NEAR(gt.pos[1], 0.0, 1e-6);
    EXPECT_NEAR(gt.pos[2], 0.0, 1e-6);
  }
  // A record with too few fields is an error naming the file and line.
  fl::test::WriteText(dir.file("d/oxts/data/0000000001.txt"), "49.0 8.4 116.0\n");
  const std::string msg = ExpectConvertError(KittiOptions{}, dir.file("d"), dir.file("p.lcmlog"));
  EXPECT_NE(msg.find("oxts/data/0000000001.txt:1: OXTS record"), std::string::npos) << msg;
}

// ---- bad input ----

TEST(KittiBadInputTest, MissingImage) {
  TempDir dir;
  fl::test::KittiRawFixture().Write(dir.file("d"));
  fs::remove(dir.file("d/image_01/data/0000000001.png"));
  const std::string msg = ExpectConvertError(KittiOptions{}, dir.file("d"), dir.file("o.lcmlog"));
  EXPECT_NE(msg.find("image_01/data/0000000001.png: missing right image"), std::string::npos)
      << msg;
  EXPECT_NE(msg.find("3 left vs 2 right"), std::string::npos) << msg;
}

TEST(KittiBadInputTest, UnreadableImage) {
  TempDir dir;
  fl::test::KittiRawFixture().Write(dir.file("d"));
  // The last image is corrupt: the error comes mid-conversion and nothing is left behind.
  fl::test::WriteText(dir.file("d/image_00/data/0000000002.png"), "not a png");
  const std::string msg = ExpectConvertError(KittiOptions{}, dir.file("d"), dir.file("o.lcmlog"));
  EXPECT_NE(msg.find("image_00/data/0000000002.png: cannot read image"), std::string::npos) << msg;
}

TEST(KittiBadInputTest, MismatchedLeftRightCounts) {
  TempDir dir;
  fl::test::KittiRawFixture().Write(dir.file("d"));
  fs::copy_file(dir.file("d/image_00/data/0000000000.png"),
                dir.file("d/image_00/data/0000000003.png"));
  const std::string msg = ExpectConvertError(KittiOptions{}, dir.file("d"), dir.file("o.lcmlog"));
  EXPECT_NE(msg.find("4 left vs 3 right"), std::string::npos) << msg;
}

TEST(KittiBadInputTest, InconsistentCalibration) {
  TempDir dir;
  fl::test::KittiRawFixture fx;
  fx.right_fx = 101.0;
  fx.Write(dir.file("d"));
  const std::string msg = ExpectConvertError(KittiOptions{}, dir.file("d"), dir.file("o.lcmlog"));
  EXPECT_NE(msg.find("calib_cam_to_cam.txt: inconsistent stereo calibration"), std::string::npos)
      << msg;
  EXPECT_NE(msg.find("P_rect_01"), std::string::npos) << msg;

  // Image size that does not match S_rect_00.
  TempDir dir2;
  fl::test::KittiRawFixture ok;
  ok.Write(dir2.file("d"));
  cv::imwrite(dir2.file("d/image_01/data/0000000001.png"), cv::Mat(9, 16, CV_8UC1, cv::Scalar(0)));
  const std::string msg2 =
      ExpectConvertError(KittiOptions{}, dir2.file("d"), dir2.file("o.lcmlog"));
  EXPECT_NE(msg2.find("0000000001.png: image is 16x9 but the calibration says 16x8"),
            std::string::npos)
      << msg2;
}

TEST(KittiBadInputTest, EmptyFolder) {
  TempDir dir;
  fs::create_directories(dir.file("empty"));
  const std::string msg =
      ExpectConvertError(KittiOptions{}, dir.file("empty"), dir.file("o.lcmlog"));
  EXPECT_NE(msg.find("not a KITTI folder"), std::string::npos) << msg;
  // Image folders present but empty.
  fl::test::KittiRawFixture().Write(dir.file("d"));
  for (const auto& e : fs::directory_iterator(dir.file("d/image_00/data"))) fs::remove(e.path());
  const std::string msg2 = ExpectConvertError(KittiOptions{}, dir.file("d"), dir.file("o.lcmlog"));
  EXPECT_NE(msg2.find("image_00/data: no .png images (empty folder)"), std::string::npos) << msg2;
  const std::string msg3 =
      ExpectConvertError(KittiOptions{}, dir.file("nope"), dir.file("o.lcmlog"));
  EXPECT_NE(msg3.find("nope: no such folder"), std::string::npos) << msg3;
}

TEST(KittiBadInputTest, BadTimestampsAndPoses) {
  TempDir dir;
  fl::test::KittiRawFixture().Write(dir.file("d"));
  fl::test::WriteText(dir.file("d/image_00/timestamps.txt"),
                      "2011-09-26 13:02:25.1\n2011-09-26 13:02:xx\n2011-09-26 13:02:25.3\n");
  const std::string msg = ExpectConvertError(KittiOptions{}, dir.file("d"), dir.file("o.lcmlog"));
  EXPECT_NE(msg.find("timestamps.txt:2:"), std::string::npos) << msg;

  TempDir dir2;
  fl::test::KittiRawFixture().Write(dir2.file("d"));
  fl::test::WriteText(dir2.file("d/poses_cam0_from_oxts.txt"), "1 0 0 0 0 1 0 0 0 0 1 0\n");
  const std::string msg2 =
      ExpectConvertError(KittiOptions{}, dir2.file("d"), dir2.file("o.lcmlog"));
  EXPECT_NE(msg2.find("1 poses for 3 frames"), std::string::npos) << msg2;
  fl::test::WriteText(dir2.file("d/poses_cam0_from_oxts.txt"),
                      "1 0 0 0 0 1 0 0 0 0 1 0\n2 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1\n");
  const std::string msg3 =
      ExpectConvertError(KittiOptions{}, dir2.file("d"), dir2.file("o.lcmlog"));
  EXPECT_NE(msg3.find("poses_cam0_from_oxts.txt:2: the 3x3 part is not a rotation"),
            std::string::npos)
      << msg3;
}

// An odometry sequence with its poses/NN.txt copied beside the images as poses.txt: that file is
// the ground truth without --poses; a raw drive's poses.txt is not looked at.
TEST(KittiOdometryTest, PosesTxtInTheFolderIsTheGroundTruth) {
  TempDir dir;
  const std::string root = dir.file("seq");
  WriteOdometryPairs(root, "image_0", "image_1", 2, cv::Mat(6, 10, CV_8UC1, cv::Scalar(90)));
  fl::test::WriteText(root + "/times.txt", "0.0\n0.1\n");
  fl::test::WriteText(root + "/calib.txt",
                      "P0: 50 0 5 0 0 50 3 0 0 0 1 0\nP1: 50 0 5 -25 0 50 3 0 0 0 1 0\n");
  KittiOptions opts;
  const std::string message = ExpectConvertError(opts, root, dir.file("o.lcmlog"));
  EXPECT_NE(message.find("no ground truth"), std::string::npos) << message;
  fl::test::WriteText(root + "/poses.txt",
                      "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0.5 0 1 0 0 0 0 1 0\n");
  const KittiSequence seq = ScanKittiFolder(opts, root);
  EXPECT_EQ(seq.poses_path, root + "/poses.txt");
  ASSERT_EQ(seq.T_cam0start_cam0.size(), 2u);
  EXPECT_NEAR(seq.T_cam0start_cam0[1].translation().x(), 0.5, 1e-12);
}

// Real files in the wild (docs/RELIABILITY.md): a folder whose images were trimmed but whose
// times.txt (and pose file) were not. The first N entries are used, with a warning.
TEST(KittiWildFilesTest, TimesLongerThanTheFramesUseTheFirstN) {
  TempDir dir;
  const std::string root = dir.file("seq");
  WriteOdometryPairs(root, "image_0", "image_1", 2, cv::Mat(6, 10, CV_8UC1, cv::Scalar(90)));
  // 5 times (and 4 poses) for the 2 frames present, as after `rm image_*/00000[2-4].png`.
  fl::test::WriteText(root + "/times.txt", "0.0\n0.1\n0.2\n0.3\n0.4\n");
  fl::test::WriteText(root + "/poses.txt",
                      "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0.5 0 1 0 0 0 0 1 0\n"
                      "1 0 0 1.0 0 1 0 0 0 0 1 0\n1 0 0 1.5 0 1 0 0 0 0 1 0\n");
  fl::test::WriteText(root + "/calib.txt",
                      "P0: 50 0 5 0 0 50 3 0 0 0 1 0\nP1: 50 0 5 -25 0 50 3 0 0 0 1 0\n");
  KittiOptions opts;
  opts.poses_file = root + "/poses.txt";
  const KittiSequence seq = ScanKittiFolder(opts, root);
  ASSERT_EQ(seq.utimes.size(), 2u);
  EXPECT_EQ(seq.utimes[1], kKittiOdometryEpochUtime + 100000);
  ASSERT_EQ(seq.T_cam0start_cam0.size(), 2u);
  EXPECT_NEAR(seq.T_cam0start_cam0[1].translation().x(), 0.5, 1e-12);
  ASSERT_EQ(seq.warnings.size(), 2u);
  EXPECT_NE(seq.warnings[0].find("times.txt: 5 time stamps for 2 images"), std::string::npos)
      << seq.warnings[0];
  EXPECT_NE(seq.warnings[0].find("using the first 2"), std::string::npos) << seq.warnings[0];
  EXPECT_NE(seq.warnings[1].find("poses.txt: 4 poses for 2 frames"), std::string::npos)
      << seq.warnings[1];
  const ConvertSummary s = ConvertKitti(opts, root, dir.file("o.lcmlog"));
  EXPECT_EQ(s.messages.at(channels::kStereo), 2);
  EXPECT_EQ(s.messages.at(channels::kGroundTruth), 2);
  EXPECT_EQ(s.warnings.size(), 2u);

  // Fewer times than images is still an error: which frame would have no time?
  fl::test::WriteText(root + "/times.txt", "0.0\n");
  const std::string msg = ExpectConvertError(opts, root, dir.file("short.lcmlog"));
  EXPECT_NE(msg.find("times.txt: 1 time stamps for 2 images"), std::string::npos) << msg;
}

// The text parsers on their own (the fuzz targets' entry points).
TEST(KittiTest, TextParsersNameTheFileAndLine) {
  EXPECT_EQ(ParseKittiTimes("0\n\n0.5\n", "t.txt").size(), 2u);
  try {
    ParseKittiTimes("0\n-1\n", "t.txt");
    FAIL() << "a negative time was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("t.txt:2: time -1 s is not in [0, 1e9]"),
              std::string::npos)
        << e.what();
  }
  // An image size too large for an int is refused, not cast (undefined behaviour).
  const std::string calib =
      "S_rect_00: 1e10 375\nS_rect_01: 1e10 375\n"
      "P_rect_00: 50 0 5 0 0 50 3 0 0 0 1 0\nP_rect_01: 50 0 5 -25 0 50 3 0 0 0 1 0\n";
  EXPECT_THROW(ParseKittiCalibration(calib, "c.txt", true, false), std::runtime_error);
  const KittiCalibration c = ParseKittiCalibration(
      "S_rect_00: 64 48\nS_rect_01: 64 48\n"
      "P_rect_00: 50 0 5 0 0 50 3 0 0 0 1 0\nP_rect_01: 50 0 5 -25 0 50 3 0 0 0 1 0\n",
      "c.txt", true, false);
  EXPECT_EQ(c.width, 64);
  EXPECT_EQ(c.height, 48);
  EXPECT_DOUBLE_EQ(c.baseline, 0.5);
}

TEST(KittiBadInputTest, NoGroundTruthNeedsAnExplicitChoice) {
  TempDir dir;
  fl::test::KittiRawFixture fx;
  fx.write_poses = false;
  fx.Write(dir.file("d"));
  const std::string msg = ExpectConvertError(KittiOptions{}, dir.file("d"), dir.file("o.lcmlog"));
  EXPECT_NE(msg.find("--poses FILE"), std::string::npos) << msg;
  KittiOptions opts;
  opts.allow_no_ground_truth = true;
  EXPECT_EQ(ConvertKitti(opts, dir.file("d"), dir.file("o.lcmlog")).messages.at(channels::kStereo),
            3);
}

}  // namespace
}  // namespace fl::importers
