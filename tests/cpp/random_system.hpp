// Small random block-sparse systems for the kernel tests, kept as dense and block-CSR copies.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "bsr.hpp"

namespace cavern::testing {

/// A 3x3-block matrix stored both densely (n_dofs x n_dofs, row-major) and as block CSR with
/// every block that is structurally present (possibly numerically zero).
struct BlockSystem {
  std::int64_t n_nodes = 0;
  std::vector<double> dense;
  std::vector<std::int64_t> indptr;
  std::vector<std::int32_t> indices;
  std::vector<double> blocks;
  std::vector<double> mass;

  BlockCsrView view() const { return {n_nodes, indptr.data(), indices.data(), blocks.data()}; }
  std::int64_t n_dofs() const { return 3 * n_nodes; }
};

/// Block CSR of the given block pattern (pattern[i*n+j] != 0 keeps block (i, j)) from `dense`.
inline void compress(BlockSystem& system, const std::vector<char>& pattern) {
  const std::int64_t n = system.n_nodes;
  const std::int64_t n_dofs = 3 * n;
  system.indptr.assign(1, 0);
  system.indices.clear();
  system.blocks.clear();
  for (std::int64_t i = 0; i < n; ++i) {
    for (std::int64_t j = 0; j < n; ++j) {
      if (!pattern[i * n + j]) continue;
      system.indices.push_back(static_cast<std::int32_t>(j));
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c)
          system.blocks.push_back(system.dense[(3 * i + r) * n_dofs + 3 * j + c]);
    }
    system.indptr.push_back(static_cast<std::int64_t>(system.indices.size()));
  }
}

/// Random symmetric positive definite K: a sum over random node pairs of [[S, -S], [-S, S]]
/// with S = B B^T, plus a grounding B B^T at every node; lumped masses in [1, 2].
inline BlockSystem random_spd_system(std::int64_t n_nodes, int links_per_node, std::uint64_t seed) {
  std::mt19937_64 generator(seed);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::uniform_int_distribution<std::int64_t> pick(0, n_nodes - 1);
  BlockSystem system;
  system.n_nodes = n_nodes;
  const std::int64_t n_dofs = 3 * n_nodes;
  system.dense.assign(n_dofs * n_dofs, 0.0);
  std::vector<char> pattern(n_nodes * n_nodes, 0);

  auto random_psd = [&](double S[9]) {
    double B[9];
    for (double& b : B) b = uniform(generator);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c)
        S[3 * r + c] =
            B[3 * r] * B[3 * c] + B[3 * r + 1] * B[3 * c + 1] + B[3 * r + 2] * B[3 * c + 2];
  };
  auto add_block = [&](std::int64_t i, std::int64_t j, const double S[9], double sign) {
    pattern[i * n_nodes + j] = 1;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c)
        system.dense[(3 * i + r) * n_dofs + 3 * j + c] += sign * S[3 * r + c];
  };
  double S[9];
  for (std::int64_t i = 0; i < n_nodes; ++i) {
    random_psd(S);
    add_block(i, i, S, 1.0);
    for (int link = 0; link < links_per_node; ++link) {
      const std::int64_t j = pick(generator);
      if (j == i) continue;
      random_psd(S);
      add_block(i, i, S, 1.0);
      add_block(j, j, S, 1.0);
      add_block(i, j, S, -1.0);
      add_block(j, i, S, -1.0);
    }
  }
  compress(system, pattern);
  std::uniform_real_distribution<double> mass(1.0, 2.0);
  for (std::int64_t i = 0; i < n_nodes; ++i) system.mass.push_back(mass(generator));
  return system;
}

/// y = A x for the dense copy.
inline std::vector<double> dense_product(const BlockSystem& system, const std::vector<double>& x) {
  const std::int64_t n = system.n_dofs();
  std::vector<double> y(n, 0.0);
  for (std::int64_t r = 0; r < n; ++r)
    for (std::int64_t c = 0; c < n; ++c) y[r] += system.dense[r * n + c] * x[c];
  return y;
}

/// max_k |a_k - b_k| / max_k |b_k|: the largest difference relative to the reference b.
inline double max_relative_difference(const std::vector<double>& a, const std::vector<double>& b) {
  double difference = 0.0, norm = 0.0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    difference = std::max(difference, std::abs(a[k] - b[k]));
    norm = std::max(norm, std::abs(b[k]));
  }
  return difference / norm;
}

/// Node p of a system split into p and p' = n (the last node), as at an interface: p's diagonal
/// block halved on each side, each coupling block kept at p or moved to p' (side), p's mass
/// divided 30/70. A bonded pair (p, p') must then reproduce the merged system.
inline BlockSystem split_node(const BlockSystem& merged, std::int64_t p, const std::vector<char>& to_copy) {
  const std::int64_t n = merged.n_nodes, nd = 3 * n, sd = 3 * (n + 1);
  BlockSystem split;
  split.n_nodes = n + 1;
  split.dense.assign(sd * sd, 0.0);
  std::vector<char> pattern((n + 1) * (n + 1), 0);
  for (std::int64_t a = 0; a < n; ++a)
    for (std::int64_t b = 0; b < n; ++b) {
      bool present = false;
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) present |= merged.dense[(3 * a + r) * nd + 3 * b + c] != 0.0;
      if (!present) continue;
      auto put = [&](std::int64_t A, std::int64_t B, double scale) {
        pattern[A * (n + 1) + B] = 1;
        for (int r = 0; r < 3; ++r)
          for (int c = 0; c < 3; ++c)
            split.dense[(3 * A + r) * sd + 3 * B + c] += scale * merged.dense[(3 * a + r) * nd + 3 * b + c];
      };
      const std::int64_t side_b = to_copy[b] ? n : p, side_a = to_copy[a] ? n : p;
      if (a == p && b == p) {
        put(p, p, 0.5);
        put(n, n, 0.5);
      } else if (a == p) {
        put(side_b, b, 1.0);
      } else if (b == p) {
        put(a, side_a, 1.0);
      } else {
        put(a, b, 1.0);
      }
    }
  compress(split, pattern);
  split.mass = merged.mass;
  split.mass.push_back(0.7 * merged.mass[p]);
  split.mass[p] *= 0.3;
  return split;
}

}  // namespace cavern::testing
