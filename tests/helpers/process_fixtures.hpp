// Background processes for tests that run the built programs: start one, wait for a condition.
#pragma once

#include <unistd.h>

#include <chrono>
#include <fstream>
#include <functional>
#include <string>
#include <thread>

namespace fl::test {

// Starts a shell command in the background, in a process group of its own (kill(-pid, ...)
// stops it and its children); returns its pid.
inline pid_t Spawn(const std::string& command) {
  const pid_t pid = fork();
  if (pid == 0) {
    setpgid(0, 0);
    execl("/bin/sh", "sh", "-c", command.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  return pid;
}

// [MB] the resident memory of this process now (VmRSS of /proc/self/status); -1 if unreadable.
inline double CurrentRssMb() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind("VmRSS:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
  }
  return -1.0;
}

// Polls `done` every 50 ms until it is true (returns true) or `timeout_s` passes (false).
inline bool WaitFor(const std::function<bool()>& done, double timeout_s = 10.0) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < end) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return false;
}

}  // namespace fl::test
