// Interlayer dynamic contact (paper Sec. 3, Eqs. 12-20; Liu & Sharan 1995): node pairs on the two
// sides of an interface, bonded / stick / sliding / separated, strength deteriorating with D(t).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "deterioration.hpp"
#include "state_archive.hpp"

namespace cavern {

/// Contact states (stored as int8).
enum ContactState : std::int8_t {
  kBonded = 0,     // bond (cohesion, tensile strength) intact, stuck
  kStick = 1,      // bond lost, in contact and stuck
  kSliding = 2,    // bond lost, in contact and slipping
  kSeparated = 3,  // open: carries nothing
};

/// Borrowed pair data (copied by ContactPairs). Pair p joins node i = pairs[2p] and node
/// j = pairs[2p+1] (j is the paper's i'); normal[3p..] is the unit normal from side i towards
/// side j; static_force[3p..] = F0 = A sigma0 n, the force side j exerts on node i in the static
/// state (node j gets -F0).
struct ContactGeometry {
  std::int64_t n_pairs = 0;
  const std::int32_t* pairs = nullptr;   // (n_pairs, 2)
  const double* area = nullptr;          // (n_pairs) lumped facet area (m^2), > 0
  const double* normal = nullptr;        // (n_pairs, 3) unit
  const double* static_force = nullptr;  // (n_pairs, 3) F0 (N)
};

/// Interface strength (Eq. 18): P_N = t_s D A, P_T = mu_s N D + c D A (c only while bonded).
struct ContactStrength {
  double cohesion = 0.0;          // c (Pa)
  double tensile_strength = 0.0;  // t_s (Pa)
  double friction_static = 0.0;   // mu_s = tan(phi_s)
  double friction_dynamic = 0.0;  // mu_d = tan(phi_d)
};

/// What the contact correction needs from the integrator about one node: its lumped mass M,
/// the implicit matrix Atilde = M (1 + dt/2 alpha) I + dt/2 C of the velocity update and the
/// implicit damping matrix alpha M I + C (C the node's 3x3 dashpot, zero for most nodes).
/// Borrowed pointers into the stepper (dashpot_slot may be null: no dashpots).
struct ImplicitNodeOperators {
  double dt = 0.0;
  double alpha = 0.0;
  const double* mass = nullptr;
  const std::int32_t* dashpot_slot = nullptr;  // (n_nodes) slot or -1
  const double* dashpot_C = nullptr;           // (slots, 9)
  const double* dashpot_inverse = nullptr;     // (slots, 9) Atilde^-1 (restricted when constrained)
  const std::int32_t* constraint_of_slot = nullptr;  // (slots) constraint or -1; null: none
  const double* constraint_projection = nullptr;     // (constraints, 9) P of constraints.hpp

  /// Atilde^-1 of node (row-major 3x3) into out.
  void inverse(std::int64_t node, double out[9]) const;
  /// alpha M I + C of node (row-major 3x3) into out.
  void damping(std::int64_t node, double out[9]) const;
  /// Replaces the 3-vector x of node by P x when the node is constrained (no-op otherwise).
  void project(std::int64_t node, double* x) const;
};

/// Below this many pairs the pair loops run on one thread (the fork costs more than the work).
constexpr std::int64_t kMinPairsForThreads = 1024;

/// Power and dissipation of one contact correction.
struct ContactStepResult {
  double contact_power = 0.0;  // sum_pairs R.(v_i - v_j) at the corrected v_{n+1} (W)
  double friction_dissipation =
      0.0;  // sum over slipping pairs of T.P_t(Delta_{n+2} - Delta_{n+1}) (J)
};

/// Explicit contact correction of the velocity-Verlet step (after the stepper's pass B).
/// Gaps below are n.Delta + g0, g0 the pair's normal gap at u = 0 (0 unless rebase() set it):
/// "closing the normal gap" drives n.Delta_{n+2} to -g0.
///
/// With state (u_{n+1}, v_{n+1}, a_{n+1}) computed without contact, a force R on node i (-R on
/// j) added to r changes v_{n+1} by dt/2 Atilde^-1 R, a_{n+1} by (R - (alpha M + C) dv)/M and so
/// u_{n+2} = u_{n+1} + dt v_{n+1} + dt^2/2 a_{n+1} by exactly dt^2 Atilde^-1 R. Hence, with
/// Delta = u_j - u_i and Delta_pred = Delta_{n+1} + dt (v_j - v_i) + dt^2/2 (a_j - a_i):
///   Delta_{n+2} = Delta_pred - dt^2 W^-1 R,  W^-1 = Atilde_i^-1 + Atilde_j^-1
/// (W = M_i M_j/(M_i + M_j) I without damping: the paper's Eq. 17 with factor 1 for this form).
/// Stick (Eq. 17): closed normal gap, no further slip:
///   R_stick = W [n n^T Delta_pred + P_t (Delta_pred - Delta_{n+1})] / dt^2.
/// Total force on i: F = F0 + R, N = -n.F (compression > 0), T = P_t F. Strength (Eqs. 18-20),
/// D = D(t_{n+1}, dv_t) of Eq. 11:
///   N < 0: stick if the bond is intact and -N <= t_s D A, else separate for good (R = -F0).
///   N >= 0: stick if |T| <= mu_s N D + (bond intact ? c D A : 0), else slip:
///     T_new = min(mu_d N D, |T|) T/|T| (never more than the force that stops the slip),
///     tangential R = T_new - P_t F0, normal R keeps the gap closed at n+2, bond lost for good.
/// A separated pair carries nothing (R = -F0) while its gap with R = -F0 stays open,
/// n.(Delta_pred + dt^2 W^-1 F0) > 0; when it would close it is frictional contact (no cohesion,
/// no tension: a tensile N keeps it separated).
/// With 3x3 dashpots W couples the normal and tangential parts: stick stays exact; a slipping
/// pair takes N from the stick solution for its friction limit and then solves the normal R
/// that closes the gap for the prescribed tangential R (exact decoupling when Atilde ~ I).
/// dv_t in D is |P_t (v_j - v_i)| at t_n: after the previous step's correction (or of the state
/// given to observe_velocity at the start).
/// Pairs are coloured so that no two pairs of one colour share a node (interfaces that do not
/// meet: one colour) and processed colour by colour, the pairs of a colour in parallel (OpenMP,
/// from kMinPairsForThreads pairs): the result is independent of the visiting order and the
/// thread count. A node shared by two pairs sees the correction of the pair of the lower colour
/// (Gauss-Seidel across colours); only pairs with distinct nodes reproduce the unsplit mesh exactly.
class ContactPairs {
 public:
  /// Copies the arrays. Throws std::invalid_argument naming a bad parameter (non-positive area,
  /// non-unit normal, negative strength, non-finite values).
  ContactPairs(const ContactGeometry& geometry, const ContactStrength& strength);

  /// Switches D(t) on (absent: D = 1). Throws std::invalid_argument for a bad parameter.
  void set_deterioration(const DeteriorationParameters& parameters);

  /// Switches the normal-stress lag of the friction on (Prakash & Clifton 1993, in the form of
  /// Cochard & Rice 2000; absent: the friction limit uses the current N): each pair carries an
  /// effective normal force N* that follows N as dN*/dt = -(|dv_t| + velocity) / length (N* - N),
  /// integrated exactly over each step with N and dv_t held (N* = N + (N*_n - N) exp(-(|dv_t| +
  /// velocity) dt / length)), and the friction limit and the sliding force use max(N*, 0) in place
  /// of N; a tensile or separated pair pulls N* towards 0. N* starts at the pairs' current N (the
  /// static state). length > 0 (m), velocity >= 0 (m/s), both finite; throws std::invalid_argument
  /// otherwise. It regularises sliding between dissimilar solids, ill-posed with a friction that
  /// follows N at once (docs/interface_slip_accuracy.md).
  void set_normal_lag(double length, double velocity);

  /// Switches the gradual release of a broken bond on (time-weakening, Andrews 2004; absent: at
  /// once): a pair whose bond breaks at t_b keeps a share w = 1 - (t - t_b)/seconds (>= 0) of its
  /// cohesion and tensile strength, so its force falls from the strength to the bare friction (or
  /// to nothing, open) over `seconds` instead of in one step, the step that rang the mesh. While
  /// w > 0 a pair in tension holds -N <= t_s D A w (state stick) or opens carrying the tensile
  /// force t_s D A w along n (state separated), and a pair in compression sticks while |T| <=
  /// mu_s N D + c D A w and slides with mu_d N D + c D A w. The work of the weakening force over
  /// the slip or the opening it drives is dissipated (counted in friction_dissipation); its work is
  /// in the contact work as every contact force's. No stiffness and no dashpot: the stable time
  /// step is unchanged. seconds finite and > 0; throws std::invalid_argument otherwise.
  void set_release_time(double seconds);

  /// Throws std::invalid_argument for a pair node outside [0, n_nodes) or a pair with i == j.
  void check_nodes(std::int64_t n_nodes) const;

  /// The contact correction at t = t_{n+1}: modifies v, a (3 n_nodes) of the pair nodes in place.
  /// u is u_{n+1}. Records R, N, T, D, state of every pair and the net force of each pair node.
  /// With observe (Stepper) it then records the slip rate of the corrected v for the next
  /// correction; a caller that hands the pairs another velocity (LocalStepper: v(t) + dv of its
  /// level) passes false and calls observe_velocity itself, so the pairs are not read twice.
  ContactStepResult correct(double t, const ImplicitNodeOperators& operators, const double* u,
                            double* v, double* a, bool observe = true);

  /// Makes the current state the static state of a new run (the static stage's hand-over,
  /// pyfem/static.py): F0 becomes the total force F0 + R of the last correction, R 0, the normal
  /// gap n.(u_j - u_i) at u is kept as an offset (the new run's u starts from 0; an open pair
  /// stays open by that gap), the slip rate 0, N* the new static N; states, bonds and deterioration kept.
  void rebase(const double* u);

  /// Normal gap offset g0 of every pair (m): the gap is g0 + n.(u_j - u_i); 0 unless rebased.
  const std::vector<double>& gap_offset() const { return gap_offset_; }
  /// F0 of every pair (n_pairs, 3) (N).
  const std::vector<double>& static_force() const { return static_force_; }

  /// Records dv_t = |P_t (v_j - v_i)| of the state v for the next correction's D.
  void observe_velocity(const double* v);

  /// sum_pairs R.(v_i - v_j) of the last recorded R against v.
  double contact_power(const double* v) const;

  /// Adds the last recorded R to node i and -R to node j of f (3 n_nodes).
  void add_last_forces(double* f) const;

  /// Writes every pair's state (bond, contact state, forces, D, slip rate, the rebased gap and
  /// static force, N* with the normal lag on, the break times with the release on) under `prefix` (checkpoint, docs/checkpoint.md); load_state reads it back
  /// into pairs built from the same interfaces. Throws std::invalid_argument for a missing block
  /// or one of another size.
  void save_state(StateArchive& archive, const std::string& prefix) const;
  void load_state(const StateArchive& archive, const std::string& prefix);

  std::int64_t n_pairs() const { return n_pairs_; }
  /// Distinct pair nodes, sorted; net_force(k) is the last net contact force on unique_nodes()[k].
  const std::vector<std::int32_t>& unique_nodes() const { return unique_nodes_; }
  const double* net_force(std::size_t k) const { return node_force_.data() + 3 * k; }

  const std::vector<std::int8_t>& state() const { return state_; }
  const std::vector<std::uint8_t>& bond_intact() const { return bond_intact_; }
  const std::vector<double>& normal_force() const { return normal_force_; }          // N (N)
  const std::vector<double>& tangential_force() const { return tangential_force_; }  // T (n,3)
  const std::vector<double>& contact_force() const { return contact_force_; }        // R (n,3)
  const std::vector<double>& deterioration() const { return deterioration_; }        // D
  /// N* of every pair (N) with the normal lag on (set_normal_lag), else empty.
  const std::vector<double>& effective_normal() const { return effective_normal_; }
  /// Delta = u_j - u_i of every pair into out (n_pairs, 3).
  void relative_displacement(const double* u, double* out) const;
  /// Number of pairs in each state 0..3.
  void state_counts(std::int64_t counts[4]) const;

 private:
  // One pair's correction (the body of correct()); writes only the pair's own state and its two
  // nodes' v, a and node forces. wear: eta(t_{n+1}); t: t_{n+1} (the release clock).
  void correct_pair(std::int64_t p, double wear, double t, const ImplicitNodeOperators& operators,
                    const double* u, double* v, double* a);
  // Fills colour_ptr_/colour_pairs_ (greedy colouring by shared nodes).
  void colour_pairs();

  std::int64_t n_pairs_;
  std::vector<std::int32_t> pairs_;
  std::vector<std::int64_t> colour_ptr_;    // (colours + 1) offsets into colour_pairs_
  std::vector<std::int64_t> colour_pairs_;  // pair indices, colour by colour, ascending within
  std::vector<double> dissipation_;         // friction dissipation of each pair in the last step
  std::vector<double> area_, normal_, static_force_;
  ContactStrength strength_;
  bool deterioration_on_ = false;
  DeteriorationParameters deterioration_parameters_;
  bool lag_on_ = false;
  double lag_length_ = 0.0, lag_velocity_ = 0.0;
  std::vector<double> effective_normal_;  // N* (N), with the normal lag on
  double release_time_ = 0.0;             // > 0: the gradual release of a broken bond is on
  std::vector<double> break_time_;        // t_b of each pair's bond break (release on; inf: intact)

  std::vector<std::int32_t> unique_nodes_;
  std::vector<std::int32_t> slot_;  // (n_pairs, 2): index of i and j in unique_nodes_
  std::vector<double> node_force_;  // (unique, 3)

  std::vector<std::int8_t> state_;
  std::vector<std::uint8_t> bond_intact_;
  std::vector<double> normal_force_, tangential_force_, contact_force_, deterioration_;
  std::vector<double> slip_rate_;  // dv_t at t_n (m/s)
  std::vector<double> gap_offset_;  // g0 (m): normal gap at u = 0
};

}  // namespace cavern
