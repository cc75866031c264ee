// Kinematic constraints of boundary nodes: a "fixed" node holds all three components, a
// "roller" node the component along its face normal (docs/boundaries.md).
//
// A constrained node moves only in its free subspace, given by the orthogonal projection P
// (P = 0 fixed, P = I - n n^T roller, P = I - n1 n1^T - n2 n2^T on an edge of two rollers).
// The velocity-Verlet update with implicit damping, Atilde v_{n+1} = M v_{n+1/2} + dt/2 r
// (Atilde = M (1 + dt/2 alpha) I + dt/2 C), becomes, with the support's reaction R in the held
// directions ((I - P) R = R) and v_{n+1} = P v_{n+1}:
//   P Atilde P v_{n+1} = P (M v_{n+1/2} + dt/2 r)   ->   v_{n+1} = Ainv_P (M v_{n+1/2} + dt/2 r),
//   Ainv_P = P (P Atilde P + (I - P))^-1 P,
//   M a_{n+1} = P (r - d),  R = -(I - P)(r - d),   d = (alpha M + C) v_{n+1}.
// The reaction does no work (R.v = 0) and R.a = 0, so the energy account needs no new term.
#pragma once

#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

#include "small_matrix.hpp"

namespace cavern {

/// out = P (P A P + (I - P))^-1 P for a symmetric A positive definite on the range of P
/// (row-major 3x3). Returns false when that restricted matrix is singular.
inline bool constrained_inverse(const double* A, const double* P, double* out) {
  double AP[9], PAP[9];
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) {
      double s = 0.0;
      for (int k = 0; k < 3; ++k) s += A[3 * r + k] * P[3 * k + c];
      AP[3 * r + c] = s;
    }
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) {
      double s = 0.0;
      for (int k = 0; k < 3; ++k) s += P[3 * r + k] * AP[3 * k + c];
      PAP[3 * r + c] = s + ((r == c ? 1.0 : 0.0) - P[3 * r + c]);
    }
  double inverse[9];
  const double determinant = invert_3x3(PAP, inverse);
  if (!(std::isfinite(determinant) && determinant > 0.0)) return false;
  double inverse_P[9];
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) {
      double s = 0.0;
      for (int k = 0; k < 3; ++k) s += inverse[3 * r + k] * P[3 * k + c];
      inverse_P[3 * r + c] = s;
    }
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) {
      double s = 0.0;
      for (int k = 0; k < 3; ++k) s += P[3 * r + k] * inverse_P[3 * k + c];
      out[3 * r + c] = s;
    }
  return true;
}

/// Throws std::invalid_argument unless P (row-major 3x3) is an orthogonal projection:
/// symmetric and P P = P, to 1e-10.
inline void check_projection(const double* P, std::int64_t index) {
  double PP[9];
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) {
      double s = 0.0;
      for (int k = 0; k < 3; ++k) s += P[3 * r + k] * P[3 * k + c];
      PP[3 * r + c] = s;
    }
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) {
      const bool symmetric = std::abs(P[3 * r + c] - P[3 * c + r]) <= 1e-10;
      const bool idempotent = std::abs(PP[3 * r + c] - P[3 * r + c]) <= 1e-10;
      if (!(std::isfinite(P[3 * r + c]) && symmetric && idempotent))
        throw std::invalid_argument("projection[" + std::to_string(index) +
                                    "] is not an orthogonal projection (symmetric, P P = P): "
                                    "build it as I - sum of e e^T over orthonormal held directions");
    }
}

}  // namespace cavern
