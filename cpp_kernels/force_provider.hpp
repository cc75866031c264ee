// Interface of everything that adds nodal forces other than the stiffness (MFEM-style operator
// pieces that the stepper sums; an effect a scene does not call for is not in the list).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace cavern {

class ForceProvider {
 public:
  virtual ~ForceProvider() = default;

  /// Adds this provider's nodal forces at time t into f (3 * n_nodes, dof = 3 node + component).
  /// u, v: the state the forces may depend on (the stepper passes u_{n+1} and v_{n+1/2}).
  /// Must write only its own nodes and must remember its forces for power().
  virtual void add_forces(double t, const double* u, const double* v, double* f) = 0;

  /// Power sum_nodes f_node . v_node of the forces added by the last add_forces call,
  /// against the velocity v (3 * n_nodes). The stepper integrates it by the trapezoid rule
  /// into this provider's work.
  virtual double power(const double* v) const = 0;

  /// Throws std::invalid_argument naming the first node index outside [0, n_nodes).
  virtual void check_nodes(std::int64_t n_nodes) const = 0;

  /// Short name used in the energy report.
  virtual std::string name() const = 0;

  /// The nodes this provider writes (empty: not listed; LocalStepper needs them).
  virtual std::vector<std::int32_t> nodes() const { return {}; }
};

}  // namespace cavern
