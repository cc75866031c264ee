// Rock bolts and anchor cables embedded in the rock mesh (docs/method.md "Rock bolts and
// cables"): one group of bolts of the same kind, each a chain of two-node axial bar segments tied
// to the rock by its grout only.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "internal_force.hpp"
#include "state_archive.hpp"

namespace cavern {

/// Material and solver parameters of one support group (SI units).
struct BoltParameters {
  double axial_stiffness = 0.0;   // EA (N), > 0
  double yield_force = 0.0;       // N, > 0: perfectly plastic at +-yield_force (tension and compression)
  double bond_stiffness = 0.0;    // N/m per m of bolt, > 0
  double bond_strength = 0.0;     // N/m, > 0: perfectly plastic slip beyond it
  double pretension = 0.0;        // N, >= 0: initial axial force of the free length's segments
  double free_length = 0.0;       // m, >= 0: ungrouted length from the head
  double head_stiffness = 0.0;    // N/m, >= 0: spring tying the head node to the rock (0: no plate)
  double tolerance = 1e-12;       // relative residual of each bolt's equilibrium
  int max_iterations = 200;
};

/// Arrays describing the bolts of one group (GroutedBolts copies them).
///   bolt_offsets (b + 1): bolt j has the bolt nodes [bolt_offsets[j], bolt_offsets[j + 1]), at
///     least 2, head first;
///   arc_length (m): s of each bolt node from its head, strictly increasing along a bolt;
///   directions (b, 3): unit axis of each (straight) bolt, head to tip;
///   host_nodes, host_weights (m, k): the rock nodes and interpolation weights N_a(x) of the host
///     cell at each bolt node (padding: weight 0 on any valid node).
struct BoltGeometry {
  std::int64_t n_bolts = 0;
  std::int64_t n_host = 0;  // k
  const std::int64_t* bolt_offsets = nullptr;
  const double* arc_length = nullptr;
  const double* directions = nullptr;
  const std::int32_t* host_nodes = nullptr;
  const double* host_weights = nullptr;
};

/// A group of grouted bolts / cables as an internal-force component.
///
/// Each bolt's own axial displacements w_k are condensed: massless, they are solved at every
/// compute() from the rock's axial displacement at the bolt nodes, ubar_k = d . sum_a N_a u_a,
/// by minimising the bolt's incremental potential (bar segments with return mapping, bond
/// springs lumped at the nodes with tributary grouted length L_k, the head spring) with Newton
/// and a backtracking line search on a tridiagonal system, to `tolerance`. The force on the
/// rock node a is -sum_k N_a F_k d (F_k the bond force, plus the head spring's); f_int is its
/// negative. The bolts add no mass and do not enter the stable time step.
class GroutedBolts : public InternalForceComponent {
 public:
  /// Throws std::invalid_argument for a bad parameter or geometry (naming it).
  GroutedBolts(const BoltGeometry& geometry, const BoltParameters& parameters);

  InternalEnergy compute(const double* u, double* out_force) override;
  void commit() override;
  void add_stiffness_damping(const double* v, double beta, double* out_force) override;
  void rebase() override;
  void save_state(StateArchive& archive, const std::string& prefix) const override;
  void load_state(const StateArchive& archive, const std::string& prefix) override;
  double stored_energy() const override { return stored_energy_; }
  double dissipation() const override { return dissipation_; }
  void check_nodes(std::int64_t n_nodes) const override;
  std::string name() const override { return "GroutedBolts"; }
  /// The host nodes of every bolt node, sorted.
  const std::vector<std::int32_t>& nodes() const override { return unique_nodes_; }

  std::int64_t n_bolts() const { return geometry_.n_bolts; }
  std::int64_t n_bolt_nodes() const { return n_nodes_; }
  std::int64_t n_segments() const { return n_nodes_ - geometry_.n_bolts; }
  /// Committed axial force of each segment (N, tension positive), bolt by bolt.
  const std::vector<double>& axial_force() const { return axial_force_; }
  /// Largest |axial force| of each segment over the commits (N).
  const std::vector<double>& peak_axial_force() const { return peak_axial_force_; }
  /// Committed bond slip w_k - ubar_k of each bolt node (m, total, along d).
  std::vector<double> bond_slip() const;
  /// Committed plastic bond slip of each bolt node (m).
  const std::vector<double>& plastic_slip() const { return plastic_slip_; }
  /// Committed plastic strain of each segment.
  const std::vector<double>& plastic_strain() const { return plastic_strain_; }
  /// Committed bolt displacements w_k (m, along d, total).
  const std::vector<double>& bolt_displacement() const { return w_; }
  /// Tributary grouted length of each bolt node (m).
  const std::vector<double>& bond_length() const { return bond_length_; }
  /// Newton iterations of the last compute(), summed over the bolts.
  std::int64_t last_iterations() const { return last_iterations_; }

 private:
  struct Trial;
  // Solves bolt j at the rock axial displacements ubar (its nodes), from w (updated in place);
  // writes the trial forces and state of its nodes/segments. Returns the iterations.
  int solve_bolt(std::int64_t j, const double* ubar, double* w, double* segment_force,
                 double* segment_plastic, double* bond_force, double* bond_plastic) const;
  void rock_axial(const double* u, std::vector<double>& ubar) const;
  // d . sum_a N_a field_a: the axial component of a nodal field (3 n) at bolt node k.
  double axial_at(std::int64_t k, const double* d, const double* field) const;
  // Adds N_a s d to out_force at each host node a of bolt node k (a tie force s along d).
  void spread(std::int64_t k, const double* d, double s, double* out_force) const;

  BoltGeometry geometry_;  // points into the owned copies below
  std::vector<std::int64_t> owned_offsets_;
  std::vector<double> owned_arc_length_, owned_directions_, owned_host_weights_;
  std::vector<std::int32_t> owned_host_nodes_;
  BoltParameters parameters_;
  std::int64_t n_nodes_ = 0;
  std::vector<double> segment_length_;   // per segment, bolt by bolt
  std::vector<double> initial_force_;    // per segment: pretension in the free length
  std::vector<double> bond_length_;      // per bolt node
  std::vector<std::int32_t> unique_nodes_;

  // Committed state.
  std::vector<double> w_, plastic_strain_, plastic_slip_, axial_force_, bond_force_;
  std::vector<double> ubar_, peak_axial_force_;
  double stored_energy_ = 0.0, dissipation_ = 0.0;
  // Reference of a rebased run: rock axial displacement, bond force and head force at u = 0,
  // and the total stored energy there.
  std::vector<double> ubar_reference_, bond_force_reference_;
  double stored_reference_ = 0.0;

  // Trial state of the last compute().
  std::vector<double> trial_w_, trial_plastic_strain_, trial_plastic_slip_, trial_axial_force_,
      trial_bond_force_, trial_ubar_;
  double trial_stored_ = 0.0, trial_dissipation_increment_ = 0.0;
  bool has_trial_ = false;
  std::int64_t last_iterations_ = 0;
};

}  // namespace cavern
