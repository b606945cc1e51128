// fl-mrpt-rawlog: a CARMEN laser log as an MRPT rawlog for MRPT's rbpf-slam (bench only:
// `fl-bench-laser --peers`; built only when CMake finds MRPT, nothing of MRPT is in the
// estimator libraries).
//
// The scans and their odometry come from fl::importers::ReadCarmenLog, the reader our own bench
// runs use, so both SLAMs get the same data. The rawlog is in MRPT's actions-observations
// format: per scan one CActionCollection holding a CActionRobotMovement2D (the odometry
// increment since the previous scan, MRPT's Gaussian motion model with the [FusionlocRawlog]
// settings of the ini) followed by one CSensoryFrame holding the CObservation2DRangeScan (the
// first beam at the scan's rad0, `radstep` apart, counter-clockwise; beams <= 0 or >=
// max_range_m invalid). MRPT's own carmen2rawlog writes no odometry actions and rbpf-slam
// crashes on its output (issue #25).
//
// The steps file (fl::peers::WriteMrptSteps) lists per rawlog step the scan's time, the
// increment and whether rbpf-slam will run its particle filter on the step: the rule of
// CMetricMapBuilderRBPF::processActionObservation (MRPT 2.5), evaluated here with MRPT's own
// CPose3D arithmetic on the same increments, with the ini's localizeLinDistance,
// localizeAngDistance_deg, insertionLinDistance and insertionAngDistance_deg. fl-bench-laser
// needs it to give each scan its pose on the most likely particle's path, which has one pose per
// filter step (fl::peers::MrptFinalTrajectory checks that the counts agree).
#include <cmath>
#include <exception>
#include <iostream>
#include <mrpt/config/CConfigFile.h>
#include <mrpt/core/Clock.h>
#include <mrpt/io/CFileOutputStream.h>
#include <mrpt/obs/CActionCollection.h>
#include <mrpt/obs/CActionRobotMovement2D.h>
#include <mrpt/obs/CObservation2DRangeScan.h>
#include <mrpt/obs/CSensoryFrame.h>
#include <mrpt/poses/CPose2D.h>
#include <mrpt/poses/CPose3D.h>
#include <mrpt/serialization/CArchive.h>
#include <set>
#include <string>

#include "fusionloc/common/program.hpp"
#include "fusionloc/importers/carmen.hpp"
#include "peers/mrpt_rbpf.hpp"

namespace {

constexpr const char* kSection = "FusionlocRawlog";

// [FusionlocRawlog] of the ini: how the CARMEN data become MRPT actions and observations.
struct RawlogOptions {
  // MRPT's Gaussian odometry model (CActionRobotMovement2D::TMotionModelOptions::gaussianModel):
  // std_xy = min_std_xy + a1 * d + a2 * |dtheta|, std_theta = min_std_theta + a3 * d + a4 *
  // |dtheta| for an increment of length d and rotation dtheta (MRPT's code uses radians).
  double odometry_a1 = 0.1;               // [m/m]
  double odometry_a2 = 0.05;              // [m/rad]
  double odometry_a3 = 0.05;              // [rad/m]
  double odometry_a4 = 0.1;               // [rad/rad]
  double odometry_min_std_xy = 0.01;      // [m]
  double odometry_min_std_theta_deg = 0.2;  // [deg]
  double max_range_m = 30.0;   // beams this long or longer (CARMEN's "no return") are invalid
  double range_std_m = 0.01;   // CObservation2DRangeScan::stdError
};

// The particle-filter and map-insertion distances of [MappingApplication] (MRPT's
// CMetricMapBuilderRBPF::TConstructionOptions; read as MRPT reads them).
struct UpdateRule {
  float localize_lin = 0, insert_lin = 0;
  double localize_ang = 0, insert_ang = 0;
};

double ReadRequired(const mrpt::config::CConfigFile& ini, const std::string& section,
                    const std::string& key, const std::string& path) {
  if (!ini.keyExists(section, key))
    throw fl::ConfigError(path + ": [" + section + "] " + key +
                          " is missing (fl-mrpt-rawlog needs it to know on which steps "
                          "rbpf-slam runs its particle filter)");
  return ini.read_double(section, key, 0.0);
}

}  // namespace

int main(int argc, char** argv) {
  fl::Program program(
      "fl-mrpt-rawlog",
      "Writes a CARMEN laser log (read with the project's CARMEN reader) as an MRPT rawlog "
      "(actions-observations: per scan its odometry increment as a CActionRobotMovement2D and "
      "the scan as a CObservation2DRangeScan) for MRPT's rbpf-slam, and a steps file with each "
      "step's time, increment and whether rbpf-slam runs its particle filter there. "
      "Bench only (fl-bench-laser --peers).");
  fl::CommandLine& cli = program.cli();
  std::string log, ini_path, rawlog_path, steps_path;
  cli.AddPositional("LOG", &log, "CARMEN log (.clf, .log, .log.gz)", /*required=*/false);
  cli.AddFlag("ini", &ini_path,
              "the MRPT ini given to rbpf-slam (config/peers/mrpt_rbpf_slam.ini): its "
              "[FusionlocRawlog] section (odometry model, max range) and the update distances "
              "of [MappingApplication]");
  cli.AddFlag("rawlog", &rawlog_path, "output rawlog");
  cli.AddFlag("steps", &steps_path, "output steps file (index utime filter dx dy dtheta)");
  if (!program.Parse(argc, argv)) return program.exit_code();
  return program.Run([&]() -> int {
    if (log.empty() || ini_path.empty() || rawlog_path.empty() || steps_path.empty())
      throw fl::UsageError("give LOG, --ini, --rawlog and --steps (see --help)");

    // Options.
    mrpt::config::CConfigFile ini(ini_path);
    RawlogOptions ro;
    {
      const std::set<std::string> known = {"odometry_a1",
                                            "odometry_a2",
                                            "odometry_a3",
                                            "odometry_a4",
                                            "odometry_min_std_xy",
                                            "odometry_min_std_theta_deg",
                                            "max_range_m",
                                            "range_std_m"};
      std::vector<std::string> keys;
      ini.getAllKeys(kSection, keys);
      for (const std::string& k : keys)
        if (!known.count(k))
          throw fl::ConfigError(ini_path + ": [" + std::string(kSection) + "] unknown key '" + k +
                                "'");
      ro.odometry_a1 = ini.read_double(kSection, "odometry_a1", ro.odometry_a1);
      ro.odometry_a2 = ini.read_double(kSection, "odometry_a2", ro.odometry_a2);
      ro.odometry_a3 = ini.read_double(kSection, "odometry_a3", ro.odometry_a3);
      ro.odometry_a4 = ini.read_double(kSection, "odometry_a4", ro.odometry_a4);
      ro.odometry_min_std_xy =
          ini.read_double(kSection, "odometry_min_std_xy", ro.odometry_min_std_xy);
      ro.odometry_min_std_theta_deg =
          ini.read_double(kSection, "odometry_min_std_theta_deg", ro.odometry_min_std_theta_deg);
      ro.max_range_m = ini.read_double(kSection, "max_range_m", ro.max_range_m);
      ro.range_std_m = ini.read_double(kSection, "range_std_m", ro.range_std_m);
      for (const double v : {ro.odometry_a1, ro.odometry_a2, ro.odometry_a3, ro.odometry_a4,
                             ro.odometry_min_std_xy, ro.odometry_min_std_theta_deg})
        if (!std::isfinite(v) || v < 0)
          throw fl::ConfigError(ini_path + ": [" + std::string(kSection) +
                                "] odometry_* must be finite and >= 0");
      if (!(ro.max_range_m > 0) || !(ro.range_std_m > 0) || !std::isfinite(ro.max_range_m))
        throw fl::ConfigError(ini_path + ": [" + std::string(kSection) +
                              "] max_range_m and range_std_m must be > 0");
    }
    UpdateRule rule;
    const std::string app = "MappingApplication";
    rule.localize_lin = static_cast<float>(ReadRequired(ini, app, "localizeLinDistance", ini_path));
    rule.insert_lin = static_cast<float>(ReadRequired(ini, app, "insertionLinDistance", ini_path));
    rule.localize_ang =
        mrpt::DEG2RAD(ReadRequired(ini, app, "localizeAngDistance_deg", ini_path));
    rule.insert_ang = mrpt::DEG2RAD(ReadRequired(ini, app, "insertionAngDistance_deg", ini_path));

    mrpt::obs::CActionRobotMovement2D::TMotionModelOptions motion;
    motion.modelSelection = mrpt::obs::CActionRobotMovement2D::mmGaussian;
    motion.gaussianModel.a1 = ro.odometry_a1;
    motion.gaussianModel.a2 = ro.odometry_a2;
    motion.gaussianModel.a3 = ro.odometry_a3;
    motion.gaussianModel.a4 = ro.odometry_a4;
    motion.gaussianModel.minStdXY = ro.odometry_min_std_xy;
    motion.gaussianModel.minStdPHI = mrpt::DEG2RAD(ro.odometry_min_std_theta_deg);

    // Data: the project's CARMEN reader (FLASER / ROBOTLASER1: ranges, beam angles, odometry).
    const fl::importers::CarmenLog carmen = fl::importers::ReadCarmenLog(log);

    mrpt::io::CFileOutputStream file;
    if (!file.open(rawlog_path))
      throw std::runtime_error(rawlog_path + ": cannot create the rawlog");
    auto archive = mrpt::serialization::archiveFrom(file);
    std::vector<fl::peers::MrptStep> steps;
    mrpt::poses::CPose3D since_localization, since_insertion;  // as CMetricMapBuilderRBPF
    bool have_map = false;
    for (size_t i = 0; i < carmen.scans.size(); ++i) {
      const fl::importers::CarmenScan& s = carmen.scans[i];
      const size_t n = s.ranges.size();
      if (n < 2 || !(s.radstep > 0))
        throw std::runtime_error(log + ":" + std::to_string(s.line) +
                                 ": a scan needs >= 2 beams with increasing angles");
      if (!steps.empty() && s.utime <= steps.back().utime)
        throw std::runtime_error(log + ":" + std::to_string(s.line) +
                                 ": time does not increase (rbpf-slam's steps are matched to "
                                 "scans by time)");
      fl::peers::MrptStep step;
      step.utime = s.utime;
      step.increment = i == 0 ? fl::Pose2() : carmen.scans[i - 1].odom.between(s.odom);
      const mrpt::Clock::time_point stamp = mrpt::Clock::fromDouble(1e-6 * static_cast<double>(s.utime));

      mrpt::obs::CActionRobotMovement2D act;
      act.computeFromOdometry(
          mrpt::poses::CPose2D(step.increment.x, step.increment.y, step.increment.theta), motion);
      act.timestamp = stamp;
      mrpt::obs::CActionCollection actions;
      actions.insert(act);

      auto obs = mrpt::obs::CObservation2DRangeScan::Create();
      obs->sensorLabel = "LASER";
      obs->timestamp = stamp;
      obs->aperture = static_cast<float>(s.radstep * static_cast<double>(n - 1));
      obs->rightToLeft = true;
      obs->maxRange = static_cast<float>(ro.max_range_m);
      obs->stdError = static_cast<float>(ro.range_std_m);
      // The first beam at rad0: MRPT's beams run from -aperture/2 to +aperture/2 of the sensor.
      obs->sensorPose = mrpt::poses::CPose3D(0, 0, 0, s.rad0 + 0.5 * obs->aperture, 0, 0);
      obs->resizeScan(n);
      for (size_t k = 0; k < n; ++k) {
        const float r = s.ranges[k];
        obs->setScanRange(k, r);
        obs->setScanRangeValidity(k, std::isfinite(r) && r > 0.0f && r < obs->maxRange);
      }
      mrpt::obs::CSensoryFrame frame;
      frame.insert(obs);
      archive << actions << frame;

      // CMetricMapBuilderRBPF::processActionObservation's rule, on the same increment.
      const mrpt::poses::CPose3D inc(act.poseChange->getMeanVal());
      since_insertion += inc;
      since_localization += inc;
      bool localize = !have_map || since_localization.norm() > rule.localize_lin ||
                      std::abs(since_localization.yaw()) > rule.localize_ang;
      const bool insert = !have_map || since_insertion.norm() > rule.insert_lin ||
                          std::abs(since_insertion.yaw()) > rule.insert_ang;
      if (insert) localize = true;
      if (localize) since_localization.setFromValues(0, 0, 0, 0, 0, 0);
      if (insert) {
        since_insertion.setFromValues(0, 0, 0, 0, 0, 0);
        have_map = true;
      }
      step.filter = localize;
      steps.push_back(step);
    }
    file.close();
    fl::peers::WriteMrptSteps(steps, steps_path);
    size_t filter = 0;
    for (const auto& st : steps) filter += st.filter ? 1 : 0;
    std::cout << "fl-mrpt-rawlog: " << steps.size() << " steps (" << filter
              << " with a particle-filter update) -> " << rawlog_path << ", " << steps_path
              << "\n";
    return 0;
  });
}
