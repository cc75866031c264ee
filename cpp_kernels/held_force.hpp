// A constant nodal force as a force provider: the static stage's loads and its hand-over force
// (the out-of-balance g = F_held - f_int(sigma_static) the dynamic run holds, pyfem/static.py).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "force_provider.hpp"

namespace cavern {

/// f_i(t) = s(t) F_i at nodes i, with s = 1 (ramp = 0) or the smoothstep s = 3 x^2 - 2 x^3,
/// x = clamp(t / ramp, 0, 1): 0 until t = 0, 1 from t = ramp on, zero slope at both ends (the
/// cubic Hermite of the values 0, 1 and slopes 0, 0 over [0, ramp]).
class HeldForce : public ForceProvider {
 public:
  /// nodes (k), forces (k, 3) copied. Throws std::invalid_argument for a non-finite force or
  /// ramp, a negative ramp, or a node listed twice.
  HeldForce(const std::int32_t* nodes, std::int64_t count, const double* forces, double ramp)
      : nodes_(nodes, nodes + count), forces_(forces, forces + 3 * count), ramp_(ramp),
        node_forces_(3 * count, 0.0) {
    if (!(std::isfinite(ramp) && ramp >= 0.0))
      throw std::invalid_argument("ramp = " + std::to_string(ramp) + " must be finite and >= 0");
    for (std::int64_t k = 0; k < 3 * count; ++k)
      if (!std::isfinite(forces_[k]))
        throw std::invalid_argument("forces[" + std::to_string(k / 3) + "] is not finite");
    std::vector<std::int32_t> sorted = nodes_;
    std::sort(sorted.begin(), sorted.end());
    for (std::size_t k = 1; k < sorted.size(); ++k)
      if (sorted[k] == sorted[k - 1])
        throw std::invalid_argument("node " + std::to_string(sorted[k]) +
                                    " is listed twice; give its force once");
  }

  /// The factor s(t) of the forces.
  double factor(double t) const {
    if (ramp_ == 0.0) return 1.0;
    const double x = std::min(std::max(t / ramp_, 0.0), 1.0);
    return -2.0 * x * x * x + 3.0 * x * x;
  }

  void add_forces(double t, const double*, const double*, double* f) override {
    const double s = factor(t);
    for (std::size_t k = 0; k < forces_.size(); ++k) node_forces_[k] = s * forces_[k];
    for (std::size_t k = 0; k < nodes_.size(); ++k) {
      double* fi = f + 3 * static_cast<std::int64_t>(nodes_[k]);
      fi[0] += node_forces_[3 * k];
      fi[1] += node_forces_[3 * k + 1];
      fi[2] += node_forces_[3 * k + 2];
    }
  }

  double power(const double* v) const override {
    double total = 0.0;
    for (std::size_t k = 0; k < nodes_.size(); ++k) {
      const double* vi = v + 3 * static_cast<std::int64_t>(nodes_[k]);
      total += node_forces_[3 * k] * vi[0] + node_forces_[3 * k + 1] * vi[1] +
               node_forces_[3 * k + 2] * vi[2];
    }
    return total;
  }

  void check_nodes(std::int64_t n_nodes) const override {
    for (std::size_t k = 0; k < nodes_.size(); ++k)
      if (nodes_[k] < 0 || nodes_[k] >= n_nodes)
        throw std::invalid_argument("held force nodes[" + std::to_string(k) + "] = " +
                                    std::to_string(nodes_[k]) + " is not a node in [0, " +
                                    std::to_string(n_nodes) + ")");
  }

  std::string name() const override { return "held_force"; }
  std::vector<std::int32_t> nodes() const override { return nodes_; }

 private:
  std::vector<std::int32_t> nodes_;
  std::vector<double> forces_;  // (k, 3)
  double ramp_;
  std::vector<double> node_forces_;  // (k, 3) of the last add_forces call
};

}  // namespace cavern
