#include "fusionloc/maps/map_export.hpp"

#include <gtest/gtest.h>
#include <pcl/io/pcd_io.h>
#include <pcl/point_types.h>
#include <yaml-cpp/yaml.h>

#include <sched.h>
#include <sys/mount.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "fusionloc/common/lcm_interface.hpp"
#include "test_paths.hpp"

namespace fl::maps {
namespace {

// A 4 x 3 grid: row 0 (bottom) = free, unknown, occupied, 50 %; row 1 all unknown;
// row 2 (top) = 100, 0, 25, 65.
fusionloc::occupancy_grid_t MakeGrid() {
  fusionloc::occupancy_grid_t g;
  g.utime = 1;
  g.resolution = 0.05;
  g.width = 4;
  g.height = 3;
  g.origin_x = -1.5;
  g.origin_y = 2.25;
  g.num_cells = 12;
  g.cells = {0, -1, 100, 50, -1, -1, -1, -1, 100, 0, 25, 65};
  return g;
}

std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const MapExportError& e) {
    return e.what();
  }
  return "(no MapExportError thrown)";
}

TEST(MapsGrid, PgmValuesYamlFieldsAndPng) {
  fl::test::TempDir dir;
  const auto files = SaveOccupancyGrid(MakeGrid(), dir.file("map"));
  ASSERT_EQ(files.size(), 3u);
  // PGM: header then 12 bytes, top row first.
  std::ifstream in(dir.file("map.pgm"), std::ios::binary);
  std::string magic, comment_or_w;
  in >> magic;
  EXPECT_EQ(magic, "P5");
  std::string line;
  std::getline(in, line);
  std::getline(in, line);  // comment
  EXPECT_EQ(line[0], '#');
  int w, h, maxval;
  in >> w >> h >> maxval;
  in.get();
  EXPECT_EQ(w, 4);
  EXPECT_EQ(h, 3);
  EXPECT_EQ(maxval, 255);
  std::vector<unsigned char> px(12);
  in.read(reinterpret_cast<char*>(px.data()), 12);
  ASSERT_TRUE(in.good());
  const std::vector<unsigned char> expected = {0,   254, 254, 0,     // top: grid row 2
                                               205, 205, 205, 205,   // grid row 1
                                               254, 205, 0,   205};  // bottom: grid row 0
  EXPECT_EQ(px, expected);

  const YAML::Node y = YAML::LoadFile(dir.file("map.yaml"));
  EXPECT_EQ(y["image"].as<std::string>(), "map.pgm");
  EXPECT_EQ(y["mode"].as<std::string>(), "trinary");
  EXPECT_DOUBLE_EQ(y["resolution"].as<double>(), 0.05);
  ASSERT_EQ(y["origin"].size(), 3u);
  EXPECT_DOUBLE_EQ(y["origin"][0].as<double>(), -1.5);
  EXPECT_DOUBLE_EQ(y["origin"][1].as<double>(), 2.25);
  EXPECT_DOUBLE_EQ(y["origin"][2].as<double>(), 0.0);
  EXPECT_EQ(y["negate"].as<int>(), 0);
  EXPECT_DOUBLE_EQ(y["occupied_thresh"].as<double>(), 0.65);
  EXPECT_DOUBLE_EQ(y["free_thresh"].as<double>(), 0.196);

  const cv::Mat png = cv::imread(dir.file("map.png"), cv::IMREAD_GRAYSCALE);
  ASSERT_EQ(png.cols, 4);
  ASSERT_EQ(png.rows, 3);
  EXPECT_EQ(png.at<uchar>(2, 3), 128);  // 50 % (grid row 0, col 3): 255 * 0.5 rounded
  EXPECT_EQ(png.at<uchar>(2, 0), 255);
  EXPECT_EQ(png.at<uchar>(1, 1), 205);
  EXPECT_FALSE(std::filesystem::exists(dir.file("map.pgm.partial")));
}

TEST(MapsGrid, InvalidGridsAreRejected) {
  fl::test::TempDir dir;
  auto g = MakeGrid();
  g.num_cells = 11;
  EXPECT_NE(ErrorOf([&] { SaveOccupancyGrid(g, dir.file("a")); }).find("num_cells = 11"),
            std::string::npos);
  g = MakeGrid();
  g.cells[5] = 101;
  const std::string msg = ErrorOf([&] { SaveOccupancyGrid(g, dir.file("a")); });
  EXPECT_NE(msg.find("row 1, column 1"), std::string::npos) << msg;
  g = MakeGrid();
  g.resolution = 0;
  EXPECT_NE(ErrorOf([&] { SaveOccupancyGrid(g, dir.file("a")); }).find("resolution"),
            std::string::npos);
  g = MakeGrid();
  g.width = 0;
  EXPECT_NE(ErrorOf([&] { SaveOccupancyGrid(g, dir.file("a")); }).find("empty map"),
            std::string::npos);
  EXPECT_NE(
      ErrorOf([&] { SaveOccupancyGrid(MakeGrid(), dir.file("no/dir/a")); }).find("cannot write"),
      std::string::npos);
  EXPECT_FALSE(std::filesystem::exists(dir.file("a.pgm")));
}

TEST(MapsPcd, BinaryRoundTripWithPcl) {
  fl::test::TempDir dir;
  std::vector<Eigen::Vector3f> pts;
  std::vector<float> intensity;
  for (int i = 0; i < 100; ++i) {
    pts.emplace_back(0.1f * i, -0.05f * i, 1.0f + 0.01f * i);
    intensity.push_back(i / 100.0f);
  }
  SavePointCloudPcd(pts, intensity, dir.file("c.pcd"));
  pcl::PointCloud<pcl::PointXYZI> back;
  ASSERT_EQ(pcl::io::loadPCDFile(dir.file("c.pcd"), back), 0);
  ASSERT_EQ(back.size(), 100u);
  EXPECT_FLOAT_EQ(back[42].x, pts[42].x());
  EXPECT_FLOAT_EQ(back[42].y, pts[42].y());
  EXPECT_FLOAT_EQ(back[42].z, pts[42].z());
  EXPECT_FLOAT_EQ(back[42].intensity, 0.42f);
  std::ifstream f(dir.file("c.pcd"));
  const std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("DATA binary"), std::string::npos);

  SavePointCloudPcd(pts, {}, dir.file("xyz.pcd"));
  pcl::PointCloud<pcl::PointXYZ> xyz;
  ASSERT_EQ(pcl::io::loadPCDFile(dir.file("xyz.pcd"), xyz), 0);
  EXPECT_EQ(xyz.size(), 100u);

  EXPECT_THROW(SavePointCloudPcd({}, {}, dir.file("e.pcd")), MapExportError);
  EXPECT_NE(ErrorOf([&] {
              SavePointCloudPcd(pts, {1.0f}, dir.file("e.pcd"));
            }).find("1 intensities for 100 points"),
            std::string::npos);
}

// On a full disk the save fails with an error that says so, and leaves no file under the
// final name nor a partial one. The disk is a 16 kB tmpfs mounted in a private mount namespace
// of a child process (needs root, as CI runs).
TEST(MapsPcd, FullDiskGivesAClearErrorAndNoFile) {
  if (geteuid() != 0) GTEST_SKIP() << "needs root to mount a tmpfs in a private mount namespace";
  fl::test::TempDir dir;
  const std::string disk = dir.file("disk");
  std::filesystem::create_directories(disk);
  int pipe_fds[2];
  ASSERT_EQ(pipe(pipe_fds), 0);
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    close(pipe_fds[0]);
    std::string report;
    if (unshare(CLONE_NEWNS) != 0 || mount("none", "/", nullptr, MS_REC | MS_PRIVATE, nullptr) != 0 ||
        mount("tmpfs", disk.c_str(), "tmpfs", 0, "size=16k") != 0) {
      report = "SETUP cannot mount a tmpfs";
    } else {
      std::vector<Eigen::Vector3f> pts;
      for (int i = 0; i < 20000; ++i) pts.emplace_back(0.01f * i, 0.0f, 1.0f);
      try {
        report = ErrorOf([&] { SavePointCloudPcd(pts, {}, disk + "/map.pcd"); });
      } catch (const std::exception& e) {
        report = std::string("not a MapExportError: ") + e.what();
      }
      for (const auto& e : std::filesystem::directory_iterator(disk)) {
        report += "\nLEFT " + e.path().filename().string();
      }
    }
    const ssize_t written = write(pipe_fds[1], report.data(), report.size());
    _exit(written == static_cast<ssize_t>(report.size()) ? 0 : 1);
  }
  close(pipe_fds[1]);
  std::string report;
  char buf[512];
  for (ssize_t n; (n = read(pipe_fds[0], buf, sizeof(buf))) > 0;) report.append(buf, static_cast<size_t>(n));
  close(pipe_fds[0]);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0)
      << "the saving child ended with wait status " << status << " (signal "
      << (WIFSIGNALED(status) ? WTERMSIG(status) : 0) << "): " << report;
  if (report.rfind("SETUP", 0) == 0) GTEST_SKIP() << report;
  EXPECT_NE(report.find("map.pcd"), std::string::npos) << report;
  EXPECT_NE(report.find("disk full"), std::string::npos) << report;
  EXPECT_EQ(report.find("LEFT"), std::string::npos) << report;
}

TEST(MapsTopView, SizeAndContent) {
  fl::test::TempDir dir;
  std::vector<Eigen::Vector3f> pts;
  for (int i = 0; i <= 100; ++i) pts.emplace_back(0.1f * i, 0.05f * i, 0.02f * i);  // 10 x 5 m
  pts.emplace_back(std::nanf(""), 0.f, 0.f);  // skipped with a warning
  SavePointCloudTopView(pts, dir.file("top.png"), 0.1);
  const cv::Mat img = cv::imread(dir.file("top.png"), cv::IMREAD_COLOR);
  ASSERT_FALSE(img.empty());
  EXPECT_EQ(img.cols, 101 + 40);
  EXPECT_EQ(img.rows, 51 + 40 + 30);
  int colored = 0;
  for (int r = 0; r < img.rows - 30; ++r) {
    for (int c = 0; c < img.cols; ++c) {
      const cv::Vec3b p = img.at<cv::Vec3b>(r, c);
      if (!(p[0] == 255 && p[1] == 255 && p[2] == 255)) ++colored;
    }
  }
  EXPECT_GE(colored, 75);  // one pixel per point, some points share a pixel
  EXPECT_LE(colored, 101);
  EXPECT_THROW(SavePointCloudTopView(pts, dir.file("t.png"), 0.0), MapExportError);
  EXPECT_NE(ErrorOf([&] { SavePointCloudTopView(pts, dir.file("t.png"), 0.0001); }).find("coarser"),
            std::string::npos);
}

TEST(MapsPointsFromMessage, Validates) {
  fusionloc::point_cloud_t m;
  m.num_points = 2;
  m.points = {{1, 2, 3}, {4, 5, 6}};
  m.num_intensities = 0;
  const auto pts = PointsFromMessage(m);
  ASSERT_EQ(pts.size(), 2u);
  EXPECT_EQ(pts[1], Eigen::Vector3f(4, 5, 6));
  m.num_intensities = 1;
  m.intensities = {0.5f};
  EXPECT_THROW(PointsFromMessage(m), MapExportError);
}

int RunProgram(const std::string& args, std::string* output) {
  const std::string cmd = fl::test::BinDir() + "/fl-map-export " + args + " 2>&1";
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) return -1;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof(buf), pipe)) > 0) output->append(buf, n);
  const int status = pclose(pipe);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(MapsProgram, ExportsLastGridAndCloudFromLog) {
  fl::test::TempDir dir;
  const std::string log = dir.file("maps.lcmlog");
  {
    LcmLogWriter w(log);
    auto early = MakeGrid();
    early.width = 2;
    early.height = 1;
    early.num_cells = 2;
    early.cells = {0, 0};
    w.Write("RBPF_MAP", early, 1);
    w.Write("RBPF_MAP", MakeGrid(), 2);  // the last one is exported
    fusionloc::point_cloud_t c;
    c.utime = 3;
    c.frame = "map";
    c.num_points = 3;
    c.points = {{0, 0, 0}, {1, 0, 0.5f}, {0, 2, 1}};
    c.num_intensities = 0;
    w.Write("FUSED_MAP", c, 3);
    w.Close();
  }
  std::string out;
  ASSERT_EQ(RunProgram(log + " --channel RBPF_MAP --out " + dir.file("grid"), &out), 0) << out;
  const YAML::Node y = YAML::LoadFile(dir.file("grid.yaml"));
  EXPECT_DOUBLE_EQ(y["origin"][0].as<double>(), -1.5);
  const cv::Mat pgm = cv::imread(dir.file("grid.pgm"), cv::IMREAD_UNCHANGED);
  EXPECT_EQ(pgm.cols, 4);

  out.clear();
  ASSERT_EQ(
      RunProgram(log + " --channel FUSED_MAP --resolution 0.1 --out " + dir.file("cloud"), &out), 0)
      << out;
  pcl::PointCloud<pcl::PointXYZ> back;
  ASSERT_EQ(pcl::io::loadPCDFile(dir.file("cloud.pcd"), back), 0);
  EXPECT_EQ(back.size(), 3u);
  EXPECT_TRUE(std::filesystem::exists(dir.file("cloud_top.png")));

  out.clear();
  EXPECT_EQ(RunProgram(log + " --channel VO_POINTS --out " + dir.file("x"), &out), 1);
  EXPECT_NE(out.find("channels present: FUSED_MAP (1), RBPF_MAP (2)"), std::string::npos) << out;
  out.clear();
  EXPECT_EQ(RunProgram(dir.file("missing.lcmlog") + " --out " + dir.file("x"), &out), 1);
  out.clear();
  EXPECT_EQ(RunProgram("--help", &out), 0);
  EXPECT_NE(out.find("map_server"), std::string::npos);
}

}  // namespace
}  // namespace fl::maps
