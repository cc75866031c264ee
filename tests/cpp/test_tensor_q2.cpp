// Sum factorisation of the Q2 hexahedron (tensor_q2.hpp): the gradients at the Gauss points
// equal the dense products of the 3D basis tables, and the divergence is their exact transpose.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "tensor_q2.hpp"

using namespace cavern;

namespace {

// Lexicographic numbering (node_order, point_order the identity) and the 1D tables of the
// quadratic Lagrange functions on 0, 1/2, 1 at the 3-point Gauss rule on [0, 1].
TensorQ2 lexicographic_q2() {
  TensorQ2 t{};
  for (int j = 0; j < 27; ++j) t.node_order[j] = t.point_order[j] = j;
  const double nodes[3] = {0.0, 0.5, 1.0};
  const double r = std::sqrt(0.6);
  const double gauss[3] = {0.5 * (1.0 - r), 0.5, 0.5 * (1.0 + r)};
  for (int g = 0; g < 3; ++g)
    for (int n = 0; n < 3; ++n) {
      const double a = nodes[(n + 1) % 3], b = nodes[(n + 2) % 3];
      const double scale = (nodes[n] - a) * (nodes[n] - b);
      t.basis[3 * g + n] = (gauss[g] - a) * (gauss[g] - b) / scale;
      t.derivative[3 * g + n] = (2.0 * gauss[g] - a - b) / scale;
    }
  return t;
}

// d phi_n / d X_m at point p from the 1D tables, the dense 3D table.
double dense_gradient(const TensorQ2& t, int p, int n, int m) {
  const int point[3] = {p / 9, (p / 3) % 3, p % 3}, node[3] = {n / 9, (n / 3) % 3, n % 3};
  double value = 1.0;
  for (int axis = 0; axis < 3; ++axis)
    value *= (axis == m ? t.derivative : t.basis)[3 * point[axis] + node[axis]];
  return value;
}

}  // namespace

TEST(TensorQ2, GradientAndDivergenceEqualTheDenseTables) {
  const TensorQ2 t = lexicographic_q2();
  std::mt19937_64 generator(3);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  double U[27], flux[3][27];
  for (double& x : U) x = unit(generator);
  for (auto& row : flux)
    for (double& x : row) x = unit(generator);
  double gradient[3][27], divergence[27];
  tensor_q2_gradient(t, U, gradient);
  tensor_q2_divergence(t, flux, divergence);
  for (int m = 0; m < 3; ++m)
    for (int p = 0; p < 27; ++p) {
      double expected = 0.0;
      for (int n = 0; n < 27; ++n) expected += dense_gradient(t, p, n, m) * U[n];
      EXPECT_NEAR(gradient[m][p], expected, 1e-13);
    }
  for (int n = 0; n < 27; ++n) {
    double expected = 0.0;
    for (int m = 0; m < 3; ++m)
      for (int p = 0; p < 27; ++p) expected += dense_gradient(t, p, n, m) * flux[m][p];
    EXPECT_NEAR(divergence[n], expected, 1e-13);
  }
  // A linear field X + 2 Y - 3 Z (nodal values) has the gradient (1, 2, -3) at every point.
  for (int n = 0; n < 27; ++n) U[n] = 0.5 * (n / 9) + 2.0 * 0.5 * ((n / 3) % 3) - 3.0 * 0.5 * (n % 3);
  tensor_q2_gradient(t, U, gradient);
  for (int p = 0; p < 27; ++p) {
    EXPECT_NEAR(gradient[0][p], 1.0, 1e-14);
    EXPECT_NEAR(gradient[1][p], 2.0, 1e-14);
    EXPECT_NEAR(gradient[2][p], -3.0, 1e-14);
  }
}
