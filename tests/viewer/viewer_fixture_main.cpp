// viewer_fixture: the known scenes of tests/helpers/viewer_fixtures.hpp for the browser test
// (tests/viewer/viewer_browser_test.py), which cannot speak LCM itself.
//   viewer_fixture describe          the grid, its probe cells and the trajectory as JSON
//   viewer_fixture publish URL S     publishes them on LCM URL every 0.25 s for S seconds
//   viewer_fixture log OUT.lcmlog    a log of the drive (FUSED_POSE) with the grid
#include <chrono>
#include <cstdio>
#include <iostream>
#include <string>
#include <thread>

#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "viewer_fixtures.hpp"

namespace {

int Describe() {
  const fl::test::ViewerGridFixture g;
  const fl::test::ViewerTrajectoryFixture t;
  const fl::test::ViewerDriveFixture d;
  std::printf("{\"grid\": {\"resolution\": %g, \"width\": %d, \"height\": %d, \"origin_x\": %g, "
              "\"origin_y\": %g}, \"probes\": [",
              g.resolution, g.width, g.height, g.origin_x, g.origin_y);
  // One probe per block and its mirror images (a flip in x or y lands on another value).
  const int probes[][2] = {{3, 5}, {3, 18}, {12 - 1 - 3, 5}, {8, 17}, {8, 6}, {14, 5}, {14, 18},
                           {0, 0}, {4, 7}, {2, 4}, {5, 5}, {3, 8}};
  bool first = true;
  for (const auto& p : probes) {
    std::printf("%s{\"row\": %d, \"col\": %d, \"x\": %g, \"y\": %g, \"value\": %d}",
                first ? "" : ", ", p[0], p[1], g.CellX(p[1]), g.CellY(p[0]), g.Cell(p[0], p[1]));
    first = false;
  }
  std::printf("], \"trajectory\": {\"n\": %d, \"x0\": %g, \"y0\": %g, \"x1\": %g, \"y1\": %g}, "
              "\"drive\": {\"duration_s\": %g}}\n",
              t.n, t.x0, t.y0, t.x1, t.y1, d.duration_s);
  return 0;
}

int Publish(const std::string& url, double seconds) {
  auto lcm = fl::MakeLcm(url);
  const auto t0 = std::chrono::steady_clock::now();
  while (std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() < seconds) {
    const fl::Utime now = fl::NowUtime();
    lcm->Publish(fl::channels::kRbpfMap, fl::test::ViewerGridMsg(now));
    lcm->Publish(fl::channels::kFusedTrajectory, fl::test::ViewerTrajectoryMsg(now));
    lcm->Publish("STATUS_FL_FIXTURE", fl::test::ViewerStatusMsg(now, "fl-fixture"));
    std::this_thread::sleep_for(std::chrono::milliseconds(250));
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string cmd = argc > 1 ? argv[1] : "";
  try {
    if (cmd == "describe") return Describe();
    if (cmd == "publish" && argc == 4) return Publish(argv[2], std::stod(argv[3]));
    if (cmd == "log" && argc == 3) {
      fl::test::WriteViewerDriveLog(argv[2]);
      return 0;
    }
  } catch (const std::exception& e) {
    std::cerr << "viewer_fixture: " << e.what() << "\n";
    return 1;
  }
  std::cerr << "usage: viewer_fixture describe | publish URL SECONDS | log OUT.lcmlog\n";
  return 2;
}
