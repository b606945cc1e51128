// fl-bench-simulator (./fusionloc bench simulator): how fast the simulator writes logs, how far its
// raw odometry drifts, and the calibration of the camera pixel noise: the error of stereo
// triangulated ORB corners against the rendered ground-truth depth, for several noise levels.
#include <time.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <sstream>

#include "fusionloc/bench/bench.hpp"
#include "fusionloc/common/program.hpp"
#include "fusionloc/sim/simulator.hpp"

namespace {

double CpuSeconds() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

std::vector<std::string> Split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream in(s);
  std::string item;
  while (std::getline(in, item, ',')) {
    if (!item.empty()) out.push_back(item);
  }
  return out;
}

// Writes a whole log of `world`, timing every step (CPU), then deletes it.
fl::bench::Run BenchLog(const std::string& world, double duration, const std::string& dir) {
  fl::sim::SimOptions o = fl::sim::DefaultOptionsForWorld(world);
  if (duration > 0) o.duration_s = duration;
  const std::string path = dir + "/fl_bench_sim_" + world + ".lcmlog";
  std::vector<double> step_ms;
  double last_cpu = CpuSeconds();
  const double cpu0 = last_cpu;
  const auto wall0 = fl::MonotonicUtime();
  fl::bench::Progress progress("bench simulator " + world, o.steps() + 1);
  const fl::sim::LogStats stats = fl::sim::WriteLog(o, path, [&](int64_t done, int64_t) {
    const double now = CpuSeconds();
    step_ms.push_back(1e3 * (now - last_cpu));
    last_cpu = now;
    progress.Update(done);
  });
  progress.Finish();
  const double cpu_s = CpuSeconds() - cpu0;
  const double wall_s = 1e-6 * static_cast<double>(fl::MonotonicUtime() - wall0);
  const double file_mb = static_cast<double>(std::filesystem::file_size(path)) / 1e6;
  std::filesystem::remove(path);

  // Raw odometry drift over the same run (no sensors: cheap).
  o.laser.enabled = o.camera.enabled = false;
  fl::sim::Simulator sim(o);
  fl::sim::SimFrame f, first;
  double path_m = 0;
  bool have_first = false;
  Eigen::Vector2d prev;
  while (sim.Step(&f)) {
    if (!have_first)
      first = f, have_first = true;
    else
      path_m += (f.T_world_base.translation() - prev).norm();
    prev = f.T_world_base.translation();
  }
  // Odometry starts at the true start pose: compare in the world frame.
  const fl::Pose2 T_world_odom = first.T_world_base * first.T_odom_base.inverse();
  const fl::Pose2 odom_end = T_world_odom * f.T_odom_base;
  const double end_err = (odom_end.translation() - f.T_world_base.translation()).norm();

  const fl::bench::Stats s = fl::bench::ComputeStats(step_ms);
  fl::bench::Run run;
  run.name = world + "-log";
  run.input = "fl-sim --world " + world + " --duration " + std::to_string(o.duration_s);
  run.Add("items", static_cast<double>(stats.frames))
      .Add("ms_per_item_mean", s.mean)
      .Add("ms_per_item_median", s.median)
      .Add("ms_per_item_p95", s.p95)
      .Add("cpu_s", cpu_s)
      .Add("wall_s", wall_s)
      .Add("sim_s_per_cpu_s", o.duration_s / cpu_s)
      .Add("log_mb", file_mb)
      .Add("path_m", path_m)
      .Add("endpoint_err_m", end_err)
      .Add("drift_pct", 100.0 * end_err / std::max(path_m, 1e-9))
      .Add("peak_rss_mb", fl::bench::PeakRssMb());
  std::ostringstream note;
  note << "one core CPU " << cpu_s << " s for " << o.duration_s
       << " s simulated; step = 0.1 s, ms per step, a stereo pair every "
       << o.PeriodSteps(o.camera.rate_hz) << " step(s) (" << o.camera.rate_hz
       << " Hz); endpoint/drift = raw wheel odometry";
  run.note = note.str();
  return run;
}

struct TriangulationErrors {
  std::vector<double> typical;          // |error| [m] of corners with true depth in [4, 6] m
  std::vector<double> all;              // true depth in [1, 10] m
  std::vector<double> typical_integer;  // same corners, integer (unrefined) disparity
  int outliers = 0;                     // |error| > 1 m (mismatches), excluded from the statistics
  int matches = 0;
};

// Sum of absolute differences of (2w+1)^2 patches centred at (ul, v) in `left` and (ur, v) in
// `right`; -1 if a patch leaves the image.
double Sad(const cv::Mat& left, const cv::Mat& right, int ul, int ur, int v, int w) {
  if (ul - w < 0 || ur - w < 0 || ul + w >= left.cols || ur + w >= right.cols || v - w < 0 ||
      v + w >= left.rows) {
    return -1;
  }
  double sum = 0;
  for (int dv = -w; dv <= w; ++dv) {
    const uint8_t* a = left.ptr<uint8_t>(v + dv);
    const uint8_t* b = right.ptr<uint8_t>(v + dv);
    for (int du = -w; du <= w; ++du) sum += std::abs(a[ul + du] - b[ur + du]);
  }
  return sum;
}

// ORB corners in the left image matched along the same rows in the right image by descriptor,
// then refined by patch (SAD) correlation over +-3 px with a parabola fit (the usual sub-pixel
// stereo matching of ORB-based stereo VO), triangulated and compared with the true depth.
void Triangulate(const cv::Mat& left, const cv::Mat& right, const std::vector<float>& depth,
                 const fl::sim::CameraOptions& cam, TriangulationErrors* out) {
  auto orb = cv::ORB::create(1000);
  std::vector<cv::KeyPoint> kl, kr;
  cv::Mat dl, dr;
  orb->detectAndCompute(left, cv::noArray(), kl, dl);
  orb->detectAndCompute(right, cv::noArray(), kr, dr);
  std::vector<std::vector<int>> rows(static_cast<size_t>(cam.height));
  for (size_t j = 0; j < kr.size(); ++j) {
    const int v = static_cast<int>(std::lround(kr[j].pt.y));
    if (v >= 0 && v < cam.height) rows[static_cast<size_t>(v)].push_back(static_cast<int>(j));
  }
  const double max_disp = cam.fx * cam.baseline_m / 0.5;
  for (size_t i = 0; i < kl.size(); ++i) {
    const cv::Point2f pl = kl[i].pt;
    int best = -1;
    double best_d = 1e9, second = 1e9;
    for (int v = static_cast<int>(pl.y) - 2; v <= static_cast<int>(pl.y) + 2; ++v) {
      if (v < 0 || v >= cam.height) continue;
      for (int j : rows[static_cast<size_t>(v)]) {
        const double disp = pl.x - kr[static_cast<size_t>(j)].pt.x;
        if (disp <= 0 || disp > max_disp) continue;
        const double d = cv::norm(dl.row(static_cast<int>(i)), dr.row(j), cv::NORM_HAMMING);
        if (d < best_d)
          second = best_d, best_d = d, best = j;
        else if (d < second)
          second = d;
      }
    }
    if (best < 0 || best_d > 50 || best_d > 0.8 * second) continue;
    const int ul = static_cast<int>(std::lround(pl.x)), v = static_cast<int>(std::lround(pl.y));
    const int ur0 = static_cast<int>(std::lround(kr[static_cast<size_t>(best)].pt.x));
    // Truth: depth at the left corner pixel, only on smooth surfaces (not at depth edges).
    const auto at = [&](int uu, int vv) {
      return depth[static_cast<size_t>(vv) * cam.width + static_cast<size_t>(uu)];
    };
    if (ul < 1 || v < 1 || ul >= cam.width - 1 || v >= cam.height - 1) continue;
    const double z_true = at(ul, v);
    if (!std::isfinite(z_true)) continue;
    bool smooth = true;
    for (int dv = -1; dv <= 1; ++dv) {
      for (int du = -1; du <= 1; ++du)
        smooth &= std::fabs(at(ul + du, v + dv) - z_true) < 0.02 * z_true;
    }
    if (!smooth || z_true < 1.0 || z_true > 10.0) continue;
    double sad[7];
    bool ok = true;
    for (int k = -3; k <= 3; ++k) {
      sad[k + 3] = Sad(left, right, ul, ur0 + k, v, 5);
      ok &= sad[k + 3] >= 0;
    }
    if (!ok) continue;
    const int kbest = static_cast<int>(std::min_element(sad, sad + 7) - sad);
    if (kbest == 0 || kbest == 6) continue;
    const double a = sad[kbest - 1], b = sad[kbest], c = sad[kbest + 1];
    const double denom = a - 2 * b + c;
    const double delta = denom > 0 ? 0.5 * (a - c) / denom : 0.0;
    if (std::fabs(delta) > 1.0) continue;
    const double disp = ul - (ur0 + (kbest - 3) + delta);
    if (disp <= 0) continue;
    ++out->matches;
    const double ray = std::hypot(1.0, std::hypot((ul - cam.cx) / cam.fx, (v - cam.cy) / cam.fx));
    const double err = std::fabs(cam.fx * cam.baseline_m / disp - z_true) * ray;
    const double err_int =
        std::fabs(cam.fx * cam.baseline_m / std::max(1.0, static_cast<double>(ul - ur0)) - z_true) *
        ray;
    if (err > 1.0) {
      ++out->outliers;
      continue;
    }
    out->all.push_back(err);
    if (z_true >= 4.0 && z_true <= 6.0) {
      out->typical.push_back(err);
      out->typical_integer.push_back(err_int);
    }
  }
}

double Rms(const std::vector<double>& e) {
  double s = 0;
  for (double x : e) s += x * x;
  return e.empty() ? 0.0 : std::sqrt(s / static_cast<double>(e.size()));
}

fl::bench::Run BenchTriangulation(const std::string& world, double sigma, int frames) {
  fl::sim::SimOptions o = fl::sim::DefaultOptionsForWorld(world);
  o.laser.enabled = o.camera.enabled = false;
  o.camera.pixel_noise_sigma = sigma;
  fl::sim::Simulator sim(o);
  fl::sim::Rng rng(12345);
  TriangulationErrors errors;
  const int64_t every = std::max<int64_t>(1, o.steps() / frames);
  fl::sim::SimFrame f;
  std::vector<uint8_t> l, r;
  std::vector<float> depth;
  while (sim.Step(&f)) {
    if (f.step % every != every / 2) continue;
    sim.camera().Render(sim.world(), f.T_world_base, fl::sim::CameraModel::kLeft, &rng, &l);
    sim.camera().Render(sim.world(), f.T_world_base, fl::sim::CameraModel::kRight, &rng, &r);
    sim.camera().RenderDepth(sim.world(), f.T_world_base, fl::sim::CameraModel::kLeft, &depth);
    const cv::Mat lm(o.camera.height, o.camera.width, CV_8UC1, l.data());
    const cv::Mat rm(o.camera.height, o.camera.width, CV_8UC1, r.data());
    Triangulate(lm, rm, depth, o.camera, &errors);
  }
  fl::bench::Run run;
  std::ostringstream name;
  name << "triangulation-" << (world == "paper" ? "" : world + "-") << "sigma-" << sigma;
  run.name = name.str();
  run.input = world + " world, " + std::to_string(frames) + " stereo frames along the route";
  std::vector<double> typical = errors.typical;
  run.Add("rms_err_4_6m", Rms(errors.typical))
      .Add("median_err_4_6m", fl::bench::ComputeStats(typical).median)
      .Add("rms_err_4_6m_integer_disp", Rms(errors.typical_integer))
      .Add("n_4_6m", static_cast<double>(errors.typical.size()))
      .Add("rms_err_1_10m", Rms(errors.all))
      .Add("matches", errors.matches)
      .Add("outlier_pct", 100.0 * errors.outliers / std::max(1, errors.matches));
  run.note =
      "ORB + row search + SAD sub-pixel refinement; error = |triangulated - true| of "
      "corners on smooth surfaces; errors > 1 m counted as outliers";
  return run;
}

}  // namespace

int main(int argc, char** argv) {
  fl::Program program("fl-bench-simulator",
                      "Simulator benchmark: log-writing speed per world, raw odometry drift, and "
                      "the stereo triangulation error of ORB corners for several pixel-noise "
                      "levels (the calibration of camera.pixel_noise_sigma).");
  fl::CommandLine& cli = program.cli();
  fl::bench::CommonArgs args;
  fl::bench::AddCommonFlags(&cli, &args, "sim");
  std::string worlds = "paper,corridor", sigmas = "0,3,6,8,10";
  std::string tmp = std::filesystem::temp_directory_path().string();
  double duration = -1;
  int frames = 60;
  cli.AddFlag("worlds", &worlds, "comma-separated worlds whose logs are timed ('' = none)");
  cli.AddFlag("duration", &duration, "simulated seconds per log (-1 = the world's default)");
  cli.AddFlag("sigmas", &sigmas, "comma-separated pixel-noise sigmas to calibrate ('' = none)");
  cli.AddFlag("frames", &frames, "stereo frames per noise level");
  cli.AddFlag("tmp", &tmp, "folder for the temporary logs");
  bool corridor_triangulation = true;
  cli.AddFlag("corridor-triangulation", &corridor_triangulation,
              "also measure the triangulation error in the corridor world at the default noise");
  if (!program.Parse(argc, argv)) return program.exit_code();
  if (frames < 1) {
    std::cerr << "fl-bench-simulator: --frames must be >= 1\n";
    return 2;
  }
  try {
    fl::bench::Report report("simulator");
    for (const std::string& w : Split(worlds)) report.AddRun(BenchLog(w, duration, tmp));
    for (const std::string& s : Split(sigmas)) {
      report.AddRun(BenchTriangulation("paper", std::stod(s), frames));
      std::cerr << "[bench simulator] sigma " << s << " done\n";
    }
    if (corridor_triangulation) {
      // The corridor at the default noise: are its textures as good for stereo as the paper's?
      report.AddRun(BenchTriangulation(
          "corridor", fl::sim::DefaultOptionsForWorld("corridor").camera.pixel_noise_sigma,
          frames));
    }
    fl::bench::Publish(report, args);
  } catch (const std::exception& e) {
    std::cerr << "fl-bench-simulator: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
