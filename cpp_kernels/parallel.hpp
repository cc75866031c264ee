// Thread control and a memory-bandwidth probe for benchmarks.
#pragma once

#include <cstdint>

namespace cavern {

/// Sets the number of OpenMP threads used by later kernel calls (n >= 1).
void set_num_threads(int n);

/// Number of OpenMP threads a parallel region would use now.
int max_threads();

/// STREAM triad a[i] = b[i] + s c[i] (24 bytes moved per element), OpenMP static.
void stream_triad(double* a, const double* b, const double* c, double s, std::int64_t n);

}  // namespace cavern
