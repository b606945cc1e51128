#include "fusionloc/procman/process.hpp"

#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <set>
#include <sstream>

namespace fl::procman {

SpawnResult SpawnProcess(const std::vector<std::string>& argv_in, const SpawnOptions& options) {
  SpawnResult r;
  if (argv_in.empty()) {
    r.error = "empty command";
    return r;
  }
  int report[2];
  if (pipe2(report, O_CLOEXEC) != 0) {
    r.error = std::string("pipe: ") + std::strerror(errno);
    return r;
  }
  int out[2] = {-1, -1};
  if (options.capture_output && pipe2(out, O_CLOEXEC) != 0) {
    r.error = std::string("pipe: ") + std::strerror(errno);
    close(report[0]);
    close(report[1]);
    return r;
  }
  std::vector<std::string> args = argv_in;
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  const char* out_path = options.output_path.empty() ? "/dev/null" : options.output_path.c_str();
  const pid_t parent = getpid();
  const pid_t pid = fork();
  if (pid < 0) {
    r.error = std::string("fork: ") + std::strerror(errno);
    close(report[0]);
    close(report[1]);
    if (out[0] >= 0) {
      close(out[0]);
      close(out[1]);
    }
    return r;
  }
  if (pid == 0) {
    // Child: only async-signal-safe calls until exec.
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent) _exit(127);  // the parent died before prctl
    setpgid(0, 0);
    sigset_t none;
    sigemptyset(&none);
    sigprocmask(SIG_SETMASK, &none, nullptr);
    for (int s : {SIGINT, SIGTERM, SIGHUP, SIGPIPE, SIGCHLD, SIGQUIT, SIGUSR1, SIGUSR2}) {
      signal(s, SIG_DFL);
    }
    const int in = open("/dev/null", O_RDONLY);
    if (in >= 0) dup2(in, 0);
    const int o = out[1] >= 0 ? out[1] : open(out_path, O_WRONLY | O_CREAT | O_APPEND, 0644);
    if (o >= 0) {
      dup2(o, 1);
      dup2(o, 2);
    }
    execvp(argv[0], argv.data());
    const int err = errno;
    (void)!write(report[1], &err, sizeof(err));
    _exit(127);
  }
  setpgid(pid, pid);  // also from the parent: no race with an early kill(-pid)
  close(report[1]);
  if (out[1] >= 0) close(out[1]);
  int child_errno = 0;
  ssize_t n;
  do {
    n = read(report[0], &child_errno, sizeof(child_errno));
  } while (n < 0 && errno == EINTR);
  close(report[0]);
  if (n == sizeof(child_errno)) {
    waitpid(pid, nullptr, 0);
    if (out[0] >= 0) close(out[0]);
    r.error = "cannot run '" + argv_in[0] + "': " + std::strerror(child_errno);
    return r;
  }
  if (out[0] >= 0) fcntl(out[0], F_SETFL, fcntl(out[0], F_GETFL) | O_NONBLOCK);
  r.pid = pid;
  r.output_fd = out[0];
  return r;
}

std::string DescribeWaitStatus(int ws) {
  if (WIFEXITED(ws)) return "exit code " + std::to_string(WEXITSTATUS(ws));
  if (WIFSIGNALED(ws)) return std::string("killed by SIG") + sigabbrev_np(WTERMSIG(ws));
  return "wait status " + std::to_string(ws);
}

// ---------------------------------------------------------------------------------------

OrphanGuard::~OrphanGuard() {
  if (fd_ >= 0) close(fd_);
  if (pid_ > 0) waitpid(pid_, nullptr, 0);
}

bool OrphanGuard::Start(std::string* error) {
  int p[2];
  if (pipe2(p, O_CLOEXEC) != 0) {
    *error = std::string("pipe: ") + std::strerror(errno);
    return false;
  }
  const long max_fd = std::min<long>(sysconf(_SC_OPEN_MAX), 65536);
  const pid_t pid = fork();
  if (pid < 0) {
    *error = std::string("fork: ") + std::strerror(errno);
    close(p[0]);
    close(p[1]);
    return false;
  }
  if (pid == 0) {
    // The guard: async-signal-safe calls only (the owner may have had threads).
    setpgid(0, 0);
    signal(SIGINT, SIG_IGN);
    signal(SIGTERM, SIG_IGN);
    signal(SIGHUP, SIG_IGN);
    signal(SIGPIPE, SIG_IGN);
    for (long fd = 0; fd < max_fd; ++fd) {
      if (fd != p[0]) close(static_cast<int>(fd));
    }
    constexpr int kMax = 4096;
    static pid_t groups[kMax];
    int count = 0;
    for (;;) {
      int32_t v = 0;
      const ssize_t n = read(p[0], &v, sizeof(v));
      if (n < 0 && errno == EINTR) continue;
      if (n != sizeof(v)) break;  // EOF: the owner is gone
      if (v > 0) {
        if (count < kMax) groups[count++] = v;
      } else {
        for (int i = 0; i < count; ++i) {
          if (groups[i] == -v) groups[i] = groups[--count];
        }
      }
    }
    for (int i = 0; i < count; ++i) kill(-groups[i], SIGKILL);
    _exit(0);
  }
  close(p[0]);
  pid_ = pid;
  fd_ = p[1];
  return true;
}

void OrphanGuard::Send(int32_t value) {
  if (fd_ < 0) return;
  ssize_t n;
  do {
    n = write(fd_, &value, sizeof(value));
  } while (n < 0 && errno == EINTR);
}

void OrphanGuard::Watch(pid_t pgid) { Send(static_cast<int32_t>(pgid)); }
void OrphanGuard::Unwatch(pid_t pgid) { Send(-static_cast<int32_t>(pgid)); }

// ---------------------------------------------------------------------------------------

namespace {

std::string ReadSmallFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

}  // namespace

double ClockTicksPerSecond() { return static_cast<double>(sysconf(_SC_CLK_TCK)); }

std::map<pid_t, GroupUsage> ReadGroupUsage(const std::vector<pid_t>& pgids) {
  std::map<pid_t, GroupUsage> out;
  const std::set<pid_t> wanted(pgids.begin(), pgids.end());
  for (pid_t g : pgids) out[g];
  if (wanted.empty()) return out;
  DIR* dir = opendir("/proc");
  if (dir == nullptr) return out;
  const long page = sysconf(_SC_PAGESIZE);
  while (dirent* e = readdir(dir)) {
    if (e->d_name[0] < '0' || e->d_name[0] > '9') continue;
    const std::string stat = ReadSmallFile(std::string("/proc/") + e->d_name + "/stat");
    const size_t close_paren = stat.rfind(')');
    if (close_paren == std::string::npos) continue;
    std::istringstream in(stat.substr(close_paren + 2));
    // Fields from 3 (state): state ppid pgrp session tty tpgid flags minflt cminflt majflt
    // cmajflt utime stime cutime cstime priority nice threads itrealvalue starttime vsize rss
    std::string state;
    long long ppid = 0, pgrp = 0;
    in >> state >> ppid >> pgrp;
    if (!in || wanted.count(static_cast<pid_t>(pgrp)) == 0 || state == "Z") continue;
    unsigned long long skip = 0, utime = 0, stime = 0, vsize = 0;
    long long rss = 0;
    for (int f = 6; f <= 13; ++f) in >> skip;
    in >> utime >> stime;
    for (int f = 16; f <= 22; ++f) in >> skip;
    in >> vsize >> rss;
    if (!in) continue;
    GroupUsage& u = out[static_cast<pid_t>(pgrp)];
    u.cpu_ticks += utime + stime;
    u.vsize_bytes += static_cast<int64_t>(vsize);
    u.rss_bytes += static_cast<int64_t>(rss) * page;
    ++u.processes;
  }
  closedir(dir);
  return out;
}

int64_t ReadPeakRss(pid_t pid) {
  std::istringstream in(ReadSmallFile("/proc/" + std::to_string(pid) + "/status"));
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmHWM:", 0) == 0) return std::atoll(line.c_str() + 6) * 1024;
  }
  return 0;
}

HostUsage ReadHostUsage() {
  HostUsage h;
  {
    std::istringstream in(ReadSmallFile("/proc/stat"));
    std::string cpu;
    in >> cpu;
    if (cpu == "cpu") {
      unsigned long long v[10] = {0};
      for (auto& x : v) in >> x;
      // user nice system idle iowait irq softirq steal guest guest_nice
      const unsigned long long idle = v[3] + v[4];
      const unsigned long long total = v[0] + v[1] + v[2] + v[3] + v[4] + v[5] + v[6] + v[7];
      h.total_ticks = total;
      h.busy_ticks = total - idle;
    }
  }
  std::istringstream in(ReadSmallFile("/proc/meminfo"));
  std::string key;
  long long kb = 0;
  std::string unit;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream l(line);
    l >> key >> kb;
    const int64_t bytes = static_cast<int64_t>(kb) * 1024;
    if (key == "MemTotal:") h.mem_total_bytes = bytes;
    if (key == "MemAvailable:") h.mem_available_bytes = bytes;
    if (key == "SwapTotal:") h.swap_total_bytes = bytes;
    if (key == "SwapFree:") h.swap_free_bytes = bytes;
  }
  return h;
}

}  // namespace fl::procman
