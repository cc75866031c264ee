#include "stepper.hpp"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "constraints.hpp"
#include "small_matrix.hpp"

namespace cavern {

Stepper::Stepper(const BlockCsrView& stiffness, const double* mass,
                 const StepperParameters& parameters)
    : SteppingBase(stiffness, mass), parameters_(parameters) {
  if (!(std::isfinite(parameters.dt) && parameters.dt > 0.0))
    throw std::invalid_argument("dt must be finite and > 0, got " + std::to_string(parameters.dt));
  if (!(std::isfinite(parameters.alpha) && parameters.alpha >= 0.0))
    throw std::invalid_argument("alpha must be finite and >= 0, got " +
                                std::to_string(parameters.alpha));
  if (!(std::isfinite(parameters.beta) && parameters.beta >= 0.0))
    throw std::invalid_argument("beta must be finite and >= 0, got " +
                                std::to_string(parameters.beta));
  external_force_.assign(n_dofs(), 0.0);
  if (parameters.beta != 0.0) v_half_.assign(n_dofs(), 0.0);
  threaded_ = stiffness.n_block_rows >= kMinRowsForThreads;
  if (parameters.single_precision_blocks && !parameters.symmetric_storage)
    throw std::invalid_argument(
        "single_precision_blocks needs symmetric_storage (the float blocks are the upper "
        "triangle's)");
  if (parameters.symmetric_storage) {
    if (parameters.single_precision_blocks)
      symmetric_ = std::make_unique<SymmetricBlockCsrSingle>(stiffness);
    else
      symmetric_ = std::make_unique<SymmetricBlockCsr>(stiffness);
    Ku_.assign(n_dofs(), 0.0);
    if (parameters.beta != 0.0) Kv_.assign(n_dofs(), 0.0);
  }
}

void Stepper::nodal_effects_changed(bool) {
  partition_checked_ = false;  // check_partition again at the next run
  build_implicit_slots();
}

void Stepper::set_mass_damping(double alpha) {
  if (!(std::isfinite(alpha) && alpha >= 0.0))
    throw std::invalid_argument("alpha must be finite and >= 0, got " + std::to_string(alpha));
  parameters_.alpha = alpha;
  build_implicit_slots();  // the slots' inverses hold M (1 + dt/2 alpha)
}

void Stepper::build_implicit_slots() {
  // One implicit slot per node with a dashpot, a constraint or both: the dashpots' slots first
  // (NodalEffects' order), then the nodes held without a dashpot.
  std::vector<std::int32_t> slot = effects_.dashpot_slot;
  std::vector<double> summed_C = effects_.dashpot_C;
  const std::int64_t n_constraints = effects_.n_constraints();
  for (std::int64_t k = 0; k < n_constraints; ++k) {
    const std::int32_t node = effects_.constraint_nodes[k];
    if (slot[node] < 0) {
      slot[node] = static_cast<std::int32_t>(summed_C.size() / 9);
      summed_C.resize(summed_C.size() + 9, 0.0);
    }
  }
  const std::size_t n_slots = summed_C.size() / 9;
  std::vector<std::int32_t> constraint_of_slot(n_slots, -1);
  for (std::int64_t k = 0; k < n_constraints; ++k)
    constraint_of_slot[slot[effects_.constraint_nodes[k]]] = static_cast<std::int32_t>(k);

  const double half_dt = 0.5 * parameters_.dt;
  std::vector<double> inverse(summed_C.size());
  for (std::int64_t node = 0; node < n_nodes(); ++node) {
    if (slot[node] < 0) continue;
    const std::int32_t constraint = constraint_of_slot[slot[node]];
    double A[9];
    implicit_node_operator(mass_[node], parameters_.alpha, half_dt, summed_C.data() + 9 * slot[node],
                           constraint >= 0 ? effects_.constraint_P.data() + 9 * constraint : nullptr, node,
                           A, inverse.data() + 9 * slot[node]);
  }

  if (n_slots == 0) slot.clear();  // nothing implicit: pass B skips the slot look-up
  dashpot_slot_ = std::move(slot);
  dashpot_C_ = std::move(summed_C);
  dashpot_inverse_ = std::move(inverse);
  constraint_of_slot_ = std::move(constraint_of_slot);
}

void Stepper::set_contact(std::shared_ptr<ContactPairs> contact) {
  partition_checked_ = false;  // check_partition again at the next run
  if (contact_)
    throw std::invalid_argument(
        "contact: this Stepper already has a ContactPairs; pass all "
        "pairs in one ContactPairs");
  contact->check_nodes(n_nodes());
  contact_ = std::move(contact);
  contact_scratch_.assign(6 * contact_->unique_nodes().size(), 0.0);
  // The pairs start carrying their static force only: no dynamic contact force, no power.
  contact_power_ = 0.0;
}

ImplicitNodeOperators Stepper::implicit_operators() const {
  ImplicitNodeOperators operators;
  operators.dt = parameters_.dt;
  operators.alpha = parameters_.alpha;
  operators.mass = mass_;
  operators.dashpot_slot = dashpot_slot_.empty() ? nullptr : dashpot_slot_.data();
  operators.dashpot_C = dashpot_C_.data();
  operators.dashpot_inverse = dashpot_inverse_.data();
  operators.constraint_of_slot = effects_.constraint_nodes.empty() ? nullptr : constraint_of_slot_.data();
  operators.constraint_projection = effects_.constraint_P.data();
  return operators;
}

void Stepper::contact_post_pass(double t, const double* u, double* v, double* a) {
  const std::vector<std::int32_t>& nodes = contact_->unique_nodes();
  const std::size_t n_pair_nodes = nodes.size();
  double* before = contact_scratch_.data();
  const bool threaded = static_cast<std::int64_t>(n_pair_nodes) >= 2 * kMinPairsForThreads;
#pragma omp parallel for schedule(static) if (threaded)
  for (std::size_t k = 0; k < n_pair_nodes; ++k)
    for (int c = 0; c < 3; ++c) {
      before[6 * k + c] = v[3 * nodes[k] + c];
      before[6 * k + 3 + c] = a[3 * nodes[k] + c];
    }

  const ImplicitNodeOperators operators = implicit_operators();
  const ContactStepResult result = contact_->correct(t, operators, u, v, a);

  // Pass B summed the pair nodes' energy terms without contact: add after minus before. The
  // external force f is not kept by pass B; M a = f - K u - g - d gives it back (d = implicit
  // damping + beta K v_{n+1/2}, unchanged stiffness part), and F = f + R - d = M a + K u + g.
  const double* g = components_.empty() ? nullptr : internal_force_.data();
  const double* g_damping = internal_damping_.empty() ? nullptr : internal_damping_.data();
  const double beta = parameters_.beta;
  double d_vMv = 0.0, d_aMa = 0.0, d_Fa = 0.0, d_external = 0.0, d_damping = 0.0;
#pragma omp parallel for schedule(static) if (threaded) \
    reduction(+ : d_vMv, d_aMa, d_Fa, d_external, d_damping)
  for (std::size_t k = 0; k < n_pair_nodes; ++k) {
    const std::int64_t node = nodes[k];
    const double m = mass_[node];
    double Ku[3], Kv[3] = {0.0, 0.0, 0.0}, damping[9], d_before[3], d_after[3];
    if (symmetric_) {
      // The same K u and K v_half pass B used (exactly symmetric storage).
      for (int c = 0; c < 3; ++c) {
        Ku[c] = Ku_[3 * node + c];
        if (beta != 0.0) Kv[c] = Kv_[3 * node + c];
      }
    } else {
      block_row_product(stiffness_, node, u, Ku);
      if (beta != 0.0) block_row_product(stiffness_, node, v_half_.data(), Kv);
    }
    operators.damping(node, damping);
    const double* v_before = before + 6 * k;
    const double* a_before = before + 6 * k + 3;
    const double* v_after = v + 3 * node;
    const double* a_after = a + 3 * node;
    multiply_3x3(damping, v_before, d_before);
    multiply_3x3(damping, v_after, d_after);
    if (g)
      for (int c = 0; c < 3; ++c) Ku[c] += g[3 * node + c];  // the whole internal force K u + g
    for (int c = 0; c < 3; ++c) {
      d_before[c] += beta * Kv[c];
      d_after[c] += beta * Kv[c];
      if (g_damping) {  // beta K0 v_{n+1/2} of the components' cells
        d_before[c] += g_damping[3 * node + c];
        d_after[c] += g_damping[3 * node + c];
      }
      const double f = m * a_before[c] + Ku[c] + d_before[c];
      d_vMv += m * (v_after[c] * v_after[c] - v_before[c] * v_before[c]);
      d_aMa += m * (a_after[c] * a_after[c] - a_before[c] * a_before[c]);
      d_Fa += (m * a_after[c] + Ku[c]) * a_after[c] - (m * a_before[c] + Ku[c]) * a_before[c];
      d_external += f * (v_after[c] - v_before[c]);
      d_damping += d_after[c] * v_after[c] - d_before[c] * v_before[c];
    }
  }
  const double dt = parameters_.dt;
  twice_kinetic_ += d_vMv;
  acceleration_term_ += -dt * dt / 8.0 * d_aMa + dt * dt / 4.0 * d_Fa;
  external_power_ += d_external;
  damping_power_ += d_damping;
  contact_power_ = result.contact_power;
  friction_dissipation_ += result.friction_dissipation;
}

void Stepper::set_partition(std::int64_t n_owned, std::shared_ptr<NodeExchange> exchange) {
  set_owned(n_owned);
  exchange_ = std::move(exchange);
  partition_checked_ = false;
}

void Stepper::check_partition() {
  if (n_owned_ < 0 || partition_checked_) return;
  std::vector<const ContactPairs*> pairs;
  if (contact_) pairs.push_back(contact_.get());
  require_effects_owned(pairs);
  partition_checked_ = true;
}

void Stepper::add_provider(std::shared_ptr<ForceProvider> provider) {
  partition_checked_ = false;  // check_partition again at the next run
  attach_provider(std::move(provider));
  // A provider added mid-run has done no work so far and applied no force at the last step.
  provider_work_.push_back(0.0);
  provider_power_.push_back(0.0);
}

void Stepper::add_internal_force(std::shared_ptr<InternalForceComponent> component,
                                 bool count_energy) {
  component->check_nodes(n_nodes());
  components_.push_back(std::move(component));
  component_counted_.push_back(count_energy ? 1 : 0);
  internal_force_.assign(n_dofs(), 0.0);
  if (parameters_.beta != 0.0) internal_damping_.assign(n_dofs(), 0.0);
  // g_n of the new component is unknown until reset_energy computes it.
  energy_started_ = false;
}

template <bool kStiffnessDamping, bool kSymmetric, bool kInternal>
void Stepper::pass_b(double* u, double* v, double* a) {
  if constexpr (kSymmetric) {
    const int threads = threaded_ ? omp_get_max_threads() : 1;
    if constexpr (kStiffnessDamping)
      symmetric_->multiply_dual(u, v_half_.data(), Ku_.data(), Kv_.data(), threads);
    else
      symmetric_->multiply(u, Ku_.data(), threads);
  }
  const bool threaded = threaded_;
  const BlockCsrView K = stiffness_;
  const double* mass = mass_;
  const double dt = parameters_.dt;
  const double half_dt = 0.5 * dt;
  const double alpha = parameters_.alpha;
  const double beta = parameters_.beta;
  const double* v_half = v_half_.data();
  double* f = external_force_.data();
  const std::int32_t* dashpot_slot = dashpot_slot_.empty() ? nullptr : dashpot_slot_.data();
  const double* dashpot_C = dashpot_C_.data();
  const double* dashpot_inverse = dashpot_inverse_.data();
  const std::int32_t* constraint_of_slot =
      effects_.constraint_nodes.empty() ? nullptr : constraint_of_slot_.data();
  const double* projection = effects_.constraint_P.data();
  double* reactions = reactions_.data();
  const double* g = internal_force_.data();
  const double* g_damping = internal_damping_.data();  // beta K0 v_{n+1/2} of the components
  const std::int64_t owned = n_owned_nodes();

  double vMv = 0.0, uKu = 0.0, aMa = 0.0, Fa = 0.0, external_power = 0.0, damping_power = 0.0;
#pragma omp parallel for schedule(static) if (threaded) \
    reduction(+ : vMv, uKu, aMa, Fa, external_power, damping_power)
  for (std::int64_t i = 0; i < K.n_block_rows; ++i) {
    double Ku[3], Kv[3] = {0.0, 0.0, 0.0};
    if constexpr (kSymmetric) {
      for (int c = 0; c < 3; ++c) {
        Ku[c] = Ku_[3 * i + c];
        if constexpr (kStiffnessDamping) Kv[c] = Kv_[3 * i + c];
      }
    } else if constexpr (kStiffnessDamping) {
      block_row_product_dual(K, i, u, v_half, Ku, Kv);
    } else {
      block_row_product(K, i, u, Ku);
    }

    const double m = mass[i];
    double* fi = f + 3 * i;
    double* vi = v + 3 * i;
    double* ai = a + 3 * i;
    const double* ui = u + 3 * i;
    double r[3], rhs[3], v_next[3], implicit_damping[3];
    for (int c = 0; c < 3; ++c) {
      r[c] = fi[c] - Ku[c] - beta * Kv[c];
      if constexpr (kInternal) {
        const double gi = g[3 * i + c];
        r[c] -= gi;
        if constexpr (kStiffnessDamping) r[c] -= g_damping[3 * i + c];
      }
      rhs[c] = m * vi[c] + half_dt * r[c];
    }
    const std::int32_t slot = dashpot_slot ? dashpot_slot[i] : -1;
    double net_force[3];
    if (slot < 0) {
      const double inverse = 1.0 / (m * (1.0 + half_dt * alpha));
      for (int c = 0; c < 3; ++c) {
        v_next[c] = rhs[c] * inverse;
        implicit_damping[c] = alpha * m * v_next[c];
        net_force[c] = r[c] - implicit_damping[c];
      }
    } else {
      multiply_3x3(dashpot_inverse + 9 * slot, rhs, v_next);
      multiply_3x3(dashpot_C + 9 * slot, v_next, implicit_damping);
      for (int c = 0; c < 3; ++c) {
        implicit_damping[c] += alpha * m * v_next[c];
        net_force[c] = r[c] - implicit_damping[c];
      }
      const std::int32_t constraint = constraint_of_slot ? constraint_of_slot[slot] : -1;
      if (constraint >= 0) {
        // The support takes the held part: R = -(I - P)(r - d), M a = P (r - d).
        double free_force[3];
        multiply_3x3(projection + 9 * constraint, net_force, free_force);
        for (int c = 0; c < 3; ++c) {
          reactions[3 * constraint + c] = free_force[c] - net_force[c];
          net_force[c] = free_force[c];
        }
      }
    }
    for (int c = 0; c < 3; ++c) {
      const double a_next = net_force[c] / m;
      double damping_force = implicit_damping[c] + beta * Kv[c];
      if constexpr (kInternal && kStiffnessDamping) damping_force += g_damping[3 * i + c];
      const double non_stiffness_force = fi[c] - damping_force;
      if (i < owned) {  // a ghost's row is its owner's to count (set_partition)
        vMv += m * v_next[c] * v_next[c];
        uKu += ui[c] * Ku[c];
        aMa += m * a_next * a_next;
        Fa += non_stiffness_force * a_next;
        external_power += fi[c] * v_next[c];
        damping_power += damping_force * v_next[c];
      }
      vi[c] = v_next[c];
      ai[c] = a_next;
      fi[c] = 0.0;  // ready for the providers of the next step
    }
  }
  twice_kinetic_ = vMv;
  twice_strain_ = uKu;
  acceleration_term_ = -dt * dt / 8.0 * aMa + dt * dt / 4.0 * Fa;
  external_power_ = external_power;
  damping_power_ = damping_power;
}

template <bool kInternal>
void Stepper::dispatch_pass_b(double* u, double* v, double* a) {
  if (symmetric_) {
    if (parameters_.beta != 0.0)
      pass_b<true, true, kInternal>(u, v, a);
    else
      pass_b<false, true, kInternal>(u, v, a);
  } else {
    if (parameters_.beta != 0.0)
      pass_b<true, false, kInternal>(u, v, a);
    else
      pass_b<false, false, kInternal>(u, v, a);
  }
}

double Stepper::pass_a_with_internal(double* u, double* v, const double* a) {
  const std::int64_t n = n_dofs();
  const double dt = parameters_.dt;
  const double half_dt = 0.5 * dt;
  const bool stiffness_damping = parameters_.beta != 0.0;
  double* v_half = v_half_.data();
  double* g = internal_force_.data();
  double* g_damping = internal_damping_.data();
  const std::int64_t owned_dofs = 3 * n_owned_nodes();
  double power = 0.0;
#pragma omp parallel for schedule(static) if (threaded_) reduction(+ : power)
  for (std::int64_t d = 0; d < n; ++d) {
    const double velocity_half = v[d] + half_dt * a[d];
    v[d] = velocity_half;
    u[d] += dt * velocity_half;
    if (d < owned_dofs) power += g[d] * velocity_half;  // g_n.v_{n+1/2}
    g[d] = 0.0;
    if (stiffness_damping) {
      v_half[d] = velocity_half;
      g_damping[d] = 0.0;
    }
  }
  if (stiffness_damping)
    for (auto& component : components_)
      component->add_stiffness_damping(v, parameters_.beta, g_damping);
  return power;
}

double Stepper::compute_internal_forces(const double* u) {
  double stored = 0.0;
  for (std::size_t k = 0; k < components_.size(); ++k) {
    const double component_stored = components_[k]->compute(u, internal_force_.data()).stored;
    if (component_counted_[k]) stored += component_stored;
  }
  return stored;
}

double Stepper::counted_dissipation() const {
  double dissipation = 0.0;
  for (std::size_t k = 0; k < components_.size(); ++k)
    if (component_counted_[k]) dissipation += components_[k]->dissipation();
  return dissipation;
}

double Stepper::internal_power(const double* v) const {
  const std::int64_t n = 3 * n_owned_nodes();
  const double* g = internal_force_.data();
  double power = 0.0;
#pragma omp parallel for schedule(static) if (threaded_) reduction(+ : power)
  for (std::int64_t d = 0; d < n; ++d) power += g[d] * v[d];
  return power;
}

void Stepper::accumulate_work(const double* v) {
  const double half_dt = 0.5 * parameters_.dt;
  for (std::size_t k = 0; k < providers_.size(); ++k) {
    const double power = providers_[k]->power(v);
    provider_work_[k] += half_dt * (provider_power_[k] + power);
    provider_power_[k] = power;
  }
}

double Stepper::run(double* u, double* v, double* a, std::int64_t n_steps, double t0) {
  check_partition();
  if (!energy_started_) reset_energy(u, v, a, t0);
  const std::int64_t n = n_dofs();
  const double dt = parameters_.dt;
  const double half_dt = 0.5 * dt;
  const bool stiffness_damping = parameters_.beta != 0.0;
  double* v_half = v_half_.data();
  double* f = external_force_.data();

  const bool internal = !components_.empty();

  PhaseTimes& times = phase_times_;
  for (std::int64_t step = 0; step < n_steps; ++step) {
    // Multiplying, not accumulating, keeps t free of drift over many steps.
    const double t_next = t0 + static_cast<double>(step + 1) * dt;

    double clock = omp_get_wtime();
    auto lap = [&clock](double& phase) {
      const double now = omp_get_wtime();
      phase += now - clock;
      clock = now;
    };
    double previous_internal_power = 0.0, stored = 0.0;
    if (internal) {
      previous_internal_power = pass_a_with_internal(u, v, a);
      lap(times.update);
      stored = compute_internal_forces(u);
      internal_power_ = internal_power(v);  // g_{n+1}.v_{n+1/2}, before pass B overwrites v
      lap(times.element_loop);
    } else {
#pragma omp parallel for schedule(static) if (threaded_)
      for (std::int64_t d = 0; d < n; ++d) {
        const double velocity_half = v[d] + half_dt * a[d];
        v[d] = velocity_half;
        u[d] += dt * velocity_half;
        if (stiffness_damping) v_half[d] = velocity_half;
      }
      lap(times.update);
    }

    for (auto& provider : providers_) provider->add_forces(t_next, u, v, f);
    lap(times.input_forces);

    const double previous_external_power = external_power_;
    const double previous_damping_power = damping_power_;
    const double previous_contact_power = contact_power_;
    if (internal)
      dispatch_pass_b<true>(u, v, a);
    else
      dispatch_pass_b<false>(u, v, a);
    lap(times.stiffness);
    if (contact_) {
      contact_post_pass(t_next, u, v, a);
      lap(times.contact);
    }
    if (exchange_) {
      exchange_->exchange(v, a);
      lap(times.exchange);
    }
    if (internal) {
      for (auto& component : components_) component->commit();
      const double dissipation = counted_dissipation();
      internal_work_ += half_dt * (previous_internal_power + internal_power_);
      internal_stored_ = stored;
      internal_dissipation_ = dissipation - dissipation_at_reset_;
      lap(times.element_loop);
    }
    external_work_ += half_dt * (previous_external_power + external_power_);
    damping_work_ += half_dt * (previous_damping_power + damping_power_);
    contact_work_ += half_dt * (previous_contact_power + contact_power_);
    accumulate_work(v);
    lap(times.input_forces);
    ++times.steps;
  }
  return t0 + static_cast<double>(n_steps) * dt;
}

void Stepper::reset_energy(const double* u, const double* v, const double* a, double t0) {
  check_partition();
  const std::int64_t n = n_dofs();
  std::vector<double> Ku(n);
  // The product the steps use (with float blocks: K rounded to float), so that H_0 is the same
  // energy as the steps' H_n.
  if (symmetric_)
    symmetric_->multiply(u, Ku.data(), threaded_ ? omp_get_max_threads() : 1);
  else
    spmv(stiffness_, u, Ku.data());
  // g(u_0) stays in internal_force_ as g_n of the first step's pass A.
  const double* g = nullptr;
  double stored = 0.0, dissipation = 0.0;
  if (!components_.empty()) {
    std::fill(internal_force_.begin(), internal_force_.end(), 0.0);
    stored = compute_internal_forces(u);
    dissipation = counted_dissipation();
    g = internal_force_.data();
  }
  double* f = external_force_.data();
  std::fill(external_force_.begin(), external_force_.end(), 0.0);
  for (auto& provider : providers_) provider->add_forces(t0, u, v, f);
  // The contact force of the last step is part of F_0 = M a_0 + K u_0, not damping.
  std::vector<double> contact_force;
  if (contact_) {
    contact_force.assign(n, 0.0);
    contact_->add_last_forces(contact_force.data());
    contact_->observe_velocity(v);
  }
  const double* contact_f = contact_ ? contact_force.data() : nullptr;

  double vMv = 0.0, uKu = 0.0, aMa = 0.0, Fa = 0.0, external_power = 0.0, damping_power = 0.0;
  const std::int64_t owned_dofs = 3 * n_owned_nodes();  // a ghost's energy is its owner's
#pragma omp parallel for schedule(static) \
    reduction(+ : vMv, uKu, aMa, Fa, external_power, damping_power)
  for (std::int64_t d = 0; d < owned_dofs; ++d) {
    const double m = mass_[d / 3];
    // The non-stiffness force that a_0 implies: M a_0 = F_0 - K u_0 - g(u_0).
    const double non_stiffness_force = m * a[d] + Ku[d] + (g ? g[d] : 0.0);
    vMv += m * v[d] * v[d];
    uKu += u[d] * Ku[d];
    aMa += m * a[d] * a[d];
    Fa += non_stiffness_force * a[d];
    external_power += f[d] * v[d];
    const double contact = contact_f ? contact_f[d] : 0.0;
    damping_power += (f[d] + contact - non_stiffness_force) * v[d];
  }
  std::fill(external_force_.begin(), external_force_.end(), 0.0);

  const double dt = parameters_.dt;
  twice_kinetic_ = vMv;
  twice_strain_ = uKu;
  acceleration_term_ = -dt * dt / 8.0 * aMa + dt * dt / 4.0 * Fa;
  initial_energy_ = 0.5 * vMv + 0.5 * uKu + acceleration_term_ + stored;
  internal_work_ = 0.0;
  internal_stored_ = stored;
  internal_dissipation_ = 0.0;
  dissipation_at_reset_ = dissipation;
  external_power_ = external_power;
  damping_power_ = damping_power;
  external_work_ = 0.0;
  damping_work_ = 0.0;
  contact_power_ = contact_ ? contact_->contact_power(v) : 0.0;
  contact_work_ = 0.0;
  friction_dissipation_ = 0.0;
  for (std::size_t k = 0; k < providers_.size(); ++k) {
    provider_power_[k] = providers_[k]->power(v);
    provider_work_[k] = 0.0;
  }
  energy_started_ = true;
}

EnergyReport Stepper::energy() const {
  EnergyReport report;
  report.kinetic = 0.5 * twice_kinetic_;
  report.strain = 0.5 * twice_strain_;
  report.total = report.kinetic + report.strain + acceleration_term_;
  report.initial = initial_energy_;
  if (!components_.empty()) {
    report.has_internal = true;
    report.internal_stored = internal_stored_;
    report.internal_dissipation = internal_dissipation_;
    report.internal_work = internal_work_;
    report.total += internal_stored_;
  }
  report.external_work = external_work_;
  report.damping_work = damping_work_;
  report.contact_work = contact_work_;
  report.friction_dissipation = friction_dissipation_;
  report.balance = report.total - report.initial - report.external_work + report.damping_work -
                   report.contact_work + report.internal_dissipation;
  for (const auto& provider : providers_) report.provider_names.push_back(provider->name());
  report.provider_work = provider_work_;
  return report;
}

namespace {
constexpr const char* kEnergyBlock = "stepper/energy";
constexpr const char* kParameterNames[] = {"dt",        "alpha",      "beta",   "dofs",
                                           "providers", "components", "contact"};
}  // namespace

std::vector<double> Stepper::checkpoint_parameters() const {
  return {parameters_.dt,
          parameters_.alpha,
          parameters_.beta,
          static_cast<double>(n_dofs()),
          static_cast<double>(providers_.size()),
          static_cast<double>(components_.size()),
          contact_ ? 1.0 : 0.0};
}

void Stepper::save_state(StateArchive& archive) const {
  archive.put("stepper/parameters", checkpoint_parameters());
  archive.put_value<std::uint8_t>("stepper/energy_started", energy_started_ ? 1 : 0);
  std::vector<double> energy;
  for (const double* term : energy_terms(*this)) energy.push_back(*term);
  archive.put(kEnergyBlock, energy);
  archive.put("stepper/provider_work", provider_work_);
  archive.put("stepper/provider_power", provider_power_);
  if (archive.per_point()) archive.put("stepper/internal_force", internal_force_);
  archive.put("stepper/reactions", reactions_);
  if (contact_) contact_->save_state(archive, "contact/");
  save_components(archive, "component/", components_);
}

void Stepper::load_state(const StateArchive& archive) {
  const std::vector<double> expected = checkpoint_parameters();
  std::vector<double> saved(expected.size());
  archive.get("stepper/parameters", saved);
  for (std::size_t j = 0; j < expected.size(); ++j)
    if (saved[j] != expected[j])
      throw std::invalid_argument("checkpoint: " + std::string(kParameterNames[j]) + " was " +
                                  std::to_string(saved[j]) + ", the model's is " +
                                  std::to_string(expected[j]) +
                                  " (a checkpoint of another scene?)");
  check_component_names(archive, "component/", components_, "");
  // Everything checked that can be checked without reading: now restore.
  std::uint8_t started = 0;
  archive.get_value("stepper/energy_started", started);
  const auto terms = energy_terms(*this);
  std::vector<double> energy(terms.size());
  archive.get(kEnergyBlock, energy);
  archive.get("stepper/provider_work", provider_work_);
  archive.get("stepper/provider_power", provider_power_);
  if (archive.per_point()) archive.get("stepper/internal_force", internal_force_);
  archive.get("stepper/reactions", reactions_);
  if (contact_) contact_->load_state(archive, "contact/");
  load_components(archive, "component/", components_);
  energy_started_ = started != 0;
  for (std::size_t j = 0; j < terms.size(); ++j) *terms[j] = energy[j];
}

}  // namespace cavern
