// Multi-rate explicit stepping (local time stepping) for M a + d(v) + K u = f_ext(t), lumped M:
// the scheme of docs/local_stepping.md (multi-level by recursion, velocity-Verlet kicks and drifts; a
// coarser level's force reaches finer nodes as kicks at the ends of its step, the impulse form of
// multiple time stepping, not Diaz & Grote's force held over the substeps: docs/local_stepping.md "The
// column split" for what that costs in stress where levels meet): the linear part (stiffness, mass-proportional damping, dashpots, force
// providers) split by columns, element-loop components (nonlinear cells) split by cells, each at
// its own level, contact pairs corrected before their nodes' drifts, fixed and roller nodes
// projected at every kick.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "bsr.hpp"
#include "contact.hpp"
#include "force_provider.hpp"
#include "internal_force.hpp"
#include "nodal_effects.hpp"
#include "state_archive.hpp"
#include "stepper.hpp"
#include "stepping_base.hpp"

namespace cavern {

/// Each node has a rate level k >= 0 (0: the finest rate, step dt_fine; k: dt_fine 2^k). With
/// L the largest level, one global step is Delta t = dt_fine 2^L; with c = L - k (0: coarsest) the
/// step is the recursion S(0, Delta t, t) of
///
///   S(c, h, t):  v += h/2 M^-1 F_c                   (start kick: the last end kick's force, FSAL;
///                                                     own nodes add their damping at the current v)
///                u += h v   on the nodes whose velocity only level-c kicks change
///                if c < L: S(c+1, h/2, t), S(c+1, h/2, t + h/2)
///                end kick at t + h: v += h/2 a_c with a_c from the level-c force at the new u,
///
/// where the level-c force on node i is -sum over the columns j of level c of K_ij u_j (the
/// stiffness split by columns), plus, on the nodes of level c themselves, f_ext(t + h) and the
/// damping -(alpha M + C_i) v: explicit at the velocity the node has at the start kick (other
/// levels' kicks may have changed it since its last end kick), implicit in the end kick as in
/// Stepper's pass B:
///   (M (1 + h/2 alpha) I + h/2 C_i) v_new = M v + h/2 r,  a = (r - (alpha M + C_i) v_new) / M.
/// With one level this is Stepper's step (tests/cpp/test_local_stepper.cpp). Second order, and
/// stable up to the global scheme's bound when every level's step is within its own cells' bound
/// (the levels of pyfem/local_stepping.py put a node at the finest rate of its cells: the one-cell
/// overlap of Diaz & Grote); checked on the user's model at set-up by iterating this map from a
/// random state (pyfem/local_stepping.py check_stability).
///
/// Energy: kinetic and strain energy of the state and the external and damping work by the
/// trapezoid rule at each node's own kicks. The scheme conserves a modified energy, not this
/// plain one: the reported balance oscillates at O(dt^2) (bounded), it is not round-off.
class LocalStepper : public SteppingBase {
 public:
  /// K borrowed (full block CSR, symmetric), mass borrowed; node_level (n_nodes) copied. The
  /// largest level L is the nodes' largest, or max_level if given (>= 0: an MPI rank's share steps
  /// the whole model's levels, set_partition). Throws std::invalid_argument for a non-positive mass
  /// or dt_fine, a negative alpha or level, more than kMaxLevels levels, or a max_level below the
  /// nodes' largest level.
  LocalStepper(const BlockCsrView& stiffness, const double* mass, const std::int32_t* node_level,
               double dt_fine, double alpha, int max_level = -1);

  static constexpr int kMaxLevels = 10;

  // set_dashpots, set_constraints (SteppingBase): every kick of a constrained node is projected
  // (its own end kick solves the constrained implicit update, P A P v = P rhs, as Stepper's pass B),
  // so from a state in the range of P its u and v stay there at every level; the held part of the
  // force is the support's reaction, which does no work (reactions()). A contact pair node may not
  // be constrained (checked at the first run).

  /// Adds a force provider; its nodes() must be listed (non-empty). Its forces act in the end
  /// kicks of each node's own level at that kick's time.
  void add_provider(std::shared_ptr<ForceProvider> provider);

  /// Adds an element-loop component (internal_force.hpp: cells not in the stiffness) whose cells
  /// step at rate level `level` (dt_fine 2^level): the cell split of docs/local_stepping.md "The
  /// scheme: the row split". Its force -f_int(u) joins the level's kicks: computed at the new
  /// u in each of the level's end kicks and committed there (its history advances once per
  /// substep of its level), reused by the next start kick. Its nodes drift at that rate or a finer
  /// one (a node drifts at the finest level that kicks it), so none drifts slower than a cell that
  /// loads it; a cell may step finer than its nodes (pyfem/local_stepping.py does so for the cells
  /// around contact pairs). Throws std::invalid_argument for a level outside [0, max_level()].
  /// count_energy = false: its forces act, its stored energy and dissipation are left out of the
  /// account (an MPI rank's copy of cells another rank counts, set_partition).
  void add_internal_force(std::shared_ptr<InternalForceComponent> component, int level,
                          bool count_energy = true);

  /// Adds contact pairs whose nodes step and drift at rate level `level` (the drift level: the
  /// finest level whose kicks move a node, from its stiffness row's columns and the element-loop
  /// cells that load it; both nodes of every pair must step and drift there:
  /// pyfem/local_stepping.py equalize_pair_drift). Their correction
  /// (ContactPairs::correct, contact.hpp) runs in each substep of that level after its start kick and
  /// before its drift, when no kick will change the pair nodes' velocities until the next one: the
  /// drift's end, u + h v, is then known exactly, and the correction is the impulse h A^-1 R (A the
  /// implicit matrix M (1 + h/2 alpha) + h/2 C of the node at that step) that closes the pair there
  /// (stick: the normal gap and the tangential offset; slip: friction), whatever the levels of the
  /// pair's neighbours; the pair nodes step at that level themselves and their rows are stepped
  /// there too (step_rows_at_drift_level).
  /// It is what Stepper's correction and its next start kick add to the drift's
  /// velocity: a one-level run gives Stepper's displacements; the velocities at a sample time lack
  /// R's first half (h/2 A^-1 R, given with the next impulse) and the returned a has no R. The
  /// contact work is the impulses' work over the drift they start, m dv . v (not the kinetic
  /// energy they add: docs/local_stepping.md "The energy account"); friction
  /// dissipation as ContactPairs reports it. Checked at
  /// the first run: std::invalid_argument naming a pair node of another drift level.
  void add_contact(std::shared_ptr<ContactPairs> pairs, int level);

  /// Steps every block of the nodes' stiffness rows at the node's drift level (the finest level
  /// that kicks it, element-loop cells included) instead of its column's level: a coarser
  /// neighbour's force then reaches the node at each of its substeps, not as kicks at the ends of
  /// the coarse step. add_contact does it for the pair nodes (a pair's friction threshold must not
  /// see a coarse level's force arrive within one substep: that made sliding first order in dt,
  /// docs/local_stepping.md). Each such node must step at its drift level itself (checked at the first
  /// run: std::invalid_argument), so that it is a column of that level in every neighbour's row and
  /// every neighbour it reads drifts there too; otherwise a neighbour drifting coarser would be read
  /// ahead of time (first order, and unstable). The caps are set at the first run. The moved
  /// blocks break the column split's exact momentum balance at O(dt^2) (docs/local_stepping.md).
  void step_rows_at_drift_level(const std::vector<std::int32_t>& nodes);

  /// The row split (nodal subcycling, docs/local_stepping.md "The scheme: the row split") instead of the
  /// column split: every node steps at its own level with its whole stiffness row, its force at
  /// the end of each of its steps read from the positions of that time, a coarser neighbour j along
  /// its drift, u_j - (T_j - t) v_j (T_j the end of j's drift: exact, no kick changes v_j within it);
  /// a node drifts at its own level only. No force is split across rates, so a coarse node next to
  /// finer ones no longer drifts with them while its own force arrives as kicks (the stress defect
  /// of the column split where levels meet). Momentum and energy are kept to O(dt^2) only.
  /// Element-loop components step at their level and read their coarser nodes along their drift;
  /// their force on such a node is what the node's own end kick reads (the finer level's end kick
  /// at the same time comes first): give each cell the finest level of its nodes. Contact pairs as in
  /// the column split (both nodes at the pairs' level). The row caps of step_rows_at_drift_level do
  /// not apply (every row steps at its own level). Set before the first run.
  void set_row_split(bool on);
  bool row_split() const { return row_split_; }

  /// One MPI rank's share of a distributed model (Stepper::set_partition, docs/scaling.md "Local
  /// time stepping on the ranks"): its first n_owned nodes are its own, the rest ghosts whose rows it
  /// computes but does not keep. Row split only (a node's u and v change only in its own level's
  /// kicks, its contact impulses and its drift): before every drift of level k, after the level's
  /// start kick and contact impulses, exchanges[k] (null: none) overwrites the velocity of this
  /// share's ghosts at level k with their owners' (NodeExchange::exchange(v, nullptr)), so every
  /// ghost drifts exactly as its owner and each owned row reads, at its end kicks, the positions
  /// the whole model's stepper would. The energy account then sums the owned nodes and the
  /// counted components (the ranks' accounts add up to the model's). Dashpots, constraints,
  /// providers and pairs must be on owned nodes. Checked at the first run (std::invalid_argument):
  /// the row split, one entry per level, effects on owned nodes. Throws std::invalid_argument for
  /// n_owned outside [0, n_nodes].
  void set_partition(std::int64_t n_owned, std::vector<std::shared_ptr<NodeExchange>> exchanges);

  /// Advances (u, v, a) by n_steps global steps from t0; returns t0 + n_steps dt(). a holds on
  /// return each node's own-level acceleration of its last end kick (the FSAL value the next
  /// start kick uses), a = -M^-1 K u + ... for a one-level model as Stepper's a. The first call
  /// computes every level's stiffness and damping force from (u, v) (a given is ignored then); the
  /// external forces enter from the first end kick on, as in a Stepper started from
  /// a_0 = M^-1 (-K u_0 - d(v_0)) (the run loop starts from rest with a_0 = 0).
  double run(double* u, double* v, double* a, std::int64_t n_steps, double t0);

  double dt() const { return dt_fine_ * static_cast<double>(std::int64_t{1} << max_level_); }
  double dt_fine() const { return dt_fine_; }
  int max_level() const { return max_level_; }
  /// Kicks of level-k forces per global step, summed over the rows they touch, relative to
  /// global stepping at dt_fine (1: no saving): the work model of pyfem/local_stepping.py (work_sums).
  double work_fraction() const;

  struct Energy {
    double kinetic = 0.0, strain = 0.0, external_work = 0.0, damping_work = 0.0, initial = 0.0;
    double internal_stored = 0.0;       // the components' committed stored energy (J)
    double internal_dissipation = 0.0;  // their dissipation since the run started (J)
    double contact_work = 0.0;          // work of the contact impulses over their drifts (J)
    double friction_dissipation = 0.0;  // of the slipping pairs (J; part of -contact_work)
    // kinetic + strain + internal_stored - initial - external_work + damping_work
    //   + internal_dissipation - contact_work
    double balance = 0.0;
  };
  /// Energies of the state of the last run() (strain by one product at the end of each run call).
  Energy energy() const { return energy_; }

  /// The run's state beyond u, v, a and t (checkpoint, docs/checkpoint.md): each level's force of
  /// its last end kick (the FSAL force the next start kick uses) and own external force (its power
  /// at the next start kick), the energy account, and the state of every
  /// element-loop component and contact pair of every level. A stepper not yet run saves only
  /// that it has not started (its first run() computes everything from u, v).
  void save_state(StateArchive& archive) const;
  /// Restores save_state's blocks into a stepper built the same way (same matrix size, levels,
  /// dt_fine, alpha, providers, and components and pairs at the same levels in the same order):
  /// the next run() continues without initialising, bit for bit as the stepper that was saved.
  /// Throws std::invalid_argument naming the first block that does not fit (then nothing may be
  /// assumed about the stepper's state).
  void load_state(const StateArchive& archive);

  // phase_times() (SteppingBase), as Stepper's phases: update (the drifts), element_loop (the
  // components' forces and commits), input_forces (the providers), stiffness (the kicks' block
  // products and velocity updates), contact (the pairs' impulses); steps counts fine steps.

 private:
  void nodal_effects_changed(bool constraints) override;
  struct Level {
    // Rows touched by the level's columns, and per row the blocks of those columns.
    std::vector<std::int32_t> rows;
    std::vector<std::int64_t> row_ptr;
    std::vector<std::int32_t> columns;
    std::vector<double> blocks;
    // Row split: per block, the coarse index of its column's level if coarser than this level
    // (the column is read along its drift), else -1.
    std::vector<std::int8_t> coarser_column;
    // Row split: the nodes of this level's components at coarser levels, their coarse index, their u
    // while the components read them along their drift, and the components' force on them at the
    // last end kick (which their own rows read at their own end kicks: the same time).
    std::vector<std::int32_t> coarser_nodes;
    std::vector<std::int8_t> coarser_nodes_level;
    std::vector<double> coarser_saved;
    std::vector<double> coarser_force;
    // Row split: per own row, the finer levels' component forces on it: (level, index into that
    // level's coarser_nodes), rows by finer_ptr.
    std::vector<std::int64_t> finer_ptr;
    std::vector<std::int32_t> finer_level;
    std::vector<std::int32_t> finer_index;
    std::vector<double> force;           // (rows, 3) level-c force (+ f_ext on own rows) of the last end kick
    std::vector<double> external;        // (rows, 3) f_ext of own rows at the last end kick
    std::vector<std::uint8_t> own;       // (rows) the row's node has this level
    std::vector<std::int32_t> drift;     // nodes drifting once per substep of this level
    std::vector<std::int32_t> provider_rows;  // rows (indices into rows) that providers load
    double step = 0.0;                   // h of this level
    std::vector<double> implicit_inverse;  // (own rows with a dashpot, 9), keyed by dashpot_slot
    std::vector<std::shared_ptr<InternalForceComponent>> components;  // cells (or bolts) at this level
    std::vector<char> component_counted;  // per component: its energy is in this account
    std::vector<std::uint8_t> component_row;  // (rows) a component of this level loads the row
    std::vector<std::shared_ptr<ContactPairs>> contacts;  // pairs drifting at this level
  };

  void substep(int c, double h, double t, double* u, double* v);
  void start_kick(int c, double h, double* v);
  // initial: evaluate the level's force at the state (v kept), for the first start kick.
  void end_kick(int c, double h, double t, const double* u, double* v, bool initial);
  void initialise(const double* u, const double* v, double t0);
  // The structure the first run needs whatever the state: levels, row caps, provider rows, the
  // contacts' checks and scratch (initialise, load_state).
  void prepare_structure();
  // What a checkpoint must match: dt_fine, alpha, nodes, levels, providers, and the components
  // and pairs per level.
  std::vector<double> checkpoint_parameters() const;
  // Rows, column blocks and drift lists of every level (the constructor; rebuild).
  void build_levels();
  void build_dashpot_inverses();
  void build_provider_rows();
  // Throws unless every contact's nodes step and drift at its level.
  void check_contacts() const;
  // Throws unless a partition's effects are on owned nodes and its stepping is the row split.
  void check_partition() const;
  // Levels, row caps and provider rows from everything added so far (initialise: once, however
  // many components, pairs and providers were added).
  void rebuild();
  // Throws std::invalid_argument unless 0 <= level <= max_level_.
  void check_level(const char* what, int level) const;
  // The contact impulses of the pairs drifting at level c, before its drift from time t.
  void correct_contacts(int c, double t, const double* u, double* v);
  double strain_energy(const double* u) const;
  // The state's kinetic, strain and components' stored energy into energy_; returns the
  // components' dissipation since their construction (initialise and the end of run).
  double measure_state(const double* u, const double* v);

  std::vector<std::int32_t> level_;  // per node, fine index k
  double dt_fine_;
  double alpha_;
  int max_level_ = 0;
  std::vector<Level> levels_;  // by coarse index c = max_level_ - k
  // v += P dv at node i (dv unchanged without a constraint); in place on dv.
  void project(std::int64_t i, double* dv) const;
  std::vector<std::int32_t> provider_nodes_;  // union of the providers' nodes (sorted)
  std::vector<double> external_;              // (3 n) scratch for the providers' forces
  std::vector<double> own_power_;             // (n) f.v - d.v of each node at its last end kick
  std::vector<double> internal_;              // (3 n) scratch: f_int of a level's components
  std::vector<double> contact_a_;             // (3 n) scratch: pair nodes' a for the correction
  // (3 n) scratch: pair nodes' v(t) before their level's start kick, then the velocity whose slip
  // rate the pairs observe (correct_contacts).
  std::vector<double> contact_observed_v_;
  std::vector<double> contact_before_v_;      // (3 n) scratch: pair nodes' v before the impulse
  std::vector<std::int32_t> drift_level_;     // per node, fine index of the finest level moving it
  std::vector<std::int32_t> row_cap_;         // per node: its row's blocks at min(column level, cap)
  std::vector<std::int32_t> capped_;          // nodes whose rows step at their drift level
  bool levels_stale_ = false;                 // components or caps added since the last build
  bool row_split_ = false;                    // set_row_split
  // Row split: the end of the current drift of each coarse index's nodes (substep), the time a
  // coarser column is read back from.
  std::vector<double> drift_end_;
  double dissipation_at_start_ = 0.0;         // the components' dissipation when the run started
  bool initialised_ = false;
  std::vector<std::shared_ptr<NodeExchange>> exchanges_;  // per fine level k (set_partition)
  Energy energy_;
};

}  // namespace cavern
