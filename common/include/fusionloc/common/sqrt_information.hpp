// Square root of an information matrix, for whitening a residual: r = S e with SᵀS = Ω, so
// that ½|r|² = ½ eᵀΩe (the cost every least-squares factor of the project minimises).
//
// S = Lᵀ from the Cholesky factor Ω = L Lᵀ (Eigen's LLT, which reads the lower triangle
// only). A caller whose Ω may be slightly asymmetric passes ½(Ω + Ωᵀ).
//
// Ceres' own pose-graph examples (examples/slam/pose_graph_{2d,3d}) use S = L instead, i.e.
// |L e|² = eᵀLᵀL e, which equals eᵀΩe only for a diagonal Ω. The g2o pose-graph benchmark
// reproduces their reference costs with SqrtConvention::kCeresExample; the estimators always
// use the exact kExact convention.
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <cmath>

namespace fl {

enum class SqrtConvention {
  kExact,         // S = Lᵀ, |S e|² = eᵀΩe
  kCeresExample,  // S = L, as Ceres' pose_graph examples (exact only for diagonal Ω)
};

// S with SᵀS = Ω (kExact). Returns false, leaving *sqrt_information unchanged, if Ω is not
// finite, is zero, is not symmetric to 1e-9 of its largest entry, or is not positive definite.
// Numerically singular counts as not positive definite: a Cholesky pivot L_ii² at or below
// 1e-12 Ω_ii (the row lost 12 digits to the rows before it: they are nearly dependent). The
// test is relative to each row's own diagonal, so it does not change when the axes are scaled
// (Ω -> DΩD): information whose entries span many orders of magnitude (1e12 next to 1e-6, as
// some published pose graphs have) is accepted when it is positive definite.
template <int N>
bool SqrtInformation(const Eigen::Matrix<double, N, N>& information,
                     Eigen::Matrix<double, N, N>* sqrt_information,
                     SqrtConvention convention = SqrtConvention::kExact) {
  if (!information.allFinite()) return false;
  const double scale = information.cwiseAbs().maxCoeff();
  if (!(scale > 0.0)) return false;
  if ((information - information.transpose()).cwiseAbs().maxCoeff() > 1e-9 * scale) return false;
  Eigen::LLT<Eigen::Matrix<double, N, N>> llt(information);
  if (llt.info() != Eigen::Success) return false;
  const Eigen::Matrix<double, N, N> l = llt.matrixL();
  for (int i = 0; i < N; ++i) {
    if (!(information(i, i) > 0.0) || !(l(i, i) * l(i, i) > 1e-12 * information(i, i))) {
      return false;
    }
  }
  *sqrt_information = convention == SqrtConvention::kExact ? l.transpose() : l;
  return true;
}

}  // namespace fl
