// The nodal effects of a stepper, written once for global and local stepping: boundary dashpots
// (3x3 per node, summed where faces meet) and kinematic constraints (a projection per node).
#pragma once

#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "constraints.hpp"

namespace cavern {

/// Validated dashpots and constraints of a model's nodes. Both setters give the strong guarantee:
/// on a bad entry they throw std::invalid_argument naming it, and nothing changes.
///
/// Dashpots: node i's C is the sum of the entries given for i, in the order given (faces meeting at
/// a node each add their share). Slots are numbered in the order of first appearance.
/// Constraints: one entry per node, P the projection onto the held directions (constraints.hpp).
struct NodalEffects {
  std::vector<std::int32_t> dashpot_slot;     // (n_nodes) slot of a node's C, -1: none
  std::vector<double> dashpot_C;              // (slots, 9) summed C, row-major
  std::vector<std::int32_t> constraint_slot;  // (n_nodes) index into constraint_P, -1: free
  std::vector<std::int32_t> constraint_nodes; // (constraints) in the order given
  std::vector<double> constraint_P;           // (constraints, 9)

  explicit NodalEffects(std::int64_t n_nodes = 0)
      : dashpot_slot(n_nodes, -1), constraint_slot(n_nodes, -1) {}

  std::int64_t n_nodes() const { return static_cast<std::int64_t>(dashpot_slot.size()); }
  std::int64_t n_constraints() const { return static_cast<std::int64_t>(constraint_nodes.size()); }
  bool has_dashpots() const { return !dashpot_C.empty(); }

  void set_dashpots(const std::int32_t* nodes, std::int64_t count, const double* C) {
    std::vector<std::int32_t> slot(n_nodes(), -1);
    std::vector<double> summed;
    for (std::int64_t k = 0; k < count; ++k) {
      const std::int32_t node = require_node("dashpot", nodes, k);
      if (slot[node] < 0) {
        slot[node] = static_cast<std::int32_t>(summed.size() / 9);
        summed.resize(summed.size() + 9, 0.0);
      }
      double* target = summed.data() + 9 * slot[node];
      for (int c = 0; c < 9; ++c) target[c] += C[9 * k + c];
    }
    for (std::int64_t node = 0; node < n_nodes(); ++node) {
      if (slot[node] < 0) continue;
      const double* Ci = summed.data() + 9 * slot[node];
      double scale = 0.0;
      for (int c = 0; c < 9; ++c) scale = std::max(scale, std::abs(Ci[c]));
      for (int r = 0; r < 3; ++r)
        for (int c = r + 1; c < 3; ++c)
          if (!(std::abs(Ci[3 * r + c] - Ci[3 * c + r]) <= 1e-10 * scale))
            throw std::invalid_argument("dashpot C at node " + std::to_string(node) +
                                        " is not symmetric (or not finite)");
    }
    dashpot_slot = std::move(slot);
    dashpot_C = std::move(summed);
  }

  void set_constraints(const std::int32_t* nodes, std::int64_t count, const double* projection) {
    std::vector<std::int32_t> slot(n_nodes(), -1);
    for (std::int64_t k = 0; k < count; ++k) {
      const std::int32_t node = require_node("constraint", nodes, k);
      if (slot[node] >= 0)
        throw std::invalid_argument("constraint nodes[" + std::to_string(k) + "] = " +
                                    std::to_string(node) +
                                    " is listed twice; combine its held directions in one P");
      check_projection(projection + 9 * k, k);
      slot[node] = static_cast<std::int32_t>(k);
    }
    constraint_slot = std::move(slot);
    constraint_nodes.assign(nodes, nodes + count);
    constraint_P.assign(projection, projection + 9 * count);
  }

  /// Throws naming the first dashpot or constraint on a node >= n_owned (a ghost of a share).
  void require_owned(std::int64_t n_owned) const {
    for (std::int64_t i = n_owned; i < n_nodes(); ++i) {
      if (dashpot_slot[i] >= 0) throw ghost_error("a dashpot", i, n_owned);
      if (constraint_slot[i] >= 0) throw ghost_error("a constraint", i, n_owned);
    }
  }

  static std::invalid_argument ghost_error(const std::string& what, std::int64_t node,
                                           std::int64_t n_owned) {
    return std::invalid_argument(what + " at node " + std::to_string(node) +
                                 ", a ghost of this share (owned nodes: [0, " +
                                 std::to_string(n_owned) +
                                 ")): a share's effects must be on its own nodes");
  }

 private:
  std::int32_t require_node(const char* what, const std::int32_t* nodes, std::int64_t k) const {
    const std::int32_t node = nodes[k];
    if (node < 0 || node >= n_nodes())
      throw std::invalid_argument(std::string(what) + " nodes[" + std::to_string(k) + "] = " +
                                  std::to_string(node) + " is not a node in [0, " +
                                  std::to_string(n_nodes()) + ")");
    return node;
  }
};

/// The implicit per-node operator of a half step h/2 with mass-proportional damping alpha and the
/// node's dashpot C (nullptr: none): A = M (1 + h/2 alpha) I + h/2 C, and its inverse (with the
/// node's constraint projection P, nullptr: free, the inverse of P A P on the free directions,
/// constraints.hpp). Throws naming the node when A is not positive definite or the constrained
/// system is singular. Returns A in `A_out` (9) and the inverse in `inverse` (9).
inline void implicit_node_operator(double mass, double alpha, double half_step, const double* C,
                                   const double* P, std::int64_t node, double* A_out,
                                   double* inverse) {
  double A[9] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
  if (C != nullptr)
    for (int c = 0; c < 9; ++c) A[c] = half_step * C[c];
  const double diagonal = mass * (1.0 + half_step * alpha);
  A[0] += diagonal;
  A[4] += diagonal;
  A[8] += diagonal;
  // (M (1 + h/2 alpha) I + h/2 C) is positive definite iff C is not too negative.
  const double minor2 = A[0] * A[4] - A[1] * A[3];
  const double determinant = invert_3x3(A, inverse);
  if (!(A[0] > 0.0 && minor2 > 0.0 && determinant > 0.0))
    throw std::invalid_argument("dashpot C at node " + std::to_string(node) +
                                " is not positive semi-definite");
  if (P != nullptr && !constrained_inverse(A, P, inverse))
    throw std::invalid_argument("constraint at node " + std::to_string(node) +
                                ": the implicit system is singular in the free directions");
  for (int c = 0; c < 9; ++c) A_out[c] = A[c];
}

}  // namespace cavern
