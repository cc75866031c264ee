// Rotations of symmetric tensors for the objectivity tests of the material laws.
#pragma once

#include <cmath>

#include "materials/principal.hpp"

namespace cavern::testing {

/// R = Rz(a) Ry(b) Rx(c), angles in radians.
inline Matrix3 rotation(double a, double b, double c) {
  const double ca = std::cos(a), sa = std::sin(a), cb = std::cos(b), sb = std::sin(b),
               cc = std::cos(c), sc = std::sin(c);
  return {{{ca * cb, ca * sb * sc - sa * cc, ca * sb * cc + sa * sc},
           {sa * cb, sa * sb * sc + ca * cc, sa * sb * cc - ca * sc},
           {-sb, cb * sc, cb * cc}}};
}

/// R T R^T.
inline Matrix3 rotate_tensor(const Matrix3& R, const Matrix3& T) {
  Matrix3 out{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k)
        for (int l = 0; l < 3; ++l) out[i][j] += R[i][k] * T[k][l] * R[j][l];
  return out;
}

}  // namespace cavern::testing
