// Kinematic constraints (fixed, roller) of the stepper: held components stay zero, the free
// motion equals the system with the held dofs removed, the reaction balances the node, and the
// discrete energy account stays exact.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "constraints.hpp"
#include "random_system.hpp"
#include "stepper.hpp"

using namespace cavern;
using namespace cavern::testing;

namespace {

/// P = I - n n^T for a unit n.
std::vector<double> roller_projection(const double n[3]) {
  std::vector<double> P(9);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) P[3 * r + c] = (r == c ? 1.0 : 0.0) - n[r] * n[c];
  return P;
}

/// Velocity Verlet on the dense system with the listed dofs removed (held at zero): the
/// independent reference of a constrained run without damping.
void reference_steps(const BlockSystem& system, const std::vector<char>& held, double dt, int n_steps,
                     std::vector<double>& u, std::vector<double>& v, std::vector<double>& a) {
  const std::int64_t n = system.n_dofs();
  for (int step = 0; step < n_steps; ++step) {
    for (std::int64_t d = 0; d < n; ++d) {
      v[d] += 0.5 * dt * a[d];
      u[d] += dt * v[d];
    }
    const std::vector<double> Ku = dense_product(system, u);
    for (std::int64_t d = 0; d < n; ++d) {
      a[d] = held[d] ? 0.0 : -Ku[d] / system.mass[d / 3];
      v[d] = held[d] ? 0.0 : v[d] + 0.5 * dt * a[d];
    }
  }
}

}  // namespace

TEST(Constraints, ConstrainedInverseSolvesTheSystemInTheFreeDirections) {
  const double A[9] = {4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0};
  double n[3] = {1.0, 2.0, 2.0};
  for (double& x : n) x /= 3.0;
  const std::vector<double> P = roller_projection(n);
  double inverse[9];
  ASSERT_TRUE(constrained_inverse(A, P.data(), inverse));
  const double rhs[3] = {0.3, -1.1, 0.7};
  double v[3], Av[3], residual[3], Pv[3];
  multiply_3x3(inverse, rhs, v);
  multiply_3x3(A, v, Av);
  for (int c = 0; c < 3; ++c) residual[c] = Av[c] - rhs[c];
  double P_residual[3];
  multiply_3x3(P.data(), residual, P_residual);
  multiply_3x3(P.data(), v, Pv);
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(P_residual[c], 0.0, 1e-14) << "P (A v - rhs) = 0, component " << c;
    EXPECT_NEAR(Pv[c], v[c], 1e-15) << "v lies in the free subspace";
  }
  EXPECT_NEAR(n[0] * v[0] + n[1] * v[1] + n[2] * v[2], 0.0, 1e-15);
}

TEST(Constraints, RejectsAMatrixThatIsNotAProjection) {
  BlockSystem system = random_spd_system(4, 2, 3);
  Stepper stepper(system.view(), system.mass.data(), {0.01, 0.0, 0.0});
  const std::int32_t node = 1;
  const double not_projection[9] = {2, 0, 0, 0, 1, 0, 0, 0, 1};
  EXPECT_THROW(stepper.set_constraints(&node, 1, not_projection), std::invalid_argument);
  const std::int32_t twice[2] = {1, 1};
  const double zeros[18] = {};
  EXPECT_THROW(stepper.set_constraints(twice, 2, zeros), std::invalid_argument);
}

TEST(Constraints, FixedAndAxisRollerEqualTheSystemWithoutTheHeldDofs) {
  // Node 0 fixed, node 3 on a roller with normal z, node 5 on a roller with normal x;
  // both storage formats against the dense reduced system.
  for (bool symmetric : {true, false}) {
    BlockSystem system = random_spd_system(8, 2, 11);
    const double dt = 0.05;  // well below 2/omega_max for these masses and blocks
    StepperParameters parameters{dt, 0.0, 0.0, symmetric};
    Stepper stepper(system.view(), system.mass.data(), parameters);
    const double ez[3] = {0, 0, 1}, ex[3] = {1, 0, 0};
    std::vector<std::int32_t> nodes = {0, 3, 5};
    std::vector<double> projection(27, 0.0);  // node 0: P = 0
    const std::vector<double> Pz = roller_projection(ez), Px = roller_projection(ex);
    std::copy(Pz.begin(), Pz.end(), projection.begin() + 9);
    std::copy(Px.begin(), Px.end(), projection.begin() + 18);
    stepper.set_constraints(nodes.data(), 3, projection.data());

    const std::int64_t n = system.n_dofs();
    std::vector<char> held(n, 0);
    held[0] = held[1] = held[2] = 1;
    held[3 * 3 + 2] = 1;
    held[3 * 5 + 0] = 1;
    std::vector<double> u(n, 0.0), v(n, 0.0), a(n, 0.0);
    for (std::int64_t d = 0; d < n; ++d)
      if (!held[d]) v[d] = std::sin(1.0 + d);  // an initial velocity in the free directions
    std::vector<double> u_ref = u, v_ref = v, a_ref = a;
    stepper.run(u.data(), v.data(), a.data(), 400, 0.0);
    reference_steps(system, held, dt, 400, u_ref, v_ref, a_ref);
    double scale = 0.0;
    for (double x : u_ref) scale = std::max(scale, std::abs(x));
    ASSERT_GT(scale, 1e-3) << "the system moved";
    int checks = 0;
    for (std::int64_t d = 0; d < n; ++d) {
      EXPECT_NEAR(u[d], u_ref[d], 1e-11 * scale) << "dof " << d;
      if (held[d]) {
        EXPECT_EQ(u[d], 0.0);
        EXPECT_EQ(v[d], 0.0);
        EXPECT_EQ(a[d], 0.0);
        ++checks;
      }
    }
    EXPECT_EQ(checks, 5);
  }
}

TEST(Constraints, ReactionBalancesTheNodeAndTheEnergyStaysExact) {
  // An oblique roller with a dashpot and mass damping, and a fixed node: n.u = 0 to round-off,
  // M a = -K u - d + R at the constrained nodes, R along the held directions only, and the
  // energy balance exact (the reaction does no work).
  BlockSystem system = random_spd_system(10, 2, 5);
  const double dt = 0.04, alpha = 0.2;
  Stepper stepper(system.view(), system.mass.data(), {dt, alpha, 0.0});
  double n[3] = {2.0, -1.0, 2.0};
  for (double& x : n) x /= 3.0;
  const std::int32_t dashpot_node = 4;
  const double C[9] = {5.0, 1.0, -2.0, 1.0, 4.0, 0.5, -2.0, 0.5, 6.0};
  stepper.set_dashpots(&dashpot_node, 1, C);
  std::vector<std::int32_t> nodes = {4, 7};
  std::vector<double> projection = roller_projection(n);
  projection.resize(18, 0.0);  // node 7 fixed
  stepper.set_constraints(nodes.data(), 2, projection.data());

  const std::int64_t count = system.n_dofs();
  std::vector<double> u(count, 0.0), v(count, 0.0), a(count, 0.0);
  for (std::int64_t d = 0; d < count; ++d) v[d] = std::cos(0.5 + d);
  for (int c = 0; c < 3; ++c) v[3 * 7 + c] = 0.0;
  const double vn = n[0] * v[12] + n[1] * v[13] + n[2] * v[14];
  for (int c = 0; c < 3; ++c) v[12 + c] -= vn * n[c];
  stepper.reset_energy(u.data(), v.data(), a.data(), 0.0);
  for (int chunk = 0; chunk < 5; ++chunk) {
    stepper.run(u.data(), v.data(), a.data(), 200, chunk * 200 * dt);
    const EnergyReport report = stepper.energy();
    const double energy_scale = std::max(report.initial, report.damping_work);
    EXPECT_LT(std::abs(report.balance), 1e-12 * energy_scale) << "after " << (chunk + 1) * 200;
  }
  EXPECT_GT(stepper.energy().damping_work, 0.1 * stepper.energy().initial) << "damping acted";

  const std::vector<double> Ku = dense_product(system, u);
  const std::vector<double>& R = stepper.reactions();
  ASSERT_EQ(R.size(), 6u);
  double dot_nu = 0.0, R_norm = 0.0, R_tangential = 0.0, Rn = 0.0;
  for (int c = 0; c < 3; ++c) {
    dot_nu += n[c] * u[12 + c];
    Rn += n[c] * R[c];
  }
  for (int c = 0; c < 3; ++c) {
    R_norm += R[c] * R[c];
    R_tangential += std::pow(R[c] - Rn * n[c], 2);
  }
  EXPECT_NEAR(dot_nu, 0.0, 1e-14);
  EXPECT_GT(std::sqrt(R_norm), 1e-6) << "the roller carried a force";
  EXPECT_LT(std::sqrt(R_tangential), 1e-12 * std::sqrt(R_norm)) << "a roller reacts along n only";
  // Node balance at the roller: M a = -K u - (alpha M + C) v + R.
  const double m = system.mass[4];
  for (int r = 0; r < 3; ++r) {
    double Cv = 0.0;
    for (int c = 0; c < 3; ++c) Cv += C[3 * r + c] * v[12 + c];
    const double residual = m * a[12 + r] - (-Ku[12 + r] - alpha * m * v[12 + r] - Cv + R[r]);
    EXPECT_NEAR(residual, 0.0, 1e-11 * (std::abs(Ku[12 + r]) + std::abs(R[r]) + 1e-300)) << "row " << r;
  }
  // The fixed node: R = K u (it does not move), all components.
  for (int c = 0; c < 3; ++c) {
    EXPECT_EQ(u[21 + c], 0.0);
    EXPECT_NEAR(R[3 + c], Ku[21 + c], 1e-11 * std::abs(Ku[21 + c]) + 1e-14);
  }
}
