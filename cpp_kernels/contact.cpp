#include "contact.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "materials/principal.hpp"
#include "small_matrix.hpp"

namespace cavern {

namespace {

inline double dot(const double* x, const double* y) {
  return x[0] * y[0] + x[1] * y[1] + x[2] * y[2];
}

// Tangential part P_t x = x - n (n.x).
inline void tangential_part(const double* n, const double* x, double* out) {
  const double normal_component = dot(n, x);
  for (int c = 0; c < 3; ++c) out[c] = x[c] - normal_component * n[c];
}

void require_finite(const double* values, std::int64_t count, const char* name) {
  for (std::int64_t k = 0; k < count; ++k)
    if (!std::isfinite(values[k]))
      throw std::invalid_argument(std::string(name) + " has a non-finite value at flat index " +
                                  std::to_string(k));
}

// W = (W^-1)^+ of the pair's symmetric positive semi-definite W^-1 = Atilde_i^-1 + Atilde_j^-1:
// the plain inverse, or, where both nodes are held along a direction (a pair on a roller or fixed
// face: W^-1 has a null space), the pseudo-inverse, so that R has no part the supports take.
void pair_mass_matrix(const double* W_inverse, double* W) {
  const double scale = std::abs(W_inverse[0]) + std::abs(W_inverse[4]) + std::abs(W_inverse[8]);
  const double determinant = invert_3x3(W_inverse, W);
  if (std::abs(determinant) > 1e-9 * scale * scale * scale && std::isfinite(determinant)) return;
  Matrix3 matrix;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) matrix[r][c] = W_inverse[3 * r + c];
  const SymmetricEigen eigen = symmetric_eigen(matrix);
  std::fill(W, W + 9, 0.0);
  for (int k = 0; k < 3; ++k) {
    if (!(eigen.values[k] > 1e-9 * scale)) continue;
    const auto& e = eigen.vectors[k];
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) W[3 * r + c] += e[r] * e[c] / eigen.values[k];
  }
}

}  // namespace

void ImplicitNodeOperators::inverse(std::int64_t node, double out[9]) const {
  const std::int32_t slot = dashpot_slot ? dashpot_slot[node] : -1;
  if (slot >= 0) {
    std::copy(dashpot_inverse + 9 * slot, dashpot_inverse + 9 * slot + 9, out);
    return;
  }
  // The same arithmetic as the stepper's pass B, so that a bonded pair is exact to round-off.
  const double diagonal = 1.0 / (mass[node] * (1.0 + 0.5 * dt * alpha));
  std::fill(out, out + 9, 0.0);
  out[0] = out[4] = out[8] = diagonal;
}

void ImplicitNodeOperators::damping(std::int64_t node, double out[9]) const {
  const std::int32_t slot = dashpot_slot ? dashpot_slot[node] : -1;
  if (slot >= 0)
    std::copy(dashpot_C + 9 * slot, dashpot_C + 9 * slot + 9, out);
  else
    std::fill(out, out + 9, 0.0);
  const double mass_damping = alpha * mass[node];
  out[0] += mass_damping;
  out[4] += mass_damping;
  out[8] += mass_damping;
}

void ImplicitNodeOperators::project(std::int64_t node, double* x) const {
  if (!constraint_of_slot || !dashpot_slot) return;
  const std::int32_t slot = dashpot_slot[node];
  const std::int32_t constraint = slot >= 0 ? constraint_of_slot[slot] : -1;
  if (constraint < 0) return;
  double projected[3];
  multiply_3x3(constraint_projection + 9 * constraint, x, projected);
  for (int c = 0; c < 3; ++c) x[c] = projected[c];
}

ContactPairs::ContactPairs(const ContactGeometry& geometry, const ContactStrength& strength)
    : n_pairs_(geometry.n_pairs), strength_(strength) {
  if (n_pairs_ < 0)
    throw std::invalid_argument("n_pairs must be >= 0, got " + std::to_string(n_pairs_));
  auto require_strength = [](double value, const char* name) {
    if (!(std::isfinite(value) && value >= 0.0))
      throw std::invalid_argument(std::string(name) + " = " + std::to_string(value) +
                                  " must be finite and >= 0");
  };
  require_strength(strength.cohesion, "cohesion");
  require_strength(strength.tensile_strength, "tensile_strength");
  require_strength(strength.friction_static, "friction_static");
  require_strength(strength.friction_dynamic, "friction_dynamic");

  pairs_.assign(geometry.pairs, geometry.pairs + 2 * n_pairs_);
  area_.assign(geometry.area, geometry.area + n_pairs_);
  normal_.assign(geometry.normal, geometry.normal + 3 * n_pairs_);
  static_force_.assign(geometry.static_force, geometry.static_force + 3 * n_pairs_);
  require_finite(normal_.data(), 3 * n_pairs_, "normal");
  require_finite(static_force_.data(), 3 * n_pairs_, "static_force");
  for (std::int64_t p = 0; p < n_pairs_; ++p) {
    if (!(std::isfinite(area_[p]) && area_[p] > 0.0))
      throw std::invalid_argument("area[" + std::to_string(p) + "] = " + std::to_string(area_[p]) +
                                  " must be finite and > 0 (m^2)");
    double* n = normal_.data() + 3 * p;
    const double length = std::sqrt(dot(n, n));
    if (std::abs(length - 1.0) > 1e-6)
      throw std::invalid_argument("normal[" + std::to_string(p) + "] has length " +
                                  std::to_string(length) + "; it must be a unit vector");
    for (int c = 0; c < 3; ++c) n[c] /= length;  // exactly unit for the projections
  }

  unique_nodes_ = pairs_;
  std::sort(unique_nodes_.begin(), unique_nodes_.end());
  unique_nodes_.erase(std::unique(unique_nodes_.begin(), unique_nodes_.end()), unique_nodes_.end());
  slot_.resize(2 * n_pairs_);
  for (std::int64_t k = 0; k < 2 * n_pairs_; ++k)
    slot_[k] = static_cast<std::int32_t>(
        std::lower_bound(unique_nodes_.begin(), unique_nodes_.end(), pairs_[k]) -
        unique_nodes_.begin());
  node_force_.assign(3 * unique_nodes_.size(), 0.0);
  colour_pairs();
  dissipation_.assign(n_pairs_, 0.0);

  state_.assign(n_pairs_, kBonded);
  bond_intact_.assign(n_pairs_, 1);
  contact_force_.assign(3 * n_pairs_, 0.0);
  deterioration_.assign(n_pairs_, 1.0);
  slip_rate_.assign(n_pairs_, 0.0);
  gap_offset_.assign(n_pairs_, 0.0);
  // Before any step the pairs carry the static force.
  normal_force_.resize(n_pairs_);
  tangential_force_.resize(3 * n_pairs_);
  for (std::int64_t p = 0; p < n_pairs_; ++p) {
    const double* n = normal_.data() + 3 * p;
    const double* F0 = static_force_.data() + 3 * p;
    normal_force_[p] = -dot(n, F0);
    tangential_part(n, F0, tangential_force_.data() + 3 * p);
  }
}

void ContactPairs::colour_pairs() {
  // Greedy: each pair (in order) takes the lowest colour none of its nodes' earlier pairs has.
  // Interfaces that do not meet give one colour; pairs sharing a node (interfaces meeting on the
  // outer boundary) get different colours.
  std::vector<std::uint64_t> used_by_node(unique_nodes_.size(), 0);  // bit c: colour c taken
  std::vector<std::int32_t> colour(n_pairs_, 0);
  int n_colours = 0;
  for (std::int64_t p = 0; p < n_pairs_; ++p) {
    const std::uint64_t taken = used_by_node[slot_[2 * p]] | used_by_node[slot_[2 * p + 1]];
    int c = 0;
    while (c < 64 && (taken >> c) & 1u) ++c;
    if (c == 64)
      throw std::invalid_argument(
          "contact pairs: more than 64 colours needed (the pairs of one node and its partner "
          "would meet more than 64 times)");
    colour[p] = c;
    used_by_node[slot_[2 * p]] |= std::uint64_t{1} << c;
    used_by_node[slot_[2 * p + 1]] |= std::uint64_t{1} << c;
    n_colours = std::max(n_colours, c + 1);
  }
  colour_ptr_.assign(n_colours + 1, 0);
  for (std::int64_t p = 0; p < n_pairs_; ++p) ++colour_ptr_[colour[p] + 1];
  for (int c = 0; c < n_colours; ++c) colour_ptr_[c + 1] += colour_ptr_[c];
  colour_pairs_.resize(n_pairs_);
  std::vector<std::int64_t> next(colour_ptr_.begin(), colour_ptr_.end() - 1);
  for (std::int64_t p = 0; p < n_pairs_; ++p) colour_pairs_[next[colour[p]]++] = p;
}

void ContactPairs::set_deterioration(const DeteriorationParameters& parameters) {
  check_deterioration(parameters);
  deterioration_parameters_ = parameters;
  deterioration_on_ = true;
}

void ContactPairs::set_normal_lag(double length, double velocity) {
  if (!(std::isfinite(length) && length > 0.0))
    throw std::invalid_argument("normal lag length = " + std::to_string(length) +
                                " must be finite and > 0 (m)");
  if (!(std::isfinite(velocity) && velocity >= 0.0))
    throw std::invalid_argument("normal lag velocity = " + std::to_string(velocity) +
                                " must be finite and >= 0 (m/s)");
  lag_on_ = true;
  lag_length_ = length;
  lag_velocity_ = velocity;
  effective_normal_ = normal_force_;  // the current (static) state: no lag yet
}

void ContactPairs::set_release_time(double seconds) {
  if (!(std::isfinite(seconds) && seconds > 0.0))
    throw std::invalid_argument("release time = " + std::to_string(seconds) +
                                " must be finite and > 0 (s)");
  release_time_ = seconds;
  // Pairs whose bond broke before (a stage's) break now: the release starts with the dynamic run.
  break_time_.assign(n_pairs_, std::numeric_limits<double>::infinity());
}

void ContactPairs::check_nodes(std::int64_t n_nodes) const {
  for (std::int64_t p = 0; p < n_pairs_; ++p) {
    for (int side = 0; side < 2; ++side) {
      const std::int32_t node = pairs_[2 * p + side];
      if (node < 0 || node >= n_nodes)
        throw std::invalid_argument("pairs[" + std::to_string(p) + ", " + std::to_string(side) +
                                    "] = " + std::to_string(node) +
                                    " is not a node of the Stepper in [0, " +
                                    std::to_string(n_nodes) + ")");
    }
    if (pairs_[2 * p] == pairs_[2 * p + 1])
      throw std::invalid_argument("pairs[" + std::to_string(p) + "] joins node " +
                                  std::to_string(pairs_[2 * p]) +
                                  " to itself; the two nodes of a pair must differ");
  }
}

ContactStepResult ContactPairs::correct(double t, const ImplicitNodeOperators& operators,
                                        const double* u, double* v, double* a,
                                        bool observe) {
  std::fill(node_force_.begin(), node_force_.end(), 0.0);
  // eta(t) is one number per step (Eq. 9); gamma depends on each pair's slip rate.
  const double wear = deterioration_on_ ? wear_factor(deterioration_parameters_, t) : 1.0;
  const bool threaded = n_pairs_ >= kMinPairsForThreads;
  // Colour by colour (pairs of one colour share no node): within a colour the pairs are
  // independent, so the result does not depend on the order they are visited in or the threads.
  for (std::size_t colour = 0; colour + 1 < colour_ptr_.size(); ++colour) {
    const std::int64_t begin = colour_ptr_[colour], end = colour_ptr_[colour + 1];
#pragma omp parallel for schedule(static) if (threaded)
    for (std::int64_t k = begin; k < end; ++k)
      correct_pair(colour_pairs_[k], wear, t, operators, u, v, a);
  }
  ContactStepResult result;
  for (std::int64_t p = 0; p < n_pairs_; ++p) result.friction_dissipation += dissipation_[p];
  result.contact_power = contact_power(v);
  if (observe) observe_velocity(v);
  return result;
}

void ContactPairs::correct_pair(std::int64_t p, double wear, double t, const ImplicitNodeOperators& operators,
                                const double* u, double* v, double* a) {
  const double dt = operators.dt;
  const double dt2 = dt * dt;
  double dissipation = 0.0;
  const std::int64_t i = pairs_[2 * p], j = pairs_[2 * p + 1];
  const double* n = normal_.data() + 3 * p;
  const double* F0 = static_force_.data() + 3 * p;
  const double area = area_[p];
  const double g0 = gap_offset_[p];

  double inverse_i[9], inverse_j[9], W_inverse[9], W[9];
  operators.inverse(i, inverse_i);
  operators.inverse(j, inverse_j);
  for (int c = 0; c < 9; ++c) W_inverse[c] = inverse_i[c] + inverse_j[c];
  pair_mass_matrix(W_inverse, W);

  // Relative displacement now and predicted at n+2 without contact force.
  double delta[3], delta_pred[3];
  for (int c = 0; c < 3; ++c) {
    delta[c] = u[3 * j + c] - u[3 * i + c];
    delta_pred[c] =
        delta[c] + dt * (v[3 * j + c] - v[3 * i + c]) + 0.5 * dt2 * (a[3 * j + c] - a[3 * i + c]);
  }
  const double D =
      deterioration_on_ ? wear * slip_rate_factor(deterioration_parameters_, slip_rate_[p]) : 1.0;

  std::int8_t state = state_[p];
  bool bond = bond_intact_[p] != 0;
  // The gradual release (set_release_time): the share w of the broken bond's strengths left; 0 with
  // the release off (the bond's strengths gone at once), 1 at the step the bond breaks.
  const bool release = release_time_ > 0.0;
  double left = 0.0;
  if (release && !bond && std::isfinite(break_time_[p]))
    left = std::max(0.0, 1.0 - (t - break_time_[p]) / release_time_);
  const auto break_bond = [&]() {  // (release on only)
    bond = false;
    break_time_[p] = t;
    left = 1.0;
  };
  double cohesive_tension = 0.0;  // t_s D A w: the tensile force an opening pair still carries
  bool cohesive_opening = false;
  double R[3];
  bool slipping = false;
  bool separated = false;
  // N* of the normal lag over this step towards a target normal force (set_normal_lag).
  const auto lagged = [&](double target) {
    const double decay = std::exp(-(slip_rate_[p] + lag_velocity_) * dt / lag_length_);
    return target + (effective_normal_[p] - target) * decay;
  };
  double effective_normal = 0.0;  // N* after this step (lag on), set in compression
  bool in_compression = false;     // else (tension, open) N* goes towards 0

  if (state == kSeparated) {
    // Gap at n+2 if the pair keeps carrying nothing (R = -F0), or, while a broken bond releases,
    // the tensile force t_s D A w along n (R = t_s D A w n - F0).
    double carried[3];
    if (left > 0.0) {
      cohesive_tension = strength_.tensile_strength * D * area * left;
      for (int c = 0; c < 3; ++c) carried[c] = F0[c] - cohesive_tension * n[c];
    } else {
      std::copy(F0, F0 + 3, carried);
    }
    double W_inverse_F0[3];
    multiply_3x3(W_inverse, carried, W_inverse_F0);
    double open_gap = g0;
    for (int c = 0; c < 3; ++c) open_gap += n[c] * (delta_pred[c] + dt2 * W_inverse_F0[c]);
    separated = open_gap > 0.0;
    cohesive_opening = separated && left > 0.0;
  }

  if (!separated) {
    // Stick (Eq. 17): close the normal gap, keep the tangential relative displacement.
    double tangential_delta[3], target[3], R_stick[3];
    tangential_part(n, delta, tangential_delta);
    for (int c = 0; c < 3; ++c) target[c] = (delta_pred[c] - tangential_delta[c] + g0 * n[c]) / dt2;
    multiply_3x3(W, target, R_stick);

    double F[3], T[3];
    for (int c = 0; c < 3; ++c) F[c] = F0[c] + R_stick[c];
    const double N = -dot(n, F);
    tangential_part(n, F, T);
    const double T_magnitude = std::sqrt(dot(T, T));

    if (N < 0.0) {
      // Tension (Eq. 18, P_N = t_s D A): only an intact bond holds it (or, with the release on,
      // the share w a broken one has left).
      if (bond && -N <= strength_.tensile_strength * D * area) {
        std::copy(R_stick, R_stick + 3, R);
        state = kBonded;
      } else if (release) {
        if (bond) break_bond();
        cohesive_tension = strength_.tensile_strength * D * area * left;
        if (left > 0.0 && -N <= cohesive_tension) {
          std::copy(R_stick, R_stick + 3, R);
          state = kStick;
        } else {
          separated = true;
          cohesive_opening = left > 0.0;
        }
      } else {
        separated = true;
      }
    } else {
      // The normal force the friction sees: N, or with the lag on N* (>= 0).
      double N_friction = N;
      if (lag_on_) {
        effective_normal = lagged(N);
        in_compression = true;
        N_friction = std::max(effective_normal, 0.0);
      }
      const double limit =
          strength_.friction_static * N_friction * D +
          (bond ? strength_.cohesion * D * area : left > 0.0 ? strength_.cohesion * D * area * left : 0.0);
      if (T_magnitude <= limit) {
        std::copy(R_stick, R_stick + 3, R);
        state = bond ? kBonded : kStick;
      } else {
        // Slip (Eq. 20): dynamic friction along the stick direction; never more than the
        // force that stops the slip (mu_d > mu_s would otherwise reverse it). With the release
        // on, the cohesion a broken bond has left adds to it.
        slipping = true;
        state = kSliding;
        if (bond && release) break_bond();
        bond = false;
        const double friction = strength_.friction_dynamic * N_friction * D;
        const double slip_force =
            std::min(left > 0.0 ? friction + strength_.cohesion * D * area * left : friction, T_magnitude);
        double R_tangential[3], F0_tangential[3], W_inverse_R[3], W_inverse_n[3];
        tangential_part(n, F0, F0_tangential);
        for (int c = 0; c < 3; ++c)
          R_tangential[c] = slip_force * T[c] / T_magnitude - F0_tangential[c];
        // Normal R that closes the gap at n+2 given the tangential R (exact with 3x3 W).
        multiply_3x3(W_inverse, R_tangential, W_inverse_R);
        multiply_3x3(W_inverse, n, W_inverse_n);
        const double normal_compliance = dt2 * dot(n, W_inverse_n);  // 0: both nodes held along n
        const double R_normal =
            normal_compliance > 0.0
                ? (dot(n, delta_pred) + g0 - dt2 * dot(n, W_inverse_R)) / normal_compliance
                : 0.0;
        for (int c = 0; c < 3; ++c) R[c] = R_normal * n[c] + R_tangential[c];
      }
    }
  }

  if (separated) {
    // Open (Eq. 19): the total force vanishes, so the dynamic force cancels the static one; while
    // a broken bond releases (cohesive_opening) the pair still carries t_s D A w along n.
    state = kSeparated;
    bond = false;
    if (cohesive_opening)
      for (int c = 0; c < 3; ++c) R[c] = cohesive_tension * n[c] - F0[c];
    else
      for (int c = 0; c < 3; ++c) R[c] = -F0[c];
  }

  // Total force after the decision.
  double F[3], T[3];
  for (int c = 0; c < 3; ++c) F[c] = F0[c] + R[c];
  tangential_part(n, F, T);

  if (slipping) {
    // Work of the slip force over the slip increment it drives, Delta_{n+2} - Delta_{n+1}
    // (= dt times the relative v_{n+3/2}: the force held over the leapfrog step).
    double W_inverse_R[3], slip_increment[3], delta_next[3];
    multiply_3x3(W_inverse, R, W_inverse_R);
    for (int c = 0; c < 3; ++c) delta_next[c] = delta_pred[c] - dt2 * W_inverse_R[c] - delta[c];
    tangential_part(n, delta_next, slip_increment);
    dissipation = dot(T, slip_increment);
  } else if (cohesive_opening) {
    // Work of the released tensile force over the opening it resists, n.(Delta_{n+2} - Delta_{n+1}).
    double W_inverse_R[3];
    multiply_3x3(W_inverse, R, W_inverse_R);
    double opening = 0.0;
    for (int c = 0; c < 3; ++c) opening += n[c] * (delta_pred[c] - dt2 * W_inverse_R[c] - delta[c]);
    dissipation = cohesive_tension * opening;
  }

  // Apply R to i and -R to j: dv = dt/2 Atilde^-1 R, da = (R - (alpha M + C) dv)/M.
  for (int side = 0; side < 2; ++side) {
    const std::int64_t node = side == 0 ? i : j;
    const double sign = side == 0 ? 1.0 : -1.0;
    const double* node_inverse = side == 0 ? inverse_i : inverse_j;
    double force[3], dv[3], damping[9], damping_dv[3];
    for (int c = 0; c < 3; ++c) force[c] = sign * R[c];
    multiply_3x3(node_inverse, force, dv);
    for (int c = 0; c < 3; ++c) dv[c] *= 0.5 * dt;
    operators.damping(node, damping);
    multiply_3x3(damping, dv, damping_dv);
    const double m = operators.mass[node];
    double* node_force = node_force_.data() + 3 * slot_[2 * p + side];
    for (int c = 0; c < 3; ++c) {
      v[3 * node + c] += dv[c];
      a[3 * node + c] += (force[c] - damping_dv[c]) / m;
      node_force[c] += force[c];
    }
    operators.project(node, a + 3 * node);  // a support takes the held part
  }

  state_[p] = state;
  bond_intact_[p] = bond ? 1 : 0;
  for (int c = 0; c < 3; ++c) {
    contact_force_[3 * p + c] = R[c];
    tangential_force_[3 * p + c] = T[c];
  }
  normal_force_[p] = -dot(n, F);
  deterioration_[p] = D;
  dissipation_[p] = dissipation;
  if (lag_on_) effective_normal_[p] = in_compression ? effective_normal : lagged(0.0);
}

void ContactPairs::rebase(const double* u) {
  for (std::int64_t p = 0; p < n_pairs_; ++p) {
    const std::int64_t i = pairs_[2 * p], j = pairs_[2 * p + 1];
    const double* n = normal_.data() + 3 * p;
    for (int c = 0; c < 3; ++c) {
      static_force_[3 * p + c] += contact_force_[3 * p + c];
      contact_force_[3 * p + c] = 0.0;
      gap_offset_[p] += n[c] * (u[3 * j + c] - u[3 * i + c]);
    }
    slip_rate_[p] = 0.0;
    if (lag_on_) effective_normal_[p] = -dot(n, static_force_.data() + 3 * p);
  }
  std::fill(node_force_.begin(), node_force_.end(), 0.0);
}

void ContactPairs::save_state(StateArchive& archive, const std::string& prefix) const {
  archive.put(prefix + "pairs", pairs_);
  archive.put(prefix + "state", state_);
  archive.put(prefix + "bond_intact", bond_intact_);
  archive.put(prefix + "normal_force", normal_force_);
  archive.put(prefix + "tangential_force", tangential_force_);
  archive.put(prefix + "contact_force", contact_force_);
  archive.put(prefix + "deterioration", deterioration_);
  archive.put(prefix + "slip_rate", slip_rate_);
  archive.put(prefix + "gap_offset", gap_offset_);
  archive.put(prefix + "static_force", static_force_);
  archive.put(prefix + "node_force", node_force_);
  if (lag_on_) archive.put(prefix + "effective_normal", effective_normal_);
  if (release_time_ > 0.0) archive.put(prefix + "break_time", break_time_);
}

void ContactPairs::load_state(const StateArchive& archive, const std::string& prefix) {
  std::vector<std::int32_t> pairs(pairs_.size());
  archive.get(prefix + "pairs", pairs);
  if (pairs != pairs_)
    throw std::invalid_argument("checkpoint block '" + prefix +
                                "pairs': the pairs join other nodes than the model's");
  archive.get(prefix + "state", state_);
  archive.get(prefix + "bond_intact", bond_intact_);
  archive.get(prefix + "normal_force", normal_force_);
  archive.get(prefix + "tangential_force", tangential_force_);
  archive.get(prefix + "contact_force", contact_force_);
  archive.get(prefix + "deterioration", deterioration_);
  archive.get(prefix + "slip_rate", slip_rate_);
  archive.get(prefix + "gap_offset", gap_offset_);
  archive.get(prefix + "static_force", static_force_);
  archive.get(prefix + "node_force", node_force_);
  if (lag_on_) archive.get(prefix + "effective_normal", effective_normal_);
  if (release_time_ > 0.0) archive.get(prefix + "break_time", break_time_);
}

void ContactPairs::observe_velocity(const double* v) {
#pragma omp parallel for schedule(static) if (n_pairs_ >= kMinPairsForThreads)
  for (std::int64_t p = 0; p < n_pairs_; ++p) {
    const std::int64_t i = pairs_[2 * p], j = pairs_[2 * p + 1];
    double relative[3], tangential[3];
    for (int c = 0; c < 3; ++c) relative[c] = v[3 * j + c] - v[3 * i + c];
    tangential_part(normal_.data() + 3 * p, relative, tangential);
    slip_rate_[p] = std::sqrt(dot(tangential, tangential));
  }
}

double ContactPairs::contact_power(const double* v) const {
  double power = 0.0;
#pragma omp parallel for schedule(static) if (n_pairs_ >= kMinPairsForThreads) reduction(+ : power)
  for (std::int64_t p = 0; p < n_pairs_; ++p) {
    const std::int64_t i = pairs_[2 * p], j = pairs_[2 * p + 1];
    const double* R = contact_force_.data() + 3 * p;
    for (int c = 0; c < 3; ++c) power += R[c] * (v[3 * i + c] - v[3 * j + c]);
  }
  return power;
}

void ContactPairs::add_last_forces(double* f) const {
  for (std::int64_t p = 0; p < n_pairs_; ++p) {
    const std::int64_t i = pairs_[2 * p], j = pairs_[2 * p + 1];
    for (int c = 0; c < 3; ++c) {
      f[3 * i + c] += contact_force_[3 * p + c];
      f[3 * j + c] -= contact_force_[3 * p + c];
    }
  }
}

void ContactPairs::relative_displacement(const double* u, double* out) const {
  for (std::int64_t p = 0; p < n_pairs_; ++p) {
    const std::int64_t i = pairs_[2 * p], j = pairs_[2 * p + 1];
    for (int c = 0; c < 3; ++c) out[3 * p + c] = u[3 * j + c] - u[3 * i + c];
  }
}

void ContactPairs::state_counts(std::int64_t counts[4]) const {
  std::fill(counts, counts + 4, 0);
  for (std::int8_t s : state_) ++counts[s];
}

}  // namespace cavern
