// Starting, watching and measuring child processes (Linux): what the deputy (and the
// supervisor) stand on.
//
// Every child runs in its own process group (its pid), with stdin from /dev/null, and with
// PR_SET_PDEATHSIG(SIGKILL) set between fork and exec, so that it dies with the thread that
// started it, however that dies. An OrphanGuard covers what PDEATHSIG cannot: the children's
// own children (`sh -c 'a & b'`), by SIGKILLing every watched process group when its owner
// is gone.
#pragma once

#include <sys/types.h>

#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace fl::procman {

struct SpawnOptions {
  // Where stdout+stderr go: a pipe whose read end is returned (non-blocking, close-on-exec),
  // or, with capture_output false, appended to output_path ("" = /dev/null).
  bool capture_output = true;
  std::string output_path;
};

struct SpawnResult {
  pid_t pid = -1;      // also the process group id; -1 if it could not be started
  int output_fd = -1;  // read end of the output pipe (capture_output), else -1
  std::string error;   // why it could not be started ("cannot run 'x': No such file ...")
};

// fork + execvp of argv (argv[0] looked up in PATH). An exec failure is reported in `error`
// (the child's errno through a close-on-exec pipe), not as an anonymous exit code 127.
SpawnResult SpawnProcess(const std::vector<std::string>& argv, const SpawnOptions& options);

// "exit code 3", "killed by SIGKILL" for a waitpid(2) status.
std::string DescribeWaitStatus(int wait_status);

// A helper process that outlives its owner by a moment: the owner tells it which process
// groups it runs (Watch/Unwatch, through a pipe); when the pipe's write end closes (the owner
// exits or is killed, even by SIGKILL), it sends SIGKILL to every watched group and exits.
// It ignores SIGINT/SIGTERM/SIGHUP and runs in its own process group, so that Ctrl-C on the
// terminal does not take it down before its owner.
class OrphanGuard {
 public:
  OrphanGuard() = default;
  ~OrphanGuard();  // closes the pipe (the guard kills what is still watched) and reaps it
  OrphanGuard(const OrphanGuard&) = delete;
  OrphanGuard& operator=(const OrphanGuard&) = delete;

  // Forks the guard. False (and *error) if it cannot.
  bool Start(std::string* error);
  void Watch(pid_t pgid);
  void Unwatch(pid_t pgid);
  pid_t pid() const { return pid_; }

 private:
  void Send(int32_t value);
  pid_t pid_ = -1;
  int fd_ = -1;
};

// What /proc says of a process group (every process whose pgrp is the id).
struct GroupUsage {
  uint64_t cpu_ticks = 0;   // [clock ticks] user+system time of the live members
  int64_t vsize_bytes = 0;  // [bytes] summed virtual size
  int64_t rss_bytes = 0;    // [bytes] summed resident size
  int processes = 0;        // [count] live members
};
// One pass over /proc for the given process groups.
std::map<pid_t, GroupUsage> ReadGroupUsage(const std::vector<pid_t>& pgids);
// [bytes] peak resident size of one process (VmHWM), 0 if unknown.
int64_t ReadPeakRss(pid_t pid);
// Clock ticks per second (for GroupUsage::cpu_ticks).
double ClockTicksPerSecond();

// Host load and memory from /proc.
struct HostUsage {
  uint64_t busy_ticks = 0, total_ticks = 0;              // [clock ticks, all CPUs] since boot
  int64_t mem_total_bytes = 0, mem_available_bytes = 0;  // [bytes]
  int64_t swap_total_bytes = 0, swap_free_bytes = 0;     // [bytes]
};
HostUsage ReadHostUsage();

}  // namespace fl::procman
