// Stereo sources and fl-stereo-driver: a folder played at a requested rate (time stamps
// 1/rate apart in data time, left and right paired by name, a missing right image an error
// or a counted skip), a side-by-side camera split into left and right with dropped frames and
// a vanishing camera counted and reconnected (a scripted grabber), and bad inputs.
#include <gtest/gtest.h>

#include <deque>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <thread>

#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/stereo/sources.hpp"
#include "fusionloc/stereo/stereo_driver_lcm.hpp"
#include "test_paths.hpp"

namespace fl::stereo {
namespace {

namespace fs = std::filesystem;
using fl::test::BinDir;
using fl::test::RunCommand;
using fl::test::TempDir;

// left/<name>.png holds the value v, right/<name>.png 100 + v: a mispair shows.
void WritePairs(const std::string& root, const std::string& left_dir, const std::string& right_dir,
                int n, int skip_right = -1) {
  fs::create_directories(root + "/" + left_dir);
  fs::create_directories(root + "/" + right_dir);
  for (int i = 0; i < n; ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "%06d.png", i);
    cv::imwrite(root + "/" + left_dir + "/" + name, cv::Mat(6, 8, CV_8U, cv::Scalar(i)));
    if (i != skip_right) {
      cv::imwrite(root + "/" + right_dir + "/" + name, cv::Mat(6, 8, CV_8U, cv::Scalar(100 + i)));
    }
  }
}

RigCalibration SmallRectified() {
  RigCalibration c;
  c.width = 8;
  c.height = 6;
  c.rectified = true;
  c.left = {10.0, 10.0, 4.0, 3.0, {}};
  c.right = c.left;
  c.translation = {-0.1, 0, 0};
  return c;
}

TEST(FolderSource, PlaysAtTheRequestedRateAndPairsByName) {
  TempDir dir;
  WritePairs(dir.path(), "left", "right", 7);
  FolderSourceOptions o;
  o.rate_hz = 8.0;
  FolderSource src(dir.path(), o, 1000000);
  EXPECT_EQ(src.pairs().layout, "left/right");
  StereoFrame f;
  int i = 0;
  while (src.Next(&f)) {
    EXPECT_EQ(f.utime, 1000000 + i * 125000);  // 1 / 8 Hz apart
    EXPECT_EQ(f.left.at<uint8_t>(0, 0), i);
    EXPECT_EQ(f.right.at<uint8_t>(0, 0), 100 + i);
    ++i;
  }
  EXPECT_EQ(i, 7);
}

TEST(FolderSource, FindsTheKittiLayouts) {
  TempDir raw, odo;
  WritePairs(raw.path(), "image_00/data", "image_01/data", 2);
  WritePairs(odo.path(), "image_0", "image_1", 3);
  EXPECT_EQ(ListImagePairs(raw.path(), false).layout, "KITTI raw");
  EXPECT_EQ(ListImagePairs(odo.path(), false).left.size(), 3u);
  EXPECT_EQ(ListImagePairs(odo.path(), false).layout, "KITTI odometry");
}

TEST(FolderSource, AMissingRightImageIsAnErrorOrACountedSkip) {
  TempDir dir;
  WritePairs(dir.path(), "left", "right", 5, /*skip_right=*/2);
  try {
    ListImagePairs(dir.path(), false);
    FAIL() << "a missing right image was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("left/000002.png"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("skip_unpaired"), std::string::npos) << e.what();
  }
  FolderSourceOptions o;
  o.skip_unpaired = true;
  FolderSource src(dir.path(), o, 0);
  EXPECT_EQ(src.pairs().unpaired.size(), 1u);
  StereoFrame f;
  std::vector<int> values;
  while (src.Next(&f)) {
    EXPECT_EQ(f.right.at<uint8_t>(0, 0), 100 + f.left.at<uint8_t>(0, 0));  // never mispaired
    values.push_back(f.left.at<uint8_t>(0, 0));
  }
  EXPECT_EQ(values, (std::vector<int>{0, 1, 3, 4}));
}

TEST(FolderSource, BadFoldersAreClearErrors) {
  TempDir dir;
  fs::create_directories(dir.file("images"));
  try {
    ListImagePairs(dir.path(), false);
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("has no image pairs: expected image_00/data/"),
              std::string::npos)
        << e.what();
  }
  fs::create_directories(dir.file("left"));
  fs::create_directories(dir.file("right"));
  cv::imwrite(dir.file("left/a.png"), cv::Mat(2, 2, CV_8U));
  cv::imwrite(dir.file("right/b.png"), cv::Mat(2, 2, CV_8U));
  try {
    ListImagePairs(dir.path(), true);
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("no image in"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ListImagePairs(dir.file("nope"), false), std::runtime_error);
}

TEST(FolderSource, AnUnreadableImageIsSkippedCountedAndKeepsItsTimeSlot) {
  TempDir dir;
  WritePairs(dir.path(), "left", "right", 3);
  std::ofstream(dir.file("right/000001.png")) << "not a png";
  FolderSourceOptions o;
  o.rate_hz = 10;
  FolderSource src(dir.path(), o, 0);
  StereoFrame f;
  std::vector<Utime> stamps;
  while (src.Next(&f)) stamps.push_back(f.utime);
  EXPECT_EQ(stamps, (std::vector<Utime>{0, 200000}));
  EXPECT_EQ(src.unreadable(), 1);
  EXPECT_NE(src.last_problem().find("right/000001.png"), std::string::npos);
}

// A camera that plays a script: frames, failed reads, failed opens.
class ScriptedGrabber : public FrameGrabber {
 public:
  std::deque<char> reads;  // 'f' frame, 'x' failed read
  int fail_opens = 0;      // after the first open
  int opens = 0;
  bool Open(std::string* error) override {
    ++opens;
    if (opens > 1 && fail_opens > 0) {
      --fail_opens;
      *error = "scripted camera unplugged";
      return false;
    }
    return true;
  }
  bool Read(cv::Mat* frame) override {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    if (reads.empty() || reads.front() == 'x') {
      if (!reads.empty()) reads.pop_front();
      return false;
    }
    reads.pop_front();
    *frame = cv::Mat(6, 16, CV_8U, cv::Scalar(10));
    (*frame)(cv::Rect(8, 0, 8, 6)).setTo(200);
    return true;
  }
  void Close() override {}
  std::string name() const override { return "scripted"; }
};

TEST(SideBySideCamera, SplitsCountsDropsAndReconnects) {
  auto g = std::make_unique<ScriptedGrabber>();
  ScriptedGrabber* grabber = g.get();
  grabber->reads = {'f', 'f', 'x', 'f'};
  for (int i = 0; i < 40; ++i) grabber->reads.push_back('x');  // ~0.2 s without a frame
  grabber->fail_opens = 2;
  CameraSourceOptions o;
  o.width = 16;
  o.height = 6;
  o.fps = 1000;  // no time-gap drops from the scripted timing
  o.frame_timeout_s = 0.1;
  o.reconnect_interval_s = 0.05;
  SideBySideCamera cam(std::move(g), o);
  StereoFrame f;
  int frames = 0;
  const Utime end = MonotonicUtime() + 2000000;
  while (MonotonicUtime() < end && cam.reconnects() == 0) {
    if (cam.Next(&f)) {
      ++frames;
      EXPECT_EQ(f.left.cols, 8);
      EXPECT_EQ(f.left.at<uint8_t>(0, 0), 10);    // left half
      EXPECT_EQ(f.right.at<uint8_t>(0, 0), 200);  // right half
    }
  }
  EXPECT_EQ(frames, 3);
  EXPECT_GE(cam.dropped(), 20);  // the failed reads until the timeout
  EXPECT_EQ(cam.disconnects(), 1);
  EXPECT_EQ(cam.reconnects(), 1);
  EXPECT_EQ(grabber->opens, 4);  // the first, two failures, the reconnect
  grabber->reads = {'f'};
  ASSERT_TRUE(cam.Next(&f));  // and frames flow again
  EXPECT_TRUE(cam.connected());
}

TEST(SideBySideCamera, NodePublishesRectifiedPairsAndCalibration) {
  auto g = std::make_unique<ScriptedGrabber>();
  for (int i = 0; i < 5; ++i) g->reads.push_back('f');
  StereoDriverOptions o;
  o.camera.width = 16;
  o.camera.height = 6;
  auto lcm = fl::MakeLcm("memq://");
  std::vector<bot_core::images_t> pairs;
  std::vector<fusionloc::stereo_calibration_t> calibs;
  lcm->Subscribe<bot_core::images_t>(
      "STEREO", [&](const bot_core::images_t& m, const std::string&) { pairs.push_back(m); });
  lcm->Subscribe<fusionloc::stereo_calibration_t>(
      "STEREO_CALIBRATION",
      [&](const fusionloc::stereo_calibration_t& m, const std::string&) { calibs.push_back(m); });
  const RigCalibration calib = SmallRectified();
  StereoDriverNode node(o, std::move(g), &calib, lcm.get(), fl::ChannelMap());
  for (int i = 0; i < 8; ++i) node.Step();
  ASSERT_EQ(pairs.size(), 5u);
  ASSERT_GE(calibs.size(), 1u);
  EXPECT_EQ(calibs[0].width, 8);
  EXPECT_EQ(calibs[0].baseline, 0.1);
  EXPECT_TRUE(calibs[0].rectified);
  const auto& p = pairs[0];
  ASSERT_EQ(p.n_images, 2);
  const int16_t kLeft = bot_core::images_t::LEFT, kRight = bot_core::images_t::RIGHT;
  EXPECT_EQ(p.image_types[0], kLeft);
  EXPECT_EQ(p.image_types[1], kRight);
  EXPECT_EQ(p.images[0].utime, p.utime);
  EXPECT_EQ(p.images[1].data[0], 200);
  EXPECT_EQ(p.images[0].data[0], 10);
}

TEST(SideBySideCamera, CapturesRawPairsForTheCalibration) {
  TempDir dir;
  auto g = std::make_unique<ScriptedGrabber>();
  for (int i = 0; i < 4; ++i) g->reads.push_back('f');
  StereoDriverOptions o;
  o.camera.width = 16;
  o.camera.height = 6;
  o.capture_folder = dir.file("pairs");
  o.capture_period_s = 0.0;
  auto lcm = fl::MakeLcm("memq://");
  StereoDriverNode node(o, std::move(g), nullptr, lcm.get(), fl::ChannelMap());  // no calib
  for (int i = 0; i < 6; ++i) node.Step();
  EXPECT_EQ(node.captured(), 4);
  EXPECT_EQ(node.published(), 0);                                     // capturing only
  const ImagePairs pairs = ListImagePairs(dir.file("pairs"), false);  // as the calibration reads
  ASSERT_EQ(pairs.left.size(), 4u);
  EXPECT_EQ(cv::imread(pairs.left[0], cv::IMREAD_GRAYSCALE).at<uint8_t>(0, 0), 10);
  EXPECT_EQ(cv::imread(pairs.right[0], cv::IMREAD_GRAYSCALE).at<uint8_t>(0, 0), 200);
}

TEST(CheckVideoDevice, NamesTheProblem) {
  TempDir dir;
  EXPECT_NE(CheckVideoDevice(dir.file("video9")).find("does not exist: is it plugged in"),
            std::string::npos);
  std::ofstream(dir.file("file")) << "x";
  EXPECT_NE(CheckVideoDevice(dir.file("file")).find("not a video device"), std::string::npos);
  EXPECT_EQ(CheckVideoDevice("/dev/null"), "");  // a character device: V4L2 decides
  std::string error;
  CameraSourceOptions o;
  o.device = "/dev/null";
  EXPECT_FALSE(MakeV4l2Grabber(o)->Open(&error));
  EXPECT_NE(error.find("V4L2 cannot capture from it"), std::string::npos) << error;
}

TEST(StereoDriverProgram, FolderToALogAtTheRequestedRate) {
  TempDir dir;
  WritePairs(dir.file("pairs"), "left", "right", 6);
  SaveRigCalibration(SmallRectified(), dir.file("rig.yaml"));
  const auto r = RunCommand(BinDir() +
                                "/fl-stereo-driver --folder pairs --calibration rig.yaml "
                                "--rate 4 --log out.lcmlog",
                            dir);
  ASSERT_EQ(r.status, 0) << r.err;
  fl::LcmLogReader in(dir.file("out.lcmlog"));
  fl::LcmLogEvent ev;
  std::vector<Utime> stamps;
  int calibrations = 0;
  while (in.Next(&ev)) {
    if (ev.channel == "STEREO") {
      bot_core::images_t m;
      ASSERT_GT(m.decode(ev.data.data(), 0, static_cast<int>(ev.data.size())), 0);
      EXPECT_EQ(m.utime, ev.utime);
      EXPECT_EQ(m.images[1].data[0], 100 + m.images[0].data[0]);
      EXPECT_EQ(m.images[0].data[0], static_cast<int>(stamps.size()));
      stamps.push_back(m.utime);
    }
    if (ev.channel == "STEREO_CALIBRATION") ++calibrations;
  }
  ASSERT_EQ(stamps.size(), 6u);
  for (size_t i = 1; i < stamps.size(); ++i) EXPECT_EQ(stamps[i] - stamps[i - 1], 250000);
  EXPECT_EQ(calibrations, 2);  // at 0 s and 1 s of data time
}

TEST(StereoDriverProgram, BadInputsExitWithTheFix) {
  TempDir dir;
  fs::create_directories(dir.file("empty"));
  const auto no_pairs = RunCommand(BinDir() + "/fl-stereo-driver --folder empty --log x", dir);
  EXPECT_EQ(no_pairs.status, 1) << no_pairs.err;
  EXPECT_NE(no_pairs.err.find("has no image pairs"), std::string::npos) << no_pairs.err;
  WritePairs(dir.file("pairs"), "left", "right", 2);
  const auto no_cal = RunCommand(BinDir() + "/fl-stereo-driver --folder pairs --log x", dir);
  EXPECT_EQ(no_cal.status, 2) << no_cal.err;
  EXPECT_NE(no_cal.err.find("give --calibration FILE"), std::string::npos) << no_cal.err;
  RigCalibration big = SmallRectified();
  big.width = 640;
  big.height = 480;
  SaveRigCalibration(big, dir.file("big.yaml"));
  const auto wrong =
      RunCommand(BinDir() + "/fl-stereo-driver --folder pairs --calibration big.yaml --log x", dir);
  EXPECT_EQ(wrong.status, 1) << wrong.err;
  EXPECT_NE(wrong.err.find("is 8x6 but the calibration is for 640x480"), std::string::npos)
      << wrong.err;
  RigCalibration cam = SmallRectified();
  cam.width = 640;
  cam.height = 480;
  SaveRigCalibration(cam, dir.file("cam.yaml"));
  const auto not_camera = RunCommand(BinDir() +
                                         "/fl-stereo-driver --lcm-url memq:// "
                                         "--calibration cam.yaml --device /dev/null",
                                     dir);
  EXPECT_EQ(not_camera.status, 1) << not_camera.err;
  EXPECT_NE(not_camera.err.find("'/dev/null': V4L2 cannot capture from it"), std::string::npos)
      << not_camera.err;
  const auto missing = RunCommand(BinDir() +
                                      "/fl-stereo-driver --lcm-url memq:// "
                                      "--calibration cam.yaml --device /dev/video77",
                                  dir);
  EXPECT_EQ(missing.status, 1) << missing.err;
  EXPECT_NE(missing.err.find("'/dev/video77' does not exist"), std::string::npos) << missing.err;
}

}  // namespace
}  // namespace fl::stereo
