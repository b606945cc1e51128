// The file faults of fl-bench-faults (file_faults.hpp).
#include "file_faults.hpp"

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <random>
#include <set>
#include <sstream>

#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/common/number_format.hpp"
#include "fusionloc/eval/metrics.hpp"
#include "fusionloc/eval/trajectory.hpp"

namespace fl::bench_faults {
namespace {

namespace fs = std::filesystem;

std::string Quote(const std::string& s) {
  std::string q = "'";
  for (const char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

std::string ReadText(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// Runs `command` with /bin/sh, its output to `log`; returns the exit code (128 + N when killed
// by signal N, as a shell reports it).
int Shell(const std::string& command, const std::string& log) {
  const int st = std::system((command + " > " + Quote(log) + " 2>&1").c_str());
  if (st == -1) throw std::runtime_error("cannot run /bin/sh for: " + command);
  if (WIFSIGNALED(st)) return 128 + WTERMSIG(st);
  return WEXITSTATUS(st);
}

bool KilledBySignal(int exit_code) { return exit_code > 128 && exit_code < 128 + 65; }

struct IndexedEvent {
  int64_t offset = 0, end = 0;  // [bytes] where it starts and ends in the file
  Utime utime = 0;
  std::string channel;
};

// Every event of an undamaged log with its byte range.
std::vector<IndexedEvent> IndexLog(const std::string& path) {
  LcmLogReader reader(path);
  std::vector<IndexedEvent> events;
  LcmLogEvent e;
  while (true) {
    const int64_t at = reader.position();
    if (!reader.Next(&e)) break;
    events.push_back(IndexedEvent{at, reader.position(), e.utime, e.channel});
  }
  if (!reader.ProblemSummary().empty()) {
    throw std::runtime_error("the source log is damaged before the bench damages it: " +
                             reader.ProblemSummary());
  }
  return events;
}

// Events of `log` on the channels in `channels` (the replayed inputs in its output).
int64_t CountEvents(const std::string& log, const std::set<std::string>& channels) {
  LcmLogReader reader(log);
  LcmLogEvent e;
  int64_t n = 0;
  while (reader.Next(&e)) n += channels.count(e.channel) ? 1 : 0;
  return n;
}

Utime FirstFusedPoseAfter(const std::string& log, Utime after) {
  try {
    const eval::Trajectory t = eval::ReadTrajectoryLcm(log, "FUSED_POSE");
    for (const auto& p : t) {
      if (p.utime > after) return p.utime;
    }
  } catch (const std::exception&) {
  }
  return -1;
}

bool CanMountTmpfs(std::string* why) {
  if (geteuid() != 0) {
    *why = "needs root (a tmpfs is mounted in a private mount namespace with unshare -m)";
    return false;
  }
  if (std::system("command -v unshare > /dev/null 2>&1") != 0) {
    *why = "needs unshare (util-linux)";
    return false;
  }
  return true;
}

// `inner` runs in a private mount namespace with a tmpfs of `size` mounted at `mount_dir`; its
// exit code goes to DIR/rc and the listing of the tmpfs to DIR/listing (the mount vanishes
// with the namespace).
int ShellOnFullDisk(const std::string& dir, const std::string& mount_dir, const std::string& size,
                    const std::string& inner) {
  fs::create_directories(mount_dir);
  const std::string script = "mount -t tmpfs -o size=" + size + " fl-bench-faults " +
                             Quote(mount_dir) + " || exit 90; " + inner + "; echo $? > " +
                             Quote(dir + "/rc") + "; ls -la " + Quote(mount_dir) + " > " +
                             Quote(dir + "/listing");
  const int shell = Shell("unshare -m sh -c " + Quote(script), dir + "/namespace.log");
  if (shell == 90) {
    throw std::runtime_error("cannot mount a tmpfs in a private mount namespace; see " + dir +
                             "/namespace.log");
  }
  const std::string rc = ReadText(dir + "/rc");
  if (rc.empty()) throw std::runtime_error("no exit code from the disk-full run; see " + dir);
  return std::atoi(rc.c_str());
}

bool Listed(const std::string& listing, const std::string& name) {
  std::istringstream in(listing);
  for (std::string line; std::getline(in, line);) {
    if (line.size() >= name.size() && line.compare(line.size() - name.size(), name.size(), name) == 0 &&
        (line.size() == name.size() || line[line.size() - name.size() - 1] == ' ')) {
      return true;
    }
  }
  return false;
}

bool NamesFullDisk(const std::string& text) {
  return text.find("No space left on device") != std::string::npos ||
         text.find("disk full") != std::string::npos;
}

class FileFaults {
 public:
  explicit FileFaults(const FileFaultSetup& s) : s_(s) {}

  // The sensor log and its undamaged replay (the reference of every ratio).
  void Prepare() {
    fs::create_directories(s_.out_dir + "/file_source");
    const std::string dir = s_.out_dir + "/file_source";
    src_ = dir + "/sensors.lcmlog";
    const std::string sim = Quote(s_.bin + "/fl-sim") + " --log " + Quote(src_) + " --world " +
                            s_.world + " --duration " + FormatDouble(s_.duration_s) +
                            " --seed " + std::to_string(s_.seed) + " --robot " +
                            Quote(s_.config_dir + "/robot/sim.yaml");
    if (Shell(sim, dir + "/sim.log") != 0) {
      throw std::runtime_error("fl-sim could not write the sensor log; see " + dir + "/sim.log");
    }
    events_ = IndexLog(src_);
    for (const auto& e : events_) channels_.insert(e.channel);
    const std::string out = dir + "/replay.lcmlog";
    if (Replay(src_, "--out " + Quote(out), dir + "/replay.log") != 0) {
      throw std::runtime_error("the undamaged replay failed; see " + dir + "/replay.log");
    }
    std::string note;
    reference_ate_ = FusedAte(out, &note);
    reference_inputs_ = CountEvents(out, channels_);
    if (reference_inputs_ != static_cast<int64_t>(events_.size())) {
      FL_LOG(WARN) << "the undamaged replay wrote " << reference_inputs_ << " of the "
                   << events_.size() << " input events to its output";
    }
  }

  bench::Run LogTruncated() {
    const std::string dir = RunDir("log_truncated");
    const int64_t size = static_cast<int64_t>(fs::file_size(src_));
    const int64_t cut = size * 6 / 10;
    size_t k = 0;  // the event the cut falls in
    while (k < events_.size() && events_[k].end <= cut) ++k;
    const std::string damaged = dir + "/truncated.lcmlog";
    {
      const std::string bytes = ReadText(src_);
      std::ofstream(damaged, std::ios::binary) << bytes.substr(0, static_cast<size_t>(cut));
    }
    const std::string out = dir + "/replay.lcmlog";
    const int rc = Replay(damaged, "--out " + Quote(out), dir + "/replay.log");
    const std::string text = ReadText(dir + "/replay.log");
    bench::Run run = Begin("log_truncated", "sensor log cut at byte " + std::to_string(cut) +
                                                " of " + std::to_string(size) +
                                                ", inside event " + std::to_string(k));
    const std::string expected = "truncated at byte offset " + std::to_string(events_[k].offset);
    const int64_t delivered = CountEvents(out, channels_);
    AddCommon(&run, rc, out, static_cast<int64_t>(k) - delivered, 0.0);
    run.Add("exit_code", rc)
        .Add("damage_offset_named", text.find(expected) != std::string::npos ? 1 : 0)
        .Add("events_before_damage", static_cast<double>(k))
        .Add("events_delivered", static_cast<double>(delivered));
    if (text.find(expected) == std::string::npos) {
      run.note += "the replay's output does not say '" + expected + "'; ";
    }
    run.note = TrimNote(run.note);
    return run;
  }

  bench::Run LogCorrupted() {
    const std::string dir = RunDir("log_corrupted");
    const int64_t size = static_cast<int64_t>(fs::file_size(src_));
    // The first event starting past 40 % of the file; the damage covers the last 100 bytes of
    // the one before it and the next 412, its header included.
    size_t k = 0;
    while (k + 1 < events_.size() && events_[k].offset < size * 4 / 10) ++k;
    const int64_t from = events_[k].offset - 100, length = 512;
    std::string bytes = ReadText(src_);
    std::mt19937 rng(static_cast<unsigned>(s_.seed));
    for (int64_t i = 0; i < length && from + i < size; ++i) {
      bytes[static_cast<size_t>(from + i)] = static_cast<char>(rng() & 0xff);
    }
    const std::string damaged = dir + "/corrupted.lcmlog";
    std::ofstream(damaged, std::ios::binary) << bytes;
    // Events whose header lies in the damage cannot be found again.
    int64_t in_damage = 0;
    for (const auto& e : events_) in_damage += e.offset >= from && e.offset < from + length;
    const std::string out = dir + "/replay.lcmlog";
    const int rc = Replay(damaged, "--out " + Quote(out), dir + "/replay.log");
    const std::string text = ReadText(dir + "/replay.log");
    bench::Run run = Begin("log_corrupted", std::to_string(length) +
                                                " random bytes written over the log at byte " +
                                                std::to_string(from) + " of " +
                                                std::to_string(size));
    // The damage must be named at an offset inside the bytes we overwrote.
    bool named = false;
    for (size_t at = text.find("byte offset "); at != std::string::npos;
         at = text.find("byte offset ", at + 1)) {
      const int64_t offset = std::atoll(text.c_str() + at + 12);
      named = named || (offset >= from && offset < from + length);
    }
    const int64_t delivered = CountEvents(out, channels_);
    const Utime fused_after = FirstFusedPoseAfter(out, events_[k].utime);
    const double recovery =
        fused_after > 0 ? 1e-6 * static_cast<double>(fused_after - events_[k].utime) : -1;
    AddCommon(&run, rc, out, static_cast<int64_t>(events_.size()) - delivered, recovery);
    run.Add("exit_code", rc)
        .Add("damage_offset_named", named ? 1 : 0)
        .Add("events_in_damage", static_cast<double>(in_damage))
        .Add("events_delivered", static_cast<double>(delivered));
    if (!named) run.note += "the replay's output names no byte offset inside the damage; ";
    run.note = TrimNote(run.note);
    return run;
  }

  bench::Run DiskFullReplayLog() {
    return ReplayOnFullDisk("disk_full_replay_log", "2m", "--out", "out.lcmlog", "out.lcmlog",
                            "fl-replay --out onto a 2 MB file system (the output log needs more)");
  }

  bench::Run DiskFullMapSave() {
    return ReplayOnFullDisk("disk_full_map_save", "64k", "--map-out", "map", "map.pcd",
                            "fl-replay --map-out onto a 64 kB file system (the map needs more)");
  }

  // fl-replay of the sensor log with `flag` DISK/`target` on a tmpfs of `size`; `file` is what
  // must not be left under its final name.
  bench::Run ReplayOnFullDisk(const std::string& name, const std::string& size,
                              const std::string& flag, const std::string& target,
                              const std::string& file, const std::string& what) {
    const std::string dir = RunDir(name);
    const std::string mount = dir + "/disk";
    const int rc = ShellOnFullDisk(
        dir, mount, size,
        Quote(s_.bin + "/fl-replay") + " " + Quote(src_) + " --quiet --config-dir " +
            Quote(s_.config_dir) + " " + flag + " " + Quote(mount + "/" + target) + " > " +
            Quote(dir + "/replay.log") + " 2>&1");
    return DiskFullRun(name, what, dir, rc, file);
  }

  bench::Run DiskFullLogger() {
    const std::string dir = RunDir("disk_full_logger");
    const std::string logger = s_.bin + "/fl-logger";
    if (!fs::exists(logger)) throw std::runtime_error(logger + " is not built");
    const std::string mount = dir + "/disk";
    const std::string url =
        "udpm://239.255.76.67:" + std::to_string(s_.port) + "?ttl=0&recv_buf_size=16777216";
    const std::string inner =
        Quote(logger) + " --lcm-url=" + Quote(url) + " " + Quote(mount + "/run.lcmlog") + " > " +
        Quote(dir + "/replay.log") + " 2>&1 & LOGGER=$!; sleep 1; " + Quote(s_.bin + "/fl-sim") +
        " --lcm-url=" + Quote(url) + " --world " + s_.world + " --duration 10 --seed " +
        std::to_string(s_.seed) + " --robot " + Quote(s_.config_dir + "/robot/sim.yaml") + " > " +
        Quote(dir + "/sim.log") + " 2>&1; kill -INT $LOGGER 2> /dev/null; wait $LOGGER; RC=$?; " +
        "cp " + Quote(mount) + "/run.lcmlog* " + Quote(dir) + "/ 2> /dev/null; (exit $RC)";
    const int rc = ShellOnFullDisk(dir, mount, "1m", inner);
    bench::Run run = DiskFullRun(
        "disk_full_logger", "fl-logger recording the live simulator onto a 1 MB file system", dir,
        rc, "run.lcmlog");
    // What was recorded before the disk filled is kept, under the name that says so.
    int64_t readable = 0;
    if (fs::exists(dir + "/run.lcmlog.partial")) {
      LcmLogReader reader(dir + "/run.lcmlog.partial");
      LcmLogEvent e;
      while (reader.Next(&e)) ++readable;
    }
    run.Add("events_readable_in_partial", static_cast<double>(readable));
    return run;
  }

  std::vector<std::string> problems;  // runs that could not be done, with the reason

 private:
  std::string RunDir(const std::string& name) {
    const std::string dir = s_.out_dir + "/" + name;
    fs::remove_all(dir);
    fs::create_directories(dir);
    return dir;
  }

  int Replay(const std::string& log, const std::string& args, const std::string& out_log) {
    return Shell(Quote(s_.bin + "/fl-replay") + " " + Quote(log) + " --quiet --config-dir " +
                     Quote(s_.config_dir) + " " + args,
                 out_log);
  }

  bench::Run Begin(const std::string& name, const std::string& what) {
    bench::Run run;
    run.name = name;
    run.input = "world " + s_.world + ", " + FormatDouble(s_.duration_s) + " s sensor log, seed " +
                std::to_string(s_.seed) + ": " + what;
    return run;
  }

  void AddCommon(bench::Run* run, int rc, const std::string& out, int64_t lost, double recovery) {
    std::string note;
    const double ate = fs::exists(out) ? FusedAte(out, &note) : -1;
    run->Add("crashes", KilledBySignal(rc) ? 1 : 0)
        .Add("fused_ate_m", ate)
        .Add("fused_ate_ratio", ate >= 0 && reference_ate_ > 0 ? ate / reference_ate_ : -1)
        .Add("messages_lost", static_cast<double>(lost))
        .Add("recovery_s", recovery);
    run->note += note;
  }

  bench::Run DiskFullRun(const std::string& name, const std::string& what, const std::string& dir,
                         int rc, const std::string& file) {
    bench::Run run = Begin(name, what);
    const std::string text = ReadText(dir + "/replay.log");
    const std::string listing = ReadText(dir + "/listing");
    const bool complete = Listed(listing, file);
    run.Add("crashes", KilledBySignal(rc) ? 1 : 0)
        .Add("exit_code", rc)
        .Add("error_names_full_disk", NamesFullDisk(text) ? 1 : 0)
        .Add("complete_file_left", complete ? 1 : 0)
        .Add("partial_file_left", Listed(listing, file + ".partial") ? 1 : 0);
    if (rc == 0) run.note += "exited 0 although the disk was full; ";
    if (complete) run.note += file + " was left under its final name; ";
    if (!NamesFullDisk(text)) run.note += "no error names the full disk; ";
    // The message the user sees.
    std::istringstream in(text);
    for (std::string line; std::getline(in, line);) {
      if (NamesFullDisk(line)) {
        run.note += "error: " + line.substr(0, 300) + "; ";
        break;
      }
    }
    run.note = TrimNote(run.note);
    return run;
  }

  FileFaultSetup s_;
  std::string src_;
  std::vector<IndexedEvent> events_;
  std::set<std::string> channels_;
  double reference_ate_ = -1;
  int64_t reference_inputs_ = 0;
};

}  // namespace

std::string TrimNote(std::string note) {
  while (note.size() >= 2 && note.compare(note.size() - 2, 2, "; ") == 0) note.resize(note.size() - 2);
  return note;
}

std::vector<std::string> FileFaultNames() {
  return {"log_truncated", "log_corrupted", "disk_full_replay_log", "disk_full_map_save",
          "disk_full_logger"};
}

double FusedAte(const std::string& log, std::string* note) {
  try {
    const eval::Trajectory est = eval::ReadTrajectoryLcm(log, "FUSED_TRAJECTORY");
    const eval::Trajectory ref = eval::ReadTrajectoryLcm(log, "GROUND_TRUTH");
    const eval::AteResult r = eval::ComputeAte(est, ref, eval::Alignment::kSE2, SecondsToUtime(0.02));
    return r.trans_m.rmse;
  } catch (const std::exception& e) {
    *note += std::string("no fused ATE: ") + e.what() + "; ";
    return -1;
  }
}

std::vector<bench::Run> RunFileFaults(const FileFaultSetup& setup,
                                      const std::vector<std::string>& only) {
  auto wanted = [&](const std::string& name) {
    return only.empty() || std::find(only.begin(), only.end(), name) != only.end();
  };
  FileFaults f(setup);
  f.Prepare();
  std::vector<bench::Run> runs;
  std::string why_not;
  const bool can_fill = CanMountTmpfs(&why_not);
  const std::vector<std::pair<std::string, bench::Run (FileFaults::*)()>> all = {
      {"log_truncated", &FileFaults::LogTruncated},
      {"log_corrupted", &FileFaults::LogCorrupted},
      {"disk_full_replay_log", &FileFaults::DiskFullReplayLog},
      {"disk_full_map_save", &FileFaults::DiskFullMapSave},
      {"disk_full_logger", &FileFaults::DiskFullLogger}};
  for (const auto& [name, fn] : all) {
    if (!wanted(name)) continue;
    if (name.rfind("disk_full_", 0) == 0 && !can_fill) {
      FL_LOG(WARN) << "bench faults: " << name << " skipped: " << why_not;
      continue;
    }
    std::cerr << "[bench faults] " << name << std::endl;
    try {
      runs.push_back((f.*fn)());
    } catch (const std::exception& e) {
      FL_LOG(ERROR) << "bench faults: " << name << " could not run: " << e.what();
      bench::Run r;
      r.name = name;
      r.input = "not run";
      r.Add("crashes", -1);
      r.note = std::string("could not run: ") + e.what();
      runs.push_back(r);
    }
  }
  return runs;
}

}  // namespace fl::bench_faults
