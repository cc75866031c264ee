// The internal-force interface: hexahedral element loops against their own stiffness matrix,
// thread independence, compute/commit separation, and the stepper's energy account with an
// elastic and a plastic component.
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <random>
#include <stdexcept>
#include <vector>

#include "force_provider.hpp"
#include "internal_force.hpp"
#include "local_stepper.hpp"
#include "materials/linear_elastic.hpp"
#include "random_system.hpp"
#include "small_matrix.hpp"
#include "stable_step.hpp"
#include "stepper.hpp"

using namespace cavern;
using namespace cavern::testing;

namespace {

constexpr double kLambda = 2.0e9, kShear = 1.5e9;  // Pa

/// A structured grid of Q1 hexahedra with jittered nodes (a non-affine mesh): element arrays
/// with 2x2x2 Gauss points, as pyfem/elements.py builds them.
struct HexMesh {
  std::int64_t n_nodes = 0, n_cells = 0;
  std::vector<double> coords;  // (n_nodes, 3)
  std::vector<std::int32_t> cell_nodes;
  std::vector<double> gradients, weights;
  HexahedronGeometry geometry() const {
    return {n_cells, 8, 8, cell_nodes.data(), gradients.data(), weights.data()};
  }
  std::int64_t n_dofs() const { return 3 * n_nodes; }
};

HexMesh hexahedron_grid(int nx, int ny, int nz, double jitter, std::uint64_t seed) {
  HexMesh mesh;
  std::mt19937_64 generator(seed);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  const double h = 0.5;  // m
  auto node_of = [&](int i, int j, int k) { return (k * (ny + 1) + j) * (nx + 1) + i; };
  mesh.n_nodes = static_cast<std::int64_t>(nx + 1) * (ny + 1) * (nz + 1);
  mesh.coords.resize(3 * mesh.n_nodes);
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i) {
        double* x = mesh.coords.data() + 3 * node_of(i, j, k);
        x[0] = h * (i + jitter * uniform(generator));
        x[1] = h * (j + jitter * uniform(generator));
        x[2] = h * (k + jitter * uniform(generator));
      }
  const double gauss[2] = {0.5 - 0.5 / std::sqrt(3.0), 0.5 + 0.5 / std::sqrt(3.0)};
  mesh.n_cells = static_cast<std::int64_t>(nx) * ny * nz;
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        std::int32_t nodes[8];
        for (int a = 0; a < 8; ++a)
          nodes[a] = node_of(i + (a & 1), j + ((a >> 1) & 1), k + ((a >> 2) & 1));
        mesh.cell_nodes.insert(mesh.cell_nodes.end(), nodes, nodes + 8);
        for (int q = 0; q < 8; ++q) {
          const double X[3] = {gauss[q & 1], gauss[(q >> 1) & 1], gauss[(q >> 2) & 1]};
          double dphi[8][3], J[3][3] = {};
          for (int a = 0; a < 8; ++a) {
            const int bits[3] = {a & 1, (a >> 1) & 1, (a >> 2) & 1};
            double factor[3], slope[3];
            for (int d = 0; d < 3; ++d) {
              factor[d] = bits[d] ? X[d] : 1.0 - X[d];
              slope[d] = bits[d] ? 1.0 : -1.0;
            }
            dphi[a][0] = slope[0] * factor[1] * factor[2];
            dphi[a][1] = factor[0] * slope[1] * factor[2];
            dphi[a][2] = factor[0] * factor[1] * slope[2];
            for (int r = 0; r < 3; ++r)
              for (int c = 0; c < 3; ++c) J[r][c] += mesh.coords[3 * nodes[a] + r] * dphi[a][c];
          }
          const double Jflat[9] = {J[0][0], J[0][1], J[0][2], J[1][0], J[1][1],
                                   J[1][2], J[2][0], J[2][1], J[2][2]};
          double inverse[9];
          const double determinant = invert_3x3(Jflat, inverse);
          for (int a = 0; a < 8; ++a)
            for (int c = 0; c < 3; ++c)  // dphi/dx_c = sum_r dphi/dX_r (J^-1)_rc
              mesh.gradients.push_back(dphi[a][0] * inverse[c] + dphi[a][1] * inverse[3 + c] +
                                       dphi[a][2] * inverse[6 + c]);
          mesh.weights.push_back(std::abs(determinant) / 8.0);
        }
      }
  return mesh;
}

std::shared_ptr<HexahedronElements<LinearElastic>> elastic_elements(const HexMesh& mesh,
                                                                    bool mean_dilatation = false) {
  ElementOptions options;
  options.mean_dilatation = mean_dilatation;
  options.min_cells_for_threads = 0;
  return std::make_shared<HexahedronElements<LinearElastic>>(
      mesh.geometry(), LinearElastic::Parameters{kLambda, kShear}, options, nullptr);
}

/// Dense matrix (n_dofs x n_dofs, row-major) of the linear map u -> f_int(u) of a component.
std::vector<double> probed_matrix(InternalForceComponent& component, std::int64_t n_dofs) {
  std::vector<double> K(n_dofs * n_dofs), u(n_dofs, 0.0), f(n_dofs);
  for (std::int64_t j = 0; j < n_dofs; ++j) {
    u[j] = 1.0;
    std::fill(f.begin(), f.end(), 0.0);
    component.compute(u.data(), f.data());
    for (std::int64_t i = 0; i < n_dofs; ++i) K[i * n_dofs + j] = f[i];
    u[j] = 0.0;
  }
  return K;
}

/// J2 perfect plasticity by radial return, a stand-in for the real laws: it checks that a
/// dissipative law plugs in and that the stepper's account closes with its dissipation.
/// trapezoid = true: delta = 1/2 (sigma_c + sigma_t) : d eps_p (closes the balance exactly,
/// material_law.hpp); false: delta = sigma_t : d eps_p (backward Euler, an energy error).
struct ToyVonMises {
  static constexpr const char* kName = "toy_von_mises";
  struct Parameters {
    double lame_lambda, shear_modulus, yield_stress;
    bool trapezoid;
  };
  struct State {
    double stress[6];
    double plastic_strain[6];  // engineering shear
  };
  static ElasticModuli elastic_moduli(const Parameters& p) {
    return {p.lame_lambda, p.shear_modulus};
  }
  static State initial_state(const Parameters&, const double initial_stress[6], double) {
    State state{};
    for (int c = 0; c < 6; ++c) state.stress[c] = initial_stress[c];
    return state;
  }
  static PointOutput output(const State&) { return {}; }
  static void rebase(const Parameters&, State&) {
    throw std::logic_error("toy_von_mises: no rebase (its stress is not incremental)");
  }
  static PointEnergy evaluate(const Parameters& p, const State& committed, const PointStrain& point,
                              State& trial) {
    double elastic[6], sigma[6];
    for (int c = 0; c < 6; ++c) elastic[c] = point.strain[c] - committed.plastic_strain[c];
    const double trace = elastic[0] + elastic[1] + elastic[2];
    for (int c = 0; c < 3; ++c)
      sigma[c] = p.lame_lambda * trace + 2.0 * p.shear_modulus * elastic[c];
    for (int c = 3; c < 6; ++c) sigma[c] = p.shear_modulus * elastic[c];
    const double mean = (sigma[0] + sigma[1] + sigma[2]) / 3.0;
    double s[6] = {sigma[0] - mean, sigma[1] - mean, sigma[2] - mean, sigma[3], sigma[4], sigma[5]};
    const double ss =
        s[0] * s[0] + s[1] * s[1] + s[2] * s[2] + 2.0 * (s[3] * s[3] + s[4] * s[4] + s[5] * s[5]);
    const double equivalent = std::sqrt(1.5 * ss);
    trial = committed;
    double d_plastic[6] = {};
    if (equivalent > p.yield_stress) {
      const double scale = p.yield_stress / equivalent;
      for (int c = 0; c < 6; ++c) {
        const double ds = s[c] * (1.0 - scale);                             // s_trial - s
        d_plastic[c] = ds / (2.0 * p.shear_modulus) * (c < 3 ? 1.0 : 2.0);  // engineering
        s[c] *= scale;
      }
    }
    for (int c = 0; c < 6; ++c) {
      trial.plastic_strain[c] = committed.plastic_strain[c] + d_plastic[c];
      trial.stress[c] = point.initial_stress[c] + s[c] + (c < 3 ? mean : 0.0);
    }
    PointEnergy energy;
    double dynamic[6], elastic_strain[6];
    for (int c = 0; c < 6; ++c) {
      dynamic[c] = trial.stress[c] - point.initial_stress[c];
      elastic_strain[c] = point.strain[c] - trial.plastic_strain[c];
    }
    energy.stored = 0.5 * stress_dot_strain(dynamic, elastic_strain) -
                    stress_dot_strain(point.initial_stress, trial.plastic_strain);
    double sigma_mid[6];
    for (int c = 0; c < 6; ++c)
      sigma_mid[c] = p.trapezoid ? 0.5 * (committed.stress[c] + trial.stress[c]) : trial.stress[c];
    energy.dissipation = stress_dot_strain(sigma_mid, d_plastic);
    return energy;
  }
};

/// A smooth force at a few nodes: f = amplitude sin(omega t) direction.
class SineForce : public ForceProvider {
 public:
  SineForce(std::vector<std::int32_t> nodes, double amplitude, double omega)
      : nodes_(std::move(nodes)), amplitude_(amplitude), omega_(omega) {}
  void add_forces(double t, const double*, const double*, double* f) override {
    value_ = amplitude_ * std::sin(omega_ * t);
    for (std::int32_t node : nodes_)
      for (int c = 0; c < 3; ++c) f[3 * node + c] += value_ * kDirection[c];
  }
  double power(const double* v) const override {
    double p = 0.0;
    for (std::int32_t node : nodes_)
      for (int c = 0; c < 3; ++c) p += value_ * kDirection[c] * v[3 * node + c];
    return p;
  }
  void check_nodes(std::int64_t) const override {}
  std::string name() const override { return "sine"; }
  std::vector<std::int32_t> nodes() const override { return nodes_; }

 private:
  static constexpr double kDirection[3] = {0.6, 0.0, 0.8};
  std::vector<std::int32_t> nodes_;
  double amplitude_, omega_, value_ = 0.0;
};

/// Block CSR of a dense matrix keeping every block with a non-zero entry.
BlockSystem block_system(const std::vector<double>& dense, const std::vector<double>& mass) {
  BlockSystem system;
  system.n_nodes = static_cast<std::int64_t>(mass.size());
  system.dense = dense;
  system.mass = mass;
  const std::int64_t n = system.n_nodes, n_dofs = 3 * n;
  std::vector<char> pattern(n * n, 0);
  for (std::int64_t r = 0; r < n_dofs; ++r)
    for (std::int64_t c = 0; c < n_dofs; ++c)
      if (dense[r * n_dofs + c] != 0.0) pattern[(r / 3) * n + c / 3] = 1;
  for (std::int64_t i = 0; i < n; ++i) pattern[i * n + i] = 1;
  compress(system, pattern);
  return system;
}

/// Grounding springs (diagonal k) on the bottom layer of nodes, so that the system has no
/// rigid-body modes; the rest of the stiffness is the elements'.
std::vector<double> grounding(const HexMesh& mesh, double k) {
  std::vector<double> dense(mesh.n_dofs() * mesh.n_dofs(), 0.0);
  for (std::int64_t node = 0; node < mesh.n_nodes; ++node)
    if (mesh.coords[3 * node + 2] < 0.25)
      for (int c = 0; c < 3; ++c) dense[(3 * node + c) * mesh.n_dofs() + 3 * node + c] = k;
  return dense;
}

std::vector<double> lumped_mass(const HexMesh& mesh, double rho) {
  std::vector<double> mass(mesh.n_nodes, 0.0);
  for (std::int64_t cell = 0; cell < mesh.n_cells; ++cell)
    for (int q = 0; q < 8; ++q)
      for (int a = 0; a < 8; ++a)
        mass[mesh.cell_nodes[8 * cell + a]] += rho * mesh.weights[8 * cell + q] / 8.0;
  return mass;
}

double max_abs(const std::vector<double>& x) {
  double m = 0.0;
  for (double value : x) m = std::max(m, std::abs(value));
  return m;
}

}  // namespace

TEST(InternalForce, ElasticElementsAreTheirSymmetricStiffnessWithRigidModesFree) {
  const HexMesh mesh = hexahedron_grid(3, 2, 2, 0.15, 3);
  auto elements = elastic_elements(mesh);
  const std::int64_t n = mesh.n_dofs();
  const std::vector<double> K = probed_matrix(*elements, n);
  const double scale = max_abs(K);
  int checks = 0;
  for (std::int64_t i = 0; i < n; ++i)
    for (std::int64_t j = 0; j < i; ++j, ++checks)
      ASSERT_NEAR(K[i * n + j], K[j * n + i], 1e-12 * scale) << i << ", " << j;
  // Rigid translations and rotations give no force.
  for (int mode = 0; mode < 6; ++mode) {
    std::vector<double> u(n), f(n, 0.0);
    for (std::int64_t node = 0; node < mesh.n_nodes; ++node) {
      const double* x = mesh.coords.data() + 3 * node;
      double* un = u.data() + 3 * node;
      if (mode < 3) {
        un[mode] = 1.0;
      } else {  // omega x x with omega = e_(mode - 3)
        const int a = (mode - 2) % 3, b = (mode - 1) % 3;
        un[a] = -x[b];
        un[b] = x[a];
      }
    }
    elements->compute(u.data(), f.data());
    EXPECT_LT(max_abs(f), 1e-12 * scale * mesh.n_nodes) << "rigid mode " << mode;
    ++checks;
  }
  // Stored energy 1/2 u.K u.
  std::mt19937_64 generator(4);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::vector<double> u(n), f(n, 0.0);
  for (double& value : u) value = 1e-3 * uniform(generator);
  const InternalEnergy energy = elements->compute(u.data(), f.data());
  double uKu = 0.0;
  for (std::int64_t i = 0; i < n; ++i) uKu += u[i] * f[i];
  EXPECT_NEAR(energy.stored, 0.5 * uKu, 1e-12 * std::abs(uKu));
  EXPECT_EQ(energy.dissipation_increment, 0.0);
  EXPECT_EQ(checks, n * (n - 1) / 2 + 6);
}

TEST(InternalForce, LinearDisplacementGivesTheExactStressWithAndWithoutMeanDilatation) {
  const HexMesh mesh = hexahedron_grid(2, 2, 2, 0.2, 8);
  const double A[3][3] = {
      {1.0e-4, 2.0e-5, -3.0e-5}, {4.0e-5, -2.0e-4, 1.0e-5}, {0.0, 5.0e-5, 3.0e-4}};
  std::vector<double> u(mesh.n_dofs()), f(mesh.n_dofs(), 0.0);
  for (std::int64_t node = 0; node < mesh.n_nodes; ++node)
    for (int i = 0; i < 3; ++i)
      u[3 * node + i] = A[i][0] * mesh.coords[3 * node] + A[i][1] * mesh.coords[3 * node + 1] +
                        A[i][2] * mesh.coords[3 * node + 2];
  const double eps[6] = {A[0][0],           A[1][1],           A[2][2],
                         A[0][1] + A[1][0], A[1][2] + A[2][1], A[0][2] + A[2][0]};
  const double trace = eps[0] + eps[1] + eps[2];
  double expected[6];
  for (int c = 0; c < 3; ++c) expected[c] = kLambda * trace + 2.0 * kShear * eps[c];
  for (int c = 3; c < 6; ++c) expected[c] = kShear * eps[c];
  for (bool mean_dilatation : {false, true}) {
    auto elements = elastic_elements(mesh, mean_dilatation);
    elements->compute(u.data(), f.data());
    elements->commit();
    std::vector<double> stress(6 * mesh.n_cells * 8);
    elements->stress(stress.data());
    for (std::size_t p = 0; p < stress.size() / 6; ++p)
      for (int c = 0; c < 6; ++c)
        ASSERT_NEAR(stress[6 * p + c], expected[c], 1e-10 * std::abs(expected[0]))
            << "point " << p << " component " << c << " mean dilatation " << mean_dilatation;
  }
}

TEST(InternalForce, MeanDilatationForceIsTheGradientOfItsEnergy) {
  const HexMesh mesh = hexahedron_grid(2, 1, 1, 0.2, 11);
  auto elements = elastic_elements(mesh, true);
  std::mt19937_64 generator(12);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  const std::int64_t n = mesh.n_dofs();
  std::vector<double> u(n), f(n, 0.0), scratch(n);
  for (double& value : u) value = 1e-3 * uniform(generator);
  elements->compute(u.data(), f.data());
  // Central differences of the stored energy (quadratic: exact up to round-off).
  const double h = 1e-6;
  for (std::int64_t j = 0; j < n; ++j) {
    std::vector<double> up = u, um = u;
    up[j] += h;
    um[j] -= h;
    const double derivative = (elements->compute(up.data(), scratch.data()).stored -
                               elements->compute(um.data(), scratch.data()).stored) /
                              (2.0 * h);
    ASSERT_NEAR(f[j], derivative, 1e-6 * max_abs(f)) << "dof " << j;
  }
  // And it differs from the plain element force (the test would pass for B-bar = B otherwise).
  auto plain = elastic_elements(mesh, false);
  std::vector<double> f_plain(n, 0.0);
  plain->compute(u.data(), f_plain.data());
  double difference = 0.0;
  for (std::int64_t j = 0; j < n; ++j)
    difference = std::max(difference, std::abs(f[j] - f_plain[j]));
  EXPECT_GT(difference, 1e-3 * max_abs(f));
}

TEST(InternalForce, ResultIsTheSameBitsForOneAndTwoThreads) {
  const HexMesh mesh = hexahedron_grid(8, 8, 8, 0.2, 5);
  ToyVonMises::Parameters parameters{kLambda, kShear, 2.0e5, true};
  ElementOptions options;
  options.min_cells_for_threads = 0;
  std::mt19937_64 generator(6);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::vector<double> u(mesh.n_dofs());
  for (double& value : u) value = 1e-4 * uniform(generator);

  const int previous = omp_get_max_threads();
  std::vector<std::vector<double>> forces, stresses;
  std::vector<InternalEnergy> energies;
  for (int threads : {1, 2}) {
    omp_set_num_threads(threads);
    HexahedronElements<ToyVonMises> elements(mesh.geometry(), parameters, options, nullptr);
    std::vector<double> f(mesh.n_dofs(), 0.0), stress(6 * mesh.n_cells * 8);
    energies.push_back(elements.compute(u.data(), f.data()));
    elements.commit();
    elements.stress(stress.data());
    forces.push_back(f);
    stresses.push_back(stress);
  }
  omp_set_num_threads(previous);
  EXPECT_EQ(std::memcmp(forces[0].data(), forces[1].data(), forces[0].size() * sizeof(double)), 0);
  EXPECT_EQ(
      std::memcmp(stresses[0].data(), stresses[1].data(), stresses[0].size() * sizeof(double)), 0);
  EXPECT_EQ(energies[0].stored, energies[1].stored);
  EXPECT_EQ(energies[0].dissipation_increment, energies[1].dissipation_increment);
  EXPECT_GT(energies[0].dissipation_increment, 0.0);  // plastic points took part
}

TEST(InternalForce, ComputeLeavesTheCommittedStateAndCommitNeedsACompute) {
  const HexMesh mesh = hexahedron_grid(2, 2, 1, 0.1, 7);
  ToyVonMises::Parameters parameters{kLambda, kShear, 1.0e5, true};
  HexahedronElements<ToyVonMises> elements(mesh.geometry(), parameters, ElementOptions{}, nullptr);
  EXPECT_THROW(elements.commit(), std::logic_error);
  std::vector<double> u(mesh.n_dofs()), f(mesh.n_dofs(), 0.0);
  for (std::int64_t d = 0; d < mesh.n_dofs(); ++d) u[d] = 1e-3 * std::sin(0.7 * d);
  const InternalEnergy first = elements.compute(u.data(), f.data());
  const InternalEnergy again = elements.compute(u.data(), f.data());  // same trial: nothing moved
  EXPECT_EQ(first.stored, again.stored);
  EXPECT_EQ(first.dissipation_increment, again.dissipation_increment);
  EXPECT_GT(first.dissipation_increment, 0.0);
  std::vector<double> stress(6 * mesh.n_cells * 8);
  elements.stress(stress.data());
  EXPECT_EQ(max_abs(stress), 0.0);  // the committed state is still the initial one
  EXPECT_EQ(elements.dissipation(), 0.0);
  elements.commit();
  elements.stress(stress.data());
  EXPECT_GT(max_abs(stress), 0.0);
  EXPECT_EQ(elements.stored_energy(), first.stored);
  EXPECT_EQ(elements.dissipation(), first.dissipation_increment);
  EXPECT_THROW(elements.commit(), std::logic_error);
}

namespace {

struct SplitRun {
  std::vector<double> u, v, a;
  EnergyReport energy;
};

/// The block's loads, on a Stepper or a LocalStepper: dashpots at kBlockDashpots and a sine
/// force on the top layer of nodes.
constexpr std::int32_t kBlockDashpots[3] = {0, 5, 9};
template <class AnyStepper>
void add_block_loads(AnyStepper& stepper, const HexMesh& mesh, double force_amplitude) {
  std::vector<double> C(27, 0.0);
  for (int k = 0; k < 3; ++k)
    for (int c = 0; c < 3; ++c) C[9 * k + 4 * c] = 2.0e6 * (1 + k);
  stepper.set_dashpots(kBlockDashpots, 3, C.data());
  std::vector<std::int32_t> top;
  for (std::int64_t node = 0; node < mesh.n_nodes; ++node)
    if (mesh.coords[3 * node + 2] > 0.9) top.push_back(static_cast<std::int32_t>(node));
  stepper.add_provider(std::make_shared<SineForce>(top, force_amplitude, 600.0));
}

/// Runs a jittered Q1 block with grounding springs, a sine force, dashpots, alpha and beta,
/// with the elastic elements' stiffness in the matrix or not, and the component if any.
SplitRun run_block(const HexMesh& mesh, bool elements_in_matrix,
                   std::shared_ptr<InternalForceComponent> component, std::int64_t n_steps,
                   double force_amplitude) {
  const std::vector<double> mass = lumped_mass(mesh, 2500.0);
  std::vector<double> dense = grounding(mesh, 1.0e9);
  if (elements_in_matrix) {
    auto elements = elastic_elements(mesh);
    const std::vector<double> K = probed_matrix(*elements, mesh.n_dofs());
    for (std::size_t k = 0; k < dense.size(); ++k) dense[k] += K[k];
  }
  const BlockSystem system = block_system(dense, mass);  // borrowed by the stepper below
  const double dt = 2.0e-5, alpha = 5.0, beta = 2.0e-6;
  Stepper stepper(system.view(), system.mass.data(), {dt, alpha, beta, true});
  add_block_loads(stepper, mesh, force_amplitude);
  if (component) stepper.add_internal_force(component);

  SplitRun run;
  run.u.assign(mesh.n_dofs(), 0.0);
  run.v.assign(mesh.n_dofs(), 0.0);
  run.a.assign(mesh.n_dofs(), 0.0);
  for (std::int64_t d = 0; d < mesh.n_dofs(); ++d) run.v[d] = 1e-3 * std::cos(1.3 * d);
  stepper.reset_energy(run.u.data(), run.v.data(), run.a.data(), 0.0);
  stepper.run(run.u.data(), run.v.data(), run.a.data(), n_steps, 0.0);
  run.energy = stepper.energy();
  return run;
}

double relative_difference(const std::vector<double>& x, const std::vector<double>& reference) {
  double difference = 0.0, norm = 0.0;
  for (std::size_t k = 0; k < x.size(); ++k) {
    difference += (x[k] - reference[k]) * (x[k] - reference[k]);
    norm += reference[k] * reference[k];
  }
  return std::sqrt(difference / norm);
}

}  // namespace

TEST(InternalForce, StepperWithElementsEqualsStepperWithTheirMatrix) {
  const HexMesh mesh = hexahedron_grid(3, 2, 2, 0.15, 21);
  const SplitRun matrix = run_block(mesh, true, nullptr, 400, 1.0e4);
  const SplitRun split = run_block(mesh, false, elastic_elements(mesh), 400, 1.0e4);
  EXPECT_LT(relative_difference(split.u, matrix.u), 1e-12);
  EXPECT_LT(relative_difference(split.v, matrix.v), 1e-12);
  EXPECT_LT(relative_difference(split.a, matrix.a), 1e-12);
  const EnergyReport& m = matrix.energy;
  const EnergyReport& s = split.energy;
  EXPECT_NEAR(s.strain + s.internal_stored, m.strain, 1e-11 * m.strain);
  EXPECT_NEAR(s.damping_work, m.damping_work, 1e-11 * m.damping_work);  // beta part included
  EXPECT_NEAR(s.total, m.total, 1e-11 * m.total);
  const double scale = std::max({std::abs(m.total), m.external_work, m.damping_work});
  EXPECT_LT(std::abs(s.balance), 1e-12 * scale);
  EXPECT_NEAR(s.internal_work, s.internal_stored, 1e-12 * scale);  // u_0 = 0: Psi_0 = 0
  EXPECT_GT(s.internal_stored, 1e-3 * scale);
  EXPECT_GT(m.damping_work, 1e-3 * scale);
}

TEST(InternalForce, PlasticElementsCloseTheEnergyBalanceWithTheirDissipation) {
  const HexMesh mesh = hexahedron_grid(3, 2, 2, 0.15, 21);
  ElementOptions options;
  options.mean_dilatation = true;
  double trapezoid_balance = 0.0, euler_balance = 0.0, scale = 0.0;
  for (bool trapezoid : {true, false}) {
    auto elements = std::make_shared<HexahedronElements<ToyVonMises>>(
        mesh.geometry(), ToyVonMises::Parameters{kLambda, kShear, 3.0e5, trapezoid}, options,
        nullptr);
    const SplitRun run = run_block(mesh, false, elements, 1500, 3.0e5);
    const EnergyReport& e = run.energy;
    scale = std::max({std::abs(e.total), e.external_work, e.damping_work});
    // Plastic flow did a fair share of the work, or the check below would be empty.
    EXPECT_GT(e.internal_dissipation, 1e-2 * scale);
    // The scheme's own identity holds whatever the law: balance - (Psi + D - W_int) is round-off.
    const double scheme_balance =
        e.balance - (e.internal_stored + e.internal_dissipation - e.internal_work);
    EXPECT_LT(std::abs(scheme_balance), 1e-12 * scale);
    (trapezoid ? trapezoid_balance : euler_balance) = std::abs(e.balance);
  }
  EXPECT_LT(trapezoid_balance, 1e-12 * scale);
  // Backward-Euler dissipation is an energy error the account shows.
  EXPECT_GT(euler_balance, 1e-6 * scale);
}

TEST(InternalForce, EmptyComponentLeavesTheRunBitwiseUnchanged) {
  // The component path with no cells against the path without components: the same bits.
  const HexMesh mesh = hexahedron_grid(2, 2, 2, 0.1, 31);
  HexMesh empty = mesh;
  empty.n_cells = 0;
  auto nothing = std::make_shared<HexahedronElements<LinearElastic>>(
      empty.geometry(), LinearElastic::Parameters{kLambda, kShear}, ElementOptions{}, nullptr);
  const SplitRun without = run_block(mesh, true, nullptr, 300, 1.0e4);
  const SplitRun with_empty = run_block(mesh, true, nothing, 300, 1.0e4);
  const std::size_t bytes = without.u.size() * sizeof(double);
  EXPECT_EQ(std::memcmp(without.u.data(), with_empty.u.data(), bytes), 0);
  EXPECT_EQ(std::memcmp(without.v.data(), with_empty.v.data(), bytes), 0);
  EXPECT_EQ(std::memcmp(without.a.data(), with_empty.a.data(), bytes), 0);
  EXPECT_EQ(without.energy.balance, with_empty.energy.balance);
  EXPECT_FALSE(without.energy.has_internal);
  EXPECT_TRUE(with_empty.energy.has_internal);
  EXPECT_GT(max_abs(without.u), 0.0);
}

// ---------------------------------------------------------------- local time stepping with cells

namespace {

/// The cells `cells` of a mesh as a mesh of their own (same nodes and coordinates).
HexMesh cell_subset(const HexMesh& mesh, const std::vector<std::int64_t>& cells) {
  HexMesh sub;
  sub.n_nodes = mesh.n_nodes;
  sub.coords = mesh.coords;
  sub.n_cells = static_cast<std::int64_t>(cells.size());
  for (const std::int64_t cell : cells) {
    sub.cell_nodes.insert(sub.cell_nodes.end(), mesh.cell_nodes.begin() + 8 * cell,
                          mesh.cell_nodes.begin() + 8 * cell + 8);
    sub.gradients.insert(sub.gradients.end(), mesh.gradients.begin() + 8 * 8 * 3 * cell,
                         mesh.gradients.begin() + 8 * 8 * 3 * (cell + 1));
    sub.weights.insert(sub.weights.end(), mesh.weights.begin() + 8 * cell,
                       mesh.weights.begin() + 8 * cell + 8);
  }
  return sub;
}

struct LevelRun {
  std::vector<double> u, v;
  LocalStepper::Energy energy;
};

/// A jittered block, grounded, with dashpots, alpha and a sine force: the cells in `matrix_cells`
/// in the stiffness, the others an element-loop component of law Law at level `component_level`
/// (the nodes' levels `node_level`), stepped n_steps global steps of dt_fine 2^max_level.
template <class Law>
LevelRun run_levels(const HexMesh& mesh, const std::vector<std::int64_t>& matrix_cells,
                    const std::vector<std::int64_t>& component_cells, const typename Law::Parameters& law,
                    const std::vector<std::int32_t>& node_level, int component_level, double dt_fine,
                    std::int64_t n_steps) {
  const std::vector<double> mass = lumped_mass(mesh, 2500.0);
  std::vector<double> dense = grounding(mesh, 1.0e9);
  const HexMesh in_matrix = cell_subset(mesh, matrix_cells);
  if (in_matrix.n_cells > 0) {
    const std::vector<double> K = probed_matrix(*elastic_elements(in_matrix), mesh.n_dofs());
    for (std::size_t k = 0; k < dense.size(); ++k) dense[k] += K[k];
  }
  const BlockSystem system = block_system(dense, mass);
  LocalStepper stepper(system.view(), system.mass.data(), node_level.data(), dt_fine, 5.0);
  add_block_loads(stepper, mesh, 3.0e5);
  const HexMesh in_loop = cell_subset(mesh, component_cells);
  ElementOptions options;  // no mean dilatation: the loop's linear law is then the matrix
  options.min_cells_for_threads = 0;
  if (in_loop.n_cells > 0)
    stepper.add_internal_force(
        std::make_shared<HexahedronElements<Law>>(in_loop.geometry(), law, options, nullptr),
        component_level);
  LevelRun run;
  run.u.assign(mesh.n_dofs(), 0.0);
  run.v.assign(mesh.n_dofs(), 0.0);
  std::vector<double> a(mesh.n_dofs(), 0.0);
  for (std::int64_t d = 0; d < mesh.n_dofs(); ++d) run.v[d] = 1e-3 * std::cos(1.3 * d);
  stepper.run(run.u.data(), run.v.data(), a.data(), n_steps, 0.0);
  run.energy = stepper.energy();
  return run;
}

}  // namespace

TEST(InternalForce, LocalStepperOneLevelWithElementsIsTheVerletStepWithThem) {
  // One level: the cell split is velocity Verlet, whether the cells are in the matrix or in the
  // element loop (the loop with the linear law is their matrix to round-off).
  const HexMesh mesh = hexahedron_grid(3, 2, 2, 0.15, 21);
  std::vector<std::int64_t> all(mesh.n_cells);
  for (std::int64_t c = 0; c < mesh.n_cells; ++c) all[c] = c;
  const std::vector<std::int32_t> one_level(mesh.n_nodes, 0);
  const LinearElastic::Parameters law{kLambda, kShear};
  const LevelRun matrix = run_levels<LinearElastic>(mesh, all, {}, law, one_level, 0, 2.0e-5, 400);
  const LevelRun loop = run_levels<LinearElastic>(mesh, {}, all, law, one_level, 0, 2.0e-5, 400);
  EXPECT_GT(max_abs(matrix.u), 1e-6);  // it moved
  EXPECT_LT(relative_difference(loop.u, matrix.u), 1e-11);
  EXPECT_LT(relative_difference(loop.v, matrix.v), 1e-11);
  EXPECT_NEAR(loop.energy.strain + loop.energy.internal_stored, matrix.energy.strain,
              1e-9 * matrix.energy.strain);
  EXPECT_GT(loop.energy.internal_stored, 0.5 * matrix.energy.strain);
}

TEST(InternalForce, LocalStepperRunsPlasticCellsAtTheirCoarserRate) {
  // Nodes with x > 1 m at level 1 (twice the step), the rest at level 0; the cells whose nodes
  // are all at level 1 in the element loop at level 1 with a yielding law, the others in the
  // matrix. Against global stepping at the fine step with the same law: second order in dt, the
  // plastic flow there, and the energy account closed by the dissipation.
  const HexMesh mesh = hexahedron_grid(6, 2, 2, 0.1, 5);
  std::vector<std::int32_t> node_level(mesh.n_nodes);
  for (std::int64_t node = 0; node < mesh.n_nodes; ++node)
    node_level[node] = mesh.coords[3 * node] > 1.0 ? 1 : 0;
  // The dashpots' nodes at the finest rate, as pyfem/local_stepping.py pins the truncation faces
  // (an implicit dashpot at a coarse rate is accurate only to (h C / M)^2, docs/local_stepping.md).
  for (const std::int32_t node : kBlockDashpots) node_level[node] = 0;
  std::vector<std::int64_t> matrix_cells, loop_cells;
  for (std::int64_t cell = 0; cell < mesh.n_cells; ++cell) {
    bool coarse = true;
    for (int a = 0; a < 8; ++a) coarse = coarse && node_level[mesh.cell_nodes[8 * cell + a]] == 1;
    (coarse ? loop_cells : matrix_cells).push_back(cell);
  }
  ASSERT_FALSE(loop_cells.empty());
  ASSERT_FALSE(matrix_cells.empty());
  // The fine step: 0.4 of the whole model's critical step, so the coarse level runs at 0.8.
  std::vector<double> dense = grounding(mesh, 1.0e9);
  const std::vector<double> K = probed_matrix(*elastic_elements(mesh), mesh.n_dofs());
  for (std::size_t k = 0; k < dense.size(); ++k) dense[k] += K[k];
  const BlockSystem whole = block_system(dense, lumped_mass(mesh, 2500.0));
  const double critical = 2.0 / std::sqrt(power_iteration(whole.view(), whole.mass.data(), 300, 3));
  const ToyVonMises::Parameters law{kLambda, kShear, 3.0e5, true};
  const std::vector<std::int32_t> one_level(mesh.n_nodes, 0);
  const std::int64_t steps = 200;  // global steps of the coarser run: T = 200 x 0.4 critical
  const LevelRun reference = run_levels<ToyVonMises>(mesh, matrix_cells, loop_cells, law, one_level,
                                                     0, 0.2 * critical / 16.0, 2 * 16 * steps);
  double errors[2], balances[2];
  for (int refinement = 0; refinement < 2; ++refinement) {
    // The fine step 0.2 (then 0.1) of the model's critical step: the coarse level at 0.4 (0.2).
    const double dt_fine = 0.2 * critical / (1 << refinement);
    const LevelRun lts = run_levels<ToyVonMises>(mesh, matrix_cells, loop_cells, law, node_level, 1,
                                                 dt_fine, steps << refinement);
    const double scale =
        std::max({lts.energy.initial, lts.energy.external_work, lts.energy.damping_work});
    EXPECT_GT(lts.energy.internal_dissipation, 0.1 * scale) << "the coarse cells yielded";
    EXPECT_NEAR(lts.energy.internal_dissipation, reference.energy.internal_dissipation,
                0.02 * reference.energy.internal_dissipation);
    errors[refinement] = relative_difference(lts.u, reference.u);
    balances[refinement] = std::abs(lts.energy.balance) / scale;
  }
  // Measured 2026-11-25: errors 7.6e-2, 2.2e-2 (order 1.77; the column split with the same cells
  // in the matrix, linear: 2.9e-1, 6.1e-2); the plain energy balance 0.28, 0.057 of the external
  // work (the account's trapezoid damping work at the nodes' own kicks is second order, not
  // round-off, docs/local_stepping.md).
  EXPECT_GT(std::log2(errors[0] / errors[1]), 1.7) << errors[0] << " " << errors[1];
  EXPECT_LT(errors[1], 0.03);
  EXPECT_GT(balances[0] / balances[1], 3.0) << balances[0] << " " << balances[1];
}
