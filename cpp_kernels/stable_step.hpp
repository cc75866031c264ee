// Bounds and estimates of the largest eigenvalue omega_max^2 of M^-1 K (critical time step
// dt_crit = 2 / omega_max for the undamped central difference).
#pragma once

#include <cstdint>

#include "bsr.hpp"

namespace cavern {

/// Gershgorin bound on the spectrum of M^-1 K (lumped mass m per node, 3 dofs per node):
///   omega_max^2 <= max over dof rows r of node i of (1/m_i) sum_c |K_rc|.
/// Guaranteed upper bound (docs/method.md section 4, critical step).
double gershgorin_bound(const BlockCsrView& K, const double* mass);

/// Power iteration on the symmetric form S = M^-1/2 K M^-1/2 from a seeded random start:
///   x <- S x / |S x|, estimate = x . S x (Rayleigh quotient, <= omega_max^2 for symmetric K).
/// Returns the Rayleigh quotient of the last iterate.
double power_iteration(const BlockCsrView& K, const double* mass, int iterations,
                       std::uint64_t seed);

}  // namespace cavern
