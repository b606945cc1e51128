#include "fusionloc/common/shutdown.hpp"

#include <atomic>
#include <csignal>
#include <cstdlib>

namespace fl {
namespace {
std::atomic<bool> g_shutdown{false};

void OnSignal(int) {
  if (g_shutdown.exchange(true)) std::_Exit(130);  // second signal: stop now
}
}  // namespace

void InstallShutdownHandlers() {
  struct sigaction sa {};
  sa.sa_handler = OnSignal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
}

bool ShutdownRequested() { return g_shutdown.load(); }
void RequestShutdown() { g_shutdown.store(true); }
void ResetShutdownForTest() { g_shutdown.store(false); }

}  // namespace fl
