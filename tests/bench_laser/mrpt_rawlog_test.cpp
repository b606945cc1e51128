// fl-mrpt-rawlog (built only when CMake finds MRPT, and so is this test): a CARMEN log becomes an
// MRPT rawlog that MRPT's own reader reads back as one odometry action and one scan per CARMEN
// scan, with the scan's geometry, times and invalid beams; the steps file marks the steps on
// which rbpf-slam runs its filter by the rule of CMetricMapBuilderRBPF (MRPT 2.5), here
// recomputed in plain 2D arithmetic.
#include <gtest/gtest.h>

#include <cmath>
#include <mrpt/core/Clock.h>
#include <mrpt/obs/CActionCollection.h>
#include <mrpt/obs/CActionRobotMovement2D.h>
#include <mrpt/obs/CObservation2DRangeScan.h>
#include <mrpt/obs/CRawlog.h>
#include <mrpt/obs/CSensoryFrame.h>
#include <string>

#include "fusionloc/common/geometry.hpp"
#include "importer_fixtures.hpp"
#include "peers/mrpt_rbpf.hpp"
#include "test_paths.hpp"

namespace {

using fl::test::BinDir;
using fl::test::RunCommand;
using fl::test::TempDir;

TEST(MrptRawlog, CarmenLogBecomesActionsAndScansMrptReadsBack) {
  TempDir dir;
  const int n = 30, beams = 181;
  // The arc of CarmenArcLog (0.1 m and 0.02 rad per scan), one beam of scan 4 at CARMEN's
  // "no return" 81.91 m.
  std::string text = "# synthetic\n";
  std::vector<fl::Pose2> pose;
  double x = 0, y = 0, th = 0;
  for (int k = 0; k < n; ++k) {
    pose.emplace_back(x, y, th);
    std::string line = fl::test::CarmenFlaser(beams, 2.0 + 0.001 * k, x, y, th, 100.0 + 0.1 * k);
    if (k == 4) {  // its first range
      const size_t a = std::string("FLASER 181 ").size();
      line.replace(a, line.find(' ', a) - a, "81.91");
    }
    text += line;
    x += 0.1 * std::cos(th);
    y += 0.1 * std::sin(th);
    th += 0.02;
  }
  fl::test::WriteText(dir.file("arc.clf"), text);
  const std::string ini = fl::test::SourceDir() + "/config/peers/mrpt_rbpf_slam.ini";
  const auto r = RunCommand(BinDir() + "/fl-mrpt-rawlog --ini " + ini +
                                " --rawlog a.rawlog --steps a.steps arc.clf",
                            dir);
  ASSERT_EQ(r.status, 0) << r.out << r.err;

  mrpt::obs::CRawlog rawlog;
  ASSERT_TRUE(rawlog.loadFromRawLogFile(dir.file("a.rawlog")));
  ASSERT_EQ(rawlog.size(), 2u * n);
  const std::vector<fl::peers::MrptStep> steps = fl::peers::ReadMrptSteps(dir.file("a.steps"));
  ASSERT_EQ(steps.size(), static_cast<size_t>(n));
  double since_m = 0;  // path length since the last filter step: the arc's chord is shorter
  fl::Pose2 since;
  for (int k = 0; k < n; ++k) {
    ASSERT_EQ(rawlog.getType(2 * k), mrpt::obs::CRawlog::etActionCollection) << k;
    ASSERT_EQ(rawlog.getType(2 * k + 1), mrpt::obs::CRawlog::etSensoryFrame) << k;
    const auto act = rawlog.getAsAction(2 * k)->getBestMovementEstimation();
    ASSERT_TRUE(act) << "step " << k << " has no odometry action";
    const fl::Pose2 expected = k == 0 ? fl::Pose2() : pose[k - 1].between(pose[k]);
    const mrpt::poses::CPose2D inc = act->poseChange->getMeanVal();
    EXPECT_NEAR(inc.x(), expected.x, 1e-6) << k;  // CARMEN prints 10 digits
    EXPECT_NEAR(inc.y(), expected.y, 1e-6) << k;
    EXPECT_NEAR(inc.phi(), expected.theta, 1e-6) << k;
    EXPECT_NEAR(steps[k].increment.x, inc.x(), 1e-12);
    const auto scan =
        rawlog.getAsObservations(2 * k + 1)->getObservationByClass<mrpt::obs::CObservation2DRangeScan>();
    ASSERT_TRUE(scan) << k;
    ASSERT_EQ(scan->getScanSize(), static_cast<size_t>(beams));
    EXPECT_EQ(steps[k].utime, 100000000 + 100000 * k);
    EXPECT_NEAR(mrpt::Clock::toDouble(scan->timestamp), 100.0 + 0.1 * k, 1e-6);
    // 181 beams over 180 degrees from the robot's right: the first at -90, the last at +90.
    EXPECT_NEAR(scan->aperture, M_PI, 1e-6);
    EXPECT_NEAR(scan->sensorPose.yaw(), 0.0, 1e-6);
    EXPECT_TRUE(scan->rightToLeft);
    EXPECT_NEAR(scan->getScanRange(1), 2.0 + 0.001 * k + 0.01, 1e-5);
    EXPECT_TRUE(scan->getScanRangeValidity(1));
    EXPECT_EQ(scan->getScanRangeValidity(0), k != 4) << "81.91 m is no return";
    // The filter rule: the first step, then whenever the odometry since the last filter step
    // exceeds 0.2 m or 5.7296 deg (the ini's localize and insertion distances).
    since = since * expected;
    since_m += k == 0 ? 0.0 : 0.1;
    const bool filter = k == 0 || std::hypot(since.x, since.y) > 0.2 ||
                        std::abs(since.theta) > 5.7296 * M_PI / 180.0;
    EXPECT_EQ(steps[k].filter, filter) << "step " << k << ", " << since_m << " m since";
    if (filter) since = fl::Pose2(), since_m = 0;
  }
}

}  // namespace
