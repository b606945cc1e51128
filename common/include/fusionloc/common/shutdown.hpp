// Clean shutdown on SIGINT/SIGTERM: processes poll ShutdownRequested() in their loop.
#pragma once

namespace fl {

// Installs handlers for SIGINT and SIGTERM that set the shutdown flag. A second signal while
// shutting down exits at once.
void InstallShutdownHandlers();
bool ShutdownRequested();
// For tests and for processes that decide to stop themselves.
void RequestShutdown();
void ResetShutdownForTest();

}  // namespace fl
