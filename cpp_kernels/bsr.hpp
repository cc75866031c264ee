// 3x3 block compressed-sparse-row view of the stiffness matrix and its products.
#pragma once

#include <cstdint>

namespace cavern {

/// Borrowed view of a square matrix stored as 3x3 blocks in CSR order.
/// Block row i holds blocks k in [indptr[i], indptr[i+1]), block column indices[k],
/// entries blocks[9k + 3r + c] (row-major). Nothing is owned.
struct BlockCsrView {
  std::int64_t n_block_rows = 0;
  const std::int64_t* indptr = nullptr;   // (n_block_rows + 1)
  const std::int32_t* indices = nullptr;  // (nnzb)
  const double* blocks = nullptr;         // (nnzb, 3, 3)

  std::int64_t n_blocks() const { return indptr[n_block_rows]; }
};

/// Row i of y = K x:  y_i = sum_k B_k x_{indices[k]}  (3 values written to row_product).
inline void block_row_product(const BlockCsrView& K, std::int64_t i, const double* x,
                              double row_product[3]) {
  double y0 = 0.0, y1 = 0.0, y2 = 0.0;
  for (std::int64_t k = K.indptr[i]; k < K.indptr[i + 1]; ++k) {
    const double* b = K.blocks + 9 * k;
    const double* xj = x + 3 * static_cast<std::int64_t>(K.indices[k]);
    y0 += b[0] * xj[0] + b[1] * xj[1] + b[2] * xj[2];
    y1 += b[3] * xj[0] + b[4] * xj[1] + b[5] * xj[2];
    y2 += b[6] * xj[0] + b[7] * xj[1] + b[8] * xj[2];
  }
  row_product[0] = y0;
  row_product[1] = y1;
  row_product[2] = y2;
}

/// Row i of the pair y1 = K x1, y2 = K x2, reading each block of K once.
inline void block_row_product_dual(const BlockCsrView& K, std::int64_t i, const double* x1,
                                   const double* x2, double row_product1[3],
                                   double row_product2[3]) {
  double y0 = 0.0, y1 = 0.0, y2 = 0.0, z0 = 0.0, z1 = 0.0, z2 = 0.0;
  for (std::int64_t k = K.indptr[i]; k < K.indptr[i + 1]; ++k) {
    const double* b = K.blocks + 9 * k;
    const std::int64_t j = 3 * static_cast<std::int64_t>(K.indices[k]);
    const double* xj = x1 + j;
    const double* wj = x2 + j;
    y0 += b[0] * xj[0] + b[1] * xj[1] + b[2] * xj[2];
    y1 += b[3] * xj[0] + b[4] * xj[1] + b[5] * xj[2];
    y2 += b[6] * xj[0] + b[7] * xj[1] + b[8] * xj[2];
    z0 += b[0] * wj[0] + b[1] * wj[1] + b[2] * wj[2];
    z1 += b[3] * wj[0] + b[4] * wj[1] + b[5] * wj[2];
    z2 += b[6] * wj[0] + b[7] * wj[1] + b[8] * wj[2];
  }
  row_product1[0] = y0;
  row_product1[1] = y1;
  row_product1[2] = y2;
  row_product2[0] = z0;
  row_product2[1] = z1;
  row_product2[2] = z2;
}

/// y = K x  (x, y: 3 * n_block_rows values; OpenMP over block rows).
void spmv(const BlockCsrView& K, const double* x, double* y);

/// y1 = K x1 and y2 = K x2 in one pass over the blocks of K.
void spmv_dual(const BlockCsrView& K, const double* x1, const double* x2, double* y1, double* y2);

}  // namespace cavern
