#include "fusionloc/common/solver_threads.hpp"

#include <gtest/gtest.h>
#include <omp.h>

#include <atomic>
#include <cstdlib>

namespace {

// The team size of a region written like CHOLMOD's (num_threads(4) clause). Atomic: the end of
// the region is a barrier inside libgomp, which ThreadSanitizer does not see (not instrumented).
int TeamSizeOfFourThreadRegion() {
  std::atomic<int> team{0};
#pragma omp parallel num_threads(4)
  {
#pragma omp single
    team.store(omp_get_num_threads());
  }
  return team.load();
}

TEST(SolverThreads, DecisionFollowsThreadsAndRespectsUserEnvironment) {
  EXPECT_TRUE(fl::DecideSolverThreads(1, nullptr, nullptr).restrict_openmp);
  EXPECT_TRUE(fl::DecideSolverThreads(0, nullptr, nullptr).restrict_openmp);
  EXPECT_TRUE(fl::DecideSolverThreads(1, "", "").restrict_openmp);
  const fl::SolverThreadsDecision many = fl::DecideSolverThreads(2, nullptr, nullptr);
  EXPECT_FALSE(many.restrict_openmp);
  EXPECT_NE(many.reason.find("num_threads 2"), std::string::npos) << many.reason;
  const fl::SolverThreadsDecision user = fl::DecideSolverThreads(1, "3", nullptr);
  EXPECT_FALSE(user.restrict_openmp);
  EXPECT_NE(user.reason.find("OMP_THREAD_LIMIT=3"), std::string::npos) << user.reason;
  EXPECT_FALSE(fl::DecideSolverThreads(1, nullptr, "2").restrict_openmp);
}

TEST(SolverThreads, SingleThreadedSolveCapsCholmodStyleTeamsAtOne) {
  if (std::getenv("OMP_THREAD_LIMIT") != nullptr ||
      std::getenv("OMP_MAX_ACTIVE_LEVELS") != nullptr) {
    GTEST_SKIP() << "OpenMP limits set in the environment; the default case is not testable";
  }
  // Without the cap, the num_threads(4) clause wins over everything but the limits above.
  ASSERT_EQ(TeamSizeOfFourThreadRegion(), 4);
  const fl::SolverThreadsDecision d = fl::ConfigureSparseSolverThreads(1);
  EXPECT_TRUE(d.restrict_openmp) << d.reason;
  EXPECT_EQ(fl::OpenMpMaxActiveLevels(), 0);
  EXPECT_EQ(TeamSizeOfFourThreadRegion(), 1);
  // Idempotent.
  fl::ConfigureSparseSolverThreads(1);
  EXPECT_EQ(TeamSizeOfFourThreadRegion(), 1);
}

}  // namespace
