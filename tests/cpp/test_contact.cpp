// Interlayer contact (contact.hpp, deterioration.hpp) inside the stepper: exact answers only.
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <vector>

#include "contact.hpp"
#include "deterioration.hpp"
#include "random_system.hpp"
#include "seismic_input.hpp"
#include "stable_step.hpp"
#include "stepper.hpp"

using namespace cavern;
using namespace cavern::testing;

namespace {

double max_abs_difference(const std::vector<double>& x, const std::vector<double>& y) {
  double difference = 0.0;
  for (std::size_t k = 0; k < x.size(); ++k)
    difference = std::max(difference, std::abs(x[k] - y[k]));
  return difference;
}

double max_abs(const std::vector<double>& x) {
  double value = 0.0;
  for (double v : x) value = std::max(value, std::abs(v));
  return value;
}

std::shared_ptr<ContactPairs> single_pair(std::int32_t i, std::int32_t j, const double n[3],
                                          const double F0[3], double area,
                                          const ContactStrength& strength) {
  const std::int32_t pairs[2] = {i, j};
  return std::make_shared<ContactPairs>(ContactGeometry{1, pairs, &area, n, F0}, strength);
}

// A constant force f on one node from t = -1 on (a two-sample table held after its end).
struct ConstantForce {
  std::vector<double> g = {1.0, 1.0}, dg = {0.0, 0.0}, ddg = {0.0, 0.0};
  std::vector<std::int64_t> node_ptr = {0, 1};
  std::vector<std::int32_t> nodes, table = {0};
  std::vector<double> tau = {0.0}, P, Q = {0.0, 0.0, 0.0};
  ConstantForce(std::int32_t node, double fx, double fy, double fz) : nodes{node}, P{fx, fy, fz} {}
  std::shared_ptr<SeismicInput> make() const {
    return std::make_shared<SeismicInput>(
        WaveformTables{-1.0, 1.0, 1, 2, g.data(), dg.data(), ddg.data()},
        InputEntries{1, 1, node_ptr.data(), nodes.data(), table.data(), tau.data(), P.data(),
                     Q.data()});
  }
};

// Two nodes, no stiffness.
BlockSystem free_pair(double mass_i, double mass_j) {
  BlockSystem system;
  system.n_nodes = 2;
  system.indptr = {0, 0, 0};
  system.mass = {mass_i, mass_j};
  return system;
}

}  // namespace

TEST(Contact, BondedPairReproducesTheMergedSystemWithDampingAndA3x3Dashpot) {
  // Merged random system; node p is split into p and p' = n (random_system.hpp split_node): its
  // diagonal block halved on each side, each coupling block moved to p' or kept at p, its mass
  // divided 30/70.
  const std::int64_t n = 20, p = 6;
  const BlockSystem merged = random_spd_system(n, 3, 17);
  std::mt19937_64 generator(3);
  std::vector<char> to_copy(n, 0);
  for (std::int64_t k = 0; k < n; ++k) to_copy[k] = (generator() % 2) ? 0 : 1;
  const BlockSystem split = split_node(merged, p, to_copy);

  const double dt = 0.5 * 2.0 / std::sqrt(gershgorin_bound(merged.view(), merged.mass.data()));
  const double alpha = 0.4;
  Stepper merged_stepper(merged.view(), merged.mass.data(), {dt, alpha, 0.0});
  Stepper split_stepper(split.view(), split.mass.data(), {dt, alpha, 0.0});
  const double C[9] = {3.0, 1.0, -0.5, 1.0, 2.0, 0.3, -0.5, 0.3, 4.0};
  const std::int32_t merged_node = p, copy_node = n;
  merged_stepper.set_dashpots(&merged_node, 1, C);
  split_stepper.set_dashpots(&copy_node, 1, C);
  const double normal[3] = {0.0, 0.6, 0.8}, F0[3] = {1.0, -30.0, -40.0};
  auto contact = single_pair(p, n, normal, F0, 1.0, {1e9, 1e9, 0.5, 0.4});
  split_stepper.set_contact(contact);

  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::vector<double> u(3 * n), v(3 * n), a(3 * n, 0.0);
  for (double& x : u) x = 0.1 * uniform(generator);
  for (double& x : v) x = uniform(generator);
  std::vector<double> us(u), vs(v), as(a);
  for (int c = 0; c < 3; ++c) {
    us.push_back(u[3 * p + c]);
    vs.push_back(v[3 * p + c]);
    as.push_back(0.0);
  }
  merged_stepper.run(u.data(), v.data(), a.data(), 200, 0.0);
  split_stepper.run(us.data(), vs.data(), as.data(), 200, 0.0);

  int checks = 0;
  for (const auto& [merged_state, split_state] :
       {std::pair{&u, &us}, std::pair{&v, &vs}, std::pair{&a, &as}}) {
    std::vector<double> split_on_merged(split_state->begin(), split_state->begin() + 3 * n);
    std::vector<double> copy_node(split_state->begin() + 3 * n, split_state->end());
    std::vector<double> merged_p(merged_state->begin() + 3 * p, merged_state->begin() + 3 * p + 3);
    const double scale = max_abs(*merged_state);
    EXPECT_GT(scale, 1e-5);
    EXPECT_LT(max_abs_difference(split_on_merged, *merged_state), 1e-12 * scale);
    EXPECT_LT(max_abs_difference(copy_node, merged_p), 1e-12 * scale);
    ++checks;
  }
  EXPECT_EQ(checks, 3);
  EXPECT_EQ(contact->state()[0], kBonded);
  const EnergyReport report = split_stepper.energy();
  const double scale =
      std::max({std::abs(report.total), std::abs(report.initial), report.damping_work});
  EXPECT_LT(std::abs(report.balance), 1e-12 * scale);
}

TEST(Contact, StuckPairKeepsItsTangentialOffsetAndClosedGapWithCoupledDashpots) {
  // Delta_{n+2} = Delta_pred - dt^2 (Atilde_i^-1 + Atilde_j^-1) R: with full 3x3 dashpots on both
  // nodes the stick force must still close the gap and freeze the tangential offset exactly.
  BlockSystem system = free_pair(1.5, 0.5);
  const double dt = 0.01, alpha = 2.0;
  Stepper stepper(system.view(), system.mass.data(), {dt, alpha, 0.0});
  const std::int32_t nodes[2] = {0, 1};
  const double C[18] = {30, 5, -8, 5, 20, 3, -8, 3, 40, 10, -2, 1, -2, 15, 4, 1, 4, 25};
  stepper.set_dashpots(nodes, 2, C);
  const double normal[3] = {0.48, 0.6, 0.64}, F0[3] = {-4.8, -6.0, -6.4};
  auto contact = single_pair(0, 1, normal, F0, 1.0, {1e6, 1e6, 0.5, 0.4});
  stepper.set_contact(contact);
  const ConstantForce force(1, 3.0, -1.0, 2.0);  // borrowed by the SeismicInput: keep alive
  stepper.add_provider(force.make());
  // A tangential offset, zero gap and different velocities: the first step moves the pair
  // freely (its force acts on u_2); from then on the gap is closed and the offset frozen.
  std::vector<double> u = {0, 0, 0, 0.006, -0.0048, 0.0}, v = {0.1, 0.2, -0.3, -0.5, 0.4, 0.9},
                      a(6, 0.0);
  double t = stepper.run(u.data(), v.data(), a.data(), 1, 0.0);
  double delta_1[3], tangential_1[3];
  contact->relative_displacement(u.data(), delta_1);
  const double gap_1 = delta_1[0] * normal[0] + delta_1[1] * normal[1] + delta_1[2] * normal[2];
  for (int c = 0; c < 3; ++c) tangential_1[c] = delta_1[c] - gap_1 * normal[c];
  EXPECT_GT(std::abs(gap_1), 1e-3);
  int checks = 0;
  for (int step = 1; step < 50; ++step) {
    t = stepper.run(u.data(), v.data(), a.data(), 1, t);
    double delta[3];
    contact->relative_displacement(u.data(), delta);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(delta[c], tangential_1[c], 1e-15) << "step " << step;
    ++checks;
  }
  EXPECT_EQ(checks, 49);
  EXPECT_EQ(contact->state()[0], kBonded);
}

TEST(Contact, SlidingPairTransmitsDynamicFrictionAndDissipates) {
  BlockSystem system = free_pair(1.0, 2.0);
  const double dt = 1e-3, N0 = 50.0, mu_d = 0.3;
  Stepper stepper(system.view(), system.mass.data(), {dt, 0.0, 0.0});
  const double normal[3] = {0.0, 0.0, 1.0}, F0[3] = {0.0, 0.0, -N0};
  auto contact = single_pair(0, 1, normal, F0, 1.0, {1.0, 1.0, 0.5, mu_d});
  stepper.set_contact(contact);
  const ConstantForce force(1, 200.0, 0.0, 0.0);  // borrowed by the SeismicInput: keep alive
  stepper.add_provider(force.make());
  std::vector<double> u(6, 0.0), v(6, 0.0), a(6, 0.0);
  double t = 0.0, previous_dissipation = 0.0;
  for (int step = 0; step < 500; ++step) {
    t = stepper.run(u.data(), v.data(), a.data(), 1, t);
    ASSERT_EQ(contact->state()[0], kSliding) << "step " << step;
    const double* T = contact->tangential_force().data();
    EXPECT_NEAR(std::hypot(T[0], T[1], T[2]), mu_d * N0, 1e-12 * N0);
    EXPECT_NEAR(contact->normal_force()[0], N0, 1e-12 * N0);
    const EnergyReport report = stepper.energy();
    EXPECT_GE(report.friction_dissipation, previous_dissipation);
    previous_dissipation = report.friction_dissipation;
    EXPECT_LT(std::abs(report.balance), 1e-12 * report.external_work);
  }
  // Node 0 (1 kg) is dragged by mu_d N0 = 15 N from the first step on; starting from a_0 = 0,
  // velocity Verlet gives v_n = 15 (t_n - dt/2).
  EXPECT_NEAR(v[0], mu_d * N0 / 1.0 * (t - 0.5 * dt), 1e-12);
  EXPECT_FALSE(contact->bond_intact()[0]);
  EXPECT_GT(previous_dissipation, 0.0);
}

TEST(Contact, SeparatedPairCarriesNothingAndClosesWithoutInterpenetration) {
  // Node 1 thrown away from node 0 along n, then pulled back by a constant force.
  BlockSystem system = free_pair(3.0, 1.0);
  const double dt = 1e-3;
  Stepper stepper(system.view(), system.mass.data(), {dt, 0.0, 0.0});
  const double normal[3] = {0.0, 1.0, 0.0}, F0[3] = {0.0, -2.0, 0.0};
  auto contact = single_pair(0, 1, normal, F0, 1.0, {1.0, 1.0, 0.5, 0.4});
  stepper.set_contact(contact);
  const ConstantForce force(1, 0.0, -10.0, 0.0);  // borrowed by the SeismicInput: keep alive
  stepper.add_provider(force.make());
  std::vector<double> u(6, 0.0), v = {0, 0, 0, 0, 2.0, 0}, a(6, 0.0);
  double t = 0.0, min_gap = 0.0, max_gap = 0.0;
  int open_steps = 0, closed_after_open = 0;
  for (int step = 0; step < 2000; ++step) {
    t = stepper.run(u.data(), v.data(), a.data(), 1, t);
    const double gap = u[4] - u[1];
    min_gap = std::min(min_gap, gap);
    max_gap = std::max(max_gap, gap);
    if (contact->state()[0] == kSeparated) {
      ++open_steps;
      EXPECT_EQ(contact->normal_force()[0], 0.0);
    } else if (open_steps > 0) {
      ++closed_after_open;
      EXPECT_GE(contact->normal_force()[0], 0.0);
    }
  }
  EXPECT_GT(open_steps, 100);
  EXPECT_GT(closed_after_open, 100);
  EXPECT_GT(max_gap, 0.05);
  EXPECT_GT(min_gap, -1e-14 * max_gap);
  const EnergyReport report = stepper.energy();
  const double scale = std::max(
      {std::abs(report.initial), std::abs(report.external_work), std::abs(report.contact_work)});
  EXPECT_LT(std::abs(report.balance), 1e-12 * scale);
  // The plastic impact of the closing pair lost kinetic energy: contact work is negative.
  EXPECT_LT(report.contact_work, 0.0);
}

TEST(Deterioration, PaperValuesFollowEqs9To11) {
  const DeteriorationParameters paper{0.75, 5.0, 20.0, 0.883, 0.02, 0.032};
  EXPECT_DOUBLE_EQ(wear_factor(paper, 0.0), 1.0);
  EXPECT_NEAR(wear_factor(paper, 20.0), 0.75 + 0.25 * std::exp(-5.0), 1e-15);
  EXPECT_NEAR(wear_factor(paper, -3.0), 1.0, 1e-15);  // before the earthquake: undamaged
  // gamma(0) = 0.883 * 0.02^-0.032 = 1.0010...; gamma falls with the slip rate.
  EXPECT_NEAR(slip_rate_factor(paper, 0.0), 0.883 * std::pow(0.02, -0.032), 1e-15);
  EXPECT_NEAR(slip_rate_factor(paper, -0.5), 0.883 * std::pow(0.52, -0.032), 1e-15);
  EXPECT_NEAR(deterioration(paper, 20.0, 0.5),
              wear_factor(paper, 20.0) * slip_rate_factor(paper, 0.5), 1e-15);
  DeteriorationParameters bad = paper;
  bad.n = 0.0;
  EXPECT_THROW(check_deterioration(bad), std::invalid_argument);
  bad = paper;
  bad.start = std::nan("");
  EXPECT_THROW(check_deterioration(bad), std::invalid_argument);
}

TEST(Deterioration, WearClockStartsAtTheEarthquakesStart) {
  // The record's window starts 1 s into the run (the filter's lead-in before it): unworn until then,
  // then Eq. 9 in the time since the start.
  DeteriorationParameters paper{0.75, 5.0, 20.0, 0.883, 0.02, 0.032};
  paper.start = 1.0;
  EXPECT_DOUBLE_EQ(wear_factor(paper, 0.0), 1.0);
  EXPECT_DOUBLE_EQ(wear_factor(paper, 0.999), 1.0);
  EXPECT_DOUBLE_EQ(wear_factor(paper, 1.0), 1.0);
  EXPECT_NEAR(wear_factor(paper, 21.0), 0.75 + 0.25 * std::exp(-5.0), 1e-15);
  EXPECT_NEAR(wear_factor(paper, 4.0), 0.75 + 0.25 * std::exp(-5.0 * 3.0 / 20.0), 1e-15);
}

TEST(Contact, RejectsBadPairs) {
  BlockSystem system = free_pair(1.0, 1.0);
  Stepper stepper(system.view(), system.mass.data(), {0.01, 0.0, 0.0});
  const double normal[3] = {0.0, 0.0, 1.0}, F0[3] = {0.0, 0.0, 0.0};
  EXPECT_THROW(stepper.set_contact(single_pair(0, 2, normal, F0, 1.0, {})), std::invalid_argument);
  EXPECT_THROW(stepper.set_contact(single_pair(1, 1, normal, F0, 1.0, {})), std::invalid_argument);
  const double long_normal[3] = {0.0, 0.0, 1.1};
  EXPECT_THROW(single_pair(0, 1, long_normal, F0, 1.0, {}), std::invalid_argument);
  EXPECT_THROW(single_pair(0, 1, normal, F0, -1.0, {}), std::invalid_argument);
  EXPECT_THROW(single_pair(0, 1, normal, F0, 1.0, {-1.0, 0.0, 0.0, 0.0}), std::invalid_argument);
}

namespace {

// One contact correction of `pairs` (n, 2) on a random state with `threads` OpenMP threads:
// v, a after it, then states, normal forces and the step's friction dissipation.
struct CorrectionResult {
  std::vector<double> v, a, normal_force;
  std::vector<std::int8_t> state;
  double dissipation = 0.0;
};

CorrectionResult correct_once(const std::vector<std::int32_t>& pairs, std::int64_t n_nodes, int threads) {
  const std::int64_t n_pairs = static_cast<std::int64_t>(pairs.size() / 2);
  std::mt19937_64 generator(5);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  // Per-pair data drawn per node (the pair's first node), so a reordered list has the same pairs.
  std::vector<double> node_area(n_nodes), node_shear(n_nodes), node_normal(n_nodes);
  for (std::int64_t i = 0; i < n_nodes; ++i) {
    node_area[i] = 1.0 + 0.5 * uniform(generator);
    node_shear[i] = 1e5 * uniform(generator);
    node_normal[i] = 1e6 * uniform(generator);  // some pairs in tension, some in compression
  }
  std::vector<double> area(n_pairs), normal(3 * n_pairs), F0(3 * n_pairs);
  for (std::int64_t p = 0; p < n_pairs; ++p) {
    const std::int32_t i = pairs[2 * p];
    area[p] = node_area[i];
    normal[3 * p + 2] = 1.0;
    F0[3 * p] = node_shear[i];
    F0[3 * p + 2] = node_normal[i];
  }
  // Weak interface: many pairs slide or open in this one step.
  ContactPairs contact(ContactGeometry{n_pairs, pairs.data(), area.data(), normal.data(), F0.data()},
                       ContactStrength{1e5, 1e5, 0.5, 0.4});
  contact.set_deterioration(DeteriorationParameters{0.75, 5.0, 20.0, 0.883, 0.02, 0.032});
  std::vector<double> mass(n_nodes), u(3 * n_nodes), v(3 * n_nodes), a(3 * n_nodes);
  std::generate(mass.begin(), mass.end(), [&] { return 1000.0 * (1.5 + uniform(generator)); });
  for (auto* x : {&u, &v, &a})
    std::generate(x->begin(), x->end(), [&] { return 1e-3 * uniform(generator); });
  ImplicitNodeOperators operators;
  operators.dt = 1e-3;
  operators.mass = mass.data();
  const int saved = omp_get_max_threads();
  omp_set_num_threads(threads);
  const ContactStepResult step = contact.correct(0.5, operators, u.data(), v.data(), a.data());
  omp_set_num_threads(saved);
  return {v, a, contact.normal_force(), contact.state(), step.friction_dissipation};
}

}  // namespace

// From kMinPairsForThreads pairs the correction runs in parallel, colour by colour: one thread or
// two, the same bits; with pairs sharing nodes (a chain i-j, j-k, ...: two colours) too; and pairs
// that share no node give the same per-pair result in any order.
TEST(ContactPairs, ParallelCorrectionIsIndependentOfThreadsAndOrder) {
  const std::int64_t n = 3 * kMinPairsForThreads;
  std::vector<std::int32_t> disjoint, chain;
  for (std::int32_t p = 0; p < n; ++p) {
    disjoint.insert(disjoint.end(), {2 * p, 2 * p + 1});
    chain.insert(chain.end(), {p, p + 1});  // node p + 1 is shared by pairs p and p + 1
  }
  int checks = 0;
  for (const auto* pairs : {&disjoint, &chain}) {
    const std::int64_t n_nodes = 2 * n + 2;
    const CorrectionResult one = correct_once(*pairs, n_nodes, 1);
    const CorrectionResult two = correct_once(*pairs, n_nodes, 2);
    EXPECT_EQ(one.v, two.v);
    EXPECT_EQ(one.a, two.a);
    EXPECT_EQ(one.state, two.state);
    EXPECT_EQ(one.normal_force, two.normal_force);
    EXPECT_EQ(one.dissipation, two.dissipation);
    // Something happened: pairs left the bonded state and friction dissipated.
    EXPECT_GT(std::count_if(one.state.begin(), one.state.end(), [](std::int8_t s) { return s != 0; }), n / 10);
    EXPECT_GT(one.dissipation, 0.0);
    checks += 1;
  }
  // Disjoint pairs reversed: each pair's result is the same.
  std::vector<std::int32_t> reversed;
  for (std::int64_t p = n - 1; p >= 0; --p) reversed.insert(reversed.end(), {disjoint[2 * p], disjoint[2 * p + 1]});
  const CorrectionResult forward = correct_once(disjoint, 2 * n + 2, 2);
  const CorrectionResult backward = correct_once(reversed, 2 * n + 2, 2);
  EXPECT_EQ(forward.v, backward.v);
  EXPECT_EQ(forward.a, backward.a);
  EXPECT_EQ(checks, 2);
}
