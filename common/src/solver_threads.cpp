#include "fusionloc/common/solver_threads.hpp"

#include <omp.h>

#include <cstdlib>

namespace fl {

SolverThreadsDecision DecideSolverThreads(int num_threads, const char* omp_thread_limit_env,
                                          const char* omp_max_active_levels_env) {
  SolverThreadsDecision d;
  if (num_threads > 1) {
    d.reason = "num_threads " + std::to_string(num_threads) +
               ": OpenMP left as configured by the environment";
    return d;
  }
  if (omp_thread_limit_env != nullptr && *omp_thread_limit_env != '\0') {
    d.reason = std::string("OMP_THREAD_LIMIT=") + omp_thread_limit_env + " set by the user: kept";
    return d;
  }
  if (omp_max_active_levels_env != nullptr && *omp_max_active_levels_env != '\0') {
    d.reason = std::string("OMP_MAX_ACTIVE_LEVELS=") + omp_max_active_levels_env +
               " set by the user: kept";
    return d;
  }
  d.restrict_openmp = true;
  d.reason = "single-threaded solve: OpenMP regions (CHOLMOD) run on the calling thread";
  return d;
}

SolverThreadsDecision ConfigureSparseSolverThreads(int num_threads) {
  SolverThreadsDecision d = DecideSolverThreads(num_threads, std::getenv("OMP_THREAD_LIMIT"),
                                                std::getenv("OMP_MAX_ACTIVE_LEVELS"));
  if (d.restrict_openmp && omp_get_max_active_levels() != 0) omp_set_max_active_levels(0);
  return d;
}

int OpenMpMaxActiveLevels() { return omp_get_max_active_levels(); }

}  // namespace fl
