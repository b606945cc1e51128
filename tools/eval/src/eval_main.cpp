// fl-eval: compares an estimated trajectory with a reference (ATE, RPE, KITTI drift, relation
// error), prints a table, and optionally writes JSON and PNG plots.
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>

#include "fusionloc/common/log.hpp"
#include "fusionloc/common/program.hpp"
#include "fusionloc/eval/metrics.hpp"
#include "fusionloc/eval/plot.hpp"
#include "fusionloc/eval/trajectory.hpp"

namespace fl::eval {
namespace {

struct Args {
  std::string est_path, ref_path;
  std::string est_channel = "";
  std::string ref_channel = "GROUND_TRUTH";
  std::string format = "auto";
  std::string est_format = "", ref_format = "";
  std::string est_times = "", ref_times = "";
  std::string align = "se3";
  double max_dt_s = 0.01;
  double rpe_delta = 1.0;
  std::string rpe_unit = "frames";
  std::string kitti_lengths = "auto";
  int kitti_step = 10;
  std::string relations;
  std::string write_relations;
  std::string json;
  std::string plot;
  std::string plot_plane = "xy";
  std::string map_log;
  std::string map_channel = "RBPF_MAP";
  std::string title;
  std::string est_name = "estimate";
  std::string ref_name = "reference";
};

std::string Num(double v, int digits = 4) {
  if (!std::isfinite(v)) return "null";
  if (v == 0.0) v = 0.0;  // no "-0"
  std::ostringstream s;
  s << std::setprecision(digits > 6 ? digits : 10) << v;
  return s.str();
}

std::string JsonString(const std::string& text) {
  std::string out = "\"";
  for (char c : text) {
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (static_cast<unsigned char>(c) < 0x20) {
      char buf[8];
      std::snprintf(buf, sizeof(buf), "\\u%04x", c);
      out += buf;
    } else {
      out += c;
    }
  }
  return out + "\"";
}

std::string JsonStats(const ErrorStats& s) {
  std::ostringstream o;
  o << "{\"rmse\": " << Num(s.rmse) << ", \"mean\": " << Num(s.mean)
    << ", \"median\": " << Num(s.median) << ", \"std\": " << Num(s.std)
    << ", \"max\": " << Num(s.max) << ", \"count\": " << s.count << "}";
  return o.str();
}

std::vector<double> ParseLengths(const std::string& text) {
  std::vector<double> lengths;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    char* end = nullptr;
    const double v = std::strtod(item.c_str(), &end);
    if (item.empty() || *end != '\0' || !(v > 0) || !std::isfinite(v)) {
      throw EvalError("--kitti-lengths: '" + item +
                      "' is not a positive length in metres; give e.g. 100,200,300 or 'auto'");
    }
    lengths.push_back(v);
  }
  if (lengths.empty()) throw EvalError("--kitti-lengths is empty; give e.g. 100,200 or 'auto'");
  return lengths;
}

void PrintStatsRow(std::ostream& out, const std::string& name, const ErrorStats& s) {
  out << "  " << std::left << std::setw(34) << name << std::right << std::fixed
      << std::setprecision(4) << std::setw(10) << s.rmse << std::setw(10) << s.mean << std::setw(10)
      << s.median << std::setw(10) << s.std << std::setw(10) << s.max << std::setw(8) << s.count
      << "\n";
}

void WriteFileAtomically(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".partial";
  {
    std::ofstream out(tmp);
    if (!out) throw EvalError("cannot write '" + path + "': does the folder exist?");
    out << text;
    if (!out.good()) throw EvalError("error writing '" + tmp + "'");
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    throw EvalError("cannot rename '" + tmp + "' to '" + path + "'");
  }
}

int Run(const Args& a) {
  const Alignment alignment = ParseAlignment(a.align);
  const DeltaUnit unit = ParseDeltaUnit(a.rpe_unit);
  if (a.plot_plane != "xy" && a.plot_plane != "xz") {
    throw EvalError("--plot-plane '" + a.plot_plane + "' unknown; use xy or xz");
  }
  if (!(a.max_dt_s >= 0) || !std::isfinite(a.max_dt_s)) {
    throw EvalError("--max-dt must be a time in seconds >= 0");
  }
  const Utime max_dt = SecondsToUtime(a.max_dt_s);
  const Trajectory est = ReadTrajectory(
      a.est_path, a.est_channel, a.est_format.empty() ? a.format : a.est_format, a.est_times);
  const Trajectory ref = ReadTrajectory(
      a.ref_path, a.ref_channel, a.ref_format.empty() ? a.format : a.ref_format, a.ref_times);

  BackgroundGrid background;  // read first, so a bad map fails before any output
  if (!a.map_log.empty()) background = ReadBackgroundGridLcm(a.map_log, a.map_channel);

  const AteResult ate = ComputeAte(est, ref, alignment, max_dt);
  const RpeResult rpe = ComputeRpe(est, ref, a.rpe_delta, unit, max_dt);
  const double ref_length = PathLength(ate.ref_matched);

  DriftResult drift;
  bool have_drift = false;
  std::string drift_note;
  if (a.kitti_lengths == "none") {
    drift_note = "not computed (--kitti-lengths none)";
  } else if (a.kitti_lengths == "auto") {
    if (ref_length < 0.1) {
      drift_note = "not computed: the reference moves only " + Num(ref_length) + " m";
    } else {
      drift = ComputeKittiDrift(est, ref, DefaultKittiLengths(ref_length), max_dt, a.kitti_step);
      have_drift = true;
    }
  } else {
    drift = ComputeKittiDrift(est, ref, ParseLengths(a.kitti_lengths), max_dt, a.kitti_step);
    have_drift = true;
  }
  if (!a.write_relations.empty()) {
    WriteRelations(RelationsFromTrajectory(ref, 1), a.write_relations);
    std::cout << "wrote " << ref.size() - 1 << " relations (consecutive reference poses) to "
              << a.write_relations << "\n";
  }
  RelationResult rel;
  const bool have_rel = !a.relations.empty();
  if (have_rel) rel = ComputeRelationError(est, a.relations, max_dt);

  // ---- table ----
  std::ostream& out = std::cout;
  const std::string unit_name = unit == DeltaUnit::kFrames   ? "frames"
                                : unit == DeltaUnit::kMeters ? "m"
                                                             : "s";
  out << "est: " << a.est_path << (a.est_channel.empty() ? "" : " [" + a.est_channel + "]") << "  ("
      << est.size() << " poses)\n"
      << "ref: " << a.ref_path << (IsLcmLog(a.ref_path) ? " [" + a.ref_channel + "]" : "") << "  ("
      << ref.size() << " poses, " << std::fixed << std::setprecision(2) << ref_length
      << " m along the associated poses)\n"
      << "pairs: " << ate.utimes.size() << " within " << std::defaultfloat << a.max_dt_s * 1000
      << " ms; alignment " << AlignmentName(alignment);
  if (alignment == Alignment::kSim3) out << " (scale " << std::setprecision(6) << ate.scale << ")";
  out << "\n";
  if (!ate.warning.empty()) out << "warning: " << ate.warning << "\n";
  out << "\n";
  out << "  " << std::left << std::setw(34) << "metric" << std::right << std::setw(10) << "rmse"
      << std::setw(10) << "mean" << std::setw(10) << "median" << std::setw(10) << "std"
      << std::setw(10) << "max" << std::setw(8) << "count"
      << "\n";
  PrintStatsRow(out, "ATE translation [m]", ate.trans_m);
  PrintStatsRow(out, "ATE rotation [deg]", ate.rot_deg);
  std::ostringstream delta_text;
  delta_text << std::defaultfloat << a.rpe_delta << " " << unit_name;
  PrintStatsRow(out, "RPE translation [m] / " + delta_text.str(), rpe.trans_m);
  PrintStatsRow(out, "RPE rotation [deg] / " + delta_text.str(), rpe.rot_deg);
  if (have_rel) {
    PrintStatsRow(out, "relation translation [m]", rel.trans_m);
    PrintStatsRow(out, "relation rotation [deg]", rel.rot_deg);
    out << "  relations: " << rel.used << " used, " << rel.skipped
        << " skipped (a time not within --max-dt of an estimated pose)\n";
  }
  out << "\n";
  if (have_drift) {
    out << "KITTI segment drift: " << std::fixed << std::setprecision(3) << drift.trans_pct
        << " %  " << drift.rot_deg_per_100m << " deg/100 m  (" << drift.segments
        << " segments, every " << a.kitti_step << " frames)\n";
    out << "  " << std::setw(10) << "length [m]" << std::setw(12) << "trans [%]" << std::setw(16)
        << "rot [deg/100m]" << std::setw(10) << "segments"
        << "\n";
    for (size_t i = 0; i < drift.lengths_m.size(); ++i) {
      out << "  " << std::setw(10) << std::setprecision(1) << drift.lengths_m[i] << std::setw(12)
          << std::setprecision(3) << drift.trans_pct_per_length[i] << std::setw(16)
          << drift.rot_deg_per_100m_per_length[i] << std::setw(10) << drift.segments_per_length[i]
          << "\n";
    }
  } else {
    out << "KITTI segment drift: " << drift_note << "\n";
  }

  // ---- JSON ----
  if (!a.json.empty()) {
    std::ostringstream j;
    j << "{\n  \"est\": " << JsonString(a.est_path)
      << ",\n  \"est_channel\": " << JsonString(a.est_channel)
      << ",\n  \"ref\": " << JsonString(a.ref_path)
      << ",\n  \"ref_channel\": " << JsonString(IsLcmLog(a.ref_path) ? a.ref_channel : "")
      << ",\n  \"est_poses\": " << est.size() << ",\n  \"ref_poses\": " << ref.size()
      << ",\n  \"pairs\": " << ate.utimes.size() << ",\n  \"max_dt_s\": " << Num(a.max_dt_s)
      << ",\n  \"warning\": " << JsonString(ate.warning)
      << ",\n  \"ref_path_length_m\": " << Num(ref_length, 10) << ",\n  \"alignment\": \""
      << AlignmentName(alignment) << "\",\n  \"scale\": " << Num(ate.scale, 10)
      << ",\n  \"T_ref_est\": [";
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) {
        j << (r || c ? ", " : "") << Num(ate.T_ref_est.matrix()(r, c), 12);
      }
    }
    j << "],\n  \"ate\": {\"trans_m\": " << JsonStats(ate.trans_m)
      << ", \"rot_deg\": " << JsonStats(ate.rot_deg)
      << "},\n  \"rpe\": {\"delta\": " << Num(a.rpe_delta) << ", \"unit\": \"" << unit_name
      << "\", \"trans_m\": " << JsonStats(rpe.trans_m)
      << ", \"rot_deg\": " << JsonStats(rpe.rot_deg) << "},\n";
    if (have_drift) {
      j << "  \"drift\": {\"trans_pct\": " << Num(drift.trans_pct)
        << ", \"rot_deg_per_100m\": " << Num(drift.rot_deg_per_100m)
        << ", \"segments\": " << drift.segments << ", \"step_frames\": " << a.kitti_step
        << ", \"per_length\": [";
      for (size_t i = 0; i < drift.lengths_m.size(); ++i) {
        j << (i ? ", " : "") << "{\"length_m\": " << Num(drift.lengths_m[i])
          << ", \"trans_pct\": " << Num(drift.trans_pct_per_length[i])
          << ", \"rot_deg_per_100m\": " << Num(drift.rot_deg_per_100m_per_length[i])
          << ", \"segments\": " << drift.segments_per_length[i] << "}";
      }
      j << "]},\n";
    } else {
      j << "  \"drift\": null,\n";
    }
    if (have_rel) {
      j << "  \"relations\": {\"file\": " << JsonString(a.relations)
        << ", \"trans_m\": " << JsonStats(rel.trans_m)
        << ", \"rot_deg\": " << JsonStats(rel.rot_deg)
        << ", \"trans_sq_mean_m2\": " << Num(rel.trans_sq_mean_m2)
        << ", \"rot_sq_mean_deg2\": " << Num(rel.rot_sq_mean_deg2) << ", \"used\": " << rel.used
        << ", \"skipped\": " << rel.skipped << "}\n";
    } else {
      j << "  \"relations\": null\n";
    }
    j << "}\n";
    WriteFileAtomically(a.json, j.str());
    out << "\nwrote " << a.json << "\n";
  }

  // ---- plots ----
  if (!a.plot.empty()) {
    const std::string title = a.title.empty() ? a.est_name + " vs " + a.ref_name : a.title;
    TopViewOptions opt;
    std::ostringstream t;
    t << title << "  (ATE " << std::fixed << std::setprecision(3) << ate.trans_m.rmse << " m RMSE, "
      << AlignmentName(alignment) << ")";
    opt.title = t.str();
    opt.plane = a.plot_plane;
    if (!a.map_log.empty()) opt.background = &background;
    PlotTrajectoriesTopView(a.plot + "_traj.png",
                            {{a.ref_name, ate.ref_matched, kPlotBlack},
                             {a.est_name + " (aligned)", ate.est_aligned, kPlotBlue}},
                            opt);
    PlotAteErrors(a.plot + "_errors.png", ate, title + ": error of the aligned estimate",
                  a.est_name, a.plot_plane);
    out << "wrote " << a.plot << "_traj.png, " << a.plot << "_errors.png\n";
  }
  return 0;
}

}  // namespace
}  // namespace fl::eval

int main(int argc, char** argv) {
  fl::eval::Args a;
  fl::Program program("fl-eval",
                      "Compares an estimated trajectory EST with a reference REF: absolute "
                      "trajectory error after alignment, relative pose error, KITTI segment "
                      "drift and (optionally) the relation error of Kuemmerle et al. 2009. "
                      "EST and REF are LCM logs (poses read from a channel) or text files "
                      "(TUM, KITTI, 2D). Exit status: 0 ok, 1 bad input, 2 bad usage.");
  fl::CommandLine& cli = program.cli();
  cli.AddPositional("EST", &a.est_path, "estimated trajectory: LCM log or text file");
  cli.AddPositional("REF", &a.ref_path, "reference trajectory: LCM log or text file");
  cli.AddFlag("est-channel", &a.est_channel,
              "pose channel when EST is an LCM log (bot_core.pose_t, fusionloc.fused_pose_t, "
              "fusionloc.wheel_odometry_t, or "
              "fusionloc.trajectory_t = its last message), e.g. FUSED_POSE, RBPF_TRAJECTORY");
  cli.AddFlag("ref-channel", &a.ref_channel, "pose channel when REF is an LCM log");
  cli.AddFlag("format", &a.format, "text format of both files: auto, tum, kitti, 2d");
  cli.AddFlag("est-format", &a.est_format, "text format of EST (overrides --format)");
  cli.AddFlag("ref-format", &a.ref_format, "text format of REF (overrides --format)");
  cli.AddFlag("est-times", &a.est_times,
              "times file for a KITTI-format EST (seconds or 'YYYY-MM-DD HH:MM:SS.f' a line); "
              "default 10 Hz from 0");
  cli.AddFlag("ref-times", &a.ref_times, "times file for a KITTI-format REF");
  cli.AddFlag("align", &a.align,
              "alignment before ATE: se2 (planar robots), se3, sim3 (unknown scale), none");
  cli.AddFlag("max-dt", &a.max_dt_s, "association tolerance [s]");
  cli.AddFlag("rpe-delta", &a.rpe_delta, "RPE step, in --rpe-unit");
  cli.AddFlag("rpe-unit", &a.rpe_unit, "RPE step unit: frames, m, s");
  cli.AddFlag("kitti-lengths", &a.kitti_lengths,
              "KITTI segment lengths [m], comma separated; 'auto' = 100..800 on paths >= 200 m, "
              "else 8 shorter ones; 'none' to skip");
  cli.AddFlag("kitti-step", &a.kitti_step, "KITTI: a segment starts every this many frames");
  cli.AddFlag("relations", &a.relations,
              "relations file (t1 t2 x y z roll pitch yaw a line) for the relation error");
  cli.AddFlag("write-relations", &a.write_relations,
              "also write a relations file from REF (each pose to the next) for --relations");
  cli.AddFlag("json", &a.json, "write the results as JSON to this file");
  cli.AddFlag("plot", &a.plot, "write PREFIX_traj.png (top view) and PREFIX_errors.png");
  cli.AddFlag("plot-plane", &a.plot_plane,
              "plane of the plots: xy (ground robot, z up) or xz (camera frames such as KITTI's "
              "poses: x right, z forward)");
  cli.AddFlag("map-log", &a.map_log,
              "LCM log whose last occupancy grid (--map-channel) is drawn under the top view");
  cli.AddFlag("map-channel", &a.map_channel, "occupancy-grid channel in --map-log");
  cli.AddFlag("title", &a.title, "plot title");
  cli.AddFlag("est-name", &a.est_name, "legend name of EST");
  cli.AddFlag("ref-name", &a.ref_name, "legend name of REF");
  cli.AddEpilog(
      "\nExamples:\n"
      "  fl-eval run.lcmlog run.lcmlog --est-channel FUSED_POSE --ref-channel GROUND_TRUTH "
      "--align se2 --plot out/run\n"
      "  fl-eval vo.txt poses_cam0_from_oxts.txt --format kitti --kitti-lengths 10,20,40,80 "
      "--json out/vo.json\n"
      "  fl-eval slam.tum corrected.tum --align se2 --relations csail.relations --rpe-delta 1 "
      "--rpe-unit m\n"
      "Metric definitions: docs/EVALUATION.md\n");
  if (!program.Parse(argc, argv)) return program.exit_code();
  try {
    return fl::eval::Run(a);
  } catch (const fl::eval::EvalError& e) {
    std::cerr << "fl-eval: error: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "fl-eval: unexpected error: " << e.what() << "\n";
    return 1;
  }
}
