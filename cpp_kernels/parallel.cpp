#include "parallel.hpp"

#include <omp.h>

namespace cavern {

void set_num_threads(int n) { omp_set_num_threads(n); }

int max_threads() { return omp_get_max_threads(); }

void stream_triad(double* a, const double* b, const double* c, double s, std::int64_t n) {
#pragma omp parallel for schedule(static)
  for (std::int64_t i = 0; i < n; ++i) a[i] = b[i] + s * c[i];
}

}  // namespace cavern
