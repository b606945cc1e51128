// fl-bench-posegraph: every g2o pose graph in DATA/posegraph/ through the fusion back-end
// (fl::fusion::OptimizePoseGraph: the same cost functors as the fusion), reporting final
// cost, iterations and solve time against the reference costs of Ceres' own examples.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <map>
#include <sstream>

#include "fusionloc/bench/bench.hpp"
#include "fusionloc/common/program.hpp"
#include "fusionloc/fusion/pose_graph.hpp"

namespace {

struct Reference {
  double cost;
  double ceres_example_s;  // Ceres' example time on these machines (0: unknown)
  bool converges;          // false: the reference did not converge in 100 iterations
};

const std::map<std::string, Reference>& References() {
  static const std::map<std::string, Reference> refs = {
      {"intel", {22.939, 0.03, true}},          {"M3500b", {4718.04, 0.0, true}},
      {"city10000", {255.99, 1.2, true}},       {"sphere2500", {675.756, 1.3, true}},
      {"parking-garage", {0.63419, 0.0, true}}, {"MIT", {682.33, 0.0, false}},
  };
  return refs;
}

}  // namespace

int main(int argc, char** argv) {
  fl::Program program("fl-bench-posegraph",
                      "Optimises every g2o pose graph (VERTEX_SE2/EDGE_SE2, VERTEX_SE3:QUAT/"
                      "EDGE_SE3:QUAT) in DATA/posegraph/ with the fusion back-end (LM, "
                      "SPARSE_NORMAL_CHOLESKY, max 100 iterations, first pose fixed) and "
                      "compares the final cost (1/2 sum |r|^2) with Ceres' example references.");
  fl::CommandLine& cli = program.cli();
  fl::bench::CommonArgs args;
  fl::bench::AddCommonFlags(&cli, &args, "posegraph");
  int repeats = 3;
  int threads = 1;
  std::string only;
  bool full_report = false;
  std::string sparse_library = "suite_sparse";
  cli.AddFlag("sparse-library", &sparse_library,
              "sparse Cholesky: suite_sparse (as Ceres' examples) or eigen_sparse");
  cli.AddFlag("full-report", &full_report, "print Ceres' full solver report of each graph");
  cli.AddFlag("repeats", &repeats, "solves per graph; the median solve time is reported");
  cli.AddFlag("threads", &threads, "Ceres threads (1 = fair single-core time)");
  cli.AddFlag("only", &only, "run only graphs whose file name contains this text");
  if (!program.Parse(argc, argv)) return program.exit_code();
  if (repeats < 1 || threads < 1) {
    std::cerr << "fl-bench-posegraph: --repeats and --threads must be >= 1\n";
    return 2;
  }
  namespace fs = std::filesystem;
  const fs::path dir = fs::path(args.data_dir) / "posegraph";
  std::vector<fs::path> files;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (it->path().extension() == ".g2o" &&
        it->path().filename().string().find(only) != std::string::npos) {
      files.push_back(it->path());
    }
  }
  if (ec || files.empty()) {
    std::cerr << "fl-bench-posegraph: no .g2o files in " << dir
              << (ec ? " (" + ec.message() + ")" : std::string())
              << "; pass --data DIR with the graphs in DIR/posegraph/\n";
    return 1;
  }
  std::sort(files.begin(), files.end());

  fl::bench::Report report("posegraph");
  int failures = 0;
  for (const fs::path& file : files) {
    const std::string name = file.stem().string();
    fl::fusion::G2oGraph original;
    fl::Status s = fl::fusion::ReadG2oFile(file.string(), &original);
    if (!s.ok()) {
      std::cerr << "fl-bench-posegraph: " << s.message() << "\n";
      ++failures;
      continue;
    }
    fl::fusion::PoseGraphSolveOptions options;
    options.num_threads = threads;
    options.sparse_library = sparse_library;
    std::vector<double> solve_times, total_times, cpu_times;
    fl::fusion::PoseGraphResult result;
    for (int r = 0; r < repeats && s.ok(); ++r) {
      fl::fusion::G2oGraph graph = original;
      s = fl::fusion::OptimizePoseGraph(&graph, options, &result);
      solve_times.push_back(result.solve_s);
      total_times.push_back(result.total_s);
      cpu_times.push_back(result.solve_cpu_s);
    }
    if (!s.ok()) {
      std::cerr << "fl-bench-posegraph: " << name << ": " << s.message() << "\n";
      ++failures;
      continue;
    }
    std::cerr << "[bench posegraph] " << name << ": "
              << (full_report ? result.full_report : result.brief_report) << "\n";
    fl::bench::Run run;
    run.name = name;
    run.input = file.string();
    run.Add("poses", static_cast<double>(original.num_poses()))
        .Add("edges", static_cast<double>(original.num_edges()))
        .Add("initial_cost", result.initial_cost)
        .Add("final_cost", result.final_cost)
        .Add("iterations", result.iterations)
        .Add("solve_s", fl::bench::ComputeStats(solve_times).median)
        .Add("solve_cpu_s", fl::bench::ComputeStats(cpu_times).median)
        .Add("total_s", fl::bench::ComputeStats(total_times).median)
        .Add("converged", result.converged ? 1.0 : 0.0);
    std::ostringstream note;
    note << result.termination;
    const auto ref = References().find(name);
    if (ref != References().end()) {
      const double rel = 100.0 * (result.final_cost - ref->second.cost) / ref->second.cost;
      run.Add("reference_cost", ref->second.cost).Add("cost_diff_pct", rel);
      note << "; cost vs reference " << ref->second.cost << ": "
           << (std::fabs(rel) <= 0.1 ? "within 0.1%" : "MISSED 0.1%");
      if (!ref->second.converges) note << " (reference not converged in 100 its)";
      if (ref->second.ceres_example_s > 0) {
        run.Add("ceres_example_s", ref->second.ceres_example_s);
        note << "; time vs Ceres example " << ref->second.ceres_example_s
             << " s: " << (run.Get("solve_s") <= ref->second.ceres_example_s ? "met" : "slower")
             << " (wall), "
             << (run.Get("solve_cpu_s") <= ref->second.ceres_example_s ? "met" : "slower")
             << " (CPU)";
      }
    } else {
      note << "; no reference cost";
    }
    run.Add("peak_rss_mb", fl::bench::PeakRssMb());
    run.note = note.str();
    report.AddRun(run);
  }
  try {
    fl::bench::Publish(report, args);
  } catch (const std::exception& e) {
    std::cerr << "fl-bench-posegraph: " << e.what() << "\n";
    return 1;
  }
  return failures == 0 ? 0 : 1;
}
