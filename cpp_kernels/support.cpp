#include "support.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace cavern {

namespace {

void require(bool condition, const std::string& message) {
  if (!condition) throw std::invalid_argument("GroutedBolts: " + message);
}

/// Return mapping of a perfectly plastic spring with trial force `trial`, capacity `cap` (> 0)
/// and stiffness `stiffness`: the force, and whether it flows.
inline double capped(double trial, double cap, bool& flows) {
  flows = std::abs(trial) > cap;
  return flows ? std::copysign(cap, trial) : trial;
}

/// The incremental potential of that spring at the trial force (Huber: quadratic inside,
/// linear beyond the capacity); its derivative with respect to the spring's elongation is the
/// returned force.
inline double potential(double trial, double cap, double stiffness) {
  const double a = std::abs(trial);
  return a <= cap ? 0.5 * trial * trial / stiffness : cap * (a - 0.5 * cap) / stiffness;
}

}  // namespace

GroutedBolts::GroutedBolts(const BoltGeometry& geometry, const BoltParameters& parameters)
    : geometry_(geometry), parameters_(parameters) {
  const BoltParameters& p = parameters_;
  require(p.axial_stiffness > 0.0 && std::isfinite(p.axial_stiffness), "axial_stiffness must be > 0");
  require(p.yield_force > 0.0 && std::isfinite(p.yield_force), "yield_force must be > 0");
  require(p.bond_stiffness > 0.0 && std::isfinite(p.bond_stiffness), "bond_stiffness must be > 0");
  require(p.bond_strength > 0.0 && std::isfinite(p.bond_strength), "bond_strength must be > 0");
  require(p.pretension >= 0.0 && p.pretension < p.yield_force,
          "pretension must be in [0, yield_force)");
  require(p.free_length >= 0.0 && std::isfinite(p.free_length), "free_length must be >= 0");
  require(p.head_stiffness >= 0.0 && std::isfinite(p.head_stiffness), "head_stiffness must be >= 0");
  require(p.pretension == 0.0 || p.head_stiffness > 0.0,
          "a pretension needs a head (head_stiffness > 0) to react on");
  require(p.tolerance > 0.0 && p.max_iterations > 0, "tolerance and max_iterations must be > 0");
  require(geometry.n_bolts >= 0 && geometry.n_host > 0, "needs n_host > 0");
  require(geometry.n_bolts == 0 || (geometry.bolt_offsets && geometry.arc_length &&
                                    geometry.directions && geometry.host_nodes &&
                                    geometry.host_weights),
          "missing arrays");
  n_nodes_ = geometry.n_bolts == 0 ? 0 : geometry.bolt_offsets[geometry.n_bolts];
  require(geometry.n_bolts == 0 || geometry.bolt_offsets[0] == 0, "bolt_offsets must start at 0");
  for (std::int64_t j = 0; j < geometry.n_bolts; ++j)
    require(geometry.bolt_offsets[j + 1] >= geometry.bolt_offsets[j] + 2,
            "bolt " + std::to_string(j) + " has fewer than 2 nodes");
  if (geometry.n_bolts > 0) {
    owned_offsets_.assign(geometry.bolt_offsets, geometry.bolt_offsets + geometry.n_bolts + 1);
    owned_arc_length_.assign(geometry.arc_length, geometry.arc_length + n_nodes_);
    owned_directions_.assign(geometry.directions, geometry.directions + 3 * geometry.n_bolts);
    owned_host_nodes_.assign(geometry.host_nodes, geometry.host_nodes + n_nodes_ * geometry.n_host);
    owned_host_weights_.assign(geometry.host_weights,
                               geometry.host_weights + n_nodes_ * geometry.n_host);
    geometry_.bolt_offsets = owned_offsets_.data();
    geometry_.arc_length = owned_arc_length_.data();
    geometry_.directions = owned_directions_.data();
    geometry_.host_nodes = owned_host_nodes_.data();
    geometry_.host_weights = owned_host_weights_.data();
  }
  segment_length_.reserve(std::max<std::int64_t>(n_nodes_ - geometry.n_bolts, 0));
  initial_force_.reserve(segment_length_.capacity());
  bond_length_.assign(n_nodes_, 0.0);
  for (std::int64_t j = 0; j < geometry.n_bolts; ++j) {
    const std::int64_t begin = geometry.bolt_offsets[j], end = geometry.bolt_offsets[j + 1];
    require(end - begin >= 2, "bolt " + std::to_string(j) + " has fewer than 2 nodes");
    const double* d = geometry.directions + 3 * j;
    const double norm = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    require(std::abs(norm - 1.0) < 1e-9, "direction of bolt " + std::to_string(j) + " is not a unit vector");
    const double* s = geometry.arc_length;
    require(s[begin] == 0.0, "bolt " + std::to_string(j) + " does not start at s = 0");
    for (std::int64_t k = begin; k + 1 < end; ++k) {
      const double length = s[k + 1] - s[k];
      require(length > 0.0 && std::isfinite(length),
              "arc_length of bolt " + std::to_string(j) + " is not strictly increasing");
      segment_length_.push_back(length);
      // The free length's segments carry the pretension (a segment straddling its end: the
      // share of it that is free would need a split; refused).
      const bool free = s[k + 1] <= p.free_length + 1e-12 * (1.0 + p.free_length);
      require(free || s[k] >= p.free_length - 1e-12 * (1.0 + p.free_length),
              "free_length must fall on a bolt node (bolt " + std::to_string(j) + ")");
      initial_force_.push_back(free ? p.pretension : 0.0);
    }
    // Tributary grouted length: the node's half segments intersected with [free_length, end].
    bool grouted = false;
    for (std::int64_t k = begin; k < end; ++k) {
      const double lo = k == begin ? s[k] : 0.5 * (s[k - 1] + s[k]);
      const double hi = k + 1 == end ? s[k] : 0.5 * (s[k] + s[k + 1]);
      bond_length_[k] = std::max(0.0, hi - std::max(lo, p.free_length));
      grouted = grouted || bond_length_[k] > 0.0;
    }
    require(grouted || p.head_stiffness > 0.0,
            "bolt " + std::to_string(j) + " is tied to nothing (free_length >= its length, no head)");
  }
  const std::int64_t k_host = geometry.n_host;
  for (std::int64_t i = 0; i < n_nodes_ * k_host; ++i) {
    require(geometry.host_nodes[i] >= 0, "host_nodes has a negative node");
    require(std::isfinite(geometry.host_weights[i]), "host_weights has a non-finite value");
  }
  unique_nodes_.assign(geometry.host_nodes, geometry.host_nodes + n_nodes_ * k_host);
  std::sort(unique_nodes_.begin(), unique_nodes_.end());
  unique_nodes_.erase(std::unique(unique_nodes_.begin(), unique_nodes_.end()), unique_nodes_.end());

  const std::int64_t n_segments = static_cast<std::int64_t>(segment_length_.size());
  w_.assign(n_nodes_, 0.0);
  plastic_slip_.assign(n_nodes_, 0.0);
  bond_force_.assign(n_nodes_, 0.0);
  ubar_.assign(n_nodes_, 0.0);
  ubar_reference_.assign(n_nodes_, 0.0);
  bond_force_reference_.assign(n_nodes_, 0.0);
  plastic_strain_.assign(n_segments, 0.0);
  axial_force_.assign(initial_force_.begin(), initial_force_.end());
  // The installed state: the bolts' equilibrium at u = 0 (with a pretension, the free length
  // pulls the head spring and the bond; without, all zero). Its energy is the initial stored
  // energy; its dissipation (none unless the pretension slips the bond) is not counted.
  std::vector<double> zero(3 * (unique_nodes_.empty() ? 0 : unique_nodes_.back() + 1), 0.0);
  std::vector<double> scratch(zero.size(), 0.0);
  compute(zero.data(), scratch.data());
  // Lock-off: the free length holds the pretension after the anchor and the head have taken it
  // (the initial force of each bolt's free segments scaled until its force is the pretension;
  // one scaling when the anchor stays elastic).
  for (int pass = 0; p.pretension > 0.0 && pass < 20; ++pass) {
    double worst = 0.0;
    for (std::int64_t j = 0; j < geometry.n_bolts; ++j) {
      const std::int64_t first = geometry_.bolt_offsets[j] - j;
      if (initial_force_[first] == 0.0) continue;  // no free segment
      worst = std::max(worst, std::abs(trial_axial_force_[first] - p.pretension));
    }
    if (worst <= 1e-12 * p.pretension) break;
    for (std::int64_t j = 0; j < geometry.n_bolts; ++j) {
      const std::int64_t first = geometry_.bolt_offsets[j] - j;
      if (initial_force_[first] == 0.0) continue;
      const double N = trial_axial_force_[first];
      const double factor = p.pretension / N;
      const std::int64_t last = geometry_.bolt_offsets[j + 1] - j - 1;
      for (std::int64_t e = first; e < last && initial_force_[e] != 0.0; ++e) initial_force_[e] *= factor;
    }
    std::fill(scratch.begin(), scratch.end(), 0.0);
    compute(zero.data(), scratch.data());
  }
  commit();
  dissipation_ = 0.0;
  peak_axial_force_.assign(n_segments, 0.0);
  for (std::int64_t e = 0; e < n_segments; ++e) peak_axial_force_[e] = std::abs(axial_force_[e]);
}

double GroutedBolts::axial_at(std::int64_t k, const double* d, const double* field) const {
  const std::int64_t k_host = geometry_.n_host;
  double x = 0.0, y = 0.0, z = 0.0;
  for (std::int64_t a = 0; a < k_host; ++a) {
    const double weight = geometry_.host_weights[k * k_host + a];
    const double* fa = field + 3 * static_cast<std::int64_t>(geometry_.host_nodes[k * k_host + a]);
    x += weight * fa[0];
    y += weight * fa[1];
    z += weight * fa[2];
  }
  return d[0] * x + d[1] * y + d[2] * z;
}

void GroutedBolts::spread(std::int64_t k, const double* d, double s, double* out_force) const {
  const std::int64_t k_host = geometry_.n_host;
  for (std::int64_t a = 0; a < k_host; ++a) {
    const double g = geometry_.host_weights[k * k_host + a] * s;
    double* f = out_force + 3 * static_cast<std::int64_t>(geometry_.host_nodes[k * k_host + a]);
    f[0] += g * d[0];
    f[1] += g * d[1];
    f[2] += g * d[2];
  }
}

void GroutedBolts::rock_axial(const double* u, std::vector<double>& ubar) const {
  ubar.resize(n_nodes_);
  for (std::int64_t j = 0; j < geometry_.n_bolts; ++j) {
    const double* d = geometry_.directions + 3 * j;
    for (std::int64_t k = geometry_.bolt_offsets[j]; k < geometry_.bolt_offsets[j + 1]; ++k)
      ubar[k] = ubar_reference_[k] + axial_at(k, d, u);
  }
}

int GroutedBolts::solve_bolt(std::int64_t j, const double* ubar, double* w, double* segment_force,
                             double* segment_plastic, double* tie_force,
                             double* bond_plastic) const {
  const BoltParameters& p = parameters_;
  const std::int64_t begin = geometry_.bolt_offsets[j], end = geometry_.bolt_offsets[j + 1];
  const std::int64_t m = end - begin, first_segment = begin - j;
  const double EA = p.axial_stiffness;
  const double* length = segment_length_.data() + first_segment;
  const double* N0 = initial_force_.data() + first_segment;
  const double* eps_p = plastic_strain_.data() + first_segment;
  const double* slip_p = plastic_slip_.data() + begin;
  const double* L = bond_length_.data() + begin;
  const double* ub = ubar + begin;
  // Scratch of this thread, reused from bolt to bolt (no allocation per bolt and step).
  thread_local std::vector<double> R, diag, off, step, trial, c;
  for (std::vector<double>* buffer : {&R, &diag, &off, &step, &trial, &c})
    buffer->assign(static_cast<std::size_t>(m), 0.0);

  // A flowing spring keeps 1e-8 of its elastic stiffness in the Newton matrix only (the
  // residual is exact): the matrix stays definite when every tie flows (a floating bolt), and
  // is the exact one when nothing flows (one step then solves the linear problem).
  constexpr double kFlowTangent = 1e-8;
  double largest = p.head_stiffness;
  for (std::int64_t e = 0; e + 1 < m; ++e) largest = std::max(largest, EA / length[e]);
  for (std::int64_t k = 0; k < m; ++k) largest = std::max(largest, p.bond_stiffness * L[k]);

  // Residual R = dPi/dw, the Newton matrix, and the potential Pi at w (forces written out).
  auto evaluate = [&](const double* x, bool matrix, double& force_scale, double& roundoff) {
    double pi = 0.0;
    force_scale = p.pretension;
    std::fill(R.begin(), R.end(), 0.0);
    if (matrix) {
      std::fill(diag.begin(), diag.end(), 0.0);
      std::fill(off.begin(), off.end(), 0.0);
    }
    for (std::int64_t e = 0; e + 1 < m; ++e) {
      const double strain = (x[e + 1] - x[e]) / length[e];
      const double trial_force = N0[e] + EA * (strain - eps_p[e]);
      bool flows = false;
      const double N = capped(trial_force, p.yield_force, flows);
      segment_force[e] = N;
      segment_plastic[e] = eps_p[e] + (trial_force - N) / EA;
      pi += length[e] * potential(trial_force, p.yield_force, EA);
      R[e] -= N;
      R[e + 1] += N;
      force_scale = std::max(force_scale, std::abs(N));
      if (matrix) {
        const double t = (flows ? kFlowTangent : 1.0) * EA / length[e];
        diag[e] += t;
        diag[e + 1] += t;
        off[e] = -t;
      }
    }
    // The residual's round-off floor: the largest stiffness times the largest displacement.
    roundoff = 0.0;
    for (std::int64_t k = 0; k < m; ++k)
      roundoff = std::max(roundoff, largest * std::max(std::abs(x[k]), std::abs(ub[k])));
    for (std::int64_t k = 0; k < m; ++k) {
      double F = 0.0;
      bond_plastic[k] = slip_p[k];
      if (L[k] > 0.0) {
        const double K = p.bond_stiffness * L[k], cap = p.bond_strength * L[k];
        const double trial_force = K * (x[k] - ub[k] - slip_p[k]);
        bool flows = false;
        F = capped(trial_force, cap, flows);
        bond_plastic[k] = slip_p[k] + (trial_force - F) / K;
        pi += potential(trial_force, cap, K);
        if (matrix) diag[k] += flows ? kFlowTangent * K : K;
      }
      if (k == 0 && p.head_stiffness > 0.0) {
        const double head = p.head_stiffness * (x[0] - ub[0]);
        F += head;
        pi += 0.5 * head * head / p.head_stiffness;
        if (matrix) diag[0] += p.head_stiffness;
      }
      tie_force[k] = F;
      R[k] += F;
      force_scale = std::max(force_scale, std::abs(F));
    }
    return pi;
  };
  auto norm_inf = [&]() {
    double r = 0.0;
    for (double value : R) r = std::max(r, std::abs(value));
    return r;
  };

  double scale = 0.0, roundoff = 0.0;
  double pi = evaluate(w, true, scale, roundoff);
  double residual = norm_inf();
  int iteration = 0;
  // Converged: the residual within `tolerance` of the forces, or at the round-off of its own
  // evaluation. At least one Newton step: in the elastic range that step is the exact linear
  // solve, so the force is linear in u to round-off whatever the size of the increment.
  auto converged = [&]() {
    return residual <= std::max(p.tolerance * scale, 1e-14 * roundoff);
  };
  while (iteration == 0 || !converged()) {
    if (iteration == p.max_iterations)
      throw std::runtime_error("GroutedBolts: bolt " + std::to_string(j) +
                               " did not reach equilibrium in " +
                               std::to_string(p.max_iterations) + " Newton iterations (residual " +
                               std::to_string(residual) + " N)");
    ++iteration;
    // Thomas algorithm on the symmetric tridiagonal matrix: step = -T^-1 R.
    c[0] = diag[0];
    step[0] = -R[0];
    for (std::int64_t k = 1; k < m; ++k) {
      const double factor = off[k - 1] / c[k - 1];
      c[k] = diag[k] - factor * off[k - 1];
      step[k] = -R[k] - factor * step[k - 1];
    }
    step[m - 1] /= c[m - 1];
    for (std::int64_t k = m - 2; k >= 0; --k) step[k] = (step[k] - off[k] * step[k + 1]) / c[k];
    double slope = 0.0;
    for (std::int64_t k = 0; k < m; ++k) slope += R[k] * step[k];
    // Backtracking on the convex potential; the full step is kept whenever it lowers the
    // residual (the exact solve of an unchanged active set, whose Pi difference may be below
    // round-off).
    double alpha = 1.0, new_pi = 0.0, new_residual = 0.0, new_scale = 0.0, new_roundoff = 0.0;
    for (int halving = 0;; ++halving) {
      for (std::int64_t k = 0; k < m; ++k) trial[k] = w[k] + alpha * step[k];
      new_pi = evaluate(trial.data(), true, new_scale, new_roundoff);
      new_residual = norm_inf();
      const bool armijo = new_pi <= pi + 1e-4 * alpha * slope;
      const bool at_roundoff =
          new_residual < residual && std::abs(new_pi - pi) <= 1e-12 * std::max(std::abs(pi), 1e-300);
      if (armijo || at_roundoff || halving == 60) break;
      alpha *= 0.5;
    }
    std::copy(trial.begin(), trial.end(), w);
    pi = new_pi;
    residual = new_residual;
    scale = new_scale;
    roundoff = new_roundoff;
  }
  return iteration;
}

InternalEnergy GroutedBolts::compute(const double* u, double* out_force) {
  const std::int64_t n_segments = static_cast<std::int64_t>(segment_length_.size());
  rock_axial(u, trial_ubar_);
  trial_w_ = w_;
  trial_axial_force_.assign(n_segments, 0.0);
  trial_plastic_strain_.assign(n_segments, 0.0);
  trial_bond_force_.assign(n_nodes_, 0.0);
  trial_plastic_slip_.assign(n_nodes_, 0.0);
  std::vector<int> iterations(geometry_.n_bolts, 0);
  std::vector<std::string> failures(geometry_.n_bolts);
  // Bolts are independent: each writes its own nodes and segments, so any thread count gives
  // the same bits. No exception leaves the parallel region: the first failure is rethrown.
#pragma omp parallel for schedule(dynamic, 16) if (geometry_.n_bolts >= 64)
  for (std::int64_t j = 0; j < geometry_.n_bolts; ++j) {
    const std::int64_t begin = geometry_.bolt_offsets[j];
    try {
      iterations[j] = solve_bolt(j, trial_ubar_.data(), trial_w_.data() + begin,
                                 trial_axial_force_.data() + (begin - j),
                                 trial_plastic_strain_.data() + (begin - j),
                                 trial_bond_force_.data() + begin,
                                 trial_plastic_slip_.data() + begin);
    } catch (const std::exception& error) {
      failures[j] = error.what();
    }
  }
  for (const std::string& failure : failures)
    if (!failure.empty()) throw std::runtime_error(failure);
  last_iterations_ = 0;
  for (int count : iterations) last_iterations_ += count;

  // Energies and the force on the rock, in a fixed order.
  const BoltParameters& p = parameters_;
  double stored = 0.0, dissipation = 0.0;
  for (std::int64_t e = 0; e < n_segments; ++e) {
    const double N = trial_axial_force_[e];
    stored += segment_length_[e] * N * N / (2.0 * p.axial_stiffness);
    dissipation += N * segment_length_[e] * (trial_plastic_strain_[e] - plastic_strain_[e]);
  }
  for (std::int64_t j = 0; j < geometry_.n_bolts; ++j) {
    const double* d = geometry_.directions + 3 * j;
    for (std::int64_t k = geometry_.bolt_offsets[j]; k < geometry_.bolt_offsets[j + 1]; ++k) {
      const double T = trial_bond_force_[k];
      double bond = T;
      if (k == geometry_.bolt_offsets[j] && p.head_stiffness > 0.0) {
        const double head = p.head_stiffness * (trial_w_[k] - trial_ubar_[k]);
        stored += 0.5 * head * head / p.head_stiffness;
        bond -= head;
      }
      if (bond_length_[k] > 0.0) {
        stored += bond * bond / (2.0 * p.bond_stiffness * bond_length_[k]);
        dissipation += bond * (trial_plastic_slip_[k] - plastic_slip_[k]);
      }
      // Relative to a rebased reference: Psi - Psi_ref - f0.u.
      stored += bond_force_reference_[k] * (trial_ubar_[k] - ubar_reference_[k]);
      const double relative = T - bond_force_reference_[k];
      if (relative != 0.0) spread(k, d, -relative, out_force);  // f_int = dPsi/du = -sum_k N_a T_k d
    }
  }
  trial_stored_ = stored - stored_reference_;
  trial_dissipation_increment_ = dissipation;
  has_trial_ = true;
  return InternalEnergy{trial_stored_, trial_dissipation_increment_};
}

void GroutedBolts::commit() {
  if (!has_trial_)
    throw std::logic_error(name() + ": commit() without a compute() since the last commit()");
  w_.swap(trial_w_);
  plastic_strain_.swap(trial_plastic_strain_);
  plastic_slip_.swap(trial_plastic_slip_);
  axial_force_.swap(trial_axial_force_);
  bond_force_.swap(trial_bond_force_);
  ubar_.swap(trial_ubar_);
  for (std::size_t e = 0; e < peak_axial_force_.size(); ++e)
    peak_axial_force_[e] = std::max(peak_axial_force_[e], std::abs(axial_force_[e]));
  stored_energy_ = trial_stored_;
  dissipation_ += trial_dissipation_increment_;
  has_trial_ = false;
}

void GroutedBolts::add_stiffness_damping(const double* v, double beta, double* out_force) {
  if (beta == 0.0 || n_nodes_ == 0) return;
  // beta K0 v, K0 the condensed elastic stiffness: vbar_k the rock's axial velocity, z the
  // bolt's elastic response, the tie forces K_k (z_k - vbar_k) on the rock.
  const BoltParameters& p = parameters_;
  std::vector<double> vbar(n_nodes_);
  for (std::int64_t j = 0; j < geometry_.n_bolts; ++j) {
    const double* d = geometry_.directions + 3 * j;
    for (std::int64_t k = geometry_.bolt_offsets[j]; k < geometry_.bolt_offsets[j + 1]; ++k)
      vbar[k] = axial_at(k, d, v);
  }
  for (std::int64_t j = 0; j < geometry_.n_bolts; ++j) {
    const std::int64_t begin = geometry_.bolt_offsets[j], end = geometry_.bolt_offsets[j + 1];
    const std::int64_t m = end - begin, first_segment = begin - j;
    std::vector<double> diag(m, 0.0), off(m, 0.0), rhs(m), c(m), tie(m);
    for (std::int64_t e = 0; e + 1 < m; ++e) {
      const double t = p.axial_stiffness / segment_length_[first_segment + e];
      diag[e] += t;
      diag[e + 1] += t;
      off[e] = -t;
    }
    for (std::int64_t k = 0; k < m; ++k) {
      tie[k] = p.bond_stiffness * bond_length_[begin + k] + (k == 0 ? p.head_stiffness : 0.0);
      diag[k] += tie[k];
      rhs[k] = tie[k] * vbar[begin + k];
    }
    c[0] = diag[0];
    for (std::int64_t k = 1; k < m; ++k) {
      const double factor = off[k - 1] / c[k - 1];
      c[k] = diag[k] - factor * off[k - 1];
      rhs[k] -= factor * rhs[k - 1];
    }
    rhs[m - 1] /= c[m - 1];
    for (std::int64_t k = m - 2; k >= 0; --k) rhs[k] = (rhs[k] - off[k] * rhs[k + 1]) / c[k];
    const double* d = geometry_.directions + 3 * j;
    for (std::int64_t k = 0; k < m; ++k) {
      const double g = beta * tie[k] * (vbar[begin + k] - rhs[k]);
      if (g != 0.0) spread(begin + k, d, g, out_force);
    }
  }
}

void GroutedBolts::rebase() {
  has_trial_ = false;
  ubar_reference_ = ubar_;
  bond_force_reference_ = bond_force_;
  // The committed state's total stored energy becomes the zero of the new run's account.
  const BoltParameters& p = parameters_;
  double total = 0.0;
  for (std::size_t e = 0; e < axial_force_.size(); ++e)
    total += segment_length_[e] * axial_force_[e] * axial_force_[e] / (2.0 * p.axial_stiffness);
  for (std::int64_t j = 0; j < geometry_.n_bolts; ++j)
    for (std::int64_t k = geometry_.bolt_offsets[j]; k < geometry_.bolt_offsets[j + 1]; ++k) {
      double bond = bond_force_[k];
      if (k == geometry_.bolt_offsets[j] && p.head_stiffness > 0.0) {
        const double head = p.head_stiffness * (w_[k] - ubar_[k]);
        total += 0.5 * head * head / p.head_stiffness;
        bond -= head;
      }
      if (bond_length_[k] > 0.0) total += bond * bond / (2.0 * p.bond_stiffness * bond_length_[k]);
    }
  stored_reference_ = total;
  stored_energy_ = 0.0;
}

void GroutedBolts::save_state(StateArchive& archive, const std::string& prefix) const {
  archive.put_value(prefix + "stored_energy", stored_energy_);
  archive.put_value(prefix + "dissipation", dissipation_);
  if (!archive.per_point()) return;
  archive.put(prefix + "w", w_);
  archive.put(prefix + "plastic_strain", plastic_strain_);
  archive.put(prefix + "plastic_slip", plastic_slip_);
  archive.put(prefix + "axial_force", axial_force_);
  archive.put(prefix + "bond_force", bond_force_);
  archive.put(prefix + "ubar", ubar_);
  archive.put(prefix + "peak_axial_force", peak_axial_force_);
  archive.put(prefix + "ubar_reference", ubar_reference_);
  archive.put(prefix + "bond_force_reference", bond_force_reference_);
  archive.put_value(prefix + "stored_reference", stored_reference_);
}

void GroutedBolts::load_state(const StateArchive& archive, const std::string& prefix) {
  archive.get_value(prefix + "stored_energy", stored_energy_);
  archive.get_value(prefix + "dissipation", dissipation_);
  has_trial_ = false;
  if (!archive.per_point()) return;
  archive.get(prefix + "w", w_);
  archive.get(prefix + "plastic_strain", plastic_strain_);
  archive.get(prefix + "plastic_slip", plastic_slip_);
  archive.get(prefix + "axial_force", axial_force_);
  archive.get(prefix + "bond_force", bond_force_);
  archive.get(prefix + "ubar", ubar_);
  archive.get(prefix + "peak_axial_force", peak_axial_force_);
  archive.get(prefix + "ubar_reference", ubar_reference_);
  archive.get(prefix + "bond_force_reference", bond_force_reference_);
  archive.get_value(prefix + "stored_reference", stored_reference_);
}

void GroutedBolts::check_nodes(std::int64_t n_nodes) const {
  if (!unique_nodes_.empty() && unique_nodes_.back() >= n_nodes)
    throw std::invalid_argument(name() + ": host node " + std::to_string(unique_nodes_.back()) +
                                " is outside the model's " + std::to_string(n_nodes) + " nodes");
}

std::vector<double> GroutedBolts::bond_slip() const {
  std::vector<double> slip(n_nodes_);
  for (std::int64_t k = 0; k < n_nodes_; ++k) slip[k] = w_[k] - ubar_[k];
  return slip;
}

}  // namespace cavern
