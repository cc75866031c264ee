// Local time stepping (local_stepper.hpp): one level is the velocity-Verlet Stepper; several
// levels are second order, stable at the global scheme's bound and keep the energy bounded.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <cstdio>
#include <random>
#include <stdexcept>
#include <string>
#include <thread>
#include <tuple>
#include <utility>
#include <vector>

#include "local_stepper.hpp"
#include "random_system.hpp"
#include "seismic_input.hpp"
#include "shares.hpp"
#include "small_matrix.hpp"
#include "stable_step.hpp"
#include "stepper.hpp"

using namespace cavern;
using namespace cavern::testing;

namespace {

// A chain of nodes joined by isotropic springs k I (3x3), unit masses; springs of the middle
// `stiff` links are `ratio` times stiffer. Gershgorin levels as pyfem/local_stepping.py: per
// link the finest of its nodes, per node the finest of its links.
struct Chain {
  BlockSystem system;
  std::vector<std::int32_t> level;
  double dt_min = 0.0;
};

Chain graded_chain(int n_nodes, int stiff, double ratio, int max_level, bool grounded = true) {
  Chain chain;
  BlockSystem& s = chain.system;
  s.n_nodes = n_nodes;
  const std::int64_t n_dofs = 3 * n_nodes;
  s.dense.assign(n_dofs * n_dofs, 0.0);
  std::vector<char> pattern(n_nodes * n_nodes, 0);
  const int first_stiff = (n_nodes - 1 - stiff) / 2;
  std::vector<double> link_k(n_nodes - 1);
  for (int e = 0; e + 1 < n_nodes; ++e) {
    const double k = (e >= first_stiff && e < first_stiff + stiff) ? ratio : 1.0;
    link_k[e] = k;
    for (int a = 0; a < 2; ++a)
      for (int b = 0; b < 2; ++b) {
        pattern[(e + a) * n_nodes + e + b] = 1;
        for (int d = 0; d < 3; ++d) s.dense[(3 * (e + a) + d) * n_dofs + 3 * (e + b) + d] += (a == b ? k : -k);
      }
  }
  // A weak grounding so that K is definite (without it K 1 = 0: a free chain keeps its momentum).
  for (int i = 0; grounded && i < n_nodes; ++i)
    for (int d = 0; d < 3; ++d) s.dense[(3 * i + d) * n_dofs + 3 * i + d] += 1e-3;
  compress(s, pattern);
  s.mass.assign(n_nodes, 1.0);
  std::vector<double> dt_node(n_nodes);
  for (int i = 0; i < n_nodes; ++i) {
    double row = 0.0;
    for (std::int64_t j = 0; j < n_dofs; ++j) row += std::abs(s.dense[(3 * i) * n_dofs + j]);
    dt_node[i] = 2.0 / std::sqrt(row / s.mass[i]);
  }
  chain.dt_min = *std::min_element(dt_node.begin(), dt_node.end());
  chain.level.assign(n_nodes, max_level);
  for (int e = 0; e + 1 < n_nodes; ++e) {
    const double dt_link = std::min(dt_node[e], dt_node[e + 1]);
    const int level = std::min(max_level, static_cast<int>(std::floor(std::log2(dt_link / chain.dt_min) + 1e-12)));
    chain.level[e] = std::min(chain.level[e], level);
    chain.level[e + 1] = std::min(chain.level[e + 1], level);
  }
  return chain;
}

std::vector<double> pulse(int n_nodes) {
  std::vector<double> u(3 * n_nodes);
  for (int i = 0; i < n_nodes; ++i) {
    const double x = (i - 0.25 * n_nodes) / (0.05 * n_nodes);
    u[3 * i] = std::exp(-x * x);
    u[3 * i + 1] = 0.5 * std::exp(-x * x);
  }
  return u;
}

}  // namespace

// One level: the same steps as Stepper (pass A, then the implicit pass B), with mass-proportional
// damping, 3x3 dashpots and a seismic input provider.
TEST(LocalStepper, OneLevelIsTheVelocityVerletStepper) {
  const BlockSystem system = random_spd_system(40, 3, 17);
  const double dt = 0.02, alpha = 0.3;
  std::mt19937_64 generator(3);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  const std::vector<std::int32_t> dashpot_nodes = {2, 5, 5, 31};
  std::vector<double> C(9 * dashpot_nodes.size(), 0.0);
  for (std::size_t k = 0; k < dashpot_nodes.size(); ++k)
    for (int d = 0; d < 3; ++d) C[9 * k + 4 * d] = 0.5 + 0.25 * d;
  // A smooth input starting at rest (g = g' = 0 at t = 0): both steppers start from the same a.
  const std::int64_t n_samples = 400;
  const double table_dt = 0.05;
  std::vector<double> g(n_samples), dg(n_samples), ddg(n_samples);
  for (std::int64_t k = 0; k < n_samples; ++k) {
    const double t = k * table_dt;
    g[k] = std::sin(t) * std::sin(t);
    dg[k] = std::sin(2 * t);
    ddg[k] = 2 * std::cos(2 * t);
  }
  const std::vector<std::int64_t> node_ptr = {0, 1, 2};
  const std::vector<std::int32_t> nodes = {7, 29}, table = {0, 0};
  const std::vector<double> tau = {0.0, 0.4};
  std::vector<double> P(6), Q(6);
  for (double& p : P) p = uniform(generator);
  for (double& q : Q) q = uniform(generator);
  const WaveformTables tables{0.0, table_dt, 1, n_samples, g.data(), dg.data(), ddg.data()};
  const InputEntries entries{2, 2, node_ptr.data(), nodes.data(), table.data(), tau.data(), P.data(), Q.data()};

  Stepper stepper(system.view(), system.mass.data(), StepperParameters{dt, alpha, 0.0, false});
  stepper.set_dashpots(dashpot_nodes.data(), static_cast<std::int64_t>(dashpot_nodes.size()), C.data());
  stepper.add_provider(std::make_shared<SeismicInput>(tables, entries));
  const std::vector<std::int32_t> levels(system.n_nodes, 0);
  LocalStepper local(system.view(), system.mass.data(), levels.data(), dt, alpha);
  local.set_dashpots(dashpot_nodes.data(), static_cast<std::int64_t>(dashpot_nodes.size()), C.data());
  local.add_provider(std::make_shared<SeismicInput>(tables, entries));
  EXPECT_EQ(local.max_level(), 0);
  EXPECT_DOUBLE_EQ(local.dt(), dt);

  std::vector<double> u(system.n_dofs()), v(system.n_dofs());
  for (double& value : u) value = 0.01 * uniform(generator);
  for (double& value : v) value = 0.1 * uniform(generator);
  // a_0 = M^-1 (-K u - (alpha M + C) v) for Stepper (the LocalStepper computes it itself).
  std::vector<double> a(system.n_dofs(), 0.0);
  for (std::int64_t i = 0; i < system.n_dofs(); ++i) {
    double Ku = 0.0;
    for (std::int64_t j = 0; j < system.n_dofs(); ++j) Ku += system.dense[i * system.n_dofs() + j] * u[j];
    a[i] = (-Ku - alpha * system.mass[i / 3] * v[i]) / system.mass[i / 3];
  }
  for (std::size_t k = 0; k < dashpot_nodes.size(); ++k)
    for (int d = 0; d < 3; ++d) {
      const std::int64_t dof = 3 * dashpot_nodes[k] + d;
      a[dof] -= C[9 * k + 4 * d] * v[dof] / system.mass[dashpot_nodes[k]];
    }
  std::vector<double> u2 = u, v2 = v, a2(system.n_dofs(), 0.0);
  stepper.run(u.data(), v.data(), a.data(), 300, 0.0);
  local.run(u2.data(), v2.data(), a2.data(), 300, 0.0);
  EXPECT_LT(max_relative_difference(u2, u), 1e-12);
  EXPECT_LT(max_relative_difference(v2, v), 1e-12);
  EXPECT_LT(max_relative_difference(a2, a), 1e-11);
  double largest = 0.0;
  for (double value : u) largest = std::max(largest, std::abs(value));
  EXPECT_GT(largest, 1e-3);  // the input and the initial state moved the system
}

namespace {

// Errors of u at T against a converged reference (global velocity Verlet at dt_min / 32) on the
// graded chain from the pulse at rest, local stepping at safety 0.8, 0.4, 0.2, by the column or the
// row split; work_fraction of the 0.8 run in *work.
std::vector<double> chain_errors(const Chain& chain, bool row_split, double* work) {
  const int max_level = *std::max_element(chain.level.begin(), chain.level.end());
  const double T = 40.0 * chain.dt_min * (1 << max_level);
  const std::vector<double> u0 = pulse(chain.system.n_nodes);
  std::vector<double> ur = u0, vr(u0.size(), 0.0), ar(u0.size(), 0.0);
  {
    const double fine = chain.dt_min / 32.0;
    Stepper reference(chain.system.view(), chain.system.mass.data(), StepperParameters{fine, 0.0, 0.0, false});
    // a_0 = -M^-1 K u_0.
    for (std::size_t i = 0; i < u0.size(); ++i) {
      double Ku = 0.0;
      for (std::size_t j = 0; j < u0.size(); ++j) Ku += chain.system.dense[i * u0.size() + j] * u0[j];
      ar[i] = -Ku;
    }
    reference.run(ur.data(), vr.data(), ar.data(), static_cast<std::int64_t>(std::llround(T / fine)), 0.0);
  }
  std::vector<double> errors;
  for (double safety : {0.8, 0.4, 0.2}) {
    const std::int64_t steps = static_cast<std::int64_t>(std::llround(T / (safety * chain.dt_min * (1 << max_level))));
    const double dt_fine = T / static_cast<double>(steps) / (1 << max_level);
    LocalStepper local(chain.system.view(), chain.system.mass.data(), chain.level.data(), dt_fine, 0.0);
    local.set_row_split(row_split);
    std::vector<double> u = u0, v(u0.size(), 0.0), a(u0.size(), 0.0);
    local.run(u.data(), v.data(), a.data(), steps, 0.0);
    double error = 0.0, norm = 0.0;
    for (std::size_t k = 0; k < u.size(); ++k) {
      error += (u[k] - ur[k]) * (u[k] - ur[k]);
      norm += ur[k] * ur[k];
    }
    errors.push_back(std::sqrt(error / norm));
    if (safety == 0.8 && work != nullptr) *work = local.work_fraction();
  }
  return errors;
}

void expect_second_order(const std::vector<double>& errors) {
  for (std::size_t k = 0; k + 1 < errors.size(); ++k) {
    const double order = std::log2(errors[k] / errors[k + 1]);
    EXPECT_GT(order, 1.8) << "errors " << errors[k] << " -> " << errors[k + 1];
    EXPECT_LT(order, 2.3);
  }
  EXPECT_GT(errors[0], 1e-6);  // the pulse moved: the comparison is not of two resting states
}

}  // namespace

// Three levels (4x jumps): second order in dt against a converged reference, and the work is a
// fraction of global stepping.
TEST(LocalStepper, SeveralLevelsAreSecondOrder) {
  const Chain chain = graded_chain(161, 24, 64.0, 5);
  ASSERT_GE(*std::max_element(chain.level.begin(), chain.level.end()), 2);
  double work = 1.0;
  expect_second_order(chain_errors(chain, false, &work));
  EXPECT_LT(work, 0.6);
}

// The plain energy's range, (lowest, highest) relative to the initial energy, over 20 000 global
// steps at safety 0.95 on the graded chain of 256x stiffness jumps, by the column or the row split.
std::pair<double, double> long_run_energy_range(bool row_split) {
  const Chain chain = graded_chain(161, 24, 256.0, 5);
  EXPECT_GE(*std::max_element(chain.level.begin(), chain.level.end()), 3);
  LocalStepper local(chain.system.view(), chain.system.mass.data(), chain.level.data(), 0.95 * chain.dt_min, 0.0);
  local.set_row_split(row_split);
  std::vector<double> u = pulse(161), v(u.size(), 0.0), a(u.size(), 0.0);
  local.run(u.data(), v.data(), a.data(), 1, 0.0);
  const double initial = local.energy().initial;
  double low = 1.0, high = 1.0;
  for (int chunk = 0; chunk < 200; ++chunk) {
    local.run(u.data(), v.data(), a.data(), 100, 0.0);
    const LocalStepper::Energy e = local.energy();
    low = std::min(low, (e.kinetic + e.strain) / initial);
    high = std::max(high, (e.kinetic + e.strain) / initial);
  }
  return {low, high};
}

// Stable at the global scheme's safety factor over a long run, the plain energy bounded (the
// scheme conserves a modified energy: the plain one oscillates, it does not grow).
TEST(LocalStepper, LongRunKeepsTheEnergyBounded) {
  const auto [low, high] = long_run_energy_range(false);
  EXPECT_GT(low, 0.9);
  EXPECT_LT(high, 1.1);
}

namespace {

double max_abs(const std::vector<double>& x) {
  double value = 0.0;
  for (double y : x) value = std::max(value, std::abs(y));
  return value;
}

double max_abs_difference(const std::vector<double>& x, const std::vector<double>& y) {
  double value = 0.0;
  for (std::size_t k = 0; k < x.size(); ++k) value = std::max(value, std::abs(x[k] - y[k]));
  return value;
}

std::shared_ptr<ContactPairs> bonded_pair(std::int32_t i, std::int32_t j) {
  const std::int32_t pairs[2] = {i, j};
  const double area = 1.0, normal[3] = {0.0, 0.6, 0.8}, F0[3] = {0.0, 0.0, 0.0};
  return std::make_shared<ContactPairs>(ContactGeometry{1, pairs, &area, normal, F0},
                                        ContactStrength{1e12, 1e12, 0.5, 0.4});
}

// The state's a = M^-1 (-K u - (alpha M + C) v) (Stepper's a_0; the LocalStepper makes its own).
std::vector<double> initial_acceleration(const BlockSystem& s, const std::vector<double>& u,
                                         const std::vector<double>& v, double alpha,
                                         std::int32_t dashpot_node, const double* C) {
  const std::int64_t nd = s.n_dofs();
  std::vector<double> a(nd);
  for (std::int64_t i = 0; i < nd; ++i) {
    double Ku = 0.0;
    for (std::int64_t j = 0; j < nd; ++j) Ku += s.dense[i * nd + j] * u[j];
    a[i] = -Ku - alpha * s.mass[i / 3] * v[i];
  }
  if (C)
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) a[3 * dashpot_node + r] -= C[3 * r + c] * v[3 * dashpot_node + c];
  for (std::int64_t i = 0; i < nd; ++i) a[i] /= s.mass[i / 3];
  return a;
}

}  // namespace

// One level with a contact pair on a 3x3 dashpot, with mass-proportional damping: Stepper's
// displacements; the pair nodes' velocities lack the last impulse's first half, h/2 A^-1 R.
TEST(LocalStepper, OneLevelWithContactIsTheStepper) {
  const std::int64_t n = 20, p = 6;
  const BlockSystem merged = random_spd_system(n, 3, 17);
  std::mt19937_64 generator(3);
  std::vector<char> to_copy(n, 0);
  for (std::int64_t k = 0; k < n; ++k) to_copy[k] = generator() % 2;
  const BlockSystem split = split_node(merged, p, to_copy);
  const double dt = 0.5 * 2.0 / std::sqrt(gershgorin_bound(merged.view(), merged.mass.data()));
  const double C[9] = {3.0, 1.0, -0.5, 1.0, 2.0, 0.3, -0.5, 0.3, 4.0};
  const std::int32_t dashpot_node = static_cast<std::int32_t>(n);  // the pair's copy
  const double alpha = 0.4;
  Stepper stepper(split.view(), split.mass.data(), {dt, alpha, 0.0});
  stepper.set_dashpots(&dashpot_node, 1, C);
  auto global_pair = bonded_pair(p, n);
  stepper.set_contact(global_pair);
  const std::vector<std::int32_t> levels(n + 1, 0);
  LocalStepper local(split.view(), split.mass.data(), levels.data(), dt, alpha);
  local.set_dashpots(&dashpot_node, 1, C);
  auto local_pair = bonded_pair(p, n);
  local.add_contact(local_pair, 0);

  // From u = 0 and a random velocity, the pair's halves together and at rest relative to each other
  // after their damping's first half step: Stepper's first step (which it does not correct) and the
  // local stepper's first impulse (zero) agree.
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::vector<double> u(3 * (n + 1), 0.0), v(3 * (n + 1));
  for (double& x : v) x = uniform(generator);
  for (int c = 0; c < 3; ++c) v[3 * n + c] = v[3 * p + c];
  for (int c = 0; c < 3; ++c) v[3 * p + c] = v[3 * n + c] = 0.0;
  std::vector<double> a = initial_acceleration(split, u, v, alpha, dashpot_node, C);
  std::vector<double> u2 = u, v2 = v, a2(u.size(), 0.0);
  stepper.run(u.data(), v.data(), a.data(), 200, 0.0);
  local.run(u2.data(), v2.data(), a2.data(), 200, 0.0);
  EXPECT_LT(max_relative_difference(u2, u), 1e-12);
  const double* R = global_pair->contact_force().data();  // Stepper's correction at the last step's end
  std::vector<double> v_lagged = v;
  double A_p = split.mass[p] * (1.0 + 0.5 * dt * alpha), A_n[9], A_n_inverse[9], dv_n[3];
  for (int c = 0; c < 9; ++c) A_n[c] = 0.5 * dt * C[c];
  for (int d = 0; d < 3; ++d) A_n[4 * d] += split.mass[n] * (1.0 + 0.5 * dt * alpha);
  invert_3x3(A_n, A_n_inverse);
  const double minus_R[3] = {-R[0], -R[1], -R[2]};
  multiply_3x3(A_n_inverse, minus_R, dv_n);
  for (int c = 0; c < 3; ++c) {
    v_lagged[3 * p + c] -= 0.5 * dt * R[c] / A_p;
    v_lagged[3 * n + c] -= 0.5 * dt * dv_n[c];
  }
  EXPECT_LT(max_relative_difference(v2, v_lagged), 1e-12);
  EXPECT_EQ(local_pair->state()[0], kBonded);
  // The correction acted: it holds the normal gap closed although the halves' own forces differ
  // (the tangential offset of the first step, taken before any correction, is kept: stick).
  EXPECT_GT(std::hypot(R[0], R[1], R[2]), 1e-4);
  const double gap = 0.6 * (u2[3 * n + 1] - u2[3 * p + 1]) + 0.8 * (u2[3 * n + 2] - u2[3 * p + 2]);
  EXPECT_LT(std::abs(gap), 1e-12 * max_abs(u2));
  const LocalStepper::Energy energy = local.energy();
  EXPECT_NE(energy.contact_work, 0.0);
  EXPECT_EQ(energy.friction_dissipation, 0.0);
}

namespace {

// The graded chain with node p split (the links to its right on the copy, the last node), levels
// `level` of the merged chain plus the copy's; from u = 0 and a velocity pulse (the halves' initial
// forces are then equal, zero, as the merged node's). The bonded split chain under local stepping
// against the merged chain under the same levels: the largest relative difference of u on the
// merged nodes and of the copy against node p.
struct SplitChainRun {
  double difference = 0.0, copy_difference = 0.0, moved = 0.0;
  std::int8_t state = -1;
  LocalStepper::Energy merged_energy, energy;  // of the merged chain and the split one
};

// strain: the chains start from u = strain x i (x and y) as well, so that the pair carries a force
// from the start and all along (its halves are pulled apart by the tensions of their links).
SplitChainRun bonded_split_chain(const Chain& chain, std::int64_t p, const std::vector<std::int32_t>& level,
                                 int pair_level, double dt_fine, std::int64_t steps, bool row_split = false,
                                 double strain = 0.0) {
  const std::int64_t n = chain.system.n_nodes;
  std::vector<char> to_copy(n, 0);
  for (std::int64_t k = p + 1; k < n; ++k) to_copy[k] = 1;
  const BlockSystem split = split_node(chain.system, p, to_copy);
  std::vector<std::int32_t> split_level = level;
  split_level.push_back(level[p]);
  LocalStepper merged(chain.system.view(), chain.system.mass.data(), level.data(), dt_fine, 0.0);
  merged.step_rows_at_drift_level({static_cast<std::int32_t>(p)});  // as add_contact does the halves'
  LocalStepper local(split.view(), split.mass.data(), split_level.data(), dt_fine, 0.0);
  merged.set_row_split(row_split);
  local.set_row_split(row_split);
  auto pair = bonded_pair(static_cast<std::int32_t>(p), static_cast<std::int32_t>(n));
  local.add_contact(pair, pair_level);
  std::vector<double> v = pulse(static_cast<int>(n)), u(v.size(), 0.0), a(v.size(), 0.0);
  for (std::int64_t i = 0; i < n; ++i) u[3 * i] = u[3 * i + 1] = strain * static_cast<double>(i);
  std::vector<double> us = u, vs = v, as(3 * (n + 1), 0.0);
  for (int c = 0; c < 3; ++c) {
    us.push_back(u[3 * p + c]);
    vs.push_back(v[3 * p + c]);
  }
  merged.run(u.data(), v.data(), a.data(), steps, 0.0);
  local.run(us.data(), vs.data(), as.data(), steps, 0.0);
  std::vector<double> on_merged(us.begin(), us.begin() + 3 * n), copy(us.begin() + 3 * n, us.end());
  std::vector<double> merged_p(u.begin() + 3 * p, u.begin() + 3 * p + 3);
  SplitChainRun run;
  run.difference = max_relative_difference(on_merged, u);
  run.copy_difference = max_abs_difference(copy, merged_p) / max_abs(u);
  run.moved = std::abs(u[3 * p]) / max_abs(u);
  run.state = pair->state()[0];
  run.merged_energy = merged.energy();
  run.energy = local.energy();
  return run;
}

// The split chain equals the merged one, the pulse reached the pair, and the pair stayed bonded.
void expect_merged(const SplitChainRun& run) {
  EXPECT_LT(run.difference, 1e-11);
  EXPECT_LT(run.copy_difference, 1e-11);
  EXPECT_GT(run.moved, 1e-3);  // the pulse reached the pair
  EXPECT_EQ(run.state, kBonded);
}

// The first node of a coarser level than its right neighbour (and of its left neighbour's level).
std::int64_t level_boundary_node(const Chain& chain) {
  for (std::int64_t k = 1; k + 1 < chain.system.n_nodes; ++k)
    if (chain.level[k] > chain.level[k + 1] && chain.level[k - 1] == chain.level[k]) return k;
  return 0;
}

}  // namespace

// Several levels: a bonded pair steps at its nodes' drift level and reproduces the merged chain
// under the same levels, both inside the chain's coarse part and where its two halves border
// different levels (the coarse side's half stepped at the fine side's drift rate, as
// pyfem/local_stepping.py equalize_pair_drift makes it); a pair whose halves drift at different
// levels, or declared at another level, is refused.
TEST(LocalStepper, BondedPairReproducesTheMergedChainAtAnyLevel) {
  const Chain chain = graded_chain(161, 24, 64.0, 5);
  const int max_level = *std::max_element(chain.level.begin(), chain.level.end());
  ASSERT_GE(max_level, 2);
  const double dt_fine = 0.8 * chain.dt_min;
  // Inside the coarse part.
  const std::int64_t p = 20;
  ASSERT_EQ(chain.level[p - 1], max_level);
  ASSERT_EQ(chain.level[p + 1], max_level);
  expect_merged(bonded_split_chain(chain, p, chain.level, max_level, dt_fine, 60));
  // At a level boundary: node `edge` of a coarser level than its right neighbour.
  const std::int64_t edge = level_boundary_node(chain);
  ASSERT_GT(edge, 0);
  const int fine = chain.level[edge + 1];
  EXPECT_THROW(bonded_split_chain(chain, edge, chain.level, fine, dt_fine, 1), std::invalid_argument);
  std::vector<std::int32_t> equalized = chain.level;
  equalized[edge] = fine;  // both halves (and the merged node) drift at the fine side's rate
  expect_merged(bonded_split_chain(chain, edge, equalized, fine, dt_fine, 60));
  EXPECT_THROW(bonded_split_chain(chain, p, chain.level, 0, dt_fine, 1), std::invalid_argument);
}

// A bonded pair that carries a force all along (the chain starts stretched) keeps the energy
// account: the pair's impulses do no work (a pair that holds does none) and the split chain's
// balance is the merged chain's, by both splits. The impulses' kinetic energy would not be: with
// halves of mass m holding a force f, each substep's impulse takes back the h^2 f^2 / m of kinetic
// energy that the two kicks around it add; booked as work it drifted the balance by that much every
// substep (31.8 here, the scale 0.066).
TEST(LocalStepper, BondedPairCarryingAForceKeepsTheEnergyAccount) {
  const Chain chain = graded_chain(161, 24, 64.0, 5);
  const int max_level = *std::max_element(chain.level.begin(), chain.level.end());
  const double dt_fine = 0.8 * chain.dt_min;
  const std::int64_t edge = level_boundary_node(chain);
  ASSERT_GT(edge, 0);
  std::vector<std::int32_t> equalized = chain.level;
  equalized[edge] = chain.level[edge + 1];
  for (const bool row_split : {false, true})
    for (const auto& [p, level, pair_level] :
         {std::make_tuple(std::int64_t{20}, chain.level, max_level),
          std::make_tuple(edge, equalized, equalized[edge])}) {
      const std::int64_t steps = 2000;
      const SplitChainRun run = bonded_split_chain(chain, p, level, pair_level, dt_fine, steps, row_split, 0.01);
      expect_merged(run);
      const LocalStepper::Energy& e = run.energy;
      const double scale = e.initial + std::abs(e.external_work);
      const std::string where = std::string(row_split ? "row" : "column") + " split, pair at " + std::to_string(p);
      EXPECT_LT(std::abs(e.contact_work), 1e-12 * scale) << where;  // a pair that holds does no work
      // Within the plain energy's own O(dt^2) oscillation at this safety factor (the merged
      // chain's balance is up to 0.06 of the scale here); the kinetic measure drifted by 150-480 x
      // the scale over these steps.
      EXPECT_LT(std::abs(e.balance - run.merged_energy.balance), 0.2 * scale)
          << where << ": balance " << e.balance << ", merged " << run.merged_energy.balance;
    }
}

// A row stepped at its node's drift level (as a contact pair node's is) moves that row's blocks
// from their columns' coarser levels to the node's. Each level then holds part of a column, and
// the column split's momentum balance (sum_i K_ij = 0 within every level) would break at O(dt^2):
// on the small case 3 that made the displacements 6-8 % off global stepping, at about first order.
// A diagonal block on each such column's node puts the balance back: a free chain keeps its
// momentum to round-off, and the capped scheme stays second order against a converged reference.
TEST(LocalStepper, RowsSteppedAtTheirDriftLevelKeepMomentumAndSecondOrder) {
  const Chain chain = graded_chain(161, 24, 64.0, 5, /*grounded=*/false);
  const int max_level = *std::max_element(chain.level.begin(), chain.level.end());
  ASSERT_GE(max_level, 2);
  // Capped rows at both level boundaries: the coarse side's node steps at the fine side's rate.
  std::vector<std::int32_t> level = chain.level;
  std::vector<std::int32_t> capped;
  for (std::int64_t k = 1; k + 1 < 161; ++k) {
    if (chain.level[k] > chain.level[k + 1] && chain.level[k - 1] == chain.level[k]) {
      level[k] = chain.level[k + 1];
      capped.push_back(static_cast<std::int32_t>(k));
    }
    if (chain.level[k] > chain.level[k - 1] && chain.level[k + 1] == chain.level[k]) {
      level[k] = chain.level[k - 1];
      capped.push_back(static_cast<std::int32_t>(k));
    }
  }
  ASSERT_EQ(capped.size(), 2u);
  const double T = 40.0 * chain.dt_min * (1 << max_level);
  std::vector<double> v0 = pulse(161);
  std::vector<double> ur(v0.size(), 0.0), vr = v0, ar(v0.size(), 0.0);
  {
    const double fine = chain.dt_min / 32.0;
    Stepper reference(chain.system.view(), chain.system.mass.data(), StepperParameters{fine, 0.0, 0.0, false});
    reference.run(ur.data(), vr.data(), ar.data(), static_cast<std::int64_t>(std::llround(T / fine)), 0.0);
  }
  double momentum0[3] = {0.0, 0.0, 0.0}, scale = 0.0;
  for (int i = 0; i < 161; ++i)
    for (int d = 0; d < 3; ++d) {
      momentum0[d] += chain.system.mass[i] * v0[3 * i + d];
      scale += chain.system.mass[i] * std::abs(v0[3 * i + d]);
    }
  ASSERT_GT(std::abs(momentum0[0]), 0.1 * scale);
  std::vector<double> errors;
  for (double safety : {0.8, 0.4, 0.2}) {
    const std::int64_t steps = static_cast<std::int64_t>(std::llround(T / (safety * chain.dt_min * (1 << max_level))));
    const double dt_fine = T / static_cast<double>(steps) / (1 << max_level);
    LocalStepper local(chain.system.view(), chain.system.mass.data(), level.data(), dt_fine, 0.0);
    local.step_rows_at_drift_level(capped);
    std::vector<double> u(v0.size(), 0.0), v = v0, a(v0.size(), 0.0);
    local.run(u.data(), v.data(), a.data(), steps, 0.0);
    for (int d = 0; d < 3; ++d) {
      double momentum = 0.0;
      for (int i = 0; i < 161; ++i) momentum += chain.system.mass[i] * v[3 * i + d];
      EXPECT_LT(std::abs(momentum - momentum0[d]), 1e-12 * scale) << "component " << d << " safety " << safety;
    }
    double error = 0.0, norm = 0.0;
    for (std::size_t k = 0; k < u.size(); ++k) {
      error += (u[k] - ur[k]) * (u[k] - ur[k]);
      norm += ur[k] * ur[k];
    }
    errors.push_back(std::sqrt(error / norm));
  }
  for (std::size_t k = 0; k + 1 < errors.size(); ++k) {
    const double order = std::log2(errors[k] / errors[k + 1]);
    EXPECT_GT(order, 1.8) << "errors " << errors[k] << " -> " << errors[k + 1];
    EXPECT_LT(order, 2.3);
  }
  EXPECT_GT(errors[0], 1e-6);  // the pulse moved
}

namespace {

// The graded chain split at node p with a weak deteriorating pair between the halves (its bond
// breaks, it opens, closes and slides) at the pair's level, a dashpot on the last node and mass-proportional damping:
// every part of the state a checkpoint must hold.
struct WeakPairChain {
  BlockSystem split;
  std::vector<std::int32_t> level;
  std::unique_ptr<LocalStepper> stepper;
  std::shared_ptr<ContactPairs> pair;
};

WeakPairChain weak_pair_chain(const Chain& chain, std::int32_t p, double dt_fine) {
  WeakPairChain out;
  const std::int64_t n = chain.system.n_nodes;
  std::vector<char> to_copy(n, 0);
  for (std::int64_t k = p + 1; k < n; ++k) to_copy[k] = 1;
  out.split = split_node(chain.system, p, to_copy);
  out.level = chain.level;
  out.level.push_back(chain.level[p]);
  out.stepper = std::make_unique<LocalStepper>(out.split.view(), out.split.mass.data(), out.level.data(),
                                               dt_fine, 0.05);
  const std::int32_t pairs[2] = {p, static_cast<std::int32_t>(n)};
  const double area = 1.0, normal[3] = {0.0, 0.6, 0.8}, F0[3] = {0.0, 0.0, 0.0};
  out.pair = std::make_shared<ContactPairs>(ContactGeometry{1, pairs, &area, normal, F0},
                                            ContactStrength{0.05, 0.02, 0.5, 0.4});
  // Deteriorating with time and with the slip rate the pair remembers from its last correction.
  out.pair->set_deterioration(DeteriorationParameters{0.75, 5.0, 100.0, 0.883, 0.02, 0.3});
  out.stepper->add_contact(out.pair, chain.level[p]);
  const std::int32_t dashpot_node = static_cast<std::int32_t>(n - 1);
  const double C[9] = {0.5, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 1.0};
  out.stepper->set_dashpots(&dashpot_node, 1, C);
  return out;
}

}  // namespace

// Checkpoint (docs/checkpoint.md): the state saved after some steps and loaded into a stepper built
// the same way continues bit for bit as the stepper that was saved, with a pair that has broken and
// slid, several levels and damping; an unstarted stepper's state restarts from (u, v); a stepper
// with other levels refuses the state.
TEST(LocalStepper, SavedStateContinuesBitForBit) {
  const Chain chain = graded_chain(81, 12, 64.0, 4);
  const int max_level = *std::max_element(chain.level.begin(), chain.level.end());
  ASSERT_GE(max_level, 2);
  const std::int32_t p = 20;
  ASSERT_EQ(chain.level[p - 1], chain.level[p]);
  ASSERT_EQ(chain.level[p + 1], chain.level[p]);
  const double dt_fine = 0.8 * chain.dt_min;
  WeakPairChain first = weak_pair_chain(chain, p, dt_fine);
  std::vector<double> v = pulse(81);
  v.insert(v.end(), {v[3 * p], v[3 * p + 1], v[3 * p + 2]});
  for (double& x : v) x *= 2.0;
  std::vector<double> u(v.size(), 0.0), a(v.size(), 0.0);
  double t = first.stepper->run(u.data(), v.data(), a.data(), 70, 0.0);  // opened, now sliding
  StateArchive saved;
  first.stepper->save_state(saved);
  std::vector<double> u_saved = u, v_saved = v, a_saved = a;
  const double t_saved = t;
  const LocalStepper::Energy energy_saved = first.stepper->energy();
  const std::int8_t state_saved = first.pair->state()[0];
  t = first.stepper->run(u.data(), v.data(), a.data(), 40, t);
  // The pair broke, opened and closed again before the save and slides across it: the state
  // restored is one that matters.
  EXPECT_EQ(state_saved, kSliding);
  EXPECT_GT(energy_saved.friction_dissipation, 0.0);
  EXPECT_GT(first.stepper->energy().friction_dissipation, energy_saved.friction_dissipation);

  WeakPairChain second = weak_pair_chain(chain, p, dt_fine);
  second.stepper->load_state(saved);
  const double t_resumed = second.stepper->run(u_saved.data(), v_saved.data(), a_saved.data(), 40, t_saved);
  EXPECT_EQ(t_resumed, t);
  EXPECT_EQ(u_saved, u);
  EXPECT_EQ(v_saved, v);
  EXPECT_EQ(a_saved, a);
  const LocalStepper::Energy e1 = first.stepper->energy(), e2 = second.stepper->energy();
  EXPECT_EQ(e1.balance, e2.balance);
  EXPECT_EQ(e1.external_work, e2.external_work);
  EXPECT_EQ(e1.damping_work, e2.damping_work);
  EXPECT_EQ(e1.contact_work, e2.contact_work);
  EXPECT_EQ(e1.friction_dissipation, e2.friction_dissipation);
  EXPECT_EQ(first.pair->state()[0], second.pair->state()[0]);

  // A stepper that has not run saves "not started": the loaded one initialises from (u, v).
  WeakPairChain fresh = weak_pair_chain(chain, p, dt_fine), loaded = weak_pair_chain(chain, p, dt_fine);
  StateArchive unstarted;
  fresh.stepper->save_state(unstarted);
  loaded.stepper->load_state(unstarted);
  std::vector<double> v0 = pulse(81), u0, u1;
  v0.insert(v0.end(), {v0[3 * p], v0[3 * p + 1], v0[3 * p + 2]});
  std::vector<double> v1 = v0, a0(v0.size(), 0.0), a1(v0.size(), 0.0);
  u0.assign(v0.size(), 0.0);
  u1 = u0;
  fresh.stepper->run(u0.data(), v0.data(), a0.data(), 10, 0.0);
  loaded.stepper->run(u1.data(), v1.data(), a1.data(), 10, 0.0);
  EXPECT_EQ(u0, u1);

  // Other levels (one node moved to the finest): refused, naming the block.
  Chain other = chain;
  other.level[5] = 0;
  WeakPairChain regraded = weak_pair_chain(other, p, dt_fine);
  try {
    regraded.stepper->load_state(saved);
    ADD_FAILURE() << "a state of other levels was accepted";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("lts/"), std::string::npos) << error.what();
  }
}

// Kinematic constraints (constraints.hpp): with one level the local stepper is Stepper with the same
// fixed and roller nodes (one roller also carrying a dashpot that couples the held and the free
// directions, so the constrained implicit update matters); with several levels a roller node's held
// component stays zero to round-off at every level and the energy stays bounded.
TEST(LocalStepper, ConstrainedNodesAsStepperAndHeldAtEveryLevel) {
  const BlockSystem system = random_spd_system(40, 3, 23);
  const double dt = 0.02, alpha = 0.3;
  std::mt19937_64 generator(5);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  const std::vector<std::int32_t> dashpot_nodes = {4, 11};
  const std::vector<double> C = {2.0, 0.7, 0.0, 0.7, 1.0, 0.3, 0.0, 0.3, 1.5,
                                 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0};
  const double s = 1.0 / std::sqrt(2.0);
  const double n[3] = {s, s, 0.0};  // a roller with a slanted normal
  std::vector<double> P(27, 0.0);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) {
      P[3 * r + c] = (r == c ? 1.0 : 0.0) - n[r] * n[c];        // node 4: roller, with the dashpot
      P[18 + 3 * r + c] = (r == c ? 1.0 : 0.0) - (r == 2 && c == 2 ? 1.0 : 0.0);  // node 30: roller z
    }
  // node 17: fixed (P = 0)
  const std::vector<std::int32_t> constrained = {4, 17, 30};
  Stepper stepper(system.view(), system.mass.data(), StepperParameters{dt, alpha, 0.0, false});
  stepper.set_dashpots(dashpot_nodes.data(), 2, C.data());
  stepper.set_constraints(constrained.data(), 3, P.data());
  const std::vector<std::int32_t> levels(system.n_nodes, 0);
  LocalStepper local(system.view(), system.mass.data(), levels.data(), dt, alpha);
  local.set_dashpots(dashpot_nodes.data(), 2, C.data());
  local.set_constraints(constrained.data(), 3, P.data());

  // u in the free range of every constrained node, at rest; Stepper's a_0 = P M^-1 (-K u).
  std::vector<double> u(system.n_dofs()), v(system.n_dofs(), 0.0), a(system.n_dofs(), 0.0);
  for (double& value : u) value = 0.01 * uniform(generator);
  auto project = [&](std::vector<double>& x) {
    for (std::size_t k = 0; k < constrained.size(); ++k) {
      double y[3];
      multiply_3x3(P.data() + 9 * k, x.data() + 3 * constrained[k], y);
      for (int d = 0; d < 3; ++d) x[3 * constrained[k] + d] = y[d];
    }
  };
  project(u);
  for (std::int64_t i = 0; i < system.n_dofs(); ++i) {
    double Ku = 0.0;
    for (std::int64_t j = 0; j < system.n_dofs(); ++j) Ku += system.dense[i * system.n_dofs() + j] * u[j];
    a[i] = -Ku / system.mass[i / 3];
  }
  project(a);
  std::vector<double> u2 = u, v2 = v, a2(system.n_dofs(), 0.0);
  stepper.run(u.data(), v.data(), a.data(), 300, 0.0);
  local.run(u2.data(), v2.data(), a2.data(), 300, 0.0);
  EXPECT_LT(max_relative_difference(u2, u), 1e-12);
  EXPECT_LT(max_relative_difference(v2, v), 1e-12);
  EXPECT_LT(max_relative_difference(a2, a), 1e-11);
  EXPECT_GT(max_abs(u), 1e-3);
  EXPECT_EQ(u2[3 * 17], 0.0);
  EXPECT_LT(std::abs(n[0] * u2[12] + n[1] * u2[13]), 1e-15);
  EXPECT_GT(std::hypot(u2[12], u2[13], u2[14]), 1e-5);  // node 4 moved, along its face
  const std::vector<double>& R = local.reactions();
  ASSERT_EQ(R.size(), 9u);
  EXPECT_LT(max_relative_difference(R, stepper.reactions()), 1e-11);
  EXPECT_GT(max_abs(R), 1e-4);

  // Several levels: rollers (held along x) on nodes of the coarse and the fine part of a graded chain.
  const Chain chain = graded_chain(81, 12, 64.0, 4);
  ASSERT_GE(*std::max_element(chain.level.begin(), chain.level.end()), 2);
  std::vector<std::int32_t> rollers;
  std::vector<double> held_x;
  for (std::int32_t node = 3; node < 81; node += 6) {
    rollers.push_back(node);
    const double roller[9] = {0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0};
    held_x.insert(held_x.end(), roller, roller + 9);
  }
  LocalStepper graded(chain.system.view(), chain.system.mass.data(), chain.level.data(), 0.8 * chain.dt_min, 0.0);
  graded.set_constraints(rollers.data(), static_cast<std::int64_t>(rollers.size()), held_x.data());
  std::vector<double> vp = pulse(81), up(vp.size(), 0.0), ap(vp.size(), 0.0);
  for (const std::int32_t node : rollers) vp[3 * node] = 0.0;
  double kinetic0 = 0.0;
  for (int i = 0; i < 81; ++i)
    for (int d = 0; d < 3; ++d) kinetic0 += 0.5 * chain.system.mass[i] * vp[3 * i + d] * vp[3 * i + d];
  double worst_held = 0.0, moved = 0.0;
  for (int chunk = 0; chunk < 20; ++chunk) {
    graded.run(up.data(), vp.data(), ap.data(), 25, 0.0);
    for (const std::int32_t node : rollers) {
      worst_held = std::max({worst_held, std::abs(up[3 * node]), std::abs(vp[3 * node])});
      moved = std::max(moved, std::abs(up[3 * node + 1]));
    }
    const LocalStepper::Energy e = graded.energy();
    EXPECT_LT(e.kinetic + e.strain, 3.0 * kinetic0);  // bounded (the plain energy of the scheme)
  }
  EXPECT_EQ(worst_held, 0.0);
  EXPECT_GT(moved, 1e-3);  // the rollers' free components moved
}

// The row split (LocalStepper::set_row_split, docs/local_stepping.md "The scheme: the row split").
namespace {

// Link strains (u_{e+1} - u_e, x component) of the chain after every global step of a run from the
// pulse at rest over n_global steps of dt_fine 2^max_level; rows: steps, columns: links.
std::vector<std::vector<double>> link_strain_history(const Chain& chain, double dt_fine, std::int64_t n_global,
                                                     bool row_split) {
  LocalStepper local(chain.system.view(), chain.system.mass.data(), chain.level.data(), dt_fine, 0.0);
  local.set_row_split(row_split);
  const int n = chain.system.n_nodes;
  std::vector<double> u = pulse(n), v(u.size(), 0.0), a(u.size(), 0.0);
  std::vector<std::vector<double>> history;
  for (std::int64_t s = 0; s < n_global; ++s) {
    local.run(u.data(), v.data(), a.data(), 1, 0.0);
    std::vector<double> strain(n - 1);
    for (int e = 0; e + 1 < n; ++e) strain[e] = u[3 * (e + 1)] - u[3 * e];
    history.push_back(strain);
  }
  return history;
}

}  // namespace

// One level: every row at that level, whole: the column split's (and so Stepper's) arithmetic.
TEST(LocalStepperRowSplit, OneLevelIsTheColumnSplit) {
  const BlockSystem system = random_spd_system(40, 3, 21);
  const std::vector<std::int32_t> levels(system.n_nodes, 0);
  std::mt19937_64 generator(5);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::vector<double> u(system.n_dofs()), v(system.n_dofs()), a(system.n_dofs(), 0.0);
  for (double& value : u) value = 0.01 * uniform(generator);
  for (double& value : v) value = 0.1 * uniform(generator);
  std::vector<double> u2 = u, v2 = v, a2 = a;
  LocalStepper columns(system.view(), system.mass.data(), levels.data(), 0.02, 0.3);
  LocalStepper rows(system.view(), system.mass.data(), levels.data(), 0.02, 0.3);
  rows.set_row_split(true);
  EXPECT_TRUE(rows.row_split());
  columns.run(u.data(), v.data(), a.data(), 200, 0.0);
  rows.run(u2.data(), v2.data(), a2.data(), 200, 0.0);
  EXPECT_LT(max_relative_difference(u2, u), 1e-14);
  EXPECT_LT(max_relative_difference(v2, v), 1e-14);
}

// Several levels (4x jumps): second order against a converged reference, as the column split.
TEST(LocalStepperRowSplit, SeveralLevelsAreSecondOrder) {
  const Chain chain = graded_chain(161, 24, 64.0, 5);
  ASSERT_GE(*std::max_element(chain.level.begin(), chain.level.end()), 2);
  expect_second_order(chain_errors(chain, true, nullptr));
}

// The strain where levels meet: the column split's error peaks at the links between levels (a
// coarse node drifts with its finer neighbours while its own force arrives as kicks); the row
// split's does not: its worst link there is 23x closer to global stepping's answer.
TEST(LocalStepperRowSplit, NoStrainPeakWhereLevelsMeet) {
  const Chain chain = graded_chain(161, 24, 64.0, 5);
  const int max_level = *std::max_element(chain.level.begin(), chain.level.end());
  const double dt_fine = 0.8 * chain.dt_min;
  const std::int64_t n_global = 40;
  // Reference: global stepping at dt_fine / 16 sampled at the global steps.
  std::vector<std::vector<double>> reference;
  {
    const double fine = dt_fine / 16.0;
    Stepper stepper(chain.system.view(), chain.system.mass.data(), StepperParameters{fine, 0.0, 0.0, false});
    std::vector<double> u = pulse(161), v(u.size(), 0.0), a(u.size(), 0.0);
    for (std::size_t i = 0; i < u.size(); ++i) {
      double Ku = 0.0;
      for (std::size_t j = 0; j < u.size(); ++j) Ku += chain.system.dense[i * u.size() + j] * u[j];
      a[i] = -Ku;
    }
    for (std::int64_t s = 0; s < n_global; ++s) {
      stepper.run(u.data(), v.data(), a.data(), 16 * (std::int64_t{1} << max_level), 0.0);
      std::vector<double> strain(160);
      for (int e = 0; e < 160; ++e) strain[e] = u[3 * (e + 1)] - u[3 * e];
      reference.push_back(strain);
    }
  }
  double scale = 0.0;
  for (const auto& row : reference)
    for (double value : row) scale = std::max(scale, std::abs(value));
  auto boundary_error = [&](bool row_split) {
    const auto history = link_strain_history(chain, dt_fine, n_global, row_split);
    double worst = 0.0;
    for (int e = 0; e < 160; ++e) {
      if (chain.level[e] == chain.level[e + 1]) continue;  // links where levels meet only
      for (std::int64_t s = 0; s < n_global; ++s)
        worst = std::max(worst, std::abs(history[s][e] - reference[s][e]));
    }
    return worst / scale;
  };
  const double columns = boundary_error(false), rows = boundary_error(true);
  std::printf("strain error at the links where levels meet: column split %.3e, row split %.3e\n", columns, rows);
  EXPECT_GT(columns, 1e-4);  // the comparison sees the stepping error
  EXPECT_LT(rows, 0.2 * columns);  // measured 5.1e-4 against 1.2e-2
}

// Stable at the global scheme's safety factor over a long run; the plain energy bounded.
TEST(LocalStepperRowSplit, LongRunKeepsTheEnergyBounded) {
  const auto [low, high] = long_run_energy_range(true);
  EXPECT_GT(low, 0.9);
  EXPECT_LT(high, 1.1);
}

// A bonded pair in the row split: both halves at one level (the finer of the two, and nothing
// else lowered), the split chain reproduces the merged chain under the same levels, inside the
// coarse part and at a level boundary.
TEST(LocalStepperRowSplit, BondedPairReproducesTheMergedChain) {
  const Chain chain = graded_chain(161, 24, 64.0, 5);
  const int max_level = *std::max_element(chain.level.begin(), chain.level.end());
  const double dt_fine = 0.8 * chain.dt_min;
  expect_merged(bonded_split_chain(chain, 20, chain.level, max_level, dt_fine, 60, true));
  const std::int64_t edge = level_boundary_node(chain);
  ASSERT_GT(edge, 0);
  std::vector<std::int32_t> equalized = chain.level;
  equalized[edge] = chain.level[edge + 1];
  expect_merged(bonded_split_chain(chain, edge, equalized, equalized[edge], dt_fine, 60, true));
}

// Local time stepping on MPI ranks' shares (LocalStepper::set_partition, docs/scaling.md "Local
// time stepping on the ranks"), the ranks run as two threads that exchange one level's ghosts'
// velocity through memory before each of that level's drifts, as MpiNodeExchange does by messages.
namespace {

/// The level-k ghosts' velocity from their owners (a is not exchanged: LocalStepper passes null).
class LevelMemoryExchange : public NodeExchange {
 public:
  LevelMemoryExchange(const Share& mine, const std::vector<std::int32_t>& level, int k,
                      std::vector<double>& mailbox_out, const std::vector<double>& mailbox_in, Barrier& barrier,
                      std::int64_t* calls)
      : mine_(mine), level_(level), k_(k), out_(mailbox_out), in_(mailbox_in), barrier_(barrier), calls_(calls) {}

  void exchange(double* v, double* a) override {
    if (a != nullptr) throw std::logic_error("LocalStepper exchanges v only");
    for (std::int64_t l = 0; l < mine_.n_owned; ++l)
      if (level_[mine_.nodes[l]] == k_)
        for (int c = 0; c < 3; ++c) out_[3 * mine_.nodes[l] + c] = v[3 * l + c];
    barrier_.arrive_and_wait();  // both posted
    for (std::size_t l = mine_.n_owned; l < mine_.nodes.size(); ++l)
      if (level_[mine_.nodes[l]] == k_)  // only this level's ghosts: the others are mid-drift
        for (int c = 0; c < 3; ++c) v[3 * l + c] = in_[3 * mine_.nodes[l] + c];
    barrier_.arrive_and_wait();  // both read
    ++*calls_;
  }

 private:
  const Share& mine_;
  const std::vector<std::int32_t>& level_;
  const int k_;
  std::vector<double>& out_;
  const std::vector<double>& in_;
  Barrier& barrier_;
  std::int64_t* calls_;
};

struct ShareRun {
  std::vector<double> u, v, a;
  LocalStepper::Energy energy;
  std::int64_t exchanges = 0;
  std::int8_t pair_state = -1;  // of the pair, on the rank that owns it
};

}  // namespace

// The graded chain cut at p by a weak deteriorating pair (it breaks, opens, closes and slides), a
// dashpot and mass-proportional damping, under the row split, on two shares: nodes owned
// alternately (every owned node has ghost neighbours, at every level; the pair's two nodes on one
// rank), and owned by blocks where one rank's share holds no node of the coarsest level (its
// stepper is given the model's). Every owned node follows the whole model's stepper to round-off
// (the shares sum a row's blocks in another order), and the two energy accounts add up to the
// whole's.
TEST(LocalStepperPartition, SharesFollowTheWholeModel) {
  Chain chain = graded_chain(81, 12, 100.0, 3);
  // Levels 0 (the stiff middle) to 3 in steps of one: a node may always step finer than it must.
  for (int i = 0; i < 81; ++i) chain.level[i] = std::min(chain.level[i], std::abs(i - 40) / 4);
  const int max_level = *std::max_element(chain.level.begin(), chain.level.end());
  ASSERT_EQ(max_level, 3);
  const std::int32_t p = 20;
  const double dt_fine = 0.8 * chain.dt_min;
  WeakPairChain whole = weak_pair_chain(chain, p, dt_fine);
  whole.stepper->set_row_split(true);
  const std::int64_t n = whole.split.n_nodes;  // 82: the pair's copy node is the last
  std::vector<double> v0 = pulse(81);
  v0.insert(v0.end(), {v0[3 * p], v0[3 * p + 1], v0[3 * p + 2]});
  for (double& x : v0) x *= 2.0;
  const std::vector<double> u0(v0.size(), 0.0), a0(v0.size(), 0.0);
  std::vector<double> u = u0, v = v0, a = a0;
  constexpr int kRuns = 4, kStepsPerRun = 30;
  double t = 0.0;
  for (int r = 0; r < kRuns; ++r) t = whole.stepper->run(u.data(), v.data(), a.data(), kStepsPerRun, t);
  ASSERT_NE(whole.pair->state()[0], kBonded);  // the pair broke, opened and slid: contact is exercised
  const LocalStepper::Energy reference = whole.stepper->energy();
  ASSERT_GT(reference.friction_dissipation, 0.0);
  ASSERT_GT(reference.damping_work, 0.0);

  const std::vector<std::int32_t>& level = whole.level;
  const std::int32_t dashpot_node = static_cast<std::int32_t>(n - 2);  // weak_pair_chain's
  auto run_shares = [&](const std::vector<int>& owner) {
    Share shares[2];
    for (int r = 0; r < 2; ++r) {
      std::vector<std::int64_t> owned;
      for (std::int64_t i = 0; i < n; ++i)
        if (owner[i] == r) owned.push_back(i);
      shares[r] = make_share(whole.split, owned);
    }
    std::vector<double> mailbox[2] = {std::vector<double>(3 * n), std::vector<double>(3 * n)};
    Barrier barrier;
    ShareRun runs[2];
    auto rank = [&](int r) {
      const Share& share = shares[r];
      const std::int64_t m = static_cast<std::int64_t>(share.nodes.size());
      std::vector<std::int64_t> local(n, -1);
      std::vector<std::int32_t> local_level(m);
      for (std::int64_t l = 0; l < m; ++l) {
        local[share.nodes[l]] = l;
        local_level[l] = level[share.nodes[l]];
      }
      LocalStepper stepper(share.system.view(), share.system.mass.data(), local_level.data(), dt_fine, 0.05,
                           max_level);
      stepper.set_row_split(true);
      std::shared_ptr<ContactPairs> pair;
      if (owner[p] == r) {
        const std::int32_t pairs[2] = {static_cast<std::int32_t>(local[p]), static_cast<std::int32_t>(local[n - 1])};
        const double area = 1.0, normal[3] = {0.0, 0.6, 0.8}, F0[3] = {0.0, 0.0, 0.0};
        pair = std::make_shared<ContactPairs>(ContactGeometry{1, pairs, &area, normal, F0},
                                              ContactStrength{0.05, 0.02, 0.5, 0.4});
        pair->set_deterioration(DeteriorationParameters{0.75, 5.0, 100.0, 0.883, 0.02, 0.3});
        stepper.add_contact(pair, level[p]);
      }
      if (owner[dashpot_node] == r) {
        const std::int32_t node = static_cast<std::int32_t>(local[dashpot_node]);
        const double C[9] = {0.5, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 1.0};
        stepper.set_dashpots(&node, 1, C);
      }
      std::vector<std::shared_ptr<NodeExchange>> exchanges;
      for (int k = 0; k <= max_level; ++k)
        exchanges.push_back(std::make_shared<LevelMemoryExchange>(share, level, k, mailbox[r], mailbox[1 - r],
                                                                  barrier, &runs[r].exchanges));
      stepper.set_partition(share.n_owned, exchanges);
      for (const std::int64_t node : share.nodes)
        for (int c = 0; c < 3; ++c) {
          runs[r].u.push_back(u0[3 * node + c]);
          runs[r].v.push_back(v0[3 * node + c]);
          runs[r].a.push_back(a0[3 * node + c]);
        }
      double time = 0.0;
      for (int s = 0; s < kRuns; ++s)
        time = stepper.run(runs[r].u.data(), runs[r].v.data(), runs[r].a.data(), kStepsPerRun, time);
      runs[r].energy = stepper.energy();
      if (pair) runs[r].pair_state = pair->state()[0];
    };
    std::thread first(rank, 0), second(rank, 1);
    first.join();
    second.join();

    double largest[3] = {0.0, 0.0, 0.0}, difference[3] = {0.0, 0.0, 0.0};
    for (int r = 0; r < 2; ++r)
      for (std::int64_t l = 0; l < shares[r].n_owned; ++l)
        for (int c = 0; c < 3; ++c) {
          const std::int64_t d = 3 * shares[r].nodes[l] + c;
          const double* mine[3] = {runs[r].u.data(), runs[r].v.data(), runs[r].a.data()};
          const double* theirs[3] = {u.data(), v.data(), a.data()};
          for (int q = 0; q < 3; ++q) {
            largest[q] = std::max(largest[q], std::abs(theirs[q][d]));
            difference[q] = std::max(difference[q], std::abs(mine[q][3 * l + c] - theirs[q][d]));
          }
        }
    EXPECT_GT(largest[0], 1e-2);  // the chain moved
    // a is the net of stiffness forces up to 100 times larger (the stiff middle's), summed in
    // another order by the shares: measured 0 (alternating) and 1.3e-11 (blocks) of its largest.
    EXPECT_LT(difference[0], 1e-12 * largest[0]);
    EXPECT_LT(difference[1], 1e-12 * largest[1]);
    EXPECT_LT(difference[2], 1e-10 * largest[2]);
    EXPECT_EQ(runs[owner[p]].pair_state, whole.pair->state()[0]);
    // Every level exchanged at each of its drifts: 2^(L - k) per global step.
    EXPECT_EQ(runs[0].exchanges, kRuns * kStepsPerRun * ((std::int64_t{1} << (max_level + 1)) - 1));
    EXPECT_EQ(runs[0].exchanges, runs[1].exchanges);
    const LocalStepper::Energy& e0 = runs[0].energy;
    const LocalStepper::Energy& e1 = runs[1].energy;
    const double scale = reference.initial + reference.external_work + reference.damping_work;
    EXPECT_NEAR(e0.kinetic + e1.kinetic, reference.kinetic, 1e-12 * scale);
    EXPECT_NEAR(e0.strain + e1.strain, reference.strain, 1e-12 * scale);
    EXPECT_NEAR(e0.initial + e1.initial, reference.initial, 1e-12 * scale);
    EXPECT_NEAR(e0.damping_work + e1.damping_work, reference.damping_work, 1e-12 * scale);
    EXPECT_NEAR(e0.contact_work + e1.contact_work, reference.contact_work, 1e-12 * scale);
    EXPECT_NEAR(e0.friction_dissipation + e1.friction_dissipation, reference.friction_dissipation, 1e-12 * scale);
    EXPECT_NEAR(e0.balance + e1.balance, reference.balance, 1e-12 * scale);
  };
  std::vector<int> alternating(n), blocks(n);
  for (std::int64_t i = 0; i < n; ++i) {
    alternating[i] = static_cast<int>(i % 2);
    blocks[i] = (i >= 30 && i < 51) ? 1 : 0;  // rank 1: the middle only, no coarsest node
  }
  alternating[n - 1] = alternating[p];  // a pair whole on one rank
  {
    SCOPED_TRACE("alternating owners");
    run_shares(alternating);
  }
  {
    SCOPED_TRACE("blocks");
    std::int32_t coarsest_in_share = 0;
    for (std::int64_t i = 29; i <= 51; ++i) coarsest_in_share = std::max(coarsest_in_share, level[i]);
    ASSERT_LT(coarsest_in_share, max_level);  // rank 1's share needs the model's max_level
    run_shares(blocks);
  }
}

// What a share cannot do: the column split (coarser levels kick finer nodes between their drifts),
// an effect on a ghost, a max_level below the nodes' largest.
TEST(LocalStepperPartition, RefusesWhatASharesExchangeCannotKeepExact) {
  const Chain chain = graded_chain(41, 8, 16.0, 2);
  const double dt_fine = 0.8 * chain.dt_min;
  const Share share = make_share(chain.system, 0, 20);
  ASSERT_GT(share.nodes.size(), 20u);
  std::vector<std::int32_t> local_level;
  for (const std::int64_t node : share.nodes) local_level.push_back(chain.level[node]);
  const int max_level = *std::max_element(chain.level.begin(), chain.level.end());
  const std::int64_t n_dofs = 3 * static_cast<std::int64_t>(share.nodes.size());
  std::vector<double> u(n_dofs, 0.0), v(n_dofs, 0.0), a(n_dofs, 0.0);
  const std::vector<std::shared_ptr<NodeExchange>> none(max_level + 1);
  auto refused = [&](LocalStepper& stepper, const std::string& expected) {
    try {
      stepper.run(u.data(), v.data(), a.data(), 1, 0.0);
      ADD_FAILURE() << "stepped: " << expected;
    } catch (const std::invalid_argument& error) {
      EXPECT_NE(std::string(error.what()).find(expected), std::string::npos) << error.what();
    }
  };
  LocalStepper columns(share.system.view(), share.system.mass.data(), local_level.data(), dt_fine, 0.0, max_level);
  columns.set_partition(share.n_owned, none);
  refused(columns, "row split only");
  LocalStepper ghost_dashpot(share.system.view(), share.system.mass.data(), local_level.data(), dt_fine, 0.0,
                             max_level);
  ghost_dashpot.set_row_split(true);
  const std::int32_t ghost = static_cast<std::int32_t>(share.n_owned);
  const double C[9] = {0.5, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 0.5};
  ghost_dashpot.set_dashpots(&ghost, 1, C);
  ghost_dashpot.set_partition(share.n_owned, none);
  refused(ghost_dashpot, "a dashpot at node 20, a ghost");
  EXPECT_THROW(LocalStepper(chain.system.view(), chain.system.mass.data(), chain.level.data(), dt_fine, 0.0,
                            max_level - 1),
               std::invalid_argument);
}
