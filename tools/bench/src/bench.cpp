#include "fusionloc/bench/bench.hpp"

#include <sys/utsname.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <set>
#include <sstream>
#include <stdexcept>

#include "fusionloc/common/json.hpp"

namespace fl::bench {
namespace {

int64_t NowUs() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

std::string FormatValue(double v) {
  if (!std::isfinite(v)) return "n/a";
  std::ostringstream s;
  const double a = std::fabs(v);
  if (a != 0.0 && (a >= 1e6 || a < 1e-3)) {
    s << std::setprecision(3) << std::scientific << v;
  } else if (v == std::floor(v) && a < 1e6) {
    s << static_cast<int64_t>(v);
  } else {
    s << std::setprecision(4) << v;
  }
  return s.str();
}

std::vector<std::string> MetricKeys(const std::vector<Run>& runs) {
  std::vector<std::string> keys;
  for (const auto& r : runs) {
    for (const auto& kv : r.metrics) {
      if (std::find(keys.begin(), keys.end(), kv.first) == keys.end()) keys.push_back(kv.first);
    }
  }
  return keys;
}

std::string Cell(const Run& r, const std::string& key) {
  for (const auto& kv : r.metrics) {
    if (kv.first == key) return FormatValue(kv.second);
  }
  return "-";
}

}  // namespace

double Run::Get(const std::string& key, double fallback) const {
  for (const auto& kv : metrics) {
    if (kv.first == key) return kv.second;
  }
  return fallback;
}

Machine ReadMachine() {
  Machine m;
  std::ifstream cpuinfo("/proc/cpuinfo");
  std::string line;
  while (std::getline(cpuinfo, line)) {
    if (line.rfind("model name", 0) == 0 && m.cpu.empty()) {
      m.cpu = line.substr(line.find(':') + 2);
    }
  }
  m.cores = static_cast<int>(sysconf(_SC_NPROCESSORS_ONLN));
  m.memory_gb = static_cast<double>(sysconf(_SC_PHYS_PAGES)) * sysconf(_SC_PAGE_SIZE) / 1e9;
#if defined(__clang__)
  m.compiler = "clang " __clang_version__;
#elif defined(__GNUC__)
  m.compiler = "gcc " __VERSION__;
#endif
#ifdef NDEBUG
  m.build_type = "Release (NDEBUG)";
#else
  m.build_type = "Debug (assertions on)";
#endif
  const std::time_t t = std::time(nullptr);
  char buf[32];
  std::strftime(buf, sizeof(buf), "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&t));
  m.date = buf;
  return m;
}

void Report::PrintTable(std::ostream& out) const {
  const auto keys = MetricKeys(runs_);
  std::vector<size_t> widths;
  size_t name_w = 3;
  for (const auto& r : runs_) name_w = std::max(name_w, r.name.size());
  for (const auto& k : keys) {
    size_t w = k.size();
    for (const auto& r : runs_) w = std::max(w, Cell(r, k).size());
    widths.push_back(w);
  }
  out << "bench " << bench_ << "\n";
  out << std::left << std::setw(static_cast<int>(name_w)) << "run";
  for (size_t i = 0; i < keys.size(); ++i) {
    out << "  " << std::right << std::setw(static_cast<int>(widths[i])) << keys[i];
  }
  out << "\n";
  for (const auto& r : runs_) {
    out << std::left << std::setw(static_cast<int>(name_w)) << r.name;
    for (size_t i = 0; i < keys.size(); ++i) {
      out << "  " << std::right << std::setw(static_cast<int>(widths[i])) << Cell(r, keys[i]);
    }
    out << "\n";
  }
  for (const auto& r : runs_) {
    if (!r.note.empty()) out << "  " << r.name << ": " << r.note << "\n";
  }
}

std::string Report::Json(const std::string& command) const {
  const Machine m = ReadMachine();
  std::ostringstream s;
  s << "{\n  \"bench\": \"" << JsonEscape(bench_) << "\",\n";
  s << "  \"command\": \"" << JsonEscape(command) << "\",\n";
  s << "  \"machine\": {\"cpu\": \"" << JsonEscape(m.cpu) << "\", \"cores\": " << m.cores
    << ", \"memory_gb\": " << JsonNumber(m.memory_gb) << ", \"compiler\": \""
    << JsonEscape(m.compiler) << "\", \"build_type\": \"" << JsonEscape(m.build_type)
    << "\", \"date\": \"" << m.date << "\"},\n";
  s << "  \"runs\": [";
  for (size_t i = 0; i < runs_.size(); ++i) {
    const Run& r = runs_[i];
    s << (i ? ",\n" : "\n") << "    {\"name\": \"" << JsonEscape(r.name) << "\", \"input\": \""
      << JsonEscape(r.input) << "\", \"metrics\": {";
    for (size_t k = 0; k < r.metrics.size(); ++k) {
      s << (k ? ", " : "") << "\"" << JsonEscape(r.metrics[k].first)
        << "\": " << JsonNumber(r.metrics[k].second);
    }
    s << "}";
    if (!r.note.empty()) s << ", \"note\": \"" << JsonEscape(r.note) << "\"";
    s << "}";
  }
  s << "\n  ]\n}\n";
  return s.str();
}

void Report::WriteJson(const std::string& path, const std::string& command) const {
  const std::filesystem::path p(path);
  if (p.has_parent_path()) std::filesystem::create_directories(p.parent_path());
  const std::string tmp = path + ".partial";
  {
    std::ofstream out(tmp);
    if (!out) throw std::runtime_error("cannot write benchmark JSON '" + path + "'");
    out << Json(command);
    if (!out) throw std::runtime_error("write error on '" + tmp + "'");
  }
  std::filesystem::rename(tmp, path);
}

std::string Report::Markdown(const std::string& command) const {
  const Machine m = ReadMachine();
  const auto keys = MetricKeys(runs_);
  std::ostringstream s;
  s << "## bench " << bench_ << "\n\n";
  s << "Command: `" << command << "`  \n";
  s << "Machine: " << m.cpu << ", " << m.cores << " cores, " << FormatValue(m.memory_gb) << " GB; "
    << m.compiler << "; " << m.build_type << "; " << m.date << "\n\n";
  s << "| run |";
  for (const auto& k : keys) s << " " << k << " |";
  s << "\n|---|";
  for (size_t i = 0; i < keys.size(); ++i) s << "---:|";
  s << "\n";
  for (const auto& r : runs_) {
    s << "| " << r.name << " |";
    for (const auto& k : keys) s << " " << Cell(r, k) << " |";
    s << "\n";
  }
  bool notes = false;
  for (const auto& r : runs_) {
    if (r.note.empty()) continue;
    if (!notes) s << "\n";
    notes = true;
    s << "- " << r.name << ": " << r.note << "\n";
  }
  return s.str();
}

void Report::RecordInMarkdown(const std::string& md_path, const std::string& command) const {
  const std::string begin = "<!-- bench:" + bench_ + ":begin -->";
  const std::string end = "<!-- bench:" + bench_ + ":end -->";
  std::string text;
  {
    std::ifstream in(md_path);
    if (in) text.assign(std::istreambuf_iterator<char>(in), {});
  }
  const std::string section = begin + "\n" + Markdown(command) + end;
  const size_t b = text.find(begin);
  const size_t e = text.find(end);
  if (b != std::string::npos && e != std::string::npos && e > b) {
    text.replace(b, e + end.size() - b, section);
  } else {
    if (text.empty()) text = "# Benchmarks\n\nRecorded by `./fusionloc bench NAME`.\n";
    if (text.back() != '\n') text += "\n";
    text += "\n" + section + "\n";
  }
  const std::string tmp = md_path + ".partial";
  {
    std::ofstream out(tmp);
    if (!out) throw std::runtime_error("cannot write '" + md_path + "'");
    out << text;
  }
  std::filesystem::rename(tmp, md_path);
}

double LeastSquaresSlope(const std::vector<double>& t, const std::vector<double>& y,
                         double t_from) {
  double n = 0, st = 0, sy = 0, stt = 0, sty = 0;
  for (size_t i = 0; i < std::min(t.size(), y.size()); ++i) {
    if (!(t[i] >= t_from) || !std::isfinite(y[i])) continue;
    n += 1;
    st += t[i];
    sy += y[i];
    stt += t[i] * t[i];
    sty += t[i] * y[i];
  }
  const double d = n * stt - st * st;
  if (n < 2 || !(d > 0)) return std::nan("");
  return (n * sty - st * sy) / d;
}

Stats ComputeStats(std::vector<double> v) {
  Stats s;
  s.count = v.size();
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  double sum = 0;
  for (double x : v) sum += x;
  s.mean = sum / v.size();
  auto pct = [&](double p) {
    const double idx = p * (v.size() - 1);
    const size_t lo = static_cast<size_t>(std::floor(idx));
    const size_t hi = std::min(lo + 1, v.size() - 1);
    return v[lo] + (v[hi] - v[lo]) * (idx - lo);
  };
  s.median = pct(0.5);
  s.p95 = pct(0.95);
  s.p99 = pct(0.99);
  s.min = v.front();
  s.max = v.back();
  return s;
}

double PeakRssMb() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind("VmHWM:", 0) == 0) {
      std::istringstream ss(line.substr(6));
      double kb = 0;
      ss >> kb;
      return kb / 1024.0;
    }
  }
  return 0.0;
}

Progress::Progress(std::string label, int64_t total, double interval_s)
    : label_(std::move(label)), total_(total), interval_s_(interval_s) {
  start_us_ = NowUs();
  last_us_ = start_us_;
}

void Progress::Update(int64_t done) {
  const int64_t now = NowUs();
  if ((now - last_us_) * 1e-6 < interval_s_) return;
  last_us_ = now;
  const double elapsed = (now - start_us_) * 1e-6;
  const double frac = total_ > 0 ? static_cast<double>(done) / total_ : 0.0;
  const double eta = frac > 0 ? elapsed * (1 - frac) / frac : 0.0;
  std::fprintf(stderr, "[%s] %lld/%lld  %3.0f%%  %.0f s elapsed, eta %.0f s\n", label_.c_str(),
               static_cast<long long>(done), static_cast<long long>(total_), 100 * frac, elapsed,
               eta);
}

void Progress::Finish() {
  std::fprintf(stderr, "[%s] done: %lld items in %.1f s\n", label_.c_str(),
               static_cast<long long>(total_), (NowUs() - start_us_) * 1e-6);
}

void AddCommonFlags(CommandLine* cli, CommonArgs* args, const std::string& bench_name) {
  if (args->data_dir.empty()) args->data_dir = FL_DEFAULT_SHARED_DATA_DIR;
  if (args->json.empty()) args->json = "out/bench/" + bench_name + ".json";
  if (args->command.empty()) args->command = "fl-bench-" + bench_name;
  cli->AddFlag("data", &args->data_dir, "folder with the input data");
  cli->AddFlag("json", &args->json, "where to write the JSON results");
  cli->AddFlag("record", &args->record,
               "markdown file whose section for this benchmark is replaced with the results "
               "(./fusionloc bench passes docs/BENCHMARKS.md)");
  cli->AddFlag("command", &args->command, "command line to record beside the results");
}

void Publish(const Report& report, const CommonArgs& args) {
  report.PrintTable(std::cout);
  if (!args.json.empty()) {
    report.WriteJson(args.json, args.command);
    std::cout << "JSON: " << args.json << "\n";
  }
  if (!args.record.empty()) {
    report.RecordInMarkdown(args.record, args.command);
    std::cout << "recorded in " << args.record << "\n";
  }
}

}  // namespace fl::bench
