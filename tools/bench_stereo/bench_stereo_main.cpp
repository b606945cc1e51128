// fl-bench-stereo: runs the stereo VO on KITTI-format folders through the real data path
// (fl::importers::ConvertKitti -> LCM log -> images_t decoded -> StereoVo::AddStereoFrame) and
// compares with GROUND_TRUTH: KITTI segment drift over the lengths that fit the path, per-frame
// relative error, end-point error, time per frame (AddStereoFrame only, one thread), lost
// frames; draws the trajectory against ground truth into a PNG. Runs per folder: `<folder>` the
// plain VO (local_ba and laser_depth off), `<folder>_ba` with the keyframe local bundle
// adjustment (local_ba.enabled), and in a folder with Velodyne scans `<folder>_lv`, laser-aided
// with local BA (laser_depth.enabled; each frame's scan read from the folder, not timed, moved
// into the left camera frame through Tr, timed with AddStereoFrame).
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <iostream>
#include <map>
#include <opencv2/core.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <sstream>

#include "bot_core/rigid_transform_t.hpp"
#include "fusionloc/bench/bench.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/common/program.hpp"
#include "fusionloc/common/yaml_options.hpp"
#include "fusionloc/eval/metrics.hpp"
#include "fusionloc/importers/kitti.hpp"
#include "fusionloc/stereo_vo/stereo_vo_lcm.hpp"

namespace {

namespace fs = std::filesystem;

// CPU time of this thread [ms]: with other processes on the machine, wall time per frame
// measures the load; thread CPU time measures the VO (one thread: OpenCV runs single-threaded).
double ThreadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

double NowMs() {
  return std::chrono::duration<double, std::milli>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// Top view (x forward, y left of the first base frame) of est against ref.
void DrawTrajectories(const fl::eval::Trajectory& est, const fl::eval::Trajectory& ref,
                      const std::string& title, const std::string& path) {
  const int W = 900, H = 900, margin = 60;
  double xmin = 1e9, xmax = -1e9, ymin = 1e9, ymax = -1e9;
  for (const auto* t : {&est, &ref}) {
    for (const auto& p : *t) {
      xmin = std::min(xmin, p.T_world_base.translation().x());
      xmax = std::max(xmax, p.T_world_base.translation().x());
      ymin = std::min(ymin, p.T_world_base.translation().y());
      ymax = std::max(ymax, p.T_world_base.translation().y());
    }
  }
  const double span = std::max({xmax - xmin, ymax - ymin, 1.0});
  const double s = (W - 2 * margin) / span;
  const double xc = 0.5 * (xmin + xmax), yc = 0.5 * (ymin + ymax);
  // Screen: up = +x (forward), left = +y (left).
  auto to_px = [&](const Eigen::Vector3d& p) {
    return cv::Point(cvRound(W / 2.0 - (p.y() - yc) * s), cvRound(H / 2.0 - (p.x() - xc) * s));
  };
  cv::Mat img(H, W, CV_8UC3, cv::Scalar(255, 255, 255));
  // Grid every 10 m.
  const double step = span > 300 ? 50.0 : 10.0;
  for (double g = std::floor((xc - span) / step) * step; g <= xc + span; g += step) {
    cv::line(img, to_px({g, yc - span, 0}), to_px({g, yc + span, 0}), cv::Scalar(230, 230, 230));
  }
  for (double g = std::floor((yc - span) / step) * step; g <= yc + span; g += step) {
    cv::line(img, to_px({xc - span, g, 0}), to_px({xc + span, g, 0}), cv::Scalar(230, 230, 230));
  }
  auto draw = [&](const fl::eval::Trajectory& t, const cv::Scalar& color) {
    for (size_t i = 1; i < t.size(); ++i) {
      cv::line(img, to_px(t[i - 1].T_world_base.translation()),
               to_px(t[i].T_world_base.translation()), color, 2, cv::LINE_AA);
    }
  };
  draw(ref, cv::Scalar(0, 0, 0));
  draw(est, cv::Scalar(0, 0, 220));
  cv::putText(img, title, {15, 30}, cv::FONT_HERSHEY_SIMPLEX, 0.6, cv::Scalar(0, 0, 0), 1,
              cv::LINE_AA);
  cv::putText(img,
              "black: ground truth   red: stereo VO   grid " + std::to_string(int(step)) +
                  " m   up = x forward, left = y left",
              {15, H - 20}, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  fs::create_directories(fs::path(path).parent_path());
  if (!cv::imwrite(path, img)) throw std::runtime_error("cannot write " + path);
}

struct RunOutput {
  fl::bench::Run run;
  std::string summary;
};

// The converter's options for a folder: an odometry sequence's own poses.txt as ground truth.
fl::importers::KittiOptions KittiOptionsFor(const std::string& folder) {
  fl::importers::KittiOptions kopts;
  kopts.laser_3d = false;  // the laser-aided run reads the scans from the folder itself
  if (!fs::exists(folder + "/image_00") && fs::exists(folder + "/poses.txt")) {
    kopts.poses_file = folder + "/poses.txt";
  }
  return kopts;
}

// The runs of a folder.
struct Mode {
  const char* suffix;
  bool local_ba;
  bool laser;  // the folder must have Velodyne scans
};
constexpr Mode kPlain{"", false, false}, kBa{"_ba", true, false}, kLaser{"_lv", true, true};

RunOutput RunFolder(const std::string& folder, const fl::vo::StereoVoOptions& options_in,
                    const std::string& png_dir, const std::string& tmp_dir, const Mode& mode) {
  const std::string base = fs::path(folder).filename().string().empty()
                               ? fs::path(folder).parent_path().filename().string()
                               : fs::path(folder).filename().string();
  const std::string name = base + mode.suffix;
  const bool laser = mode.laser;
  const std::string log_path = tmp_dir + "/" + name + ".lcmlog";
  const fl::importers::KittiOptions kopts = KittiOptionsFor(folder);
  fl::vo::StereoVoOptions options = options_in;
  options.local_ba.enabled = mode.local_ba;
  options.laser_depth.enabled = false;
  fl::importers::KittiSequence seq;
  std::map<fl::Utime, size_t> frame_of;
  if (laser) {
    options.laser_depth.enabled = true;
    seq = fl::importers::ScanKittiFolder(kopts, folder);
    if (seq.velodyne_scans.empty()) throw std::runtime_error(folder + ": no Velodyne scans");
    for (size_t i = 0; i < seq.utimes.size(); ++i) frame_of[seq.utimes[i]] = i;
  }
  // Velodyne -> left camera: the left camera is cam0 shifted by its optical centre.
  Eigen::Isometry3d T_left_velo = seq.T_cam0_velo;
  T_left_velo.pretranslate(-seq.calibration.left_center_in_cam0);
  int laser_fallbacks = 0;
  double laser_depth_sum = 0;
  const fl::importers::ConvertSummary conv = fl::importers::ConvertKitti(kopts, folder, log_path);
  for (const auto& w : conv.warnings) FL_LOG(WARN) << name << ": " << w;

  fl::LcmLogReader reader(log_path);
  fl::LcmLogEvent ev;
  std::unique_ptr<fl::vo::StereoVo> vo;
  std::optional<bot_core::rigid_transform_t> camera_to_base;
  fl::eval::Trajectory est, ref;
  std::vector<double> ms, cpu_ms;
  int frames = 0, lost = 0, rejected = 0, keyframes = 0, factors = 0, adjusted = 0;
  double inliers_sum = 0, ba_points_sum = 0, ba_ms_sum = 0;
  fl::bench::Progress progress("bench stereo " + name,
                               conv.messages.count("STEREO") ? conv.messages.at("STEREO") : 0);
  while (reader.Next(&ev)) {
    const int size = static_cast<int>(ev.data.size());
    if (ev.channel == fl::channels::kCameraToBase && !camera_to_base) {
      bot_core::rigid_transform_t msg{};
      if (msg.decode(ev.data.data(), 0, size) != size) throw std::runtime_error("bad mounting");
      camera_to_base = msg;
    } else if (ev.channel == fl::channels::kStereoCalibration && !vo) {
      fusionloc::stereo_calibration_t msg;
      if (msg.decode(ev.data.data(), 0, size) != size) throw std::runtime_error("bad calibration");
      if (!camera_to_base)
        throw std::runtime_error(log_path + ": STEREO_CALIBRATION before CAMERA_TO_BASE");
      vo = std::make_unique<fl::vo::StereoVo>(options,
                                              fl::vo::CalibrationFromLcm(msg, *camera_to_base));
    } else if (ev.channel == fl::channels::kGroundTruth) {
      bot_core::pose_t msg{};
      if (msg.decode(ev.data.data(), 0, size) != size) throw std::runtime_error("bad pose");
      ref.push_back({msg.utime, fl::IsometryFromArrays(msg.pos, msg.orientation)});
    } else if (ev.channel == fl::channels::kStereo) {
      if (!vo) throw std::runtime_error(log_path + ": STEREO before STEREO_CALIBRATION");
      bot_core::images_t msg;
      if (msg.decode(ev.data.data(), 0, size) != size) throw std::runtime_error("bad images_t");
      cv::Mat left, right;  // decoding is not timed
      if (auto s = fl::vo::StereoImagesToGray(msg, &left, &right); !s.ok()) {
        throw std::runtime_error(s.message());
      }
      fl::importers::VelodyneScan scan;  // reading is not timed
      if (laser) {
        const auto it = frame_of.find(msg.utime);
        if (it != frame_of.end())
          scan = fl::importers::ReadVelodyneBin(seq.velodyne_scans[it->second]);
      }
      const double t0 = NowMs(), c0 = ThreadCpuMs();
      fl::vo::LaserCloud cloud;  // the VO applies the extrinsic, inside the timing
      if (laser) {
        cloud.utime = msg.utime;  // KITTI: the scan is synchronised with the camera trigger
        cloud.points = std::move(scan.points);
        cloud.T_camera_laser = T_left_velo;
      }
      const fl::vo::StereoVoResult r = vo->AddStereoFrame(
          msg.utime, left, right, laser && !cloud.points.empty() ? &cloud : nullptr);
      ms.push_back(NowMs() - t0);
      cpu_ms.push_back(ThreadCpuMs() - c0);
      if (laser) {
        if (!r.laser_message.empty()) {
          ++laser_fallbacks;
          FL_LOG(WARN) << name << " frame " << frames << ": " << r.laser_message;
        }
        laser_depth_sum += r.stats.laser_depth_cur;
      }
      ++frames;
      progress.Update(frames);
      if (r.state == fl::vo::TrackingState::kNotTracked) ++lost;
      if (r.state == fl::vo::TrackingState::kRejected) ++rejected;
      if (r.state != fl::vo::TrackingState::kTracked &&
          r.state != fl::vo::TrackingState::kInitialized) {
        FL_LOG(WARN) << name << " frame " << frames - 1 << ": " << r.message;
      }
      if (r.state == fl::vo::TrackingState::kTracked) inliers_sum += r.stats.inliers;
      FL_LOG(DEBUG) << name << " frame " << frames - 1 << " " << fl::vo::ToString(r.state)
                    << ": features " << r.stats.features_left << "/" << r.stats.features_right
                    << " stereo " << r.stats.stereo_matches << " quads " << r.stats.quads.kept
                    << " (candidates " << r.stats.quads.candidates << ", open "
                    << r.stats.quads.not_closed << ", slope " << r.stats.quads.slope_rejected
                    << ", parallax " << r.stats.quads.parallax_rejected << ") inliers "
                    << r.stats.inliers << " rms " << r.stats.reprojection_rms_px << " px; ms "
                    << r.stats.ms_features << " + " << r.stats.ms_matching << " + "
                    << r.stats.ms_motion << " = " << r.stats.ms_total << "; laser points "
                    << r.stats.laser_points_in_view << " depth prev/cur "
                    << r.stats.laser_depth_prev << "/" << r.stats.laser_depth_cur
                    << " rejected: discontinuity " << r.stats.laser_depth_inconsistent
                    << ", stereo " << r.stats.laser_depth_disagrees << " (" << r.stats.ms_laser
                    << " ms)";
      keyframes += r.is_keyframe ? 1 : 0;
      factors += r.factor ? 1 : 0;
      if (r.stats.local_ba) {
        ++adjusted;
        ba_points_sum += r.stats.ba_points;
        ba_ms_sum += r.stats.ms_ba;
      }
      if (r.pose_valid) est.push_back({msg.utime, r.T_world_base});
    }
  }
  progress.Finish();
  if (ref.empty()) throw std::runtime_error(folder + ": no ground truth (GROUND_TRUTH)");
  if (est.size() < 2) throw std::runtime_error(folder + ": fewer than 2 VO poses");
  std::sort(ref.begin(), ref.end(), [](const auto& a, const auto& b) { return a.utime < b.utime; });

  const fl::Utime max_dt = 20000;
  const double path = fl::eval::PathLength(ref);
  const std::vector<double> lengths = fl::eval::DefaultKittiLengths(path);
  const fl::eval::DriftResult drift = fl::eval::ComputeKittiDrift(est, ref, lengths, max_dt, 1);
  const fl::eval::RpeResult rpe =
      fl::eval::ComputeRpe(est, ref, 1, fl::eval::DeltaUnit::kFrames, max_dt);
  const fl::eval::AteResult ate =
      fl::eval::ComputeAte(est, ref, fl::eval::Alignment::kNone, max_dt);
  const double endpoint =
      (est.back().T_world_base.translation() - ref.back().T_world_base.translation()).norm();
  const fl::bench::Stats st = fl::bench::ComputeStats(ms);
  const fl::bench::Stats cpu = fl::bench::ComputeStats(cpu_ms);

  RunOutput out;
  out.run.name = name;
  out.run.input = folder;
  out.run.Add("drift_pct", drift.trans_pct)
      .Add("drift_deg_per_100m", drift.rot_deg_per_100m)
      .Add("rpe_trans_m", rpe.trans_m.rmse)
      .Add("rpe_rot_deg", rpe.rot_deg.rmse)
      .Add("ate_rmse_m", ate.trans_m.rmse)
      .Add("endpoint_err_m", endpoint)
      .Add("path_m", path)
      .Add("ms_per_item_median", st.median)
      .Add("ms_per_item_p95", st.p95)
      .Add("ms_per_item_mean", st.mean)
      .Add("cpu_ms_per_item_median", cpu.median)
      .Add("cpu_ms_per_item_p95", cpu.p95)
      .Add("items", frames)
      .Add("lost_frames", lost + rejected)
      .Add("keyframes", keyframes)
      .Add("inliers_mean", frames > 1 ? inliers_sum / (frames - 1 - lost) : 0)
      .Add("peak_rss_mb", fl::bench::PeakRssMb());
  if (mode.local_ba) {
    out.run.Add("ba_windows", adjusted)
        .Add("ba_points_mean", adjusted > 0 ? ba_points_sum / adjusted : 0)
        .Add("ba_ms_mean", adjusted > 0 ? ba_ms_sum / adjusted : 0);
  }
  if (laser) {
    out.run.Add("laser_depth_features_mean", frames > 0 ? laser_depth_sum / frames : 0)
        .Add("laser_fallback_frames", laser_fallbacks);
  }
  std::ostringstream note;
  note << "KITTI segment lengths";
  for (double l : drift.lengths_m) note << " " << l;
  note << " m (" << drift.segments << " segments, every frame a start); targets drift <= 0.8 %"
       << (drift.trans_pct <= 0.8 ? " met" : " NOT met") << ", <= 1.0 deg/100 m"
       << (drift.rot_deg_per_100m <= 1.0 ? " met" : " NOT met") << ", median <= 15 ms"
       << (st.median <= 15.0 ? " met" : " NOT met") << " (wall; thread CPU median " << cpu.median
       << " ms)"
       << ", no lost frames" << (lost + rejected == 0 ? " met" : " NOT met")
       << "; one thread, decoding excluded";
  if (mode.local_ba && !laser) {
    note << "; local BA (issue 26 target: KITTI raw 0001 drift <= 0.50 %"
         << (name.find("0001") == std::string::npos ? " n/a here"
                                                    : (drift.trans_pct <= 0.50 ? " met" : " NOT met"))
         << ")";
  }
  if (laser) {
    note << "; laser-aided with local BA (issue 26 targets: 04 snippet drift <= 0.40 %"
         << (drift.trans_pct <= 0.40 ? " met" : " NOT met")
         << ", time <= 1.5x the plain run's; scan reading excluded, extrinsic included)";
  }
  out.run.note = note.str();
  const std::string png = png_dir + "/stereo_" + name + ".png";
  fl::eval::WriteTrajectoryTum(est, png_dir + "/stereo_" + name + "_vo.tum");
  fl::eval::WriteTrajectoryTum(ref, png_dir + "/stereo_" + name + "_gt.tum");
  std::ostringstream title;
  title.precision(3);
  title << name << ": drift " << drift.trans_pct << " %, " << drift.rot_deg_per_100m
        << " deg/100m, end " << endpoint << " m";
  DrawTrajectories(est, ref, title.str(), png);
  out.summary = "trajectory plot: " + png;
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  fl::Program program("fl-bench-stereo",
                      "Stereo VO benchmark on KITTI-format folders (raw drive or odometry "
                      "sequence with poses): KITTI segment drift, per-frame relative error, "
                      "end-point error, time per frame on one thread, trajectory PNG.");
  fl::CommandLine& cli = program.cli();
  fl::bench::CommonArgs args;
  fl::bench::AddCommonFlags(&cli, &args, "stereo");
  std::string folders, config, png_dir = "out/bench";
  int threads = 1;
  cli.AddFlag("folders", &folders,
              "comma-separated KITTI folders (default: DATA/stereo/kitti_raw_2011_09_26_drive_0001"
              " and DATA/lidar_stereo/kitti_odometry_04_f000-050 if present, or DATA itself if it"
              " is a KITTI folder); each runs plain (<name>) and with local BA (<name>_ba), and with"
              " Velodyne scans laser-aided with local BA (<name>_lv)");
  cli.AddFlag("config", &config, "stereo VO options YAML (default: built-in defaults)");
  cli.AddFlag("png-dir", &png_dir, "folder for the trajectory PNGs");
  cli.AddFlag("threads", &threads, "OpenCV threads (1 = the single-core number)");
  cli.AddEpilog("\nExample: ./fusionloc bench stereo --data ../shared/data\n");
  if (!program.Parse(argc, argv)) return program.exit_code();
  try {
    cv::setNumThreads(threads);
    fl::vo::StereoVoOptions options;
    if (!config.empty()) options = fl::LoadYamlFile<fl::vo::StereoVoOptions>(config);
    std::vector<std::string> list;
    if (folders.empty()) {
      const bool is_kitti =
          fs::exists(args.data_dir + "/image_00") || fs::exists(args.data_dir + "/image_0");
      list.push_back(is_kitti ? args.data_dir
                              : args.data_dir + "/stereo/kitti_raw_2011_09_26_drive_0001");
      const std::string lidar = args.data_dir + "/lidar_stereo/kitti_odometry_04_f000-050";
      if (!is_kitti && fs::is_directory(lidar)) list.push_back(lidar);
    } else {
      std::stringstream ss(folders);
      for (std::string f; std::getline(ss, f, ',');) {
        if (!f.empty()) list.push_back(f);
      }
    }
    const std::string tmp =
        (fs::temp_directory_path() / ("fl_bench_stereo_" + std::to_string(::getpid()))).string();
    fs::create_directories(tmp);
    fl::bench::Report report("stereo");
    for (const std::string& folder : list) {
      if (!fs::is_directory(folder)) {
        throw std::runtime_error("no such folder: " + folder + " (give --folders or --data)");
      }
      std::vector<Mode> modes = {kPlain, kBa};
      if (!fl::importers::ScanKittiFolder(KittiOptionsFor(folder), folder).velodyne_scans.empty()) {
        modes.push_back(kLaser);
      }
      for (const Mode& mode : modes) {
        RunOutput out = RunFolder(folder, options, png_dir, tmp, mode);
        std::cerr << out.summary << "\n";
        report.AddRun(std::move(out.run));
      }
    }
    fs::remove_all(tmp);
    fl::bench::Publish(report, args);
  } catch (const std::exception& e) {
    std::cerr << "fl-bench-stereo: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
