#include "bsr.hpp"

namespace cavern {

void spmv(const BlockCsrView& K, const double* x, double* y) {
#pragma omp parallel for schedule(static)
  for (std::int64_t i = 0; i < K.n_block_rows; ++i) block_row_product(K, i, x, y + 3 * i);
}

void spmv_dual(const BlockCsrView& K, const double* x1, const double* x2, double* y1, double* y2) {
#pragma omp parallel for schedule(static)
  for (std::int64_t i = 0; i < K.n_block_rows; ++i)
    block_row_product_dual(K, i, x1, x2, y1 + 3 * i, y2 + 3 * i);
}

}  // namespace cavern
