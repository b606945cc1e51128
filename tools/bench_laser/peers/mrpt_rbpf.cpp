#include "peers/mrpt_rbpf.hpp"

#include <fcntl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "fusionloc/bench/bench.hpp"

namespace fl::peers {
namespace fs = std::filesystem;

namespace {

std::runtime_error LineError(const std::string& path, int64_t line, const std::string& what) {
  return std::runtime_error(path + ":" + std::to_string(line) + ": " + what);
}

// Non-comment lines of a text file, split into numbers; `comment` starts a comment line.
struct NumberLine {
  int64_t line = 0;
  std::vector<double> v;
};
std::vector<NumberLine> ReadNumberLines(const std::string& path, char comment) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open (was it written by the run?)");
  std::vector<NumberLine> out;
  std::string text;
  int64_t n = 0;
  while (std::getline(in, text)) {
    ++n;
    const size_t first = text.find_first_not_of(" \t\r");
    if (first == std::string::npos || text[first] == comment) continue;
    NumberLine l;
    l.line = n;
    std::istringstream ss(text);
    std::string tok;
    while (ss >> tok) {
      char* end = nullptr;
      const double d = std::strtod(tok.c_str(), &end);
      if (end == tok.c_str() || *end != '\0' || !std::isfinite(d))
        throw LineError(path, n, "'" + tok + "' is not a finite number");
      l.v.push_back(d);
    }
    out.push_back(std::move(l));
  }
  return out;
}

void CheckFields(const std::string& path, const NumberLine& l, size_t min_fields,
                 const std::string& format) {
  if (l.v.size() < min_fields)
    throw LineError(path, l.line,
                    "expected " + format + " (" + std::to_string(min_fields) + " numbers), got " +
                        std::to_string(l.v.size()));
}

// Each line's first number is its step index 0, 1, 2, ...
void CheckIndex(const std::string& path, const NumberLine& l, size_t expected) {
  if (l.v[0] != static_cast<double>(expected))
    throw LineError(path, l.line,
                    "step " + std::to_string(static_cast<long long>(l.v[0])) + " where step " +
                        std::to_string(expected) + " was expected (steps in order from 0)");
}

std::string Tail(const std::string& path, int lines) {
  std::ifstream in(path);
  std::vector<std::string> all;
  std::string l;
  while (std::getline(in, l)) all.push_back(l);
  std::string out;
  for (size_t i = all.size() > static_cast<size_t>(lines) ? all.size() - lines : 0; i < all.size();
       ++i)
    out += "    " + all[i] + "\n";
  return out;
}

int64_t CountLines(const std::string& path) {
  std::ifstream in(path);
  int64_t n = 0;
  std::string l;
  while (std::getline(in, l))
    if (!l.empty() && l[0] != '%') ++n;
  return n;
}

struct ChildResult {
  int status = 0;  // waitpid status
  double peak_rss_mb = 0.0, cpu_s = 0.0, wall_s = 0.0;
};

// Runs argv with stdout and stderr to `log`; `poll` is called about every 2 s while it runs.
ChildResult RunChild(const std::vector<std::string>& argv, const std::string& log,
                     const std::function<void()>& poll) {
  const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw std::runtime_error(log + ": cannot create: " + std::strerror(errno));
  const auto t0 = std::chrono::steady_clock::now();
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(fd);
    throw std::runtime_error(std::string("fork: ") + std::strerror(errno));
  }
  if (pid == 0) {
    ::dup2(fd, 1);
    ::dup2(fd, 2);
    const int null = ::open("/dev/null", O_RDONLY);
    if (null >= 0) ::dup2(null, 0);
    std::vector<char*> args;
    for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    ::execvp(args[0], args.data());
    std::fprintf(stderr, "exec %s: %s\n", args[0], std::strerror(errno));
    ::_exit(127);
  }
  ::close(fd);
  ChildResult r;
  struct rusage ru {};
  auto last_poll = t0;
  for (;;) {
    const pid_t w = ::wait4(pid, &r.status, WNOHANG, &ru);
    if (w == pid) break;
    if (w < 0 && errno != EINTR)
      throw std::runtime_error(std::string("wait4: ") + std::strerror(errno));
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    const auto now = std::chrono::steady_clock::now();
    if (poll && now - last_poll > std::chrono::seconds(2)) {
      poll();
      last_poll = now;
    }
  }
  r.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.peak_rss_mb = static_cast<double>(ru.ru_maxrss) / 1024.0;  // KiB -> MiB, as PeakRssMb
  r.cpu_s = static_cast<double>(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
            1e-6 * static_cast<double>(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
  return r;
}

std::string ExitText(int status) {
  if (WIFEXITED(status)) return "exit status " + std::to_string(WEXITSTATUS(status));
  if (WIFSIGNALED(status)) return std::string("killed by signal ") + strsignal(WTERMSIG(status));
  return "status " + std::to_string(status);
}

}  // namespace

void WriteMrptSteps(const std::vector<MrptStep>& steps, const std::string& path) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error(path + ": cannot create");
  out << "# fl-mrpt-rawlog steps: index utime_us filter dx_m dy_m dtheta_rad\n"
      << "# filter = 1: rbpf-slam runs its particle filter on this step (a new path pose)\n";
  char buf[160];
  for (size_t i = 0; i < steps.size(); ++i) {
    const MrptStep& s = steps[i];
    std::snprintf(buf, sizeof(buf), "%zu %lld %d %.17g %.17g %.17g\n", i,
                  static_cast<long long>(s.utime), s.filter ? 1 : 0, s.increment.x, s.increment.y,
                  s.increment.theta);
    out << buf;
  }
  if (!out.flush()) throw std::runtime_error(path + ": write failed");
}

std::vector<MrptStep> ReadMrptSteps(const std::string& path) {
  std::vector<MrptStep> steps;
  for (const NumberLine& l : ReadNumberLines(path, '#')) {
    CheckFields(path, l, 6, "index utime_us filter dx dy dtheta");
    CheckIndex(path, l, steps.size());
    if (l.v[2] != 0.0 && l.v[2] != 1.0) throw LineError(path, l.line, "filter must be 0 or 1");
    MrptStep s;
    s.utime = static_cast<fl::Utime>(std::llround(l.v[1]));
    s.filter = l.v[2] == 1.0;
    s.increment = Pose2(l.v[3], l.v[4], l.v[5]);
    if (!steps.empty() && s.utime <= steps.back().utime)
      throw LineError(path, l.line, "time does not increase");
    steps.push_back(s);
  }
  if (steps.empty()) throw std::runtime_error(path + ": no steps");
  return steps;
}

std::vector<Pose2> ReadMrptPath(const std::string& path) {
  std::vector<Pose2> poses;
  for (const NumberLine& l : ReadNumberLines(path, '%')) {
    CheckFields(path, l, 3, "x y yaw");
    poses.emplace_back(l.v[0], l.v[1], l.v[2]);
  }
  if (poses.empty()) throw std::runtime_error(path + ": no poses");
  return poses;
}

std::vector<Pose2> ReadMrptStepPoses(const std::string& path) {
  std::vector<Pose2> poses;
  for (const NumberLine& l : ReadNumberLines(path, '%')) {
    CheckFields(path, l, 7, "step x y z yaw pitch roll [timestamp]");
    CheckIndex(path, l, poses.size());
    poses.emplace_back(l.v[1], l.v[2], l.v[4]);
  }
  return poses;
}

std::vector<double> ReadMrptStepTimes(const std::string& path) {
  std::vector<double> ms;
  for (const NumberLine& l : ReadNumberLines(path, '%')) {
    CheckFields(path, l, 2, "step execution_time_ms [map_size inserted]");
    CheckIndex(path, l, ms.size());
    ms.push_back(l.v[1]);
  }
  return ms;
}

fl::eval::Trajectory MrptFinalTrajectory(const std::vector<MrptStep>& steps,
                                         const std::vector<Pose2>& path) {
  size_t filter_steps = 0;
  for (const MrptStep& s : steps) filter_steps += s.filter ? 1 : 0;
  if (path.size() != filter_steps + 1)
    throw std::runtime_error(
        "MRPT's most likely path has " + std::to_string(path.size()) + " poses, but the " +
        "rawlog's " + std::to_string(steps.size()) + " steps have " +
        std::to_string(filter_steps) + " particle-filter updates (expected " +
        std::to_string(filter_steps + 1) +
        " poses: the start and one per update); the steps file and the run disagree");
  if (steps.empty() || !steps.front().filter)
    throw std::runtime_error("the first rawlog step must be a particle-filter step (MRPT always "
                             "updates on its first observation)");
  fl::eval::Trajectory out;
  out.reserve(steps.size());
  size_t k = 0;
  Pose2 since;  // odometry since the last filter step
  for (const MrptStep& s : steps) {
    if (s.filter) {
      ++k;
      since = Pose2();
    } else {
      since = since * s.increment;
    }
    out.push_back({s.utime, (path[k] * since).ToIsometry3()});
  }
  return out;
}

fl::eval::Trajectory MrptOnlineTrajectory(const std::vector<MrptStep>& steps,
                                          const std::vector<Pose2>& step_poses) {
  if (step_poses.size() != steps.size())
    throw std::runtime_error("MRPT's per-step pose log has " + std::to_string(step_poses.size()) +
                             " steps, the rawlog " + std::to_string(steps.size()) +
                             " (the run stopped early or the files are from different runs)");
  fl::eval::Trajectory out;
  out.reserve(steps.size());
  for (size_t i = 0; i < steps.size(); ++i)
    out.push_back({steps[i].utime, step_poses[i].ToIsometry3()});
  return out;
}

std::string MrptRunIni(const std::string& ini_text, const std::string& output_dir) {
  std::istringstream in(ini_text);
  std::string line, out, section;
  bool found = false;
  int64_t n = 0;
  while (std::getline(in, line)) {
    ++n;
    std::string t = line.substr(0, line.find_first_of("#;"));
    t.erase(0, t.find_first_not_of(" \t\r"));
    t.erase(t.find_last_not_of(" \t\r") + 1);
    if (!t.empty() && t.front() == '[' && t.back() == ']') section = t.substr(1, t.size() - 2);
    const std::string key = t.substr(0, t.find_first_of(" \t="));
    if (section == "MappingApplication" && (key == "logOutput_dir" || key == "rawlog_file"))
      throw std::runtime_error("line " + std::to_string(n) + ": [MappingApplication] " + key +
                               " is set by fl-bench-laser --peers (each run gets its own "
                               "folder and rawlog); remove it from the ini");
    out += line + "\n";
    if (t == "[MappingApplication]" && !found) {
      found = true;
      out += "# added by fl-bench-laser --peers:\nlogOutput_dir=" + output_dir + "\n";
    }
  }
  if (!found)
    throw std::runtime_error("no [MappingApplication] section (rbpf-slam reads its options "
                             "from it)");
  return out;
}

MrptRbpfRun RunMrptRbpf(const MrptRbpfOptions& o, const std::string& carmen_log) {
  fs::create_directories(o.work_dir);
  const std::string rawlog = o.work_dir + "/mrpt.rawlog";
  const std::string steps_file = o.work_dir + "/mrpt.steps";
  const std::string out_dir = o.work_dir + "/rbpf_out";
  const std::string run_ini = o.work_dir + "/rbpf_slam.ini";

  // 1. The rawlog, from the CARMEN log through the project's reader.
  const std::string tool_log = o.work_dir + "/fl-mrpt-rawlog.log";
  const ChildResult w = RunChild(
      {o.rawlog_tool, "--ini", o.ini, "--rawlog", rawlog, "--steps", steps_file, carmen_log},
      tool_log, nullptr);
  if (!WIFEXITED(w.status) || WEXITSTATUS(w.status) != 0)
    throw std::runtime_error(o.rawlog_tool + " failed (" + ExitText(w.status) + "):\n" +
                             Tail(tool_log, 10));
  MrptRbpfRun run;
  run.steps = ReadMrptSteps(steps_file);

  // 2. rbpf-slam with the repository's ini and our output folder.
  std::string ini_text;
  {
    std::ifstream in(o.ini);
    if (!in) throw std::runtime_error(o.ini + ": cannot open");
    std::stringstream ss;
    ss << in.rdbuf();
    ini_text = ss.str();
  }
  try {
    ini_text = MrptRunIni(ini_text, out_dir);
  } catch (const std::exception& e) {
    throw std::runtime_error(o.ini + ": " + e.what());
  }
  {
    std::ofstream out(run_ini);
    out << ini_text;
    if (!out.flush()) throw std::runtime_error(run_ini + ": write failed");
  }
  const std::string slam_log = o.work_dir + "/rbpf-slam.log";
  const std::string times_file = out_dir + "/log_times.txt";
  fl::bench::Progress progress(o.label, static_cast<int64_t>(run.steps.size()));
  const ChildResult r = RunChild({o.rbpf_slam, run_ini, rawlog}, slam_log,
                                 [&] { progress.Update(CountLines(times_file)); });
  progress.Finish();
  if (!WIFEXITED(r.status) || WEXITSTATUS(r.status) != 0)
    throw std::runtime_error(o.rbpf_slam + " " + run_ini + " " + rawlog + " failed (" +
                             ExitText(r.status) + "); last lines of " + slam_log + ":\n" +
                             Tail(slam_log, 15));
  run.peak_rss_mb = r.peak_rss_mb;
  run.cpu_s = r.cpu_s;
  run.wall_s = r.wall_s;
  run.output_dir = out_dir;

  // 3. Its outputs, a pose for every scan.
  run.final_trajectory =
      MrptFinalTrajectory(run.steps, ReadMrptPath(out_dir + "/most_likely_path.txt"));
  run.online =
      MrptOnlineTrajectory(run.steps, ReadMrptStepPoses(out_dir + "/log_estimated_path.txt"));
  run.ms_per_step = ReadMrptStepTimes(times_file);
  if (run.ms_per_step.size() != run.steps.size())
    throw std::runtime_error(times_file + ": " + std::to_string(run.ms_per_step.size()) +
                             " steps, the rawlog has " + std::to_string(run.steps.size()));
  for (const MrptStep& s : run.steps) run.filter_steps += s.filter ? 1 : 0;
  for (const NumberLine& l : ReadNumberLines(times_file, '%'))
    if (l.v.size() >= 4 && l.v[3] != 0.0) ++run.inserted_steps;
  return run;
}

}  // namespace fl::peers
