#include "fusionloc/importers/carmen.hpp"

#include <zlib.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <random>
#include <sstream>
#include <stdexcept>

#include "bot_core/planar_lidar_t.hpp"
#include "bot_core/pose_t.hpp"
#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/common/number_format.hpp"
#include "fusionloc/wheel_odometry_t.hpp"

namespace fl::importers {
namespace {

[[noreturn]] void LineError(const std::string& path, int64_t line, const std::string& what) {
  throw std::runtime_error(path + ":" + std::to_string(line) + ": " + what);
}

// A line with fewer fields than its message type needs (it stops early).
class TruncatedLine : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};
[[noreturn]] void TruncatedLineError(const std::string& path, int64_t line,
                                     const std::string& what) {
  throw TruncatedLine(path + ":" + std::to_string(line) + ": " + what);
}

std::vector<std::string> Tokenize(const std::string& line) {
  std::vector<std::string> out;
  size_t i = 0;
  const size_t n = line.size();
  while (i < n) {
    while (i < n && std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    const size_t start = i;
    while (i < n && !std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    if (i > start) out.push_back(line.substr(start, i - start));
  }
  return out;
}

// Parses a finite number that is the whole token; else a FILE:LINE error naming the field.
// Numbers too small for a normal double (CARMEN loggers print values such as 9.53173e-312:
// strtod gives the subnormal or 0 with ERANGE) are accepted; only inf, nan and overflow are
// refused.
double ParseNumber(const std::string& token, const char* field, const std::string& type,
                   const std::string& path, int64_t line) {
  char* end = nullptr;
  const double v = std::strtod(token.c_str(), &end);
  if (end == token.c_str() || *end != '\0' || !std::isfinite(v)) {
    LineError(path, line,
              type + " field '" + field + "' is '" + token +
                  "', not a finite number (corrupt line; repair or delete it)");
  }
  return v;
}

std::string ToLower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// Reads text lines from a plain or gzip-compressed file through zlib.
class LineReader {
 public:
  explicit LineReader(const std::string& path) : path_(path) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec)) {
      throw std::runtime_error(path + ": no such file (check the path)");
    }
    file_ = gzopen(path.c_str(), "rb");
    if (!file_) {
      throw std::runtime_error(path + ": cannot open: " + std::strerror(errno) +
                               " (check permissions)");
    }
    gzbuffer(file_, 1 << 17);
  }
  ~LineReader() {
    if (file_) gzclose(file_);
  }
  LineReader(const LineReader&) = delete;
  LineReader& operator=(const LineReader&) = delete;

  // False at the end of the file; throws on a read or decompression error.
  bool Next(std::string* line) {
    line->clear();
    char buf[8192];
    bool any = false;
    while (gzgets(file_, buf, sizeof(buf)) != nullptr) {
      any = true;
      line->append(buf);
      if (!line->empty() && line->back() == '\n') break;
    }
    if (!any) {
      int err = Z_OK;
      const char* msg = gzerror(file_, &err);
      if (err != Z_OK && err != Z_STREAM_END) {
        throw std::runtime_error(path_ + ": read error after line " + std::to_string(line_) + ": " +
                                 (msg ? msg : "unknown") +
                                 " (truncated or corrupt gzip file? re-download it)");
      }
      return false;
    }
    // A decompression error can also end a partial line.
    int err = Z_OK;
    const char* msg = gzerror(file_, &err);
    if (err != Z_OK && err != Z_STREAM_END) {
      throw std::runtime_error(path_ + ":" + std::to_string(line_ + 1) +
                               ": read error: " + (msg ? msg : "unknown") +
                               " (truncated or corrupt gzip file? re-download it)");
    }
    last_had_newline_ = !line->empty() && line->back() == '\n';
    while (!line->empty() && (line->back() == '\n' || line->back() == '\r')) line->pop_back();
    ++line_;
    return true;
  }
  int64_t line_number() const { return line_; }
  // The line Next() returned last ended in a newline (else the file ends in mid-line).
  bool last_had_newline() const { return last_had_newline_; }

 private:
  std::string path_;
  gzFile file_ = nullptr;
  int64_t line_ = 0;
  bool last_had_newline_ = true;
};

// Box-Muller on mt19937_64 (fully specified by the standard, unlike std::normal_distribution),
// so that a seed gives the same odometry on every platform.
class Gaussian {
 public:
  explicit Gaussian(uint64_t seed) : gen_(seed) {}
  double Sample() {
    const double u1 = 1.0 - Uniform();  // (0, 1]
    const double u2 = Uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * M_PI * u2);
  }

 private:
  double Uniform() { return static_cast<double>(gen_() >> 11) * (1.0 / 9007199254740992.0); }
  std::mt19937_64 gen_;
};

bot_core::pose_t MakePose(Utime utime, const Pose2& p) {
  bot_core::pose_t msg{};
  msg.utime = utime;
  msg.pos[0] = p.x;
  msg.pos[1] = p.y;
  msg.pos[2] = 0.0;
  msg.orientation[0] = std::cos(0.5 * p.theta);
  msg.orientation[1] = 0.0;
  msg.orientation[2] = 0.0;
  msg.orientation[3] = std::sin(0.5 * p.theta);
  return msg;
}

}  // namespace

Status CarmenNoiseModel::Validate() const {
  const double vals[] = {a1, a2, a3, a4, min_sigma_xy, min_sigma_theta};
  const char* names[] = {"a1", "a2", "a3", "a4", "min_sigma_xy", "min_sigma_theta"};
  for (int i = 0; i < 6; ++i) {
    if (!std::isfinite(vals[i]) || vals[i] < 0.0) {
      return Status::Error(std::string("noise.") + names[i] + " = " + std::to_string(vals[i]) +
                           " must be a finite number >= 0");
    }
  }
  if (!std::isfinite(scale_error) || std::abs(scale_error) >= 0.5) {
    return Status::Error("noise.scale_error = " + std::to_string(scale_error) +
                         " must be in (-0.5, 0.5) (a fraction, e.g. 0.01 for 1%)");
  }
  if (!std::isfinite(yaw_bias) || std::abs(yaw_bias) > 1.0) {
    return Status::Error("noise.yaw_bias = " + std::to_string(yaw_bias) +
                         " rad/m must be in [-1, 1]");
  }
  return Status::Ok();
}

Status CarmenOptions::Validate() const {
  if (noisy_odometry != "auto" && noisy_odometry != "true" && noisy_odometry != "false") {
    return Status::Error("noisy_odometry = '" + noisy_odometry +
                         "' must be one of: auto, true, false");
  }
  if (timestamp != "ipc" && timestamp != "logger") {
    return Status::Error("timestamp = '" + timestamp + "' must be 'ipc' or 'logger'");
  }
  if (!timestamps_from.empty() && !ground_truth_from.empty()) {
    return Status::Error(
        "timestamps_from (for a corrected log) and ground_truth_from (for a raw log) cannot be "
        "used together");
  }
  if (!(range_match_tolerance > 0.0) || !std::isfinite(range_match_tolerance)) {
    return Status::Error("range_match_tolerance must be > 0 m");
  }
  if (repeated_stamps != "auto" && repeated_stamps != "keep" && repeated_stamps != "by_order") {
    return Status::Error("repeated_stamps = '" + repeated_stamps +
                         "' must be one of: auto, keep, by_order");
  }
  if (!(by_order_interval_s > 0.0 && by_order_interval_s <= 3600.0)) {
    return Status::Error("by_order_interval_s = " + std::to_string(by_order_interval_s) +
                         " must be in (0, 3600] s");
  }
  if (!(fov_deg > 0.0 && fov_deg <= 360.0)) {
    return Status::Error("fov_deg = " + std::to_string(fov_deg) + " must be in (0, 360]");
  }
  return noise.Validate();
}

double CarmenBeamStep(int n, double fov_rad) {
  const double deg = M_PI / 180.0;
  if (std::abs(fov_rad - M_PI) < 1e-9) {
    if (n == 181 || n == 180) return 1.0 * deg;
    if (n == 361 || n == 360) return 0.5 * deg;
    if (n == 401 || n == 400) return 0.25 * deg;
  }
  return n > 1 ? fov_rad / (n - 1) : 0.0;
}

CarmenLog ReadCarmenLog(const std::string& path, const std::string& timestamp, double fov_deg) {
  if (timestamp != "ipc" && timestamp != "logger") {
    throw std::invalid_argument("ReadCarmenLog: timestamp must be 'ipc' or 'logger', not '" +
                                timestamp + "'");
  }
  const bool use_ipc = timestamp == "ipc";
  const double fov = fov_deg * M_PI / 180.0;
  CarmenLog log;
  log.path = path;
  LineReader reader(path);
  std::string text;
  int64_t flaser_lines = 0, robotlaser_lines = 0;
  // One line; throws std::runtime_error "FILE:LINE: ..." if it is malformed.
  const auto parse_line = [&](const std::string& text, int64_t line) {
    const std::vector<std::string> t = Tokenize(text);
    if (t.empty() || t[0][0] == '#') return;
    const std::string& type = t[0];
    if (type == "FLASER") {
      if (t.size() < 2) TruncatedLineError(path, line, "truncated FLASER line: no beam count");
      char* end = nullptr;
      const long n = std::strtol(t[1].c_str(), &end, 10);
      if (*end != '\0' || n <= 0 || n > 100000) {
        LineError(path, line, "FLASER beam count '" + t[1] + "' is not an integer in [1, 100000]");
      }
      const size_t expected = static_cast<size_t>(n) + 11;
      if (t.size() < expected) {
        TruncatedLineError(path, line,
                  "truncated FLASER line: n = " + std::to_string(n) + " beams need " +
                      std::to_string(expected) +
                      " fields (FLASER n r_1..r_n x y theta odom_x "
                      "odom_y odom_theta ipc_timestamp hostname logger_timestamp), found " +
                      std::to_string(t.size()) +
                      " (line cut short, or fewer ranges than n; repair or delete the line)");
      }
      if (t.size() > expected) {
        LineError(path, line,
                  "FLASER line has " + std::to_string(t.size()) + " fields but n = " +
                      std::to_string(n) + " beams need " + std::to_string(expected) +
                      " (more ranges than n, or an unknown FLASER variant)");
      }
      CarmenScan s;
      s.line = line;
      s.ranges.resize(static_cast<size_t>(n));
      for (long i = 0; i < n; ++i) {
        s.ranges[static_cast<size_t>(i)] = static_cast<float>(
            ParseNumber(t[static_cast<size_t>(2 + i)], "range", "FLASER", path, line));
      }
      const size_t k = static_cast<size_t>(2 + n);
      s.pose.x = ParseNumber(t[k], "x", "FLASER", path, line);
      s.pose.y = ParseNumber(t[k + 1], "y", "FLASER", path, line);
      s.pose.theta = ParseNumber(t[k + 2], "theta", "FLASER", path, line);
      s.odom.x = ParseNumber(t[k + 3], "odom_x", "FLASER", path, line);
      s.odom.y = ParseNumber(t[k + 4], "odom_y", "FLASER", path, line);
      s.odom.theta = ParseNumber(t[k + 5], "odom_theta", "FLASER", path, line);
      s.ipc_timestamp = ParseNumber(t[k + 6], "ipc_timestamp", "FLASER", path, line);
      s.logger_timestamp = ParseNumber(t[k + 8], "logger_timestamp", "FLASER", path, line);
      s.utime = SecondsToUtime(use_ipc ? s.ipc_timestamp : s.logger_timestamp);
      s.radstep = static_cast<float>(CarmenBeamStep(static_cast<int>(n), fov));
      s.rad0 = static_cast<float>(-0.5 * fov);
      ++flaser_lines;
      log.order.push_back({true, log.scans.size()});
      log.scans.push_back(std::move(s));
    } else if (type == "ROBOTLASER1") {
      // 1 + 7 header fields, n, ranges, m, remissions, 6 poses, 5 robot fields, 3 stamps.
      const char* kFormat =
          " (ROBOTLASER1 laser_type start_angle fov angular_resolution max_range accuracy "
          "remission_mode n r_1..r_n m e_1..e_m laser_x laser_y laser_theta robot_x robot_y "
          "robot_theta laser_tv laser_rv forward_safety_dist side_safety_dist turn_axis "
          "ipc_timestamp hostname logger_timestamp)";
      auto count_at = [&](size_t k, const char* what) -> size_t {
        if (t.size() <= k) {
          TruncatedLineError(path, line,
                    "truncated ROBOTLASER1 line: only " + std::to_string(t.size()) + " fields" +
                        kFormat + "; repair or delete the line");
        }
        char* end = nullptr;
        const long v = std::strtol(t[k].c_str(), &end, 10);
        if (*end != '\0' || v < 0 || v > 100000) {
          LineError(path, line,
                    std::string("ROBOTLASER1 ") + what + " '" + t[k] +
                        "' is not an integer in [0, 100000]");
        }
        return static_cast<size_t>(v);
      };
      const size_t n = count_at(8, "beam count");
      if (n == 0) LineError(path, line, "ROBOTLASER1 line with 0 beams");
      const size_t m = count_at(9 + n, "remission count");
      const size_t expected = n + m + 24;
      if (t.size() != expected) {
        (t.size() < expected ? TruncatedLineError : LineError)(path, line,
                  std::string(t.size() < expected ? "truncated ROBOTLASER1 line"
                                                  : "ROBOTLASER1 line too long") +
                      ": n = " + std::to_string(n) + " beams and m = " + std::to_string(m) +
                      " remissions need " + std::to_string(expected) + " fields, found " +
                      std::to_string(t.size()) + kFormat);
      }
      const auto num = [&](size_t k, const char* field) {
        return ParseNumber(t[k], field, "ROBOTLASER1", path, line);
      };
      CarmenScan s;
      s.line = line;
      s.rad0 = static_cast<float>(num(2, "start_angle"));
      s.radstep = static_cast<float>(num(4, "angular_resolution"));
      if (!(std::abs(s.radstep) > 0.0f)) {
        LineError(path, line, "ROBOTLASER1 angular_resolution is 0");
      }
      s.ranges.resize(n);
      for (size_t i = 0; i < n; ++i) s.ranges[i] = static_cast<float>(num(9 + i, "range"));
      if (m == n) {  // remissions per beam become intensities; any other count is dropped
        s.intensities.resize(m);
        for (size_t i = 0; i < m; ++i) {
          s.intensities[i] = static_cast<float>(num(10 + n + i, "remission"));
        }
      }
      const size_t k = 10 + n + m;
      s.pose = Pose2(num(k, "laser_x"), num(k + 1, "laser_y"), num(k + 2, "laser_theta"));
      s.odom = Pose2(num(k + 3, "robot_x"), num(k + 4, "robot_y"), num(k + 5, "robot_theta"));
      s.ipc_timestamp = num(k + 11, "ipc_timestamp");
      s.logger_timestamp = num(k + 13, "logger_timestamp");
      s.utime = SecondsToUtime(use_ipc ? s.ipc_timestamp : s.logger_timestamp);
      ++robotlaser_lines;
      log.order.push_back({true, log.scans.size()});
      log.scans.push_back(std::move(s));
    } else if (type == "ODOM") {
      if (t.size() != 10) {
        (t.size() < 10 ? TruncatedLineError : LineError)(path, line,
                  std::string(t.size() < 10 ? "truncated ODOM line" : "ODOM line too long") +
                      ": expected 10 fields (ODOM x y theta tv rv accel ipc_timestamp hostname "
                      "logger_timestamp), found " +
                      std::to_string(t.size()) + " (repair or delete the line)");
      }
      CarmenOdom o;
      o.line = line;
      o.pose.x = ParseNumber(t[1], "x", "ODOM", path, line);
      o.pose.y = ParseNumber(t[2], "y", "ODOM", path, line);
      o.pose.theta = ParseNumber(t[3], "theta", "ODOM", path, line);
      o.tv = ParseNumber(t[4], "tv", "ODOM", path, line);
      o.rv = ParseNumber(t[5], "rv", "ODOM", path, line);
      o.accel = ParseNumber(t[6], "accel", "ODOM", path, line);
      const double ipc = ParseNumber(t[7], "ipc_timestamp", "ODOM", path, line);
      const double logger = ParseNumber(t[9], "logger_timestamp", "ODOM", path, line);
      o.utime = SecondsToUtime(use_ipc ? ipc : logger);
      log.order.push_back({false, log.odom.size()});
      log.odom.push_back(o);
    } else {
      ++log.skipped_types[type];
    }
  };
  // A log cut short while it was written ends in a partial line: the last line, if it does
  // not parse and is incomplete (no newline at its end, or fewer fields than its type needs),
  // is dropped with a warning naming it; everything before it is kept. Any other bad line is
  // an error.
  bool have = reader.Next(&text);
  while (have) {
    const int64_t line = reader.line_number();
    const bool complete = reader.last_had_newline();
    const std::string current = std::move(text);
    have = reader.Next(&text);
    try {
      parse_line(current, line);
    } catch (const std::runtime_error& e) {
      const bool truncated = dynamic_cast<const TruncatedLine*>(&e) != nullptr;
      if (have || (complete && !truncated)) throw;
      FL_LOG(WARN) << "dropped the last line (" << e.what()
                   << "): the log ends in an incomplete line, probably cut short while written";
      log.dropped_last_line = line;
    }
  }
  log.lines = reader.line_number();
  if (flaser_lines > 0 && robotlaser_lines > 0) {
    throw std::runtime_error(path + ": has both FLASER (" + std::to_string(flaser_lines) +
                             ") and ROBOTLASER1 (" + std::to_string(robotlaser_lines) +
                             ") lines, usually the same scans twice; keep one kind (e.g. grep "
                             "-v '^FLASER')");
  }
  if (log.scans.empty()) {
    std::string seen;
    for (const auto& [k, v] : log.skipped_types) seen += " " + k + " x" + std::to_string(v);
    throw std::runtime_error(
        path + ": no FLASER or ROBOTLASER1 line in " + std::to_string(log.lines) + " lines" +
        (seen.empty() ? std::string(" (empty file?)") : " (found:" + seen + ")") +
        "; a CARMEN laser log with FLASER or ROBOTLASER1 scans is needed");
  }
  return log;
}

bool IsCorrectedCarmenLog(const CarmenOptions& options, const std::string& path) {
  if (options.noisy_odometry == "true") return true;
  if (options.noisy_odometry == "false") return false;
  const std::string name = ToLower(std::filesystem::path(path).filename().string());
  return name.find("corrected") != std::string::npos;
}

std::vector<Pose2> SynthesizeNoisyOdometry(const CarmenNoiseModel& noise, uint64_t seed,
                                           const std::vector<Pose2>& corrected) {
  std::vector<Pose2> out;
  if (corrected.empty()) return out;
  out.reserve(corrected.size());
  Gaussian gauss(seed);
  out.push_back(corrected[0]);
  for (size_t k = 1; k < corrected.size(); ++k) {
    const Pose2 u = corrected[k - 1].between(corrected[k]);
    const double d = std::hypot(u.x, u.y);
    const double adt = std::abs(u.theta);
    // Three samples every step (also when standing still) so that step k always uses the
    // same samples for a given seed.
    const double nx = gauss.Sample(), ny = gauss.Sample(), nt = gauss.Sample();
    Pose2 m = u;
    if (d > 0.0 || adt > 0.0) {
      const double sxy = std::max(noise.min_sigma_xy, noise.a1 * d + noise.a2 * adt);
      const double sth = std::max(noise.min_sigma_theta, noise.a3 * adt + noise.a4 * d);
      m.x = (1.0 + noise.scale_error) * u.x + sxy * nx;
      m.y = (1.0 + noise.scale_error) * u.y + sxy * ny;
      m.theta = u.theta + noise.yaw_bias * d + sth * nt;
    }
    out.push_back(out.back() * m);
  }
  return out;
}

OdometryErrorFit FitOdometryError(const std::vector<Pose2>& odometry,
                                  const std::vector<Pose2>& reference) {
  if (odometry.size() != reference.size()) {
    throw std::invalid_argument("FitOdometryError: " + std::to_string(odometry.size()) +
                                " odometry poses but " + std::to_string(reference.size()) +
                                " reference poses");
  }
  OdometryErrorFit fit;
  double t_exy2 = 0, t_d2 = 0, t_et2 = 0, t_ex = 0, t_d = 0, t_et = 0;
  double r_exy2 = 0, r_et2 = 0, r_dt2 = 0;
  for (size_t k = 1; k < reference.size(); ++k) {
    const Pose2 u = reference[k - 1].between(reference[k]);
    const Pose2 o = odometry[k - 1].between(odometry[k]);
    const double d = std::hypot(u.x, u.y), adt = std::abs(u.theta);
    const double ex = o.x - u.x, ey = o.y - u.y, et = WrapAngle(o.theta - u.theta);
    if (adt < 0.1 && d > 0.05) {
      ++fit.translation_steps;
      t_exy2 += 0.5 * (ex * ex + ey * ey);
      t_d2 += d * d;
      t_et2 += et * et;
      t_ex += ex;
      t_d += d;
      t_et += et;
    } else if (d < 0.1 && adt > 0.1) {
      ++fit.rotation_steps;
      r_exy2 += 0.5 * (ex * ex + ey * ey);
      r_et2 += et * et;
      r_dt2 += adt * adt;
    }
  }
  if (fit.translation_steps > 0) {
    fit.a1 = std::sqrt(t_exy2 / t_d2);
    fit.a4 = std::sqrt(t_et2 / t_d2);
    fit.scale_error = t_ex / t_d;
    fit.yaw_bias = t_et / t_d;
  }
  if (fit.rotation_steps > 0) {
    fit.a3 = std::sqrt(r_et2 / r_dt2);
    fit.a2 = std::sqrt(r_exy2 / r_dt2);
  }
  return fit;
}

std::string OdometryErrorFit::ToString() const {
  std::ostringstream ss;
  ss.precision(3);
  ss << translation_steps << " translation steps: a1 " << a1 << " m/m, a4 " << a4
     << " rad/m, scale_error " << scale_error << ", yaw_bias " << yaw_bias << " rad/m; "
     << rotation_steps << " rotation steps: a3 " << a3 << " rad/rad, a2 " << a2 << " m/rad";
  return ss.str();
}

std::vector<size_t> MatchScansByRanges(const CarmenLog& superset, const CarmenLog& subset,
                                       double tolerance, const std::string& hint) {
  std::vector<size_t> match;
  match.reserve(subset.scans.size());
  size_t next = 0;  // superset scans before `next` are used up (matches are in order)
  for (const CarmenScan& s : subset.scans) {
    bool found = false;
    for (size_t j = next; j < superset.scans.size() && !found; ++j) {
      const CarmenScan& r = superset.scans[j];
      if (r.ranges.size() != s.ranges.size()) continue;
      bool same = true;
      for (size_t i = 0; i < r.ranges.size() && same; ++i) {
        same = std::abs(r.ranges[i] - s.ranges[i]) <= tolerance;
      }
      if (same) {
        match.push_back(j);
        next = j + 1;
        found = true;
      }
    }
    if (!found) {
      throw std::runtime_error(
          subset.path + ":" + std::to_string(s.line) + ": no scan of '" + superset.path +
          "' after line " + std::to_string(next > 0 ? superset.scans[next - 1].line : 0) +
          " has the same ranges (within " + std::to_string(tolerance) + " m); " + hint);
    }
  }
  return match;
}

void RecoverTimestampsByRanges(const CarmenLog& raw, double tolerance, CarmenLog* log) {
  const std::vector<size_t> match = MatchScansByRanges(
      raw, *log, tolerance,
      "its time stamp cannot be recovered: is the raw log of the same run? (omit "
      "--timestamps-from to keep the log's own time stamps)");
  for (size_t k = 0; k < match.size(); ++k) log->scans[k].utime = raw.scans[match[k]].utime;
  // ODOM lines cannot be matched; they keep their own stamps (only used for raw logs).
}

int64_t CountRepeatedStamps(const CarmenLog& log) {
  int64_t n = 0;
  for (size_t i = 1; i < log.scans.size(); ++i) {
    if (log.scans[i].utime == log.scans[i - 1].utime) ++n;
  }
  return n;
}

void StampScansByOrder(double interval_s, CarmenLog* log) {
  if (log->scans.empty()) return;
  const Utime first = log->scans.front().utime;
  const Utime step = SecondsToUtime(interval_s);
  for (size_t k = 0; k < log->scans.size(); ++k) {
    log->scans[k].utime = first + static_cast<Utime>(k) * step;
  }
}

ConvertSummary ConvertCarmen(const CarmenOptions& options, const std::string& in,
                             const std::string& out_log) {
  const Status valid = options.Validate();
  if (!valid.ok()) throw std::invalid_argument("CARMEN options: " + valid.message());
  {
    std::error_code ec;
    if (std::filesystem::equivalent(in, out_log, ec)) {
      throw std::invalid_argument("output '" + out_log + "' is the input file; choose another");
    }
  }
  CarmenLog log = ReadCarmenLog(in, options.timestamp, options.fov_deg);
  ConvertSummary summary;
  summary.input = in;
  summary.output = out_log;
  if (log.dropped_last_line > 0) {
    summary.warnings.push_back("dropped the incomplete last line " + in + ":" +
                            std::to_string(log.dropped_last_line));
  }
  if (!options.timestamps_from.empty()) {
    const CarmenLog raw =
        ReadCarmenLog(options.timestamps_from, options.timestamp, options.fov_deg);
    RecoverTimestampsByRanges(raw, options.range_match_tolerance, &log);
    summary.notes.push_back("scan time stamps taken from '" + options.timestamps_from +
                            "' by matching ranges (" + std::to_string(log.scans.size()) +
                            " scans matched)");
  }
  if (options.timestamps_from.empty()) {
    const int64_t repeated = CountRepeatedStamps(log);
    const bool by_order =
        options.repeated_stamps == "by_order" ||
        (options.repeated_stamps == "auto" &&
         repeated * 4 > static_cast<int64_t>(log.scans.size()));
    if (by_order && repeated > 0) {
      StampScansByOrder(options.by_order_interval_s, &log);
      summary.warnings.push_back(
          std::to_string(repeated) + " of " + std::to_string(log.scans.size()) +
          " scans repeat the time stamp before them (too few digits in the log?): every scan "
          "is stamped by its order instead, " + FormatDouble(options.by_order_interval_s) +
          " s apart (repeated_stamps: by_order; the time is synthetic, the order is the "
          "log's). Give --timestamps-from RAW_LOG of the same run to recover the real stamps");
    }
  }
  const bool corrected = IsCorrectedCarmenLog(options, in);

  // Raw log with a corrected log of the same run: reference poses for the matched scans.
  std::vector<bool> has_reference(log.scans.size(), false);
  std::vector<Pose2> reference(log.scans.size());
  if (!options.ground_truth_from.empty()) {
    if (corrected) {
      throw std::invalid_argument(
          "ground_truth_from is for raw logs, but '" + in +
          "' is treated as corrected (its own poses are the ground truth); drop "
          "--ground-truth-from or set --noisy-odometry false");
    }
    const CarmenLog ref =
        ReadCarmenLog(options.ground_truth_from, options.timestamp, options.fov_deg);
    const std::vector<size_t> match = MatchScansByRanges(
        log, ref, options.range_match_tolerance,
        "it has no partner in the raw log: is the corrected log of the same run?");
    std::vector<Pose2> odom_at_match, ref_poses;
    for (size_t k = 0; k < match.size(); ++k) {
      has_reference[match[k]] = true;
      reference[match[k]] = ref.scans[k].pose;
      odom_at_match.push_back(log.scans[match[k]].odom);
      ref_poses.push_back(ref.scans[k].pose);
    }
    summary.notes.push_back(
        "the log's odometry vs the reference (upper bounds, the reference has errors too): " +
        FitOdometryError(odom_at_match, ref_poses).ToString());
    summary.notes.push_back("GROUND_TRUTH for " + std::to_string(match.size()) + " of " +
                            std::to_string(log.scans.size()) + " scans from '" +
                            options.ground_truth_from + "' (matched by ranges)");
  }

  // Odometry per scan: the line's own (raw) or synthetic noisy (corrected).
  std::vector<Pose2> scan_odom;
  scan_odom.reserve(log.scans.size());
  if (corrected) {
    std::vector<Pose2> poses;
    poses.reserve(log.scans.size());
    for (const auto& s : log.scans) poses.push_back(s.pose);
    scan_odom = SynthesizeNoisyOdometry(options.noise, options.seed, poses);
  } else {
    for (const auto& s : log.scans) scan_odom.push_back(s.odom);
  }

  // Time checks: never reordered, but counted and reported.
  int64_t backwards = 0, duplicates = 0;
  for (size_t i = 1; i < log.scans.size(); ++i) {
    if (log.scans[i].utime < log.scans[i - 1].utime) ++backwards;
    if (log.scans[i].utime == log.scans[i - 1].utime) ++duplicates;
  }
  if (backwards > 0) {
    summary.warnings.push_back(std::to_string(backwards) +
                               " scans have a time stamp earlier than the scan before; kept in "
                               "file order");
  }
  if (duplicates > 0) {
    std::string hint;
    if (duplicates * 4 > static_cast<int64_t>(log.scans.size())) {
      hint =
          " (the log's time stamps have too few digits: give --timestamps-from RAW_LOG of "
          "the same run to recover them)";
    }
    summary.warnings.push_back(std::to_string(duplicates) +
                               " scans share the time stamp of the scan before; kept" + hint);
  }
  for (const auto& [type, count] : log.skipped_types) {
    summary.notes.push_back("skipped " + std::to_string(count) + " '" + type +
                            "' lines (not converted)");
  }
  if (corrected && !log.odom.empty()) {
    summary.notes.push_back(
        "ignored " + std::to_string(log.odom.size()) +
        " ODOM lines: corrected log, ODOMETRY carries seeded synthetic odometry instead");
  }

  if (!corrected) {
    // The laser pose relative to the robot pose is the laser's mounting; LASER is in the
    // laser frame, so a user must know it (CARMEN: robot_frontlaser_offset).
    const Pose2 mount = log.scans[0].odom.between(log.scans[0].pose);
    double max_change = 0.0;
    for (const CarmenScan& sc : log.scans) {
      const Pose2 d = mount.between(sc.odom.between(sc.pose));
      max_change = std::max(max_change, std::hypot(d.x, d.y) + std::abs(d.theta));
    }
    if (max_change > 0.01) {
      summary.warnings.push_back(
          "x y theta is not one rigid mounting away from the odometry (their offset changes by "
          "up to " +
          std::to_string(max_change) +
          " along the log): it is probably a localised or corrected pose. It is not converted; "
          "ODOMETRY is the odometry. To use x y theta as GROUND_TRUTH, convert with "
          "--noisy-odometry true (which replaces the odometry by synthetic noisy odometry)");
    } else if (std::hypot(mount.x, mount.y) > 0.005 || std::abs(mount.theta) > 0.005) {
      std::ostringstream ss;
      ss << "the laser pose differs from the robot pose by (" << mount.x << " m, " << mount.y
         << " m, " << mount.theta << " rad) in the robot frame: the laser's mounting. LASER is "
         << "in the laser frame; use this as T_base_laser";
      summary.notes.push_back(ss.str());
    }
    int64_t odom_backwards = 0;
    Utime prev_t = 0;
    bool first = true;
    for (const CarmenLog::Entry& e : log.order) {
      const Utime t = e.is_scan ? log.scans[e.index].utime : log.odom[e.index].utime;
      if (!e.is_scan && !first && t < prev_t) ++odom_backwards;
      prev_t = t;
      first = false;
    }
    if (odom_backwards > 0) {
      summary.warnings.push_back(std::to_string(odom_backwards) +
                                 " ODOM lines have a time stamp earlier than the line before; "
                                 "kept in file order");
    }
  }

  LcmLogWriter writer(out_log);
  try {
    auto write = [&](const char* channel, const auto& msg, Utime utime) {
      writer.Write(channel, msg, utime);
      summary.Count(channel, utime);
    };
    bool have_prev = false;
    Pose2 prev_odom;
    Utime prev_utime = 0;
    for (const CarmenLog::Entry& e : log.order) {
      if (!e.is_scan) {
        if (corrected) continue;
        const CarmenOdom& o = log.odom[e.index];
        fusionloc::wheel_odometry_t odo{};
        odo.utime = o.utime;
        odo.x = o.pose.x;
        odo.y = o.pose.y;
        odo.theta = o.pose.theta;
        odo.v = o.tv;
        odo.omega = o.rv;
        write(channels::kOdometry, odo, o.utime);
        continue;
      }
      const CarmenScan& s = log.scans[e.index];
      const Pose2& odom = scan_odom[e.index];
      fusionloc::wheel_odometry_t odo{};
      odo.utime = s.utime;
      odo.x = odom.x;
      odo.y = odom.y;
      odo.theta = odom.theta;
      if (have_prev && s.utime > prev_utime) {
        const Pose2 u = prev_odom.between(odom);
        const double dt = UtimeToSeconds(s.utime - prev_utime);
        odo.v = u.x / dt;
        odo.omega = u.theta / dt;
      }
      have_prev = true;
      prev_odom = odom;
      prev_utime = s.utime;
      write(channels::kOdometry, odo, s.utime);

      bot_core::planar_lidar_t scan{};
      scan.utime = s.utime;
      scan.nranges = static_cast<int32_t>(s.ranges.size());
      scan.ranges = s.ranges;
      scan.intensities = s.intensities;
      scan.nintensities = static_cast<int32_t>(s.intensities.size());
      scan.rad0 = s.rad0;
      scan.radstep = s.radstep;
      write(channels::kLaser, scan, s.utime);

      if (corrected) write(channels::kGroundTruth, MakePose(s.utime, s.pose), s.utime);
      if (has_reference[e.index]) {
        write(channels::kGroundTruth, MakePose(s.utime, reference[e.index]), s.utime);
      }
    }
    writer.Close();
  } catch (...) {
    writer.Abandon();
    throw;
  }
  return summary;
}

}  // namespace fl::importers
