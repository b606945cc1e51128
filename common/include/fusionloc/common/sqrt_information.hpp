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
// finite, is zero, is not symmetric to 1e-9 of its largest entry, or is not positive definite
// (a Cholesky pivot at or below 1e-12 √max|Ω| counts as singular).
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
  if (l.diagonal().minCoeff() <= 1e-12 * std::sqrt(scale)) return false;
  *sqrt_information = convention == SqrtConvention::kExact ? l.transpose() : l;
  return true;
}

}  // namespace fl
