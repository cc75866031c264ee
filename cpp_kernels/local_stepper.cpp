#include "local_stepper.hpp"

#include <omp.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <unordered_map>
#include <stdexcept>
#include <string>

#include "constraints.hpp"
#include "small_matrix.hpp"

namespace cavern {

namespace {
// A level's loops run on the OpenMP threads from this many rows. It was 4 096 (the Stepper's
// kMinRowsForThreads) until 2026-11-29: a small graded model (17 892 dofs, levels of 2 598 / 1 318 /
// 1 162 / 886 nodes, a new user's trial) then stepped every level on one thread, and local stepping
// took 1.21 s against global stepping's 0.62 s on 2 threads; from 512 rows, 0.68 s (256 to 1 024
// measured alike, within this machine's noise; docs/local_stepping.md "When it is on").
constexpr std::int64_t kMinRowsForThreadsLocal = 512;

const std::shared_ptr<NodeExchange>& nullptr_exchange() {
  static const std::shared_ptr<NodeExchange> none;
  return none;
}
}

LocalStepper::LocalStepper(const BlockCsrView& stiffness, const double* mass,
                           const std::int32_t* node_level, double dt_fine, double alpha, int max_level)
    : SteppingBase(stiffness, mass), dt_fine_(dt_fine), alpha_(alpha) {
  if (!(std::isfinite(dt_fine) && dt_fine > 0.0))
    throw std::invalid_argument("dt_fine must be finite and > 0, got " + std::to_string(dt_fine));
  if (!(std::isfinite(alpha) && alpha >= 0.0))
    throw std::invalid_argument("alpha must be finite and >= 0, got " + std::to_string(alpha));
  const std::int64_t n = stiffness.n_block_rows;
  level_.assign(node_level, node_level + n);
  for (std::int64_t i = 0; i < n; ++i) {
    if (level_[i] < 0 || level_[i] >= kMaxLevels)
      throw std::invalid_argument("node_level[" + std::to_string(i) + "] = " +
                                  std::to_string(level_[i]) + " must be in [0, " +
                                  std::to_string(kMaxLevels) + ")");
    max_level_ = std::max(max_level_, level_[i]);
  }
  if (max_level >= 0) {  // a share of a model whose coarsest level may have no node here
    if (max_level < max_level_ || max_level >= kMaxLevels)
      throw std::invalid_argument("max_level = " + std::to_string(max_level) + " must be in [" +
                                  std::to_string(max_level_) + " (the nodes' largest level), " +
                                  std::to_string(kMaxLevels) + ")");
    max_level_ = max_level;
  }
  levels_.resize(max_level_ + 1);
  row_cap_.assign(n, kMaxLevels);
  build_levels();
  external_.assign(3 * n, 0.0);
  internal_.assign(3 * n, 0.0);
  own_power_.assign(2 * n, 0.0);
}

void LocalStepper::nodal_effects_changed(bool constraints) {
  build_dashpot_inverses();
  if (constraints) initialised_ = false;
}

void LocalStepper::set_partition(std::int64_t n_owned,
                                 std::vector<std::shared_ptr<NodeExchange>> exchanges) {
  set_owned(n_owned);
  exchanges_ = std::move(exchanges);
  initialised_ = false;
}

void LocalStepper::check_partition() const {
  if (n_owned_ < 0) return;
  if (!row_split_)
    throw std::invalid_argument("a share of a distributed model steps by the row split only (set_row_split): "
                                "in the column split coarser levels kick finer nodes between their drifts");
  if (exchanges_.size() != static_cast<std::size_t>(max_level_ + 1))
    throw std::invalid_argument("set_partition: " + std::to_string(exchanges_.size()) + " exchanges for " +
                                std::to_string(max_level_ + 1) + " levels (one per level, null: none)");
  std::vector<const ContactPairs*> pairs;
  for (const Level& level : levels_)
    for (const auto& set : level.contacts) pairs.push_back(set.get());
  require_effects_owned(pairs);
}

void LocalStepper::set_row_split(bool on) {
  row_split_ = on;
  levels_stale_ = true;
  initialised_ = false;
}

void LocalStepper::project(std::int64_t i, double* dv) const {
  const std::int32_t k = effects_.constraint_slot[i];
  if (k < 0) return;
  double projected[3];
  multiply_3x3(effects_.constraint_P.data() + 9 * k, dv, projected);
  for (int d = 0; d < 3; ++d) dv[d] = projected[d];
}

void LocalStepper::build_levels() {
  const std::int64_t n = n_nodes();
  const BlockCsrView& stiffness = stiffness_;
  // Rows touched by each level's columns or components, and each node's active (finest
  // touching) level.
  std::vector<int> active(n, 0);
  std::vector<std::uint8_t> loaded(n);
  // A capped row i moves its block K_ij from column j's level to the cap's finer one. The column
  // split conserves momentum because every level holds whole columns (sum_i K_ij = 0, the
  // rigid translation); the moved block breaks that at both levels. A diagonal block on node j
  // puts it back: -K_ij at the cap's level, +K_ij at column j's level (the matrix is unchanged).
  std::unordered_map<std::int64_t, std::array<double, 9>> balance;  // key: node * kMaxLevels + level
  for (std::int64_t i = 0; i < n; ++i) {
    if (row_cap_[i] >= kMaxLevels) continue;
    for (std::int64_t b = stiffness.indptr[i]; b < stiffness.indptr[i + 1]; ++b) {
      const std::int32_t j = stiffness.indices[b];
      if (j == i || level_[j] <= row_cap_[i]) continue;
      std::array<double, 9>& finer = balance.try_emplace(std::int64_t{j} * kMaxLevels + row_cap_[i]).first->second;
      std::array<double, 9>& own = balance.try_emplace(std::int64_t{j} * kMaxLevels + level_[j]).first->second;
      for (int e = 0; e < 9; ++e) {
        finer[e] -= stiffness.blocks[9 * b + e];
        own[e] += stiffness.blocks[9 * b + e];
      }
    }
  }
  for (int c = 0; c <= max_level_; ++c) {
    Level& level = levels_[c];
    const int k = max_level_ - c;
    level.step = dt_fine_ * static_cast<double>(std::int64_t{1} << k);
    level.rows.clear();
    level.row_ptr.assign(1, 0);
    level.columns.clear();
    level.blocks.clear();
    level.coarser_column.clear();
    level.own.clear();
    level.drift.clear();
    level.component_row.clear();
    std::fill(loaded.begin(), loaded.end(), 0);  // the nodes this level's components load
    for (const auto& component : level.components)
      for (const std::int32_t node : component->nodes()) loaded[node] = 1;
    if (row_split_) {  // the level's own rows, whole (set_row_split)
      level.coarser_nodes.clear();
      level.coarser_nodes_level.clear();
      for (std::int64_t i = 0; i < n; ++i) {
        if (loaded[i] && level_[i] < k)
          throw std::invalid_argument("row split: node " + std::to_string(i) + " at level " +
                                      std::to_string(level_[i]) + " is in an element-loop component at the "
                                      "coarser level " + std::to_string(k) + ": give each cell the finest "
                                      "level of its nodes (pyfem/local_stepping.py)");
        if (loaded[i] && level_[i] > k) {
          level.coarser_nodes.push_back(static_cast<std::int32_t>(i));
          level.coarser_nodes_level.push_back(static_cast<std::int8_t>(max_level_ - level_[i]));
        }
      }
      level.coarser_saved.assign(3 * level.coarser_nodes.size(), 0.0);
      level.coarser_force.assign(3 * level.coarser_nodes.size(), 0.0);
      for (std::int64_t i = 0; i < n; ++i) {
        if (level_[i] != k) continue;
        for (std::int64_t b = stiffness.indptr[i]; b < stiffness.indptr[i + 1]; ++b) {
          const std::int32_t j = stiffness.indices[b];
          level.columns.push_back(j);
          level.blocks.insert(level.blocks.end(), stiffness.blocks + 9 * b, stiffness.blocks + 9 * b + 9);
          level.coarser_column.push_back(static_cast<std::int8_t>(level_[j] > k ? max_level_ - level_[j] : -1));
        }
        level.rows.push_back(static_cast<std::int32_t>(i));
        level.row_ptr.push_back(static_cast<std::int64_t>(level.columns.size()));
        level.own.push_back(1);
        level.component_row.push_back(loaded[i]);
        active[i] = c;
      }
      level.force.assign(3 * level.rows.size(), 0.0);
      level.external.assign(3 * level.rows.size(), 0.0);
      continue;
    }
    for (std::int64_t i = 0; i < n; ++i) {
      const std::int64_t before = static_cast<std::int64_t>(level.columns.size());
      std::int64_t diagonal = -1;
      for (std::int64_t b = stiffness.indptr[i]; b < stiffness.indptr[i + 1]; ++b) {
        const std::int32_t j = stiffness.indices[b];
        if (std::min(level_[j], row_cap_[i]) != k) continue;
        if (j == i) diagonal = static_cast<std::int64_t>(level.columns.size());
        level.columns.push_back(j);
        level.blocks.insert(level.blocks.end(), stiffness.blocks + 9 * b, stiffness.blocks + 9 * b + 9);
      }
      if (!balance.empty()) {
        const auto found = balance.find(i * kMaxLevels + k);
        if (found != balance.end()) {
          if (diagonal < 0) {
            diagonal = static_cast<std::int64_t>(level.columns.size());
            level.columns.push_back(static_cast<std::int32_t>(i));
            level.blocks.insert(level.blocks.end(), 9, 0.0);
          }
          for (int e = 0; e < 9; ++e) level.blocks[9 * diagonal + e] += found->second[e];
        }
      }
      const bool own = level_[i] == k;
      if (static_cast<std::int64_t>(level.columns.size()) > before || own || loaded[i]) {
        level.rows.push_back(static_cast<std::int32_t>(i));
        level.row_ptr.push_back(static_cast<std::int64_t>(level.columns.size()));
        level.own.push_back(own ? 1 : 0);
        level.component_row.push_back(loaded[i]);
        active[i] = std::max(active[i], c);
      }
    }
    level.force.assign(3 * level.rows.size(), 0.0);
    level.external.assign(3 * level.rows.size(), 0.0);
  }
  drift_level_.assign(n, 0);
  for (std::int64_t i = 0; i < n; ++i) {
    levels_[active[i]].drift.push_back(static_cast<std::int32_t>(i));
    drift_level_[i] = max_level_ - active[i];
  }
  if (row_split_) {  // each own row's finer component forces (set_row_split)
    std::vector<std::vector<std::pair<std::int32_t, std::int32_t>>> entries(n);
    for (int c = 0; c <= max_level_; ++c)
      for (std::size_t q = 0; q < levels_[c].coarser_nodes.size(); ++q)
        entries[levels_[c].coarser_nodes[q]].emplace_back(c, static_cast<std::int32_t>(q));
    for (Level& level : levels_) {
      level.finer_ptr.assign(1, 0);
      level.finer_level.clear();
      level.finer_index.clear();
      for (const std::int32_t i : level.rows) {
        for (const auto& [c, q] : entries[i]) {
          level.finer_level.push_back(c);
          level.finer_index.push_back(q);
        }
        level.finer_ptr.push_back(static_cast<std::int64_t>(level.finer_level.size()));
      }
    }
  }
}

void LocalStepper::check_level(const char* what, int level) const {
  if (level < 0 || level > max_level_)
    throw std::invalid_argument(std::string(what) + " level " + std::to_string(level) + " must be in [0, " +
                                std::to_string(max_level_) + "]");
}

void LocalStepper::add_internal_force(std::shared_ptr<InternalForceComponent> component,
                                      int level, bool count_energy) {
  check_level("component", level);
  component->check_nodes(n_nodes());
  levels_[max_level_ - level].components.push_back(std::move(component));
  levels_[max_level_ - level].component_counted.push_back(count_energy ? 1 : 0);
  levels_stale_ = true;  // its rows join the level's at the next run (rebuild)
  initialised_ = false;
}

void LocalStepper::add_contact(std::shared_ptr<ContactPairs> pairs, int level) {
  check_level("contact", level);
  pairs->check_nodes(n_nodes());
  step_rows_at_drift_level(pairs->unique_nodes());
  Level& target = levels_[max_level_ - level];
  target.contacts.push_back(std::move(pairs));
  initialised_ = false;
}

void LocalStepper::step_rows_at_drift_level(const std::vector<std::int32_t>& nodes) {
  for (const std::int32_t node : nodes) {
    if (node < 0 || node >= n_nodes())
      throw std::invalid_argument("step_rows_at_drift_level: " + std::to_string(node) + " is not a node");
    capped_.push_back(node);
  }
  levels_stale_ = true;  // the caps are set at the next run, when every component is known
  initialised_ = false;
}

void LocalStepper::rebuild() {
  // Rows, blocks and drift lists of the components added so far; the capped rows then take their
  // nodes' drift levels from that build (a cap moves a row's blocks to a finer level than their
  // columns', which changes no node's drift level: the capped node drifts there already, and the
  // balance blocks it puts on its neighbours' diagonals sit at levels where they drift already)
  // and the levels are built again with them.
  if (!levels_stale_) {  // the constructor's build holds: only the providers' rows are new
    build_provider_rows();
    return;
  }
  levels_stale_ = false;
  std::fill(row_cap_.begin(), row_cap_.end(), kMaxLevels);
  if (row_split_) drift_end_.assign(max_level_ + 1, 0.0);
  build_levels();
  if (!capped_.empty() && !row_split_) {
    for (const std::int32_t node : capped_) {
      if (level_[node] != drift_level_[node])
        throw std::invalid_argument(
            "step_rows_at_drift_level: node " + std::to_string(node) + " steps at level " +
            std::to_string(level_[node]) + " but drifts at level " + std::to_string(drift_level_[node]) +
            ": its row can step at its drift level only if it steps there itself, so that every "
            "neighbour it reads drifts there too (pyfem/local_stepping.py equalize_pair_drift)");
      row_cap_[node] = drift_level_[node];
    }
    build_levels();
  }
  build_provider_rows();
}

void LocalStepper::check_contacts() const {
  // A pair node's element-loop force must reach it at every substep of its pairs' level: no
  // component at a coarser level may hold it (pyfem/local_stepping.py pair_cell_cap).
  std::vector<int> pair_level(static_cast<std::size_t>(n_nodes()), -1);
  for (int c = 0; c <= max_level_; ++c)
    for (const auto& pairs : levels_[c].contacts)
      for (const std::int32_t node : pairs->unique_nodes()) pair_level[node] = max_level_ - c;
  for (int c = 0; c <= max_level_; ++c)
    for (const auto& component : levels_[c].components)
      for (const std::int32_t node : component->nodes())
        if (pair_level[node] >= 0 && max_level_ - c > pair_level[node])
          throw std::invalid_argument(
              "contact pair node " + std::to_string(node) + " (pairs at level " +
              std::to_string(pair_level[node]) + ") is loaded by an element-loop component at the coarser "
              "level " + std::to_string(max_level_ - c) + ": its force would reach the pair as kicks at the "
              "ends of the coarse step (pyfem/local_stepping.py pair_cell_cap)");
  for (int c = 0; c <= max_level_; ++c) {
    const int k = max_level_ - c;
    for (const auto& pairs : levels_[c].contacts)
      for (const std::int32_t node : pairs->unique_nodes()) {
        if (effects_.constraint_slot[node] >= 0)
          throw std::invalid_argument("contact pair node " + std::to_string(node) +
                                      " is constrained: local time stepping does not take contact "
                                      "pairs on fixed or roller faces");
        if (drift_level_[node] != k || level_[node] != k)
          throw std::invalid_argument(
              "contact pair node " + std::to_string(node) + " steps at level " +
              std::to_string(level_[node]) + " and drifts at level " +
              std::to_string(drift_level_[node]) + ", its pairs at level " + std::to_string(k) +
              ": both nodes of a pair must step and drift at its level (pyfem/local_stepping.py "
              "equalize_pair_drift)");
      }
  }
}

void LocalStepper::correct_contacts(int c, double t, const double* u, double* v) {
  Level& level = levels_[c];
  const double h = level.step;
  // Stepper's operators at this level's step: correct() then gives dv = h/2 A^-1 R and
  // da = (R - (alpha M + C) dv) / M with A = M (1 + h/2 alpha) + h/2 C, and dv + h/2 da = h A^-1 R
  // is what Stepper's correction (in its end update) and its next start kick add to the drift's
  // velocity; its prediction u + h v + h^2/2 a with v + h/2 a = the drift's velocity is exact here.
  ImplicitNodeOperators operators;
  operators.dt = h;
  operators.alpha = alpha_;
  operators.mass = mass_;
  operators.dashpot_slot = effects_.dashpot_C.empty() ? nullptr : effects_.dashpot_slot.data();
  operators.dashpot_C = effects_.dashpot_C.data();
  operators.dashpot_inverse = level.implicit_inverse.data();
  // The slip rate the pairs keep for their next correction (the deterioration's gamma, the normal
  // lag's decay) is Stepper's: that of v(t) + dv, the velocity at the step's start with half the
  // impulse, not the drift's velocity half a step later (a first-order difference in dt).
  // contact_observed_v_ holds v(t) (substep); minus the drift's velocity, plus the corrected one.
  double* observed = contact_observed_v_.data();
  // The impulses' work is that over the drift they start, m dv . v_drift (dv the velocity they add):
  // not the kinetic energy they add, which is larger by m dv^2 / 2. A pair that holds a force f
  // between halves of mass m each takes back, in every substep, the h f / m by which the two kicks
  // around it drove the halves apart: the kinetic energy falls by h^2 f^2 / m each time and the
  // kicks give it back, but a kinetic measure would book it as work every substep (a drift of the
  // balance, docs/local_stepping.md "The energy account").
  for (const auto& pairs : level.contacts) {
    const std::vector<std::int32_t>& nodes = pairs->unique_nodes();
    for (const std::int64_t i : nodes)
      for (int d = 0; d < 3; ++d) {
        contact_a_[3 * i + d] = 0.0;  // v is the drift's velocity: u(t + h) = u + h v
        contact_before_v_[3 * i + d] = v[3 * i + d];
        observed[3 * i + d] -= v[3 * i + d];
      }
    const ContactStepResult result = pairs->correct(t, operators, u, v, contact_a_.data(), false);
    double work = 0.0;
    for (const std::int64_t i : nodes)
      for (int d = 0; d < 3; ++d) {
        observed[3 * i + d] += v[3 * i + d];  // v(t) + dv
        v[3 * i + d] += 0.5 * h * contact_a_[3 * i + d];
        work += mass_[i] * (v[3 * i + d] - contact_before_v_[3 * i + d]) * v[3 * i + d];
      }
    pairs->observe_velocity(observed);
    energy_.contact_work += work;
    energy_.friction_dissipation += result.friction_dissipation;
  }
}

void LocalStepper::build_dashpot_inverses() {
  for (Level& level : levels_) {
    level.implicit_inverse.assign(effects_.dashpot_C.size(), 0.0);
    const double half = 0.5 * level.step;
    // Every dashpot node at every level's step: the end kicks use their own level's, the contact
    // impulses (correct_contacts) their drift level's.
    for (std::int64_t node = 0; node < n_nodes(); ++node) {
      const std::int32_t slot = effects_.dashpot_slot[node];
      if (slot < 0) continue;
      double A[9];
      implicit_node_operator(mass_[node], alpha_, half, effects_.dashpot_C.data() + 9 * slot, nullptr, node,
                             A, level.implicit_inverse.data() + 9 * slot);
    }
  }
}

void LocalStepper::add_provider(std::shared_ptr<ForceProvider> provider) {
  const std::vector<std::int32_t> nodes = provider->nodes();
  if (nodes.empty())
    throw std::invalid_argument("LocalStepper: provider '" + provider->name() +
                                "' does not list its nodes");
  attach_provider(provider);
  provider_nodes_.insert(provider_nodes_.end(), nodes.begin(), nodes.end());
  std::sort(provider_nodes_.begin(), provider_nodes_.end());
  provider_nodes_.erase(std::unique(provider_nodes_.begin(), provider_nodes_.end()),
                        provider_nodes_.end());
  initialised_ = false;  // its rows are found at the next run (rebuild)
}

void LocalStepper::build_provider_rows() {
  for (Level& level : levels_) {
    level.provider_rows.clear();
    for (std::size_t r = 0; r < level.rows.size(); ++r)
      if (level.own[r] &&
          std::binary_search(provider_nodes_.begin(), provider_nodes_.end(), level.rows[r]))
        level.provider_rows.push_back(static_cast<std::int32_t>(r));
  }
}

double LocalStepper::work_fraction() const {
  // Per global step level c does 2^c kicks' products over its blocks; global stepping at dt_fine
  // does 2^L products over all blocks.
  double work = 0.0;
  for (int c = 0; c <= max_level_; ++c)
    work += static_cast<double>(std::int64_t{1} << c) * static_cast<double>(levels_[c].columns.size());
  return work / (static_cast<double>(std::int64_t{1} << max_level_) *
                 static_cast<double>(stiffness_.n_blocks()));
}

void LocalStepper::start_kick(int c, double h, double* v) {
  const double started = omp_get_wtime();
  Level& level = levels_[c];
  const double half = 0.5 * h;
  const std::int64_t n_rows = static_cast<std::int64_t>(level.rows.size());
#pragma omp parallel for schedule(static) if (n_rows >= kMinRowsForThreadsLocal)
  for (std::int64_t r = 0; r < n_rows; ++r) {
    const std::int64_t i = level.rows[r];
    double* vi = v + 3 * i;
    const double* force = level.force.data() + 3 * r;
    const double m = mass_[i];
    if (!level.own[r]) {
      double dv[3] = {half * force[0] / m, half * force[1] / m, half * force[2] / m};
      project(i, dv);  // a constrained node's held part goes to the support
      for (int d = 0; d < 3; ++d) vi[d] += dv[d];
      continue;
    }
    // The node's own level: its damping at the velocity it has now (other levels' kicks may have
    // changed it since this level's last end kick), explicit in this half as in Stepper's pass A.
    double damping[3] = {alpha_ * m * vi[0], alpha_ * m * vi[1], alpha_ * m * vi[2]};
    const std::int32_t slot = effects_.dashpot_slot[i];
    if (slot >= 0) {
      double C_v[3];
      multiply_3x3(effects_.dashpot_C.data() + 9 * slot, vi, C_v);
      for (int d = 0; d < 3; ++d) damping[d] += C_v[d];
    }
    const double* external = level.external.data() + 3 * r;
    double external_power = 0.0, damping_power = 0.0;
    for (int d = 0; d < 3; ++d) {
      external_power += external[d] * vi[d];
      damping_power += damping[d] * vi[d];
    }
    own_power_[2 * i] = external_power;
    own_power_[2 * i + 1] = damping_power;
    double dv[3];
    for (int d = 0; d < 3; ++d) dv[d] = half * (force[d] - damping[d]) / m;
    project(i, dv);  // the held part goes to the support
    for (int d = 0; d < 3; ++d) vi[d] += dv[d];
  }
  phase_times_.stiffness += omp_get_wtime() - started;
}

void LocalStepper::end_kick(int c, double h, double t, const double* u, double* v, bool initial) {
  Level& level = levels_[c];
  const double half = 0.5 * h;
  // External forces of this level's own nodes at t (not in the initial evaluation: the first start
  // kick, like Stepper's first pass A from a_0 = M^-1 (-K u_0 - d(v_0)), has none).
  double clock = omp_get_wtime();
  auto lap = [&clock](double& phase) {
    const double now = omp_get_wtime();
    phase += now - clock;
    clock = now;
  };
  if (!level.provider_rows.empty() && !initial) {
    for (auto& provider : providers_) provider->add_forces(t, u, v, external_.data());
  }
  lap(phase_times_.input_forces);
  // The level's element-loop cells at the new u (their trial state; committed below). Row split:
  // their coarser nodes read along their drift (u restored exactly after), and their force on them
  // kept for those nodes' own end kicks.
  const std::int64_t n_coarser = static_cast<std::int64_t>(level.coarser_nodes.size());
  double* moving = const_cast<double*>(u);  // the caller's state (substep), put back below
  for (std::int64_t q = 0; q < n_coarser; ++q) {
    const std::int64_t j = level.coarser_nodes[q];
    const double behind = drift_end_[level.coarser_nodes_level[q]] - t;
    for (int d = 0; d < 3; ++d) {
      level.coarser_saved[3 * q + d] = u[3 * j + d];
      moving[3 * j + d] -= behind * v[3 * j + d];
    }
  }
  for (const auto& component : level.components) component->compute(u, internal_.data());
  for (std::int64_t q = 0; q < n_coarser; ++q) {
    const std::int64_t j = level.coarser_nodes[q];
    for (int d = 0; d < 3; ++d) {
      moving[3 * j + d] = level.coarser_saved[3 * q + d];
      level.coarser_force[3 * q + d] = internal_[3 * j + d];
      internal_[3 * j + d] = 0.0;
    }
  }
  lap(phase_times_.element_loop);
  const std::int64_t n_rows = static_cast<std::int64_t>(level.rows.size());
  const std::int64_t owned = n_owned_nodes();
  double external_work = 0.0, damping_work = 0.0;
#pragma omp parallel for schedule(static) if (n_rows >= kMinRowsForThreadsLocal) \
    reduction(+ : external_work, damping_work)
  for (std::int64_t r = 0; r < n_rows; ++r) {
    const std::int64_t i = level.rows[r];
    double f[3] = {0.0, 0.0, 0.0};
    if (row_split_) {  // a coarser column along its drift: u_j - (T_j - t) v_j
      for (std::int64_t b = level.row_ptr[r]; b < level.row_ptr[r + 1]; ++b) {
        const double* block = level.blocks.data() + 9 * b;
        const std::int64_t j = level.columns[b];
        double uj[3] = {u[3 * j], u[3 * j + 1], u[3 * j + 2]};
        const int coarser = level.coarser_column[b];
        if (coarser >= 0) {
          const double behind = drift_end_[coarser] - t;
          for (int d = 0; d < 3; ++d) uj[d] -= behind * v[3 * j + d];
        }
        f[0] -= block[0] * uj[0] + block[1] * uj[1] + block[2] * uj[2];
        f[1] -= block[3] * uj[0] + block[4] * uj[1] + block[5] * uj[2];
        f[2] -= block[6] * uj[0] + block[7] * uj[1] + block[8] * uj[2];
      }
    } else {
      for (std::int64_t b = level.row_ptr[r]; b < level.row_ptr[r + 1]; ++b) {
        const double* block = level.blocks.data() + 9 * b;
        const double* uj = u + 3 * static_cast<std::int64_t>(level.columns[b]);
        f[0] -= block[0] * uj[0] + block[1] * uj[1] + block[2] * uj[2];
        f[1] -= block[3] * uj[0] + block[4] * uj[1] + block[5] * uj[2];
        f[2] -= block[6] * uj[0] + block[7] * uj[1] + block[8] * uj[2];
      }
    }
    if (level.component_row[r])
      for (int d = 0; d < 3; ++d) {
        f[d] -= internal_[3 * i + d];
        internal_[3 * i + d] = 0.0;  // ready for the next level's components
      }
    if (row_split_)  // finer levels' cells on this node, evaluated at t by their end kicks
      for (std::int64_t e = level.finer_ptr[r]; e < level.finer_ptr[r + 1]; ++e) {
        const double* from = levels_[level.finer_level[e]].coarser_force.data() + 3 * level.finer_index[e];
        for (int d = 0; d < 3; ++d) f[d] -= from[d];
      }
    const double m = mass_[i];
    double* vi = v + 3 * i;
    double* force = level.force.data() + 3 * r;
    if (!level.own[r]) {
      double dv[3] = {half * f[0] / m, half * f[1] / m, half * f[2] / m};
      project(i, dv);  // a constrained node's held part goes to the support
      for (int d = 0; d < 3; ++d) {
        force[d] = f[d];
        vi[d] += dv[d];
      }
      continue;
    }
    double external[3] = {external_[3 * i], external_[3 * i + 1], external_[3 * i + 2]};
    double* stored_external = level.external.data() + 3 * r;
    for (int d = 0; d < 3; ++d) {
      force[d] = f[d] + external[d];  // the start kick adds the damping at its own velocity
      stored_external[d] = external[d];
    }
    double rhs[3], v_new[3], damping[3];
    for (int d = 0; d < 3; ++d) rhs[d] = m * vi[d] + half * (f[d] + external[d]);
    const std::int32_t slot = effects_.dashpot_slot[i];
    if (initial) {  // the state's own force and damping at v, nothing stepped
      double C_v[3] = {0.0, 0.0, 0.0};
      if (slot >= 0) multiply_3x3(effects_.dashpot_C.data() + 9 * slot, vi, C_v);
      for (int d = 0; d < 3; ++d) {
        v_new[d] = vi[d];
        damping[d] = alpha_ * m * vi[d] + C_v[d];
      }
    } else if (effects_.constraint_slot[i] >= 0) {  // P A P v_new = P rhs (constraints.hpp)
      double A[9] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0}, A_inverse[9] = {}, C_v[3] = {0.0, 0.0, 0.0};
      if (slot >= 0)
        for (int k = 0; k < 9; ++k) A[k] = half * effects_.dashpot_C[9 * slot + k];
      for (int d = 0; d < 3; ++d) A[4 * d] += m * (1.0 + half * alpha_);
      // A is positive definite (m > 0, C positive semi-definite: set_dashpots checks it), so the
      // restricted matrix is regular.
      constrained_inverse(A, effects_.constraint_P.data() + 9 * effects_.constraint_slot[i], A_inverse);
      multiply_3x3(A_inverse, rhs, v_new);
      if (slot >= 0) multiply_3x3(effects_.dashpot_C.data() + 9 * slot, v_new, C_v);
      for (int d = 0; d < 3; ++d) damping[d] = alpha_ * m * v_new[d] + C_v[d];
    } else if (slot < 0) {
      const double inverse = 1.0 / (m * (1.0 + half * alpha_));
      for (int d = 0; d < 3; ++d) {
        v_new[d] = rhs[d] * inverse;
        damping[d] = alpha_ * m * v_new[d];
      }
    } else {
      multiply_3x3(level.implicit_inverse.data() + 9 * slot, rhs, v_new);
      multiply_3x3(effects_.dashpot_C.data() + 9 * slot, v_new, damping);
      for (int d = 0; d < 3; ++d) damping[d] += alpha_ * m * v_new[d];
    }
    double external_power = 0.0, damping_power = 0.0;
    for (int d = 0; d < 3; ++d) {
      vi[d] = v_new[d];
      external_power += external[d] * v_new[d];
      damping_power += damping[d] * v_new[d];
    }
    // Trapezoid rule over the node's own substep (its start kick to this end kick); a ghost's is
    // its owner's to count (set_partition).
    if (i < owned) {
      external_work += half * (own_power_[2 * i] + external_power);
      damping_work += half * (own_power_[2 * i + 1] + damping_power);
    }
  }
  energy_.external_work += external_work;
  energy_.damping_work += damping_work;
  lap(phase_times_.stiffness);
  // The initial evaluation only reads the committed state (no step was taken).
  if (!initial)
    for (const auto& component : level.components) component->commit();
  lap(phase_times_.element_loop);
  if (!level.provider_rows.empty() && !initial)
    for (const std::int32_t node : provider_nodes_)
      for (int d = 0; d < 3; ++d) external_[3 * static_cast<std::int64_t>(node) + d] = 0.0;
  lap(phase_times_.input_forces);
}

void LocalStepper::substep(int c, double h, double t, double* u, double* v) {
  for (const auto& pairs : levels_[c].contacts)  // v(t) of the pair nodes (correct_contacts)
    for (const std::int64_t i : pairs->unique_nodes())
      for (int d = 0; d < 3; ++d) contact_observed_v_[3 * i + d] = v[3 * i + d];
  start_kick(c, h, v);
  // Every kick that moves this level's drift nodes before their drift ends has been given (coarser
  // levels' start kicks at t came first, finer levels do not touch them): the pairs' impulses now.
  if (!levels_[c].contacts.empty()) {
    const double started = omp_get_wtime();
    correct_contacts(c, t, u, v);
    phase_times_.contact += omp_get_wtime() - started;
  }
  if (row_split_) drift_end_[c] = t + h;  // this level's nodes now drift to t + h
  // A share (set_partition): the ghosts of this level take their owners' drift velocity.
  const std::shared_ptr<NodeExchange>& exchange =
      exchanges_.empty() ? nullptr_exchange() : exchanges_[max_level_ - c];
  if (exchange) {
    const double started = omp_get_wtime();
    exchange->exchange(v, nullptr);
    phase_times_.exchange += omp_get_wtime() - started;
  }
  const double drift_started = omp_get_wtime();
  const std::vector<std::int32_t>& drift = levels_[c].drift;
  const std::int64_t n_drift = static_cast<std::int64_t>(drift.size());
#pragma omp parallel for schedule(static) if (n_drift >= kMinRowsForThreadsLocal)
  for (std::int64_t k = 0; k < n_drift; ++k) {
    const std::int64_t i = drift[k];
    for (int d = 0; d < 3; ++d) u[3 * i + d] += h * v[3 * i + d];
  }
  phase_times_.update += omp_get_wtime() - drift_started;
  if (c < max_level_) {
    substep(c + 1, 0.5 * h, t, u, v);
    substep(c + 1, 0.5 * h, t + 0.5 * h, u, v);
  }
  end_kick(c, h, t + h, u, v, false);
}

void LocalStepper::prepare_structure() {
  rebuild();
  check_contacts();
  check_partition();
  // Each constrained node's implicit update at every level's step (its own end kicks use its own
  // level's; checked at all, before any OpenMP loop can meet a singular one).
  for (std::int64_t i = 0; i < n_nodes(); ++i) {
    const std::int32_t k = effects_.constraint_slot[i];
    if (k < 0) continue;
    const std::int32_t slot = effects_.dashpot_slot[i];
    for (const Level& level : levels_) {
      double A[9], A_inverse[9];
      implicit_node_operator(mass_[i], alpha_, 0.5 * level.step,
                             slot >= 0 ? effects_.dashpot_C.data() + 9 * slot : nullptr,
                             effects_.constraint_P.data() + 9 * k, i, A, A_inverse);
    }
  }
  if (contact_a_.empty())
    for (const Level& level : levels_)
      if (!level.contacts.empty()) {
        contact_a_.assign(3 * n_nodes(), 0.0);
        contact_observed_v_.assign(3 * n_nodes(), 0.0);
        contact_before_v_.assign(3 * n_nodes(), 0.0);
      }
}

void LocalStepper::initialise(const double* u, const double* v, double t0) {
  prepare_structure();
  std::fill(drift_end_.begin(), drift_end_.end(), t0);  // row split: every node at its drift's end
  // Every level's force at (u, v, t0): an end kick of zero length that keeps v.
  std::vector<double> v_copy(v, v + 3 * n_nodes());
  // Row split: finest first, so that a coarser row reads its finer cells' forces at t0.
  for (int k = 0; k <= max_level_; ++k) {
    const int c = row_split_ ? max_level_ - k : k;
    end_kick(c, 0.0, t0, u, v_copy.data(), true);
  }
  // The pairs' slip rate for D is that of the state (Stepper::reset_energy).
  for (Level& level : levels_)
    for (const auto& pairs : level.contacts) pairs->observe_velocity(v);
  energy_.contact_work = energy_.friction_dissipation = 0.0;
  // Initial powers for the trapezoid rule at each own node.
  energy_.initial = 0.0;
  dissipation_at_start_ = measure_state(u, v);
  energy_.internal_dissipation = 0.0;
  energy_.initial = energy_.kinetic + energy_.strain + energy_.internal_stored;
  energy_.external_work = energy_.damping_work = 0.0;
  energy_.balance = 0.0;
  initialised_ = true;
}

double LocalStepper::measure_state(const double* u, const double* v) {
  double kinetic = 0.0;
  for (std::int64_t i = 0; i < n_owned_nodes(); ++i)  // a ghost's energy is its owner's
    for (int d = 0; d < 3; ++d) kinetic += 0.5 * mass_[i] * v[3 * i + d] * v[3 * i + d];
  energy_.kinetic = kinetic;
  energy_.strain = strain_energy(u);
  energy_.internal_stored = 0.0;
  double dissipation = 0.0;
  for (const Level& level : levels_)
    for (std::size_t k = 0; k < level.components.size(); ++k)
      if (level.component_counted[k]) {
        energy_.internal_stored += level.components[k]->stored_energy();
        dissipation += level.components[k]->dissipation();
      }
  return dissipation;
}

double LocalStepper::strain_energy(const double* u) const {
  double twice = 0.0;
  const std::int64_t n = n_owned_nodes();  // owned rows: the ranks' sums add up to u.K u
#pragma omp parallel for schedule(static) if (n >= kMinRowsForThreadsLocal) reduction(+ : twice)
  for (std::int64_t i = 0; i < n; ++i) {
    double Ku[3];
    block_row_product(stiffness_, i, u, Ku);
    for (int d = 0; d < 3; ++d) twice += u[3 * i + d] * Ku[d];
  }
  return 0.5 * twice;
}

double LocalStepper::run(double* u, double* v, double* a, std::int64_t n_steps, double t0) {
  if (!initialised_) initialise(u, v, t0);
  const double step = dt();
  for (std::int64_t s = 0; s < n_steps; ++s)
    substep(0, step, t0 + static_cast<double>(s) * step, u, v);
  phase_times_.steps += n_steps * (std::int64_t{1} << max_level_);
  // Total acceleration: the sum over the levels touching a node (every level's last end kick is
  // at the end of the global step).
  const std::int64_t n = n_nodes();
  std::fill(a, a + 3 * n, 0.0);
  for (const Level& level : levels_)
    for (std::size_t r = 0; r < level.rows.size(); ++r)
      for (int d = 0; d < 3; ++d) a[3 * static_cast<std::int64_t>(level.rows[r]) + d] += level.force[3 * r + d];
  for (std::int64_t i = 0; i < n; ++i) {
    double damping[3] = {alpha_ * mass_[i] * v[3 * i], alpha_ * mass_[i] * v[3 * i + 1], alpha_ * mass_[i] * v[3 * i + 2]};
    if (effects_.dashpot_slot[i] >= 0) {
      double C_v[3];
      multiply_3x3(effects_.dashpot_C.data() + 9 * effects_.dashpot_slot[i], v + 3 * i, C_v);
      for (int d = 0; d < 3; ++d) damping[d] += C_v[d];
    }
    for (int d = 0; d < 3; ++d) a[3 * i + d] -= damping[d];
    const std::int32_t k = effects_.constraint_slot[i];
    if (k >= 0) {  // the held part of the net force is the support's reaction, R = -(I - P)(r - d)
      double free_part[3];
      multiply_3x3(effects_.constraint_P.data() + 9 * k, a + 3 * i, free_part);
      for (int d = 0; d < 3; ++d) {
        reactions_[3 * k + d] = free_part[d] - a[3 * i + d];
        a[3 * i + d] = free_part[d];
      }
    }
    for (int d = 0; d < 3; ++d) a[3 * i + d] /= mass_[i];
  }
  energy_.internal_dissipation = measure_state(u, v) - dissipation_at_start_;
  energy_.balance = energy_.kinetic + energy_.strain + energy_.internal_stored - energy_.initial -
                    energy_.external_work + energy_.damping_work + energy_.internal_dissipation -
                    energy_.contact_work;
  return t0 + static_cast<double>(n_steps) * step;
}

namespace {
// The energy account's terms in a checkpoint, in this order.
std::vector<double*> energy_terms(LocalStepper::Energy& e) {
  return {&e.kinetic,       &e.strain,          &e.external_work,        &e.damping_work,
          &e.initial,       &e.internal_stored, &e.internal_dissipation, &e.contact_work,
          &e.friction_dissipation, &e.balance};
}

std::string level_prefix(int c) { return "lts/level/" + std::to_string(c) + "/"; }
}  // namespace

namespace {
// What checkpoint_parameters() holds, in order; then two per level (components, pairs).
constexpr const char* kLocalParameterNames[] = {"dt_fine", "alpha", "nodes", "max_level", "providers",
                                                "constraints"};

std::string local_parameter_name(std::size_t j, std::size_t levels) {
  constexpr std::size_t fixed = sizeof(kLocalParameterNames) / sizeof(kLocalParameterNames[0]);
  if (j < fixed) return kLocalParameterNames[j];
  if (j == fixed + 2 * levels) return "the row split (set_row_split)";
  return std::string((j - fixed) % 2 ? "contact pair sets" : "element-loop components") + " at coarse level " +
         std::to_string((j - fixed) / 2);
}
}  // namespace

std::vector<double> LocalStepper::checkpoint_parameters() const {
  std::vector<double> parameters{dt_fine_, alpha_, static_cast<double>(n_nodes()),
                                 static_cast<double>(max_level_), static_cast<double>(providers_.size()),
                                 static_cast<double>(effects_.constraint_P.size() / 9)};
  for (const Level& level : levels_) {
    parameters.push_back(static_cast<double>(level.components.size()));
    parameters.push_back(static_cast<double>(level.contacts.size()));
  }
  if (row_split_) parameters.push_back(1.0);  // absent for the column split: its checkpoints as before
  return parameters;
}

void LocalStepper::save_state(StateArchive& archive) const {
  archive.put("lts/parameters", checkpoint_parameters());
  archive.put("lts/node_level", level_);
  archive.put_value<std::uint8_t>("lts/started", initialised_ ? 1 : 0);
  if (!initialised_) return;  // the first run() computes everything from (u, v)
  Energy energy = energy_;
  std::vector<double> terms;
  for (const double* term : energy_terms(energy)) terms.push_back(*term);
  archive.put("lts/energy", terms);
  archive.put_value("lts/dissipation_at_start", dissipation_at_start_);
  archive.put("lts/reactions", reactions_);
  for (int c = 0; c <= max_level_; ++c) {
    const Level& level = levels_[c];
    const std::string prefix = level_prefix(c);
    if (archive.per_point()) {  // per row: not in a sample's state (StateArchive::per_point)
      archive.put(prefix + "force", level.force);
      archive.put(prefix + "external", level.external);
    }
    save_components(archive, prefix + "component/", level.components);
    for (std::size_t k = 0; k < level.contacts.size(); ++k)
      level.contacts[k]->save_state(archive, prefix + "contact/" + std::to_string(k) + "/");
  }
}

void LocalStepper::load_state(const StateArchive& archive) {
  const std::vector<double> expected = checkpoint_parameters();
  std::vector<double> saved;
  archive.get_resized("lts/parameters", saved);
  for (std::size_t j = 0; j < std::max(saved.size(), expected.size()); ++j)
    if (j >= saved.size() || j >= expected.size() || saved[j] != expected[j])
      throw std::invalid_argument(
          "checkpoint: " + local_parameter_name(j, levels_.size()) + " was " +
          (j < saved.size() ? std::to_string(saved[j]) : std::string("absent")) + ", the model's is " +
          (j < expected.size() ? std::to_string(expected[j]) : std::string("absent")) +
          " (a checkpoint of another scene?)");
  std::vector<std::int32_t> levels(level_.size());
  archive.get("lts/node_level", levels);
  for (std::size_t i = 0; i < levels.size(); ++i)
    if (levels[i] != level_[i])
      throw std::invalid_argument("checkpoint block 'lts/node_level': node " + std::to_string(i) +
                                  " was at rate level " + std::to_string(levels[i]) + ", the model's is " +
                                  std::to_string(level_[i]) + " (another mesh or time step?)");
  for (int c = 0; c <= max_level_; ++c)
    check_component_names(archive, level_prefix(c) + "component/", levels_[c].components,
                          "level " + std::to_string(c) + " ");
  std::uint8_t started = 0;
  archive.get_value("lts/started", started);
  if (!started) {
    initialised_ = false;
    return;
  }
  prepare_structure();  // the levels' force arrays are sized by the build
  std::vector<double*> terms = energy_terms(energy_);
  std::vector<double> values(terms.size());
  archive.get("lts/energy", values);
  archive.get_value("lts/dissipation_at_start", dissipation_at_start_);
  archive.get("lts/reactions", reactions_);
  for (int c = 0; c <= max_level_; ++c) {
    Level& level = levels_[c];
    const std::string prefix = level_prefix(c);
    if (archive.per_point()) {
      archive.get(prefix + "force", level.force);
      archive.get(prefix + "external", level.external);
    }
    load_components(archive, prefix + "component/", level.components);
    for (std::size_t k = 0; k < level.contacts.size(); ++k)
      level.contacts[k]->load_state(archive, prefix + "contact/" + std::to_string(k) + "/");
  }
  for (std::size_t j = 0; j < terms.size(); ++j) *terms[j] = values[j];
  initialised_ = true;
}

}  // namespace cavern
