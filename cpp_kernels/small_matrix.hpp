// 3x3 matrix helpers shared by the stepper's implicit dashpots and the contact pairs.
#pragma once

namespace cavern {

/// inverse = A^-1 by cofactors (row-major 3x3); returns det A (the caller checks it).
inline double invert_3x3(const double* A, double* inverse) {
  const double c00 = A[4] * A[8] - A[5] * A[7];
  const double c01 = A[5] * A[6] - A[3] * A[8];
  const double c02 = A[3] * A[7] - A[4] * A[6];
  const double determinant = A[0] * c00 + A[1] * c01 + A[2] * c02;
  const double s = 1.0 / determinant;
  inverse[0] = c00 * s;
  inverse[1] = (A[2] * A[7] - A[1] * A[8]) * s;
  inverse[2] = (A[1] * A[5] - A[2] * A[4]) * s;
  inverse[3] = c01 * s;
  inverse[4] = (A[0] * A[8] - A[2] * A[6]) * s;
  inverse[5] = (A[2] * A[3] - A[0] * A[5]) * s;
  inverse[6] = c02 * s;
  inverse[7] = (A[1] * A[6] - A[0] * A[7]) * s;
  inverse[8] = (A[0] * A[4] - A[1] * A[3]) * s;
  return determinant;
}

/// y = A x (row-major 3x3).
inline void multiply_3x3(const double* A, const double* x, double* y) {
  y[0] = A[0] * x[0] + A[1] * x[1] + A[2] * x[2];
  y[1] = A[3] * x[0] + A[4] * x[1] + A[5] * x[2];
  y[2] = A[6] * x[0] + A[7] * x[1] + A[8] * x[2];
}

}  // namespace cavern
