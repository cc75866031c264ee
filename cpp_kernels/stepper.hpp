// Explicit central-difference time stepping in velocity-Verlet form with implicit per-node
// damping, force providers and an exact discrete energy balance (docs/method.md section 4).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "bsr.hpp"
#include "contact.hpp"
#include "force_provider.hpp"
#include "state_archive.hpp"
#include "internal_force.hpp"
#include "nodal_effects.hpp"
#include "stepping_base.hpp"
#include "symmetric_bsr.hpp"

namespace cavern {

struct StepperParameters {
  double dt = 0.0;     // time step (s)
  double alpha = 0.0;  // mass-proportional Rayleigh coefficient (1/s), implicit per node
  double beta = 0.0;   // stiffness-proportional Rayleigh coefficient (s), explicit on v_{n+1/2}
  // true: the stepper keeps the upper triangle of K (about half the bytes streamed per step)
  // and pass B reads K u from a buffer; false: pass B is fused with the full block-CSR product.
  bool symmetric_storage = true;
  /// true: the upper triangle's blocks are stored as float (half the block bytes; the state,
  /// the products' sums and the energy account stay double; the stepped matrix is K rounded to
  /// float, exactly symmetric, so the energy identity holds for it). Needs symmetric_storage.
  bool single_precision_blocks = false;
};

/// Below this many block rows a loop runs on one thread: the two barriers a step costs more
/// than the work they share (measured: tiny systems ran 80x slower on two busy cores).
constexpr std::int64_t kMinRowsForThreads = 4096;

/// Energy terms of the current state (J). balance = total - initial - external_work +
/// damping_work - contact_work + internal_dissipation is zero to round-off for a linear problem
/// with symmetric K, and with internal-force components whose laws close their own account
/// (materials/material_law.hpp).
struct EnergyReport {
  double kinetic = 0.0;        // 1/2 v.Mv
  double strain = 0.0;         // 1/2 u.Ku
  double total = 0.0;          // H_n (+ internal_stored with components)
  double initial = 0.0;        // H_0 (+ internal_stored at the reset)
  double external_work = 0.0;  // trapezoid integral of f_ext . v
  double damping_work = 0.0;   // trapezoid integral of d . v (dissipated)
  double contact_work =
      0.0;  // trapezoid integral of sum_pairs R.(v_i - v_j) (work done on the mesh)
  double friction_dissipation = 0.0;  // sum over slipping steps of T.(slip increment), >= 0
  bool has_internal = false;          // internal-force components present
  double internal_stored = 0.0;       // sum of the components' stored energy Psi_n
  double internal_dissipation = 0.0;  // their dissipation since the reset
  double internal_work = 0.0;         // W_int = sum 1/2 (g_n + g_{n+1}).(u_{n+1} - u_n)
  double balance = 0.0;
  std::vector<std::string> provider_names;
  std::vector<double> provider_work;  // each provider's share of external_work
};

/// Velocity-Verlet central difference for M a + d(v) + K u = f_ext(t), lumped M.
/// Per step, from (u_n, v_n, a_n) at t_n:
///   pass A (per dof):  v_{n+1/2} = v_n + dt/2 a_n,  u_{n+1} = u_n + dt v_{n+1/2}
///   providers:         f = f_ext(t_{n+1})
///   pass B (per node, fused with the SpMV):
///     r = f - K (u_{n+1} + beta v_{n+1/2})
///     (M (1 + dt/2 alpha) I + dt/2 C_i) v_{n+1} = M v_{n+1/2} + dt/2 r
///     a_{n+1} = (r - (alpha M + C_i) v_{n+1}) / M
/// Energy (leapfrog M (v_{n+1/2} - v_{n-1/2}) = dt (F_n - K u_n) with F the non-stiffness force
/// f_ext - d, d = (alpha M + C) v_n + beta K v_{n-1/2}):
///   E_{n+1/2} = 1/2 v_{n+1/2}.M v_{n+1/2} + 1/2 u_n.K u_{n+1} grows by dt F_n.v_n, so
///   H_n = E_{n+1/2} - dt/2 F_n.v_n = 1/2 v.Mv + 1/2 u.Ku - dt^2/8 a.Ma + dt^2/4 F.a
///   obeys H_{n+1} - H_n = dt/2 (F_n.v_n + F_{n+1}.v_{n+1}) exactly (K symmetric).
/// Contact (optional, after pass B): ContactPairs::correct adds R to r of the pair nodes and
/// updates their v_{n+1}, a_{n+1}; R is then one more non-stiffness force in F (H_n and the
/// trapezoid work contact_work), and the pass-B energy sums of the pair nodes are corrected by
/// the difference of their contributions after and before the correction.
/// Internal-force components (optional, internal_force.hpp; none: not one extra operation per
/// node): g(u) = sum_components f_int(u) joins the stiffness,
///     r = f - K (u_{n+1} + beta v_{n+1/2}) - g(u_{n+1}) - beta K0 v_{n+1/2},
/// each component computing its trial state at u_{n+1} after pass A and committing it after
/// the step; K0 is the components' initial elastic stiffness (the damping their cells would
/// get in the matrix), a damping force in d. With G = K u + g, the leapfrog gives for any g
/// (no symmetry or linearity needed)
///   K_n = 1/2 v_n.M v_n - dt^2/8 a_n.M a_n = 1/2 v_{n+1/2}.M v_{n-1/2},
///   K_{n+1} - K_n + 1/2 (G_n + G_{n+1}).(u_{n+1} - u_n) = dt/2 (F_n + F_{n+1}).v_{n+1/2}
///     = dt/2 (F_n.v_n + F_{n+1}.v_{n+1}) - dt^2/4 (F_{n+1}.a_{n+1} - F_n.a_n).
/// The K part of the G term is 1/2 u.Ku |_n^{n+1} exactly; the g part is the internal work by
/// the trapezoid rule in displacement,
///     W_int += 1/2 (g_n + g_{n+1}).(u_{n+1} - u_n) = dt/2 (g_n + g_{n+1}).v_{n+1/2}
/// (g_n.v_{n+1/2} summed in pass A, g_{n+1}.v_{n+1/2} after the components), so
/// H_n + W_int - W_ext + W_damp - W_contact is constant to round-off. Per point W_int is the
/// trapezoid sum of (sigma - sigma0) : d eps; the balance reported uses the laws' stored energy
/// Psi and dissipation D instead,
///     balance = H_n + Psi_n - (H_0 + Psi_0) - W_ext + W_damp - W_contact + D,
/// which is round-off when Psi_n - Psi_0 + D = W_int (elastic laws, and the rules of
/// materials/material_law.hpp) and otherwise shows the law's own energy error.
/// The stiffness, mass and providers are borrowed; u, v, a are modified in place.
class Stepper : public SteppingBase {
 public:
  /// Throws std::invalid_argument for a non-positive mass or dt, or negative alpha, beta.
  Stepper(const BlockCsrView& stiffness, const double* mass, const StepperParameters& parameters);

  // set_dashpots, set_constraints, reactions, phase_times, n_nodes, n_owned_nodes: SteppingBase.
  // Dashpots: (M(1 + dt/2 alpha) I + dt/2 C)^-1 precomputed per node; constraints: u, v, a of a
  // constrained node must start in the range of P (zero for the held components).

  /// Changes the mass-proportional damping coefficient alpha (1/s, finite, >= 0) for the
  /// following steps (the static stage's dynamic relaxation adapts it to the lowest frequency,
  /// pyfem/static.py). The energy account keeps running; its damping work uses the new alpha.
  /// Throws std::invalid_argument for a bad alpha.
  void set_mass_damping(double alpha);

  /// Adds a force provider (shared: the caller may keep and query it).
  void add_provider(std::shared_ptr<ForceProvider> provider);

  /// Adds an internal-force component (shared: the caller may keep and query it). Its cells
  /// must not be in the stiffness matrix. The energy account restarts at the next run() unless
  /// reset_energy is called after this. Throws std::invalid_argument for a node outside the model.
  /// count_energy = false: its forces act but its stored energy and dissipation are left out of
  /// the account (an MPI rank's copy of cells another rank owns and counts, docs/scaling.md).
  void add_internal_force(std::shared_ptr<InternalForceComponent> component,
                          bool count_energy = true);

  /// One MPI rank's share of a distributed model (docs/scaling.md): its first n_owned nodes are
  /// its own, the rest ghosts whose rows it computes but does not keep. The energy account then
  /// sums over the owned nodes only (the ranks' accounts add up to the model's), and after each
  /// step `exchange` (null: none) overwrites the ghosts' v and a with their owners'. Dashpots,
  /// constraints, providers and pairs must be on owned nodes: run() and reset_energy() throw
  /// std::invalid_argument naming the first one on a ghost (a provider whose nodes() is empty
  /// is not listed and cannot be checked). Throws std::invalid_argument for n_owned outside
  /// [0, n_nodes].
  void set_partition(std::int64_t n_owned, std::shared_ptr<NodeExchange> exchange);

  /// Attaches the interlayer contact pairs (shared). Throws std::invalid_argument for a pair node
  /// outside the model, a pair joining a node to itself, or a second ContactPairs.
  void set_contact(std::shared_ptr<ContactPairs> contact);

  /// Advances (u, v, a) (3 n_nodes each, in place) by n_steps from t0; returns t0 + n_steps dt.
  /// Starts the energy account from this state if reset_energy was never called.
  double run(double* u, double* v, double* a, std::int64_t n_steps, double t0);

  /// Sets H_0 from the state (u, v, a) at t0 and zeroes the accumulated work. H_0 uses
  /// F_0 = M a_0 + K u_0 + g(u_0) (exact for any a_0); the damping power at t0 is
  /// (f_ext(t0) - F_0).v_0, which is the damping force's power whenever a_0 came from this
  /// scheme. Components compute g(u_0) and Psi_0 without committing (their state is unchanged).
  void reset_energy(const double* u, const double* v, const double* a, double t0);

  EnergyReport energy() const;

  /// The complete state a run needs to continue bit for bit from the state (u, v, a) it has
  /// reached (checkpoint, docs/checkpoint.md): the energy account, the last internal force and
  /// reactions, the contact pairs' and every component's state. u, v, a and t are the caller's.
  void save_state(StateArchive& archive) const;
  /// Restores save_state's archive into a stepper built from the same scene (same dt, alpha,
  /// beta, dofs, providers, pairs and components, in the same order). Throws
  /// std::invalid_argument naming the first block that does not fit.
  void load_state(const StateArchive& archive);

  double dt() const { return parameters_.dt; }

 private:
  void nodal_effects_changed(bool constraints) override;
  // With a partition: throws unless dashpots, constraints, listed providers and pairs are on
  // owned nodes (set_partition); once until an effect or the partition changes.
  void check_partition();
  template <bool kStiffnessDamping, bool kSymmetric, bool kInternal>
  void pass_b(double* u, double* v, double* a);
  template <bool kInternal>
  void dispatch_pass_b(double* u, double* v, double* a);
  // Pass A with components: also returns g_n.v_{n+1/2}, zeroes g for the next compute and,
  // with beta, fills internal_damping_ with the components' beta K0 v_{n+1/2}.
  double pass_a_with_internal(double* u, double* v, const double* a);
  // One step's components: compute g(u_{n+1}) into internal_force_ (before pass B); returns
  // their stored energy.
  double compute_internal_forces(const double* u);
  // Dissipation of the components whose energy this account counts.
  double counted_dissipation() const;
  // g.v with g = internal_force_ (owned dofs).
  double internal_power(const double* v) const;
  void accumulate_work(const double* v);
  void contact_post_pass(double t, const double* u, double* v, double* a);
  ImplicitNodeOperators implicit_operators() const;
  // What a checkpoint must match: dt, alpha, beta, dofs, providers, components, contact.
  std::vector<double> checkpoint_parameters() const;
  // The energy account's scalars in one order for save_state and load_state (pointers to const
  // for a const Stepper).
  template <class Self>
  static auto energy_terms(Self& self) {
    return std::array{&self.initial_energy_,    &self.twice_kinetic_,      &self.twice_strain_,
                      &self.acceleration_term_, &self.external_work_,      &self.damping_work_,
                      &self.external_power_,    &self.damping_power_,      &self.contact_work_,
                      &self.contact_power_,     &self.friction_dissipation_, &self.internal_work_,
                      &self.internal_power_,    &self.internal_stored_,    &self.internal_dissipation_,
                      &self.dissipation_at_reset_};
  }
  // Slots of the nodes with a dashpot or a constraint, and per slot the inverse of the implicit
  // velocity system (restricted to the free directions for a constrained node).
  void build_implicit_slots();

  std::unique_ptr<SymmetricProduct> symmetric_;  // owned upper triangle, when symmetric_storage
  std::vector<double> Ku_, Kv_;                   // K u_{n+1}, K v_{n+1/2} for the symmetric path
  bool threaded_ = true;                          // n_nodes >= kMinRowsForThreads
  StepperParameters parameters_;

  // Per node its slot (-1: none) and per slot C, the inverse of the implicit 3x3 system and the
  // constraint (-1: none), from effects_.
  std::vector<std::int32_t> dashpot_slot_;
  std::vector<double> dashpot_C_;              // (slots, 9)
  std::vector<double> dashpot_inverse_;        // (slots, 9)
  std::vector<std::int32_t> constraint_of_slot_;  // (slots) constraint index or -1

  std::shared_ptr<ContactPairs> contact_;  // null: no contact, no cost
  std::vector<std::shared_ptr<InternalForceComponent>> components_;  // empty: no cost
  std::vector<char> component_counted_;  // per component: its energy is in this account
  bool partition_checked_ = false;       // the effects were found on owned nodes (check_partition)
  std::shared_ptr<NodeExchange> exchange_;
  std::vector<double> internal_force_;  // g (3 n_nodes) of the last compute, with components
  std::vector<double> internal_damping_;  // beta K0 v_{n+1/2} of the components, when beta != 0
  std::vector<double> contact_scratch_;    // (unique pair nodes, 6): v, a before the correction

  // Scratch, allocated once: external forces (zeroed again by pass B as it reads them) and,
  // for beta != 0, a copy of v_{n+1/2} that pass B reads while overwriting v.
  std::vector<double> external_force_;
  std::vector<double> v_half_;

  // Energy account.
  bool energy_started_ = false;
  double initial_energy_ = 0.0;
  double twice_kinetic_ = 0.0;      // v.Mv
  double twice_strain_ = 0.0;       // u.Ku
  double acceleration_term_ = 0.0;  // -dt^2/8 a.Ma + dt^2/4 F.a
  double external_work_ = 0.0;
  double damping_work_ = 0.0;
  double external_power_ = 0.0;  // f_ext.v at the current step
  double damping_power_ = 0.0;   // d.v at the current step
  double contact_work_ = 0.0;
  double contact_power_ = 0.0;  // sum_pairs R.(v_i - v_j) at the current step
  double friction_dissipation_ = 0.0;
  double internal_work_ = 0.0;
  double internal_power_ = 0.0;  // g_{n+1}.v_{n+1/2} of the current step
  double internal_stored_ = 0.0;       // Psi_n
  double internal_dissipation_ = 0.0;  // D since the reset
  double dissipation_at_reset_ = 0.0;  // sum of the components' dissipation() at the reset
  std::vector<double> provider_work_;
  std::vector<double> provider_power_;
};

}  // namespace cavern
