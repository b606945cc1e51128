// Shared helpers for the tests of Ceres cost functors (GradientChecker options, random
// information matrices).
#pragma once

#include <ceres/numeric_diff_options.h>

#include <Eigen/Core>
#include <random>

namespace fl::test {

// Ridders' extrapolation from a smaller first step than the default 1e-2 (relative): with
// parameters of magnitude ~3 the default first step spans a large part of a sine period.
inline ceres::NumericDiffOptions CheckerOptions() {
  ceres::NumericDiffOptions nd;
  nd.ridders_relative_initial_step_size = 1e-4;
  return nd;
}

// A random symmetric positive-definite 3x3 (A A^T + I).
inline Eigen::Matrix3d RandomSpd3(std::mt19937* rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Matrix3d a;
  for (int i = 0; i < 9; ++i) a.data()[i] = n(*rng);
  return a * a.transpose() + Eigen::Matrix3d::Identity();
}

}  // namespace fl::test
