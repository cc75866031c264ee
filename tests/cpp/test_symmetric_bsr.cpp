#include <gtest/gtest.h>
#include <omp.h>

#include <cmath>
#include <limits>
#include <utility>
#include <vector>

#include "bsr.hpp"
#include "random_system.hpp"
#include "symmetric_bsr.hpp"

using namespace cavern;
using namespace cavern::testing;

namespace {

std::vector<double> random_vector(std::int64_t n, unsigned seed) {
  std::mt19937_64 generator(seed);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::vector<double> x(n);
  for (double& value : x) value = uniform(generator);
  return x;
}

// K with integer entries (every summation order exact, in double and float): symmetric diagonal
// blocks and, per coupling (i, j), i < j, a nonsymmetric block A with K_ij = A, K_ji = A^T.
BlockSystem integer_system(std::int64_t n, const std::vector<std::pair<int, int>>& couplings) {
  BlockSystem system;
  system.n_nodes = n;
  const std::int64_t n_dofs = 3 * n;
  system.dense.assign(n_dofs * n_dofs, 0.0);
  std::vector<char> pattern(n * n, 0);
  for (std::int64_t i = 0; i < n; ++i) {
    pattern[i * n + i] = 1;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) system.dense[(3 * i + r) * n_dofs + 3 * i + c] = 1 + r + c + i;
  }
  for (std::size_t p = 0; p < couplings.size(); ++p) {
    const auto [i, j] = couplings[p];
    pattern[i * n + j] = pattern[j * n + i] = 1;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) {
        const double value = 1 + 3 * r + c + 9 * static_cast<int>(p);  // A_rc != A_cr
        system.dense[(3 * i + r) * n_dofs + 3 * j + c] = value;
        system.dense[(3 * j + c) * n_dofs + 3 * i + r] = value;
      }
  }
  compress(system, pattern);
  return system;
}

}  // namespace

// Nonsymmetric off-diagonal blocks, so y_j += B^T x_i is told apart from B x_i; node 4 (the last)
// coupled to 0, 2 and 3 (x_j read masked, the last stored block reading the padding); with 2
// threads rows [0, 2) and with 3 threads rows [0, 1) and [1, 3) write through the spill buffers.
// Integer entries: exact for double and float blocks, single and dual products, any thread count.
TEST(SymmetricBlockCsr, NonsymmetricBlocksLastNodeAndSpillsAreExact) {
  const BlockSystem system = integer_system(5, {{0, 1}, {0, 4}, {1, 2}, {2, 4}, {3, 4}});
  std::vector<double> x(system.n_dofs()), w(system.n_dofs());
  for (std::int64_t d = 0; d < system.n_dofs(); ++d) {
    x[d] = static_cast<double>(d % 5) - 2.0;
    w[d] = static_cast<double>(d % 3) + 1.0;
  }
  const auto expected = dense_product(system, x);
  const auto expected_w = dense_product(system, w);
  const SymmetricBlockCsr upper(system.view());
  const SymmetricBlockCsrSingle single(system.view());
  for (int threads : {1, 2, 3}) {
    std::vector<double> y(system.n_dofs(), 99.0), y_single(system.n_dofs(), 99.0);
    std::vector<double> y1(system.n_dofs(), 99.0), y2(system.n_dofs(), 99.0);
    upper.multiply(x.data(), y.data(), threads);
    single.multiply(x.data(), y_single.data(), threads);
    upper.multiply_dual(x.data(), w.data(), y1.data(), y2.data(), threads);
    EXPECT_EQ(y, expected) << threads << " threads";
    EXPECT_EQ(y_single, expected) << threads << " threads";
    EXPECT_EQ(y1, expected) << threads << " threads";
    EXPECT_EQ(y2, expected_w) << threads << " threads";
  }
}

// The 4th lane of the vector loads (the next node's x, the next row's block value, the padding)
// never reaches y: NaN at node 2, coupled to nothing, leaves rows 0 and 1 exact.
TEST(SymmetricBlockCsr, FourthLaneNeverReachesTheResult) {
  const BlockSystem system = integer_system(3, {{0, 1}});
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::vector<double> x = {1, -2, 3, 2, 1, -1, nan, nan, nan};
  const std::vector<double> clean = {1, -2, 3, 2, 1, -1, 0, 0, 0};
  const auto expected = dense_product(system, clean);
  const SymmetricBlockCsr upper(system.view());
  const SymmetricBlockCsrSingle single(system.view());
  for (int threads : {1, 2}) {
    std::vector<double> y(9, 99.0), y_single(9, 99.0);
    upper.multiply(x.data(), y.data(), threads);
    single.multiply(x.data(), y_single.data(), threads);
    for (int d = 0; d < 6; ++d) {
      EXPECT_EQ(y[d], expected[d]) << d << ", " << threads << " threads";
      EXPECT_EQ(y_single[d], expected[d]) << d << ", " << threads << " threads";
    }
    EXPECT_TRUE(std::isnan(y[6]));
  }
}

// The symmetric product equals the full block product for 1, 2 and 3 threads (the spill
// buffers of lower row ranges must reach the rows of higher ones).
TEST(SymmetricBlockCsr, EqualsFullProductForAnyThreadCount) {
  const BlockSystem system = random_spd_system(400, 6, 7);
  const SymmetricBlockCsr upper(system.view());
  EXPECT_LT(upper.n_blocks(), system.view().n_blocks());
  const auto x = random_vector(system.n_dofs(), 1);
  const auto w = random_vector(system.n_dofs(), 2);
  std::vector<double> full(system.n_dofs()), full_w(system.n_dofs());
  spmv(system.view(), x.data(), full.data());
  spmv(system.view(), w.data(), full_w.data());
  int checks = 0;
  const int saved = omp_get_max_threads();
  for (int threads : {1, 2, 3}) {
    omp_set_num_threads(threads);
    std::vector<double> y(system.n_dofs(), 99.0), y1(system.n_dofs(), 99.0), y2(system.n_dofs(), 99.0);
    upper.multiply(x.data(), y.data());
    upper.multiply_dual(x.data(), w.data(), y1.data(), y2.data());
    EXPECT_LT(max_relative_difference(y, full), 1e-13) << threads << " threads";
    EXPECT_LT(max_relative_difference(y1, full), 1e-13) << threads << " threads";
    EXPECT_LT(max_relative_difference(y2, full_w), 1e-13) << threads << " threads";
    checks += 3;
  }
  omp_set_num_threads(saved);
  EXPECT_EQ(checks, 9);
}

// A node coupled to nothing (no blocks at all in its row) gets a zero diagonal block.
TEST(SymmetricBlockCsr, RowWithoutBlocksGivesZero) {
  const std::vector<std::int64_t> indptr = {0, 1, 1, 2};
  const std::vector<std::int32_t> indices = {0, 2};
  const std::vector<double> blocks = {2, 0, 0, 0, 2, 0, 0, 0, 2, 3, 0, 0, 0, 3, 0, 0, 0, 3};
  const SymmetricBlockCsr upper(BlockCsrView{3, indptr.data(), indices.data(), blocks.data()});
  EXPECT_EQ(upper.n_blocks(), 3);
  const std::vector<double> x = {1, 1, 1, 5, 5, 5, 1, 1, 1};
  std::vector<double> y(9, 99.0);
  upper.multiply(x.data(), y.data(), 1);
  const std::vector<double> expected = {2, 2, 2, 0, 0, 0, 3, 3, 3};
  EXPECT_EQ(y, expected);
}

// Float blocks: the product is that of K rounded to float (each block entry to the nearest
// float), summed in double: equal to the double product within float rounding (~6e-8 of the
// entries), the same for any thread count up to the order of the spilled sums, half the block bytes.
TEST(SymmetricBlockCsr, SinglePrecisionBlocksAreTheMatrixRoundedToFloat) {
  const BlockSystem system = random_spd_system(400, 6, 11);
  const SymmetricBlockCsr upper(system.view());
  const SymmetricBlockCsrSingle single(system.view());
  const auto x = random_vector(system.n_dofs(), 3);
  // The reference: the full matrix with every entry rounded to float, multiplied in double.
  BlockCsrView view = system.view();
  std::vector<double> rounded(view.blocks, view.blocks + 9 * view.n_blocks());
  for (double& value : rounded) value = static_cast<double>(static_cast<float>(value));
  BlockCsrView rounded_view = view;
  rounded_view.blocks = rounded.data();
  std::vector<double> exact(system.n_dofs()), reference(system.n_dofs());
  spmv(view, x.data(), exact.data());
  spmv(rounded_view, x.data(), reference.data());
  const int saved = omp_get_max_threads();
  std::vector<double> first;
  for (int threads : {1, 2, 3}) {
    omp_set_num_threads(threads);
    std::vector<double> y(system.n_dofs(), 99.0);
    single.multiply(x.data(), y.data());
    EXPECT_LT(max_relative_difference(y, reference), 1e-13) << threads << " threads";
    const double rounding = max_relative_difference(y, exact);
    EXPECT_GT(rounding, 0.0);  // the float storage is used, not a double copy
    EXPECT_LT(rounding, 1e-6);
    // Thread counts change only the order in which the spilled transposed blocks are added.
    if (first.empty())
      first = y;
    else
      EXPECT_LT(max_relative_difference(y, first), 1e-14) << threads << " threads";
  }
  omp_set_num_threads(saved);
  EXPECT_LT(single.bytes(), upper.bytes());
  EXPECT_EQ(upper.bytes() - single.bytes(),
            static_cast<std::int64_t>(9 * upper.n_blocks() * (sizeof(double) - sizeof(float))));
}
