#include "stable_step.hpp"

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

namespace cavern {

double gershgorin_bound(const BlockCsrView& K, const double* mass) {
  double bound = 0.0;
#pragma omp parallel for schedule(static) reduction(max : bound)
  for (std::int64_t i = 0; i < K.n_block_rows; ++i) {
    double row_sums[3] = {0.0, 0.0, 0.0};
    for (std::int64_t k = K.indptr[i]; k < K.indptr[i + 1]; ++k) {
      const double* b = K.blocks + 9 * k;
      for (int r = 0; r < 3; ++r)
        row_sums[r] += std::abs(b[3 * r]) + std::abs(b[3 * r + 1]) + std::abs(b[3 * r + 2]);
    }
    const double largest = std::max({row_sums[0], row_sums[1], row_sums[2]});
    bound = std::max(bound, largest / mass[i]);
  }
  return bound;
}

double power_iteration(const BlockCsrView& K, const double* mass, int iterations,
                       std::uint64_t seed) {
  const std::int64_t n_dofs = 3 * K.n_block_rows;
  std::vector<double> x(n_dofs), scaled(n_dofs), y(n_dofs), inverse_sqrt_mass(K.n_block_rows);
  for (std::int64_t i = 0; i < K.n_block_rows; ++i) inverse_sqrt_mass[i] = 1.0 / std::sqrt(mass[i]);

  std::mt19937_64 generator(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  double norm2 = 0.0;
  for (double& value : x) {
    value = normal(generator);
    norm2 += value * value;
  }
  double scale = 1.0 / std::sqrt(norm2);
  for (double& value : x) value *= scale;

  double estimate = 0.0;
  for (int iteration = 0; iteration < iterations; ++iteration) {
    // y = M^-1/2 K M^-1/2 x with x of unit length.
    for (std::int64_t d = 0; d < n_dofs; ++d) scaled[d] = inverse_sqrt_mass[d / 3] * x[d];
    spmv(K, scaled.data(), y.data());
    double rayleigh = 0.0, y_norm2 = 0.0;
#pragma omp parallel for schedule(static) reduction(+ : rayleigh, y_norm2)
    for (std::int64_t d = 0; d < n_dofs; ++d) {
      y[d] *= inverse_sqrt_mass[d / 3];
      rayleigh += x[d] * y[d];
      y_norm2 += y[d] * y[d];
    }
    estimate = rayleigh;
    if (y_norm2 == 0.0) break;  // x in the null space of K: nothing more to learn
    scale = 1.0 / std::sqrt(y_norm2);
    for (std::int64_t d = 0; d < n_dofs; ++d) x[d] = y[d] * scale;
  }
  return estimate;
}

}  // namespace cavern
