#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <vector>

#include "random_system.hpp"
#include "seismic_input.hpp"
#include "stable_step.hpp"
#include "stepper.hpp"

using namespace cavern;
using namespace cavern::testing;

TEST(Stepper, DashpotStepSolvesTheImplicit3x3System) {
  // One node with a spring block, a full symmetric dashpot and alpha damping.
  BlockSystem system;
  system.n_nodes = 1;
  system.indptr = {0, 1};
  system.indices = {0};
  system.blocks = {4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0};
  system.mass = {2.5};
  const double dt = 0.1, alpha = 0.3;
  Stepper stepper(system.view(), system.mass.data(), {dt, alpha, 0.0});
  const std::int32_t node = 0;
  const double C[9] = {5.0, 1.0, -2.0, 1.0, 4.0, 0.5, -2.0, 0.5, 6.0};
  stepper.set_dashpots(&node, 1, C);

  std::vector<double> u = {0.01, -0.02, 0.03}, v = {1.0, -0.5, 0.25}, a = {0.2, 0.1, -0.3};
  const std::vector<double> u0 = u, v0 = v, a0 = a;
  stepper.run(u.data(), v.data(), a.data(), 1, 0.0);

  const double m = system.mass[0];
  double v_half[3], u1[3];
  for (int c = 0; c < 3; ++c) {
    v_half[c] = v0[c] + 0.5 * dt * a0[c];
    u1[c] = u0[c] + dt * v_half[c];
    EXPECT_NEAR(u[c], u1[c], 1e-15);
  }
  for (int r = 0; r < 3; ++r) {
    double Ku = 0.0, Cv = 0.0;
    for (int c = 0; c < 3; ++c) {
      Ku += system.blocks[3 * r + c] * u1[c];
      Cv += C[3 * r + c] * v[c];
    }
    // (M (1 + dt/2 alpha) I + dt/2 C) v1 = M v_half + dt/2 r, r = -K u1
    const double lhs = m * (1.0 + 0.5 * dt * alpha) * v[r] + 0.5 * dt * Cv;
    const double rhs = m * v_half[r] - 0.5 * dt * Ku;
    EXPECT_NEAR(lhs, rhs, 1e-14) << "row " << r;
    EXPECT_NEAR(a[r], (-Ku - alpha * m * v[r] - Cv) / m, 1e-14) << "row " << r;
  }
}

TEST(Stepper, RejectsAnIndefiniteDashpot) {
  BlockSystem system = random_spd_system(3, 1, 2);
  Stepper stepper(system.view(), system.mass.data(), {0.1, 0.0, 0.0});
  const std::int32_t node = 1;
  const double C[9] = {-1e3, 0, 0, 0, 1, 0, 0, 0, 1};
  EXPECT_THROW(stepper.set_dashpots(&node, 1, C), std::invalid_argument);
}

TEST(Stepper, EnergyBalanceIsZeroToRoundOffWithInputAndDamping) {
  const BlockSystem system = random_spd_system(30, 3, 42);
  const double omega_max = std::sqrt(gershgorin_bound(system.view(), system.mass.data()));
  const double alpha = 0.4, beta = 0.002;
  const double dt = 0.5 * 2.0 / omega_max;
  Stepper stepper(system.view(), system.mass.data(), {dt, alpha, beta});

  // Dashpots at three nodes: C = D D^T.
  std::mt19937_64 generator(9);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  const std::vector<std::int32_t> dashpot_nodes = {2, 7, 19};
  std::vector<double> C(27);
  for (int k = 0; k < 3; ++k) {
    double D[9];
    for (double& d : D) d = uniform(generator);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c)
        C[9 * k + 3 * r + c] =
            D[3 * r] * D[3 * c] + D[3 * r + 1] * D[3 * c + 1] + D[3 * r + 2] * D[3 * c + 2];
  }
  stepper.set_dashpots(dashpot_nodes.data(), 3, C.data());

  // A smooth pulse g = sin^2 on two tables, pushed in at four nodes with delays.
  const std::int64_t n_samples = 400;
  const double table_dt = 0.05;
  std::vector<double> g(2 * n_samples), dg(2 * n_samples), ddg(2 * n_samples);
  for (int table = 0; table < 2; ++table)
    for (std::int64_t k = 0; k < n_samples; ++k) {
      const double w = 1.0 + table, t = k * table_dt;
      g[table * n_samples + k] = std::sin(w * t) * std::sin(w * t);
      dg[table * n_samples + k] = w * std::sin(2 * w * t);
      ddg[table * n_samples + k] = 2 * w * w * std::cos(2 * w * t);
    }
  const std::vector<std::int64_t> node_ptr = {0, 2, 3, 4, 5};
  const std::vector<std::int32_t> nodes = {0, 7, 11, 29};
  const std::vector<std::int32_t> table = {0, 1, 0, 1, 1};
  const std::vector<double> tau = {0.0, 0.3, 0.1, 0.7, 1.1};
  std::vector<double> P(15), Q(15);
  for (double& p : P) p = uniform(generator);
  for (double& q : Q) q = uniform(generator);
  auto input = std::make_shared<SeismicInput>(
      WaveformTables{0.0, table_dt, 2, n_samples, g.data(), dg.data(), ddg.data()},
      InputEntries{4, 5, node_ptr.data(), nodes.data(), table.data(), tau.data(), P.data(),
                   Q.data()});
  stepper.add_provider(input);

  std::vector<double> u(system.n_dofs()), v(system.n_dofs()), a(system.n_dofs(), 0.0);
  for (double& value : u) value = 0.01 * uniform(generator);
  for (double& value : v) value = 0.1 * uniform(generator);
  stepper.reset_energy(u.data(), v.data(), a.data(), 0.0);

  double scale = 0.0;
  for (int chunk = 0; chunk < 10; ++chunk) {
    stepper.run(u.data(), v.data(), a.data(), 100, chunk * 100 * dt);
    const EnergyReport report = stepper.energy();
    scale = std::max({scale, std::abs(report.total), report.external_work, report.damping_work});
    EXPECT_LT(std::abs(report.balance), 1e-12 * scale) << "after " << (chunk + 1) * 100 << " steps";
  }
  const EnergyReport report = stepper.energy();
  // The checks above mean something only if every term did work.
  EXPECT_GT(std::abs(report.external_work), 1e-3 * scale);
  EXPECT_GT(report.damping_work, 1e-3 * scale);
  ASSERT_EQ(report.provider_work.size(), 1u);
  EXPECT_NEAR(report.provider_work[0], report.external_work, 1e-12 * scale);
}

TEST(StableStep, GershgorinBoundIsAbovePowerIterationEstimate) {
  const BlockSystem system = random_spd_system(12, 2, 5);
  const double bound = gershgorin_bound(system.view(), system.mass.data());
  const double estimate = power_iteration(system.view(), system.mass.data(), 500, 1);
  // Power iteration approaches omega_max^2 from below, Gershgorin bounds it from above.
  EXPECT_GE(bound, estimate);
  EXPECT_GT(estimate, 0.2 * bound);
}
