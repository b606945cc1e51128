// Thread count of the sparse Cholesky inside Ceres (CHOLMOD), which Ceres' own
// Solver::Options::num_threads does not control.
//
// Debian 12's SuiteSparse 5.12 is built with OpenMP, and CHOLMOD's supernodal factorisation
// opens `#pragma omp parallel for num_threads(CHOLMOD_OMP_NUM_THREADS)` teams, a compile-time
// 4, around small per-supernode loops. The clause overrides OMP_NUM_THREADS, so even a
// "single-threaded" Ceres solve starts 4 threads per loop; on a 2-core robot computer the
// threads spend the factorisation waking each other (futex), and sphere2500 takes 3.4 s
// instead of 1.8 s (`./fusionloc bench posegraph`, docs/BENCHMARKS.md).
//
// ConfigureSparseSolverThreads(1) makes every OpenMP region of the process run on the
// calling thread (omp_set_max_active_levels(0)), which caps those teams at one thread.
// The setting is process-wide; it is what a single-core solve (num_threads = 1) needs. With
// num_threads > 1, OpenMP is left as the environment configures it. A user who exported
// OMP_THREAD_LIMIT or OMP_MAX_ACTIVE_LEVELS keeps their setting: we never override it.
#pragma once

#include <string>

namespace fl {

struct SolverThreadsDecision {
  bool restrict_openmp = false;  // true: OpenMP regions run on one thread
  std::string reason;            // one line for logs and status
};

// The decision alone (pure, for tests): env values are those of OMP_THREAD_LIMIT and
// OMP_MAX_ACTIVE_LEVELS, nullptr when unset.
SolverThreadsDecision DecideSolverThreads(int num_threads, const char* omp_thread_limit_env,
                                          const char* omp_max_active_levels_env);

// Reads the environment, applies the decision and returns it. Idempotent and cheap; call it
// before ceres::Solve.
SolverThreadsDecision ConfigureSparseSolverThreads(int num_threads);

// OpenMP's current max-active-levels (0 = all regions serial); for tests and diagnostics.
int OpenMpMaxActiveLevels();

}  // namespace fl
