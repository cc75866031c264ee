// Sum factorisation of the Q2 hexahedron's gradients at its 3 x 3 x 3 Gauss points
// (docs/ARCHITECTURE.md "Kernel", element loop). The 27 basis functions are products
// l_a(X) l_b(Y) l_c(Z) of the 1D quadratic Lagrange functions on the nodes 0, 1/2, 1 and the
// points are the products of the 1D Gauss points, so the reference gradient of a nodal field
//   dU/dX (g1, g2, g3) = sum_{a,b,c} l_a'(g1) l_b(g2) l_c(g3) U(a, b, c)
// is three 3 x 3 contractions, one per axis, instead of a 27 x 27 product: 8 contractions of
// 81 multiply-adds per field component (648) against 2187 for the dense gradients, and the
// same for the transposed sum that gives the nodal forces. Used by HexahedronElements when the
// geometry is given in this form (internal_force.hpp); the cell's own Jacobian is applied at
// each point.
#pragma once

#include <cstdint>

namespace cavern {

/// The tensor structure of one Q2 cell type: where each lexicographic node and point is in the
/// element's own numbering, and the 1D tables. Lexicographic index = 9 i_X + 3 i_Y + i_Z.
struct TensorQ2 {
  std::int32_t node_order[27];   // local basis index of lexicographic node (a, b, c)
  std::int32_t point_order[27];  // quadrature point index of lexicographic point (g1, g2, g3)
  double basis[9];               // [g][n] = l_n(g) at the 1D Gauss points
  double derivative[9];          // [g][n] = l_n'(g) (1 / reference length)
};

namespace tensor_q2 {

// out = M applied along `axis` of the 3 x 3 x 3 array in (out[.. g ..] = sum_n M[g][n] in[.. n ..]);
// kTranspose: out[.. n ..] = sum_g M[g][n] in[.. g ..]. kAdd adds to out instead of writing it.
template <int kAxis, bool kTranspose, bool kAdd>
inline void contract(const double* M, const double* in, double* out) {
  constexpr int stride = kAxis == 0 ? 9 : (kAxis == 1 ? 3 : 1);
  // The two other axes, as (outer, inner) strides.
  constexpr int outer = kAxis == 0 ? 3 : 9;
  constexpr int inner = kAxis == 2 ? 3 : 1;
  double m[3][3];  // m[out index][in index]
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) m[r][c] = kTranspose ? M[3 * c + r] : M[3 * r + c];
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) {
      const int base = a * outer + b * inner;
      const double x0 = in[base], x1 = in[base + stride], x2 = in[base + 2 * stride];
      for (int r = 0; r < 3; ++r) {
        const double sum = m[r][0] * x0 + m[r][1] * x1 + m[r][2] * x2;
        double& target = out[base + r * stride];
        target = kAdd ? target + sum : sum;
      }
    }
}

}  // namespace tensor_q2

/// Reference gradients of a nodal field: gradient[m][p] = dU/dX_m at lexicographic point p, from
/// U at the lexicographic nodes (27 values).
inline void tensor_q2_gradient(const TensorQ2& t, const double* U, double gradient[3][27]) {
  using tensor_q2::contract;
  const double* B = t.basis;
  const double* D = t.derivative;
  double zB[27], zD[27], yBzB[27], yDzB[27], yBzD[27];
  contract<2, false, false>(B, U, zB);
  contract<2, false, false>(D, U, zD);
  contract<1, false, false>(B, zB, yBzB);
  contract<1, false, false>(D, zB, yDzB);
  contract<1, false, false>(B, zD, yBzD);
  contract<0, false, false>(D, yBzB, gradient[0]);
  contract<0, false, false>(B, yDzB, gradient[1]);
  contract<0, false, false>(B, yBzD, gradient[2]);
}

/// The transpose: nodal[n] = sum_p sum_m dphi_n/dX_m(p) flux[m][p] (lexicographic n and p).
inline void tensor_q2_divergence(const TensorQ2& t, const double flux[3][27], double* nodal) {
  using tensor_q2::contract;
  const double* B = t.basis;
  const double* D = t.derivative;
  double pX[27], pY[27], pZ[27], wB[27], wD[27];
  contract<0, true, false>(D, flux[0], pX);
  contract<0, true, false>(B, flux[1], pY);
  contract<0, true, false>(B, flux[2], pZ);
  contract<1, true, false>(B, pX, wB);
  contract<1, true, true>(D, pY, wB);
  contract<1, true, false>(B, pZ, wD);
  contract<2, true, false>(B, wB, nodal);
  contract<2, true, true>(D, wD, nodal);
}

}  // namespace cavern
