// Shared pieces of every benchmark program (fl-bench-<name>, run by `./fusionloc bench NAME`):
// the one JSON format, the terminal table, machine facts, timing statistics, peak memory,
// progress lines, and recording the results in docs/BENCHMARKS.md.
//
// JSON (same for every benchmark):
//   {"bench": NAME, "machine": {...}, "command": "...",
//    "runs": [{"name": RUN, "input": PATH, "metrics": {KEY: NUMBER, ...}}]}
// Standard metric keys where they apply: ate_rmse_m, ate_rmse_deg, rpe_trans_m, rpe_rot_deg,
// drift_pct, drift_deg_per_100m, endpoint_err_m, ms_per_item_mean, ms_per_item_median,
// ms_per_item_p95, items, peak_rss_mb, final_cost, iterations, solve_s, latency_ms_p50,
// latency_ms_p99, dropped.
#pragma once

#include <cstdint>
#include <map>
#include <ostream>
#include <string>
#include <utility>
#include <vector>

#include "fusionloc/common/command_line.hpp"

namespace fl::bench {

struct Run {
  std::string name;                                     // e.g. "intel-corrected"
  std::string input;                                    // path of the data
  std::vector<std::pair<std::string, double>> metrics;  // in insertion (column) order
  std::string note;  // free text for the markdown table (e.g. "target <= 0.05 m: met")

  Run& Add(const std::string& key, double value) {
    metrics.emplace_back(key, value);
    return *this;
  }
  double Get(const std::string& key, double fallback = 0.0) const;
};

struct Machine {
  std::string cpu;
  int cores = 0;
  double memory_gb = 0.0;
  std::string compiler;
  std::string build_type;
  std::string date;  // UTC, ISO 8601
};
Machine ReadMachine();

class Report {
 public:
  explicit Report(std::string bench) : bench_(std::move(bench)) {}
  void AddRun(Run run) { runs_.push_back(std::move(run)); }
  const std::vector<Run>& runs() const { return runs_; }
  const std::string& bench() const { return bench_; }

  // Aligned table of all runs and the union of their metric keys.
  void PrintTable(std::ostream& out) const;
  std::string Json(const std::string& command) const;
  // Writes the JSON; creates the folder. Throws std::runtime_error on failure.
  void WriteJson(const std::string& path, const std::string& command) const;
  // Markdown section: heading, command, machine, table, notes.
  std::string Markdown(const std::string& command) const;
  // Replaces (or appends) this benchmark's section in a markdown file, between the markers
  // "<!-- bench:NAME:begin -->" and "<!-- bench:NAME:end -->".
  void RecordInMarkdown(const std::string& md_path, const std::string& command) const;

 private:
  std::string bench_;
  std::vector<Run> runs_;
};

// Summary statistics of per-item times (ms) or errors.
struct Stats {
  double mean = 0, median = 0, p95 = 0, p99 = 0, max = 0, min = 0;
  size_t count = 0;
};
Stats ComputeStats(std::vector<double> values);

// Least-squares slope of y over t using the points with t >= t_from and a finite y (a trend,
// e.g. memory per minute after a warm-up); NaN with fewer than two such points.
double LeastSquaresSlope(const std::vector<double>& t, const std::vector<double>& y,
                         double t_from = -1e300);

// Peak resident memory of this process so far (VmHWM), in MB.
double PeakRssMb();

// Progress of a long run on stderr: "[bench laser] intel  300/910  33%  eta 12 s".
// Prints at most every `interval_s` seconds and at the end.
class Progress {
 public:
  Progress(std::string label, int64_t total, double interval_s = 2.0);
  void Update(int64_t done);
  void Finish();

 private:
  std::string label_;
  int64_t total_;
  double interval_s_;
  int64_t start_us_;
  int64_t last_us_;
};

// Common flags of every fl-bench-* program.
struct CommonArgs {
  std::string data_dir;  // --data DIR: extra inputs (default: the shared data folder)
  std::string json;      // --json FILE (default: out/bench/NAME.json)
  std::string record;    // --record FILE.md: update this markdown file (empty: don't)
  std::string command;   // the command line that produced the results, for the record
};

// Registers --data, --json, --record and --command on a program's command line, with the
// defaults used by `./fusionloc bench NAME`.
void AddCommonFlags(CommandLine* cli, CommonArgs* args, const std::string& bench_name);

// Prints the table, writes the JSON and, if args.record is set, the markdown section.
void Publish(const Report& report, const CommonArgs& args);

}  // namespace fl::bench
