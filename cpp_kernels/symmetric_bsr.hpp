// Symmetric 3x3 block CSR: only the blocks on and above the diagonal are stored.
//
// The stiffness matrix is symmetric, so half of its blocks carry no information. The
// explicit step is bound by streaming the matrix from memory; storing the upper triangle
// moves about half the bytes per product, at the price of scattered writes y_j += B^T x_i
// that stay in cache (the vectors are small next to the matrix).
#pragma once

#include <omp.h>
#if defined(__AVX2__)
#include <immintrin.h>
#endif

#include <algorithm>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "bsr.hpp"

namespace cavern {

/// The products the stepper needs of its stored stiffness (one virtual call per product).
class SymmetricProduct {
 public:
  virtual ~SymmetricProduct() = default;
  /// y = K x (x, y: 3 n values; y is overwritten); `threads` 0: as many as OpenMP would use.
  virtual void multiply(const double* x, double* y, int threads = 0) const = 0;
  /// y1 = K x1 and y2 = K x2 reading each stored block once.
  virtual void multiply_dual(const double* x1, const double* x2, double* y1, double* y2,
                             int threads = 0) const = 0;
  /// Bytes streamed per product: blocks, column indices and row pointers.
  virtual std::int64_t bytes() const = 0;
};

/// Owned upper-triangular block storage of a symmetric matrix given as a full BlockCsrView,
/// its blocks stored as Scalar (double, or float: half the block bytes; the products
/// accumulate in double, so the stored matrix is K rounded to float, exactly symmetric).
/// Row i holds its diagonal block first, then the blocks of columns j > i (sorted).
/// K x = U x + (strict U)^T x.
template <class Scalar>
class SymmetricBlockCsrT : public SymmetricProduct {
 public:
  /// Copies the blocks with column >= row from K; a row without a diagonal block (a node
  /// held by nothing but its mass) gets a zero one, so every row starts with its diagonal.
  explicit SymmetricBlockCsrT(const BlockCsrView& K) : n_(K.n_block_rows) {
    indptr_.assign(n_ + 1, 0);
    for (std::int64_t i = 0; i < n_; ++i) {
      indptr_[i + 1] = 1;  // the diagonal
      for (std::int64_t k = K.indptr[i]; k < K.indptr[i + 1]; ++k)
        if (K.indices[k] > i) ++indptr_[i + 1];
    }
    for (std::int64_t i = 0; i < n_; ++i) indptr_[i + 1] += indptr_[i];
    indices_.resize(indptr_[n_]);
    // The vector row loop reads a block's last row as 4 values: kPadding zeros after the last block.
    std::vector<double> blocks(9 * indptr_[n_] + kPadding, 0.0);
    for (std::int64_t i = 0; i < n_; ++i) {
      indices_[indptr_[i]] = static_cast<std::int32_t>(i);
      std::int64_t next = indptr_[i] + 1;  // slot indptr_[i] is the diagonal
      for (std::int64_t k = K.indptr[i]; k < K.indptr[i + 1]; ++k) {
        const std::int32_t j = K.indices[k];
        if (j < i) continue;
        const std::int64_t slot = (j == i) ? indptr_[i] : next++;
        indices_[slot] = j;
        // A repeated block (duplicate column) adds, as it does in the full product.
        for (int c = 0; c < 9; ++c) blocks[9 * slot + c] += K.blocks[9 * k + c];
      }
      // Columns after the diagonal in increasing order keep the scattered writes local.
      sort_row(i, blocks);
    }
    if constexpr (std::is_same_v<Scalar, double>)
      blocks_ = std::move(blocks);
    else
      blocks_.assign(blocks.begin(), blocks.end());  // rounded once, after the sums
  }

  std::int64_t n_block_rows() const { return n_; }
  std::int64_t n_blocks() const { return indptr_[n_]; }
  /// Bytes streamed per product: blocks, column indices and row pointers.
  std::int64_t bytes() const override {
    return static_cast<std::int64_t>((blocks_.size() - kPadding) * sizeof(Scalar) +
                                     indices_.size() * sizeof(std::int32_t) +
                                     indptr_.size() * sizeof(std::int64_t));
  }

  /// y = K x (x, y: 3 n values; y is overwritten). OpenMP over `threads` row ranges
  /// (0: as many as OpenMP would use now).
  void multiply(const double* x, double* y, int threads = 0) const override {
    product<1>(x, nullptr, y, nullptr, threads);
  }

  /// y1 = K x1 and y2 = K x2 reading each stored block once.
  void multiply_dual(const double* x1, const double* x2, double* y1, double* y2,
                     int threads = 0) const override {
    product<2>(x1, x2, y1, y2, threads);
  }

 private:
  static constexpr std::size_t kPadding = 4;

  void sort_row(std::int64_t i, std::vector<double>& all_blocks) {
    const std::int64_t begin = indptr_[i] + 1, end = indptr_[i + 1];
    std::vector<std::int64_t> order(end - begin);
    for (std::int64_t k = 0; k < end - begin; ++k) order[k] = begin + k;
    std::sort(order.begin(), order.end(),
              [&](std::int64_t a, std::int64_t b) { return indices_[a] < indices_[b]; });
    std::vector<std::int32_t> indices(order.size());
    std::vector<double> blocks(9 * order.size());
    for (std::size_t k = 0; k < order.size(); ++k) {
      indices[k] = indices_[order[k]];
      std::copy(all_blocks.data() + 9 * order[k], all_blocks.data() + 9 * order[k] + 9,
                blocks.data() + 9 * k);
    }
    std::copy(indices.begin(), indices.end(), indices_.begin() + begin);
    std::copy(blocks.begin(), blocks.end(), all_blocks.begin() + 9 * begin);
  }

  // Row ranges with about equal numbers of blocks, and for each range the columns beyond
  // it that its rows write to (held in a per-thread spill buffer, added after a barrier).
  void partition(int threads) const {
    if (threads == partition_threads_) return;
    row_start_.assign(threads + 1, n_);
    row_start_[0] = 0;
    const std::int64_t total = n_blocks();
    std::int64_t row = 0;
    for (int t = 1; t < threads; ++t) {
      const std::int64_t target = total * t / threads;
      while (row < n_ && indptr_[row] < target) ++row;
      row_start_[t] = row;
    }
    spill_end_.assign(threads, 0);
    spill_.assign(threads, {});
    for (int t = 0; t < threads; ++t) {
      std::int64_t last = row_start_[t + 1];
      for (std::int64_t i = row_start_[t]; i < row_start_[t + 1]; ++i)
        if (indptr_[i + 1] > indptr_[i]) last = std::max<std::int64_t>(last, indices_[indptr_[i + 1] - 1] + 1);
      spill_end_[t] = last;
      spill_[t].assign(3 * (last - row_start_[t + 1]), 0.0);
    }
    partition_threads_ = threads;
  }

  template <int kVectors>
  void product(const double* x1, const double* x2, double* y1, double* y2, int threads) const {
    if (threads <= 0) threads = omp_get_max_threads();
    partition(threads);
    // Two vectors share one spill buffer layout: the second half holds vector 2.
    if (kVectors == 2)
      for (int t = 0; t < threads; ++t) spill_[t].resize(6 * (spill_end_[t] - row_start_[t + 1]));
#pragma omp parallel num_threads(threads)
    {
      // A smaller team than asked (nested parallelism) falls back to one thread doing all rows.
      const int team = omp_get_num_threads();
      const int t = omp_get_thread_num();
      if (team == threads) {
        rows<kVectors>(t, x1, x2, y1, y2);
#pragma omp barrier
        add_spills<kVectors>(t, y1, y2);
      } else if (t == 0) {
        for (int s = 0; s < threads; ++s) rows<kVectors>(s, x1, x2, y1, y2);
        for (int s = 0; s < threads; ++s) add_spills<kVectors>(s, y1, y2);
      }
    }
  }

  template <int kVectors>
  void rows(int t, const double* x1, const double* x2, double* y1, double* y2) const {
    const std::int64_t r0 = row_start_[t], r1 = row_start_[t + 1];
    const std::int64_t spill_size = 3 * (spill_end_[t] - r1);
    double* spill1 = spill_[t].data();
    double* spill2 = spill1 + spill_size;
    std::fill(y1 + 3 * r0, y1 + 3 * r1, 0.0);
    if (kVectors == 2) std::fill(y2 + 3 * r0, y2 + 3 * r1, 0.0);
    std::fill(spill_[t].begin(), spill_[t].end(), 0.0);
#if defined(__AVX2__)
    if constexpr (kVectors == 1) {
      rows_avx2(r0, r1, x1, y1, spill1);
      return;
    }
#endif
    for (std::int64_t i = r0; i < r1; ++i) {
      const double* xi = x1 + 3 * i;
      const double* wi = (kVectors == 2) ? x2 + 3 * i : nullptr;
      const Scalar* d = blocks_.data() + 9 * indptr_[i];
      double a0 = y1[3 * i] + d[0] * xi[0] + d[1] * xi[1] + d[2] * xi[2];
      double a1 = y1[3 * i + 1] + d[3] * xi[0] + d[4] * xi[1] + d[5] * xi[2];
      double a2 = y1[3 * i + 2] + d[6] * xi[0] + d[7] * xi[1] + d[8] * xi[2];
      double b0 = 0.0, b1 = 0.0, b2 = 0.0;
      if constexpr (kVectors == 2) {
        b0 = y2[3 * i] + d[0] * wi[0] + d[1] * wi[1] + d[2] * wi[2];
        b1 = y2[3 * i + 1] + d[3] * wi[0] + d[4] * wi[1] + d[5] * wi[2];
        b2 = y2[3 * i + 2] + d[6] * wi[0] + d[7] * wi[1] + d[8] * wi[2];
      }
      for (std::int64_t k = indptr_[i] + 1; k < indptr_[i + 1]; ++k) {
        const Scalar* b = blocks_.data() + 9 * k;
        const std::int64_t j = indices_[k];
        const double* xj = x1 + 3 * j;
        a0 += b[0] * xj[0] + b[1] * xj[1] + b[2] * xj[2];
        a1 += b[3] * xj[0] + b[4] * xj[1] + b[5] * xj[2];
        a2 += b[6] * xj[0] + b[7] * xj[1] + b[8] * xj[2];
        // The transposed block sends row i's values to row j.
        double* target = (j < r1) ? y1 + 3 * j : spill1 + 3 * (j - r1);
        target[0] += b[0] * xi[0] + b[3] * xi[1] + b[6] * xi[2];
        target[1] += b[1] * xi[0] + b[4] * xi[1] + b[7] * xi[2];
        target[2] += b[2] * xi[0] + b[5] * xi[1] + b[8] * xi[2];
        if constexpr (kVectors == 2) {
          const double* wj = x2 + 3 * j;
          b0 += b[0] * wj[0] + b[1] * wj[1] + b[2] * wj[2];
          b1 += b[3] * wj[0] + b[4] * wj[1] + b[5] * wj[2];
          b2 += b[6] * wj[0] + b[7] * wj[1] + b[8] * wj[2];
          double* target2 = (j < r1) ? y2 + 3 * j : spill2 + 3 * (j - r1);
          target2[0] += b[0] * wi[0] + b[3] * wi[1] + b[6] * wi[2];
          target2[1] += b[1] * wi[0] + b[4] * wi[1] + b[7] * wi[2];
          target2[2] += b[2] * wi[0] + b[5] * wi[1] + b[8] * wi[2];
        }
      }
      y1[3 * i] = a0;
      y1[3 * i + 1] = a1;
      y1[3 * i + 2] = a2;
      if constexpr (kVectors == 2) {
        y2[3 * i] = b0;
        y2[3 * i + 1] = b1;
        y2[3 * i + 2] = b2;
      }
    }
  }

#if defined(__AVX2__)
  // Four stored values as doubles (float blocks widened: the sums stay in double).
  static __m256d load4(const double* p) { return _mm256_loadu_pd(p); }
  static __m256d load4(const float* p) { return _mm256_cvtps_pd(_mm_loadu_ps(p)); }

  // rows() for one vector with AVX2: a block's rows B_r are loaded as 4 values
  // (the 4th is the next row's first, multiplied but never summed or stored). Row i gathers
  // (B_r0 x_j0, B_r1 x_j1, B_r2 x_j2) per lane over its blocks and sums the lanes at its end;
  // the transposed block sends B^T x_i = sum_r B_r x_ir to row j as 2 + 1 values (plain loads
  // and stores, which the next read of the same row receives from the store buffer). The sums
  // are the same products, added in another order than the scalar loop's (round-off only).
  void rows_avx2(std::int64_t r0, std::int64_t r1, const double* x, double* y, double* spill) const {
    const __m256i first3 = _mm256_setr_epi64x(-1, -1, -1, 0);
    const Scalar* all = blocks_.data();
    for (std::int64_t i = r0; i < r1; ++i) {
      const __m256d xi = _mm256_maskload_pd(x + 3 * i, first3);
      const __m256d xi0 = _mm256_set1_pd(x[3 * i]);
      const __m256d xi1 = _mm256_set1_pd(x[3 * i + 1]);
      const __m256d xi2 = _mm256_set1_pd(x[3 * i + 2]);
      const Scalar* d = all + 9 * indptr_[i];
      __m256d row0 = _mm256_mul_pd(load4(d), xi);
      __m256d row1 = _mm256_mul_pd(load4(d + 3), xi);
      __m256d row2 = _mm256_mul_pd(load4(d + 6), xi);
      for (std::int64_t k = indptr_[i] + 1; k < indptr_[i + 1]; ++k) {
        const Scalar* b = all + 9 * k;
        const std::int64_t j = indices_[k];
        const __m256d b0 = load4(b), b1 = load4(b + 3), b2 = load4(b + 6);
        // x_j as 4 values, the 4th from the next node (masked at the last node: no read past x).
        const __m256d xj = (j + 1 < n_) ? _mm256_loadu_pd(x + 3 * j) : _mm256_maskload_pd(x + 3 * j, first3);
        row0 = _mm256_add_pd(row0, _mm256_mul_pd(b0, xj));
        row1 = _mm256_add_pd(row1, _mm256_mul_pd(b1, xj));
        row2 = _mm256_add_pd(row2, _mm256_mul_pd(b2, xj));
        const __m256d sent = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(b0, xi0), _mm256_mul_pd(b1, xi1)),
                                           _mm256_mul_pd(b2, xi2));
        double* target = (j < r1) ? y + 3 * j : spill + 3 * (j - r1);
        _mm_storeu_pd(target, _mm_add_pd(_mm_loadu_pd(target), _mm256_castpd256_pd128(sent)));
        _mm_store_sd(target + 2, _mm_add_sd(_mm_load_sd(target + 2), _mm256_extractf128_pd(sent, 1)));
      }
      alignas(32) double s0[4], s1[4], s2[4];
      _mm256_store_pd(s0, row0);
      _mm256_store_pd(s1, row1);
      _mm256_store_pd(s2, row2);
      y[3 * i] += s0[0] + s0[1] + s0[2];
      y[3 * i + 1] += s1[0] + s1[1] + s1[2];
      y[3 * i + 2] += s2[0] + s2[1] + s2[2];
    }
  }
#endif

  // Thread t adds what the row ranges before it wrote beyond themselves into its rows.
  template <int kVectors>
  void add_spills(int t, double* y1, double* y2) const {
    const std::int64_t r0 = row_start_[t], r1 = row_start_[t + 1];
    for (int s = 0; s < t; ++s) {
      const std::int64_t begin = std::max(r0, row_start_[s + 1]);
      const std::int64_t end = std::min(r1, spill_end_[s]);
      const std::int64_t spill_size = 3 * (spill_end_[s] - row_start_[s + 1]);
      const double* spill1 = spill_[s].data() - 3 * row_start_[s + 1];
      for (std::int64_t d = 3 * begin; d < 3 * end; ++d) y1[d] += spill1[d];
      if constexpr (kVectors == 2) {
        const double* spill2 = spill1 + spill_size;
        for (std::int64_t d = 3 * begin; d < 3 * end; ++d) y2[d] += spill2[d];
      }
    }
  }

  std::int64_t n_;
  std::vector<std::int64_t> indptr_;
  std::vector<std::int32_t> indices_;
  std::vector<Scalar> blocks_;
  mutable int partition_threads_ = 0;
  mutable std::vector<std::int64_t> row_start_;
  mutable std::vector<std::int64_t> spill_end_;
  mutable std::vector<std::vector<double>> spill_;
};

using SymmetricBlockCsr = SymmetricBlockCsrT<double>;
using SymmetricBlockCsrSingle = SymmetricBlockCsrT<float>;

}  // namespace cavern
