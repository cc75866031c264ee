#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "bsr.hpp"
#include "random_system.hpp"

using namespace cavern;
using namespace cavern::testing;

namespace {

// Non-symmetric random blocks on a random pattern, so a transposed block would be caught.
BlockSystem random_nonsymmetric_system(std::int64_t n_nodes, std::uint64_t seed) {
  std::mt19937_64 generator(seed);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  BlockSystem system;
  system.n_nodes = n_nodes;
  const std::int64_t n_dofs = 3 * n_nodes;
  system.dense.assign(n_dofs * n_dofs, 0.0);
  std::vector<char> pattern(n_nodes * n_nodes, 0);
  for (std::int64_t i = 0; i < n_nodes; ++i)
    for (std::int64_t j = 0; j < n_nodes; ++j) {
      if (i != j && uniform(generator) < 0.4) continue;  // keep about 30 % of the blocks
      pattern[i * n_nodes + j] = 1;
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c)
          system.dense[(3 * i + r) * n_dofs + 3 * j + c] = uniform(generator);
    }
  compress(system, pattern);
  return system;
}

double max_abs_difference(const std::vector<double>& a, const std::vector<double>& b) {
  double largest = 0.0;
  for (std::size_t k = 0; k < a.size(); ++k) largest = std::max(largest, std::abs(a[k] - b[k]));
  return largest;
}

}  // namespace

TEST(BlockCsr, SpmvEqualsDenseProduct) {
  const BlockSystem system = random_nonsymmetric_system(23, 7);
  std::mt19937_64 generator(3);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::vector<double> x(system.n_dofs()), y(system.n_dofs());
  for (double& value : x) value = uniform(generator);
  spmv(system.view(), x.data(), y.data());
  const std::vector<double> expected = dense_product(system, x);
  EXPECT_LT(max_abs_difference(y, expected), 1e-13);
  EXPECT_GT(max_abs_difference(expected, std::vector<double>(x.size(), 0.0)), 0.1);
}

TEST(BlockCsr, DualSpmvEqualsTwoDenseProducts) {
  const BlockSystem system = random_nonsymmetric_system(17, 11);
  std::mt19937_64 generator(5);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::vector<double> x1(system.n_dofs()), x2(system.n_dofs()), y1(system.n_dofs()),
      y2(system.n_dofs());
  for (double& value : x1) value = uniform(generator);
  for (double& value : x2) value = uniform(generator);
  spmv_dual(system.view(), x1.data(), x2.data(), y1.data(), y2.data());
  EXPECT_LT(max_abs_difference(y1, dense_product(system, x1)), 1e-13);
  EXPECT_LT(max_abs_difference(y2, dense_product(system, x2)), 1e-13);
}
