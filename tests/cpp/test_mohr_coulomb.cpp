// Single-integration-point tests of the rock law (materials/mohr_coulomb.hpp) and of the
// principal decomposition (materials/principal.hpp): closed-form stress paths, the yield
// condition and flow rule of every return, energy, objectivity. Tension positive, Pa.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <random>
#include <stdexcept>

#include "rotation.hpp"
#include "materials/mohr_coulomb.hpp"
#include "materials/principal.hpp"

using namespace cavern;
using cavern::testing::rotate_tensor;
using cavern::testing::rotation;

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kMPa = 1.0e6;
constexpr double kInfinity = std::numeric_limits<double>::infinity();
// Tolerances of the brief: returned states satisfy the yield condition to 1e-10 relative; the
// reference numbers of issue 9 are given to 7 digits (1e-6 relative).
constexpr double kYieldTolerance = 1e-10;
constexpr double kReferenceTolerance = 1e-6;

MohrCoulombParameters parameters(double E, double nu, double c, double phi, double psi, double t) {
  MohrCoulombParameters p;
  p.young_modulus = E;
  p.poisson_ratio = nu;
  p.cohesion = c;
  p.friction_angle = phi;
  p.dilation_angle = psi;
  p.tensile_strength = t;
  p.damage_max = 0.0;
  return p;
}

// The single-point case of issue 9: E = 10 GPa, nu = 0.25, c = 1 MPa, phi = 30, psi = 10.
MohrCoulombParameters issue_parameters(double t = kInfinity) {
  return parameters(10.0e9, 0.25, 1.0 * kMPa, 30.0, 10.0, t);
}

// Table 1 non-sandstone: the cut-off is active (t = 0.25 MPa < c cot(phi) = 0.72 MPa).
MohrCoulombParameters soft_rock(double psi = 0.0) {
  return parameters(2.0e9, 0.30, 0.35 * kMPa, 26.0, psi, 0.25 * kMPa);
}

// Strain (engineering shear) whose elastic image C : eps is the given stress.
Voigt strain_of_stress(const MohrCoulombMaterial& m, const Voigt& s) {
  const double E = m.young_modulus, nu = m.poisson_ratio, G = m.shear_modulus;
  const double trace = s[0] + s[1] + s[2];
  return {((1.0 + nu) * s[0] - nu * trace) / E,
          ((1.0 + nu) * s[1] - nu * trace) / E,
          ((1.0 + nu) * s[2] - nu * trace) / E,
          s[3] / G,
          s[4] / G,
          s[5] / G};
}

Voigt diagonal(double a, double b, double c) { return {a, b, c, 0.0, 0.0, 0.0}; }

double max_abs(const Voigt& v) {
  double m = 0.0;
  for (double x : v) m = std::max(m, std::abs(x));
  return m;
}

// Yield residual of the effective stress relative to the strength k = 2 c cos(phi) (or t).
double relative_yield(const MohrCoulombMaterial& m, const MohrCoulombState& state) {
  const double scale =
      std::max(m.strength, std::isfinite(m.tensile_strength) ? m.tensile_strength : 0.0);
  return mohr_coulomb_yield(m, principal_stresses(state.effective_stress).values) / scale;
}

// One step from the stress-free state whose trial stress is `trial` (Pa).
MohrCoulombStep return_from_trial(const MohrCoulombMaterial& m, const Voigt& trial) {
  return mohr_coulomb_update(m, MohrCoulombState{}, strain_of_stress(m, trial));
}


Voigt stress_voigt(const Matrix3& T) {
  return {T[0][0], T[1][1], T[2][2], T[0][1], T[1][2], T[0][2]};
}
Voigt strain_voigt(const Matrix3& T) {
  return {T[0][0], T[1][1], T[2][2], 2.0 * T[0][1], 2.0 * T[1][2], 2.0 * T[0][2]};
}

// Mixed control: axial strain increment on component `axis` prescribed, the two other normal
// stresses held at `lateral_stress` with equal lateral strain increments (the paths below are
// axisymmetric about `axis`), shear strains zero. Solves the scalar lateral strain by the
// Illinois variant of regula falsi (the response is continuous and increasing in it).
// `h`: the point's characteristic length (m; the crack band's, 0 for none).
MohrCoulombStep drive_axisymmetric(const MohrCoulombMaterial& m, const MohrCoulombState& state,
                                   int axis, double axial_increment, double lateral_stress,
                                   double h = 0.0) {
  const int lateral = (axis + 1) % 3;
  auto step_for = [&](double e) {
    Voigt d{};
    for (int i = 0; i < 3; ++i) d[i] = (i == axis) ? axial_increment : e;
    return mohr_coulomb_update(m, state, d, h);
  };
  auto residual = [&](double e) { return step_for(e).state.stress[lateral] - lateral_stress; };
  const double width = std::abs(axial_increment) + 1e-12;
  double a = -2.0 * width, b = 2.0 * width;
  double fa = residual(a), fb = residual(b);
  while (fa > 0.0) {
    a -= 4.0 * width;
    fa = residual(a);
  }
  while (fb < 0.0) {
    b += 4.0 * width;
    fb = residual(b);
  }
  const double tolerance = 1e-13 * std::max(m.strength, std::abs(lateral_stress));
  int side = 0;
  double e = 0.5 * (a + b);
  for (int iteration = 0; iteration < 500; ++iteration) {
    e = (a * fb - b * fa) / (fb - fa);
    const double fe = residual(e);
    if (std::abs(fe) <= tolerance) break;
    if (fe < 0.0) {
      a = e;
      fa = fe;
      if (side == -1) fb *= 0.5;
      side = -1;
    } else {
      b = e;
      fb = fe;
      if (side == 1) fa *= 0.5;
      side = 1;
    }
  }
  return step_for(e);
}

// Rows of `vectors` orthonormal within `tolerance`.
void expect_orthonormal(const Matrix3& vectors, double tolerance) {
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      double product = 0.0;
      for (int k = 0; k < 3; ++k) product += vectors[i][k] * vectors[j][k];
      EXPECT_NEAR(product, i == j ? 1.0 : 0.0, tolerance) << "rows " << i << ", " << j;
    }
}

}  // namespace

// ---------------------------------------------------------------- principal decomposition

TEST(MaterialPrincipal, ReproducesTensorsWithRepeatedEigenvalues) {
  std::mt19937_64 generator(17);
  std::uniform_real_distribution<double> angle(0.0, 2.0 * kPi);
  const std::array<std::array<double, 3>, 6> spectra{{{3.0, 2.0, -1.0},
                                                      {2.0, 2.0, -5.0},
                                                      {4.0, -1.0, -1.0},
                                                      {-7.0, -7.0, -7.0},
                                                      {1.0, 1.0 + 1e-13, 1.0 - 1e-13},
                                                      {0.0, 0.0, 0.0}}};
  int checks = 0;
  for (const auto& spectrum : spectra)
    for (int sample = 0; sample < 20; ++sample) {
      const Matrix3 R = rotation(angle(generator), angle(generator), angle(generator));
      const Matrix3 D{{{spectrum[0], 0.0, 0.0}, {0.0, spectrum[1], 0.0}, {0.0, 0.0, spectrum[2]}}};
      const Matrix3 A = rotate_tensor(R, D);
      const SymmetricEigen eigen = symmetric_eigen(A);
      std::array<double, 3> expected = spectrum;
      std::sort(expected.begin(), expected.end(), std::greater<double>());
      for (int k = 0; k < 3; ++k) EXPECT_NEAR(eigen.values[k], expected[k], 1e-14 * 7.0);
      EXPECT_GE(eigen.values[0], eigen.values[1]);
      EXPECT_GE(eigen.values[1], eigen.values[2]);
      // Orthonormal, right-handed basis that reproduces A.
      expect_orthonormal(eigen.vectors, 1e-15 * 4.0);
      // The fast estimate used to screen elastic steps is within its documented 1e-8 of the
      // deviatoric size (here at most 7).
      const auto estimate = symmetric_eigenvalues_estimate(A);
      for (int k = 0; k < 3; ++k) EXPECT_NEAR(estimate[k], expected[k], 1e-8 * 7.0);
      const Voigt back = stress_voigt_from_principal(eigen.values, eigen.vectors);
      const Voigt original = stress_voigt(A);
      for (int k = 0; k < 6; ++k) EXPECT_NEAR(back[k], original[k], 1e-14 * 7.0);
      ++checks;
    }
  EXPECT_EQ(checks, 120);
}

TEST(MaterialPrincipal, CosThirdOfAcosMatchesTheTrigonometricForm) {
  // cos_third_of_acos replaces cos(acos(r) / 3) in the eigenvalue estimate: its stated errors
  // (principal.hpp) on a dense grid of t = sqrt((1 + r) / 2), the double root t -> 0 included,
  // and the exact ends r = 1 (c = 1) and r = -1 (c = 1/2).
  double worst_far = 0.0, worst_near = 0.0, worst = 0.0;
  for (int i = 0; i <= 200000; ++i) {
    const double t = i / 200000.0;
    const double r = std::clamp(2.0 * t * t - 1.0, -1.0, 1.0);
    const double error = std::abs(cos_third_of_acos(r) - std::cos(std::acos(r) / 3.0));
    worst = std::max(worst, error);
    if (t > 0.05) worst_far = std::max(worst_far, error);
    if (t > 1e-3) worst_near = std::max(worst_near, error);
  }
  EXPECT_LT(worst_far, 1e-15);
  EXPECT_LT(worst_near, 5e-14);
  EXPECT_LT(worst, 1e-11);
  EXPECT_NEAR(cos_third_of_acos(1.0), 1.0, 2e-16);
  EXPECT_EQ(cos_third_of_acos(-1.0), 0.5);  // the double root: exact, no Newton step
  // A geostatic state with sigma_xx = sigma_yy has r = -1 exactly: its estimate is exact.
  const Matrix3 k0{{{1.0, 0.0, 0.0}, {0.0, 1.0, 0.0}, {0.0, 0.0, -2.0}}};
  const auto values = symmetric_eigenvalues_estimate(k0);
  EXPECT_NEAR(values[0], 1.0, 1e-15);
  EXPECT_NEAR(values[1], 1.0, 1e-15);
  EXPECT_NEAR(values[2], -2.0, 1e-15);
  EXPECT_NEAR(cos_third_of_acos(0.0), std::cos(kPi / 6.0), 1e-15);
}

TEST(MaterialPrincipal, ClosedFormMatchesJacobiAcrossGaps) {
  // symmetric_eigen_fast against symmetric_eigen on spectra from well separated down to gaps
  // just above and below its threshold (1e-3 of the deviatoric size, here 2/3 of the spread) and
  // repeated values, with a mean of the order of the spread and 1e3 times it, at magnitudes 1,
  // 1e77 and 1e-77: the values within 1e-14 of the scale, each pair's residual |A v - l v| within
  // 1e-13 of the scale (the closed form's vector error is ~1e-16 over the relative gap, ~1e-13 at
  // the threshold; Jacobi's ~1e-15), the reconstructed tensor within 1e-13, the basis orthonormal and
  // right-handed within 1e-13, whichever path it took. Every tensor is rotated arbitrarily.
  std::mt19937_64 generator(23);
  std::uniform_real_distribution<double> angle(0.0, 2.0 * kPi);
  std::uniform_real_distribution<double> value(-10.0, 10.0);
  const double gaps[] = {1.0, 1e-1, 1e-2, 2e-3, 1e-3, 0.5e-3, 1e-4, 1e-8, 0.0};
  const double means[] = {1.0, 1e3};
  const double magnitudes[] = {1.0, 1e77, 1e-77};
  int checks = 0;
  for (const double magnitude : magnitudes)
    for (const double mean_factor : means)
      for (const double gap : gaps)
        for (int sample = 0; sample < 20; ++sample) {
          const double size = magnitude * (1.0 + std::abs(value(generator)));
          const double base = mean_factor * magnitude * value(generator);
          const bool low_pair = sample % 2 == 0;  // which two values are close
          std::array<double, 3> spectrum =
              low_pair ? std::array<double, 3>{base + 2.0 * size, base + gap * size, base}
                       : std::array<double, 3>{base + gap * size, base, base - 2.0 * size};
          const Matrix3 R = rotation(angle(generator), angle(generator), angle(generator));
          const Matrix3 D{
              {{spectrum[0], 0.0, 0.0}, {0.0, spectrum[1], 0.0}, {0.0, 0.0, spectrum[2]}}};
          const Matrix3 A = rotate_tensor(R, D);
          const double scale = std::abs(base) + 2.0 * size;
          const auto estimate = symmetric_eigenvalues_estimate(A);
          SymmetricEigen closed;
          // The closed form is taken above the threshold and refused below it (Jacobi then).
          EXPECT_EQ(symmetric_eigen_closed_form(A, estimate, closed), gap >= 1e-3)
              << gap << " " << magnitude << " " << mean_factor;
          // Below it the pair form takes the nearly repeated pair (Jacobi only for a zero deviator).
          SymmetricEigen pair;
          if (gap < 1e-3) EXPECT_TRUE(symmetric_eigen_pair_form(A, estimate, pair)) << gap;
          const SymmetricEigen fast = symmetric_eigen_fast(A, estimate);
          const SymmetricEigen jacobi = symmetric_eigen(A);
          for (int k = 0; k < 3; ++k) {
            EXPECT_NEAR(fast.values[k], jacobi.values[k], 1e-14 * scale);
            double residual = 0.0;
            for (int i = 0; i < 3; ++i) {
              double row = -fast.values[k] * fast.vectors[k][i];
              for (int j = 0; j < 3; ++j) row += A[i][j] * fast.vectors[k][j];
              residual += row * row;
            }
            EXPECT_LE(std::sqrt(residual), 1e-13 * scale) << gap << " " << magnitude << " " << mean_factor << " closed " << (gap >= 1e-3);
          }
          EXPECT_GE(fast.values[0], fast.values[1]);
          EXPECT_GE(fast.values[1], fast.values[2]);
          expect_orthonormal(fast.vectors, 1e-13);
          const auto& e = fast.vectors;  // right-handed: e0 x e1 = e2
          EXPECT_NEAR(e[0][1] * e[1][2] - e[0][2] * e[1][1], e[2][0], 1e-13);
          EXPECT_NEAR(e[0][2] * e[1][0] - e[0][0] * e[1][2], e[2][1], 1e-13);
          EXPECT_NEAR(e[0][0] * e[1][1] - e[0][1] * e[1][0], e[2][2], 1e-13);
          const Voigt back = stress_voigt_from_principal(fast.values, fast.vectors);
          const Voigt original = stress_voigt(A);
          for (int k = 0; k < 6; ++k) EXPECT_NEAR(back[k], original[k], 1e-13 * scale);
          ++checks;
        }
  EXPECT_EQ(checks, 3 * 2 * 9 * 20);
}

TEST(MaterialPrincipal, PairFormMatchesJacobiAtRepeatedPairs) {
  // The pair form on exactly and nearly repeated pairs (top and bottom), with pair gaps from 1e-2
  // of the spread down to 0 and tensors whose pair lies along the axes (a geostatic
  // sigma_xx = sigma_yy state) or rotated arbitrarily: the values within 1e-14 of the scale of
  // Jacobi's (the pair's gap within 1e-14 too), each pair |A v - l v| within 1e-14, orthonormal
  // and right-handed, and the distinct projection n n^T within 1e-14 |A| / gap of Jacobi's.
  std::mt19937_64 generator(29);
  std::uniform_real_distribution<double> angle(0.0, 2.0 * kPi);
  std::uniform_real_distribution<double> value(-10.0, 10.0);
  const double gaps[] = {1e-2, 1e-4, 1e-7, 1e-12, 0.0};
  int checks = 0;
  for (const double gap : gaps)
    for (int sample = 0; sample < 200; ++sample) {
      const double size = 1.0 + std::abs(value(generator));
      const double base = (sample % 3 == 0 ? 1e3 : 1.0) * value(generator);
      const bool top = sample % 2 == 0;
      const std::array<double, 3> spectrum =
          top ? std::array<double, 3>{base + gap * size, base, base - 3.0 * size}
              : std::array<double, 3>{base + 3.0 * size, base + gap * size, base};
      const Matrix3 R = sample % 5 == 0 ? rotation(0.0, 0.0, angle(generator))
                                        : rotation(angle(generator), angle(generator), angle(generator));
      const Matrix3 D{{{spectrum[0], 0.0, 0.0}, {0.0, spectrum[1], 0.0}, {0.0, 0.0, spectrum[2]}}};
      const Matrix3 A = rotate_tensor(R, D);
      const double scale = std::abs(base) + 3.0 * size;
      SymmetricEigen pair;
      ASSERT_TRUE(symmetric_eigen_pair_form(A, symmetric_eigenvalues_estimate(A), pair));
      const SymmetricEigen jacobi = symmetric_eigen(A);
      for (int k = 0; k < 3; ++k) {
        EXPECT_NEAR(pair.values[k], jacobi.values[k], 1e-14 * scale) << gap << " " << k;
        double residual = 0.0;
        for (int i = 0; i < 3; ++i) {
          double row = -pair.values[k] * pair.vectors[k][i];
          for (int j = 0; j < 3; ++j) row += A[i][j] * pair.vectors[k][j];
          residual += row * row;
        }
        EXPECT_LE(std::sqrt(residual), 1e-14 * scale) << gap;
      }
      const int pair_low = top ? 0 : 1, distinct = top ? 2 : 0;
      EXPECT_NEAR(pair.values[pair_low] - pair.values[pair_low + 1], gap * size, 1e-14 * scale);
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
          EXPECT_NEAR(pair.vectors[distinct][i] * pair.vectors[distinct][j],
                      jacobi.vectors[distinct][i] * jacobi.vectors[distinct][j],
                      1e-14 * scale / size);  // both vectors' error: ~1e-16 |A| / gap
      expect_orthonormal(pair.vectors, 1e-15 * 4.0);
      const auto& e = pair.vectors;
      EXPECT_NEAR(e[0][1] * e[1][2] - e[0][2] * e[1][1], e[2][0], 1e-15 * 4.0);
      EXPECT_NEAR(e[0][2] * e[1][0] - e[0][0] * e[1][2], e[2][1], 1e-15 * 4.0);
      EXPECT_NEAR(e[0][0] * e[1][1] - e[0][1] * e[1][0], e[2][2], 1e-15 * 4.0);
      ++checks;
    }
  EXPECT_EQ(checks, 5 * 200);
  // A hydrostatic tensor has no distinct value: refused (symmetric_eigen_fast then takes Jacobi).
  SymmetricEigen out;
  const Matrix3 hydrostatic{{{-3.0, 0.0, 0.0}, {0.0, -3.0, 0.0}, {0.0, 0.0, -3.0}}};
  EXPECT_FALSE(symmetric_eigen_pair_form(hydrostatic, symmetric_eigenvalues_estimate(hydrostatic), out));
}

TEST(MaterialPrincipal, SeparatedEstimateIsWithinItsBound) {
  // eigenvalues_estimate_separated: when both gaps of the estimate exceed kClosedFormGap of its
  // deviatoric size, the estimate is within 1e-12 of max |value| (the Mohr-Coulomb screen of a
  // trial near the surface takes 1e-9 as its margin). Gaps log-uniform from 1e-4 to 2 of the size,
  // means 0, of the size and 1e3 times it, arbitrary rotations.
  std::mt19937_64 generator(31);
  std::uniform_real_distribution<double> angle(0.0, 2.0 * kPi);
  std::uniform_real_distribution<double> value(-10.0, 10.0), exponent(-4.0, 0.3);
  double worst = 0.0;
  int separated = 0, near_threshold = 0, refused = 0;
  for (int sample = 0; sample < 200000; ++sample) {
    const double size = 1.0 + std::abs(value(generator));
    const double base = (sample % 3 == 0 ? 1e3 : sample % 3 == 1 ? 1.0 : 0.0) * value(generator);
    const double g1 = std::pow(10.0, exponent(generator)) * size;
    const double g2 = std::pow(10.0, exponent(generator)) * size;
    const Matrix3 D{{{base + g1 + g2, 0.0, 0.0}, {0.0, base + g2, 0.0}, {0.0, 0.0, base}}};
    const Matrix3 A =
        rotate_tensor(rotation(angle(generator), angle(generator), angle(generator)), D);
    const auto estimate = symmetric_eigenvalues_estimate(A);
    if (!eigenvalues_estimate_separated(estimate)) {
      ++refused;
      continue;
    }
    ++separated;
    if (std::min(g1, g2) < 3e-3 * size) ++near_threshold;
    const SymmetricEigen exact = symmetric_eigen(A);
    const double scale = std::max(std::abs(exact.values[0]), std::abs(exact.values[2]));
    for (int k = 0; k < 3; ++k) worst = std::max(worst, std::abs(estimate[k] - exact.values[k]) / scale);
  }
  EXPECT_GT(separated, 100000);
  EXPECT_GT(near_threshold, 5000);  // the bound is tried where it is loosest
  EXPECT_GT(refused, 5000);
  EXPECT_LT(worst, 1e-12);
  std::printf("[ info ] separated estimates: worst error %.2g of max |value|\n", worst);
}

TEST(MohrCoulomb, NearSurfaceTrialsKeepTheExactDecision) {
  // Trials just inside and just outside the surface (yield function from -1e-5 to +1e-5 of the
  // strength; the estimate screen's margin is 1e-6, the separated estimate's 1e-9), on the main
  // plane's sector and near both edges (pairs 1e-2 to 1e-8 of the strength apart): elastic
  // exactly when the yield function of Jacobi's values is <= 0 (the band within 1e-10 of 0
  // excepted, where round-off decides), and an elastic step returns the trial's bits.
  std::mt19937_64 generator(37);
  std::uniform_real_distribution<double> angle(0.0, 2.0 * kPi);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  int elastic = 0, plastic = 0, close_band = 0, edges = 0;
  for (const MohrCoulombMaterial& m :
       {mohr_coulomb_material(issue_parameters()), mohr_coulomb_material(soft_rock())}) {
    const double k = m.strength, sp = m.sin_phi;
    for (int sample = 0; sample < 6000; ++sample) {
      const double s3 = -12.0 * kMPa + 10.0 * kMPa * std::abs(unit(generator));
      const double s1 = (k + s3 * (1.0 - sp)) / (1.0 + sp);  // on the main plane
      const int kind = sample % 3;  // 0: sigma_2 inside the sector, 1: near s1, 2: near s3
      const double pair = std::pow(10.0, -2.0 - 6.0 * std::abs(unit(generator))) * k;
      const double s2 = kind == 0 ? s3 + (s1 - s3) * (0.1 + 0.8 * std::abs(unit(generator)))
                        : kind == 1 ? s1 - pair
                                    : s3 + pair;
      edges += kind != 0;
      const double shift = 1e-5 * k * unit(generator);  // moves the yield function by ~2 shift
      const Matrix3 D{{{s1 + shift, 0.0, 0.0}, {0.0, s2, 0.0}, {0.0, 0.0, s3 - shift}}};
      const Voigt trial = stress_voigt(
          rotate_tensor(rotation(angle(generator), angle(generator), angle(generator)), D));
      const double f = mohr_coulomb_yield(m, principal_stresses(trial).values);
      if (std::abs(f) < 1e-10 * k) {
        ++close_band;
        continue;
      }
      MohrCoulombState old;
      old.effective_stress = old.stress = trial;
      const MohrCoulombStep step = mohr_coulomb_update(m, old, Voigt{});
      if (f < 0.0) {
        ++elastic;
        ASSERT_EQ(step.region, ReturnRegion::elastic) << f / k;
        for (int c = 0; c < 6; ++c) EXPECT_EQ(step.state.effective_stress[c], trial[c]);
      } else {
        ++plastic;
        EXPECT_NE(step.region, ReturnRegion::elastic) << f / k;
      }
    }
  }
  EXPECT_GT(elastic, 4000);
  EXPECT_GT(plastic, 4000);
  EXPECT_GT(edges, 6000);
  EXPECT_LT(close_band, 100);
}

TEST(MohrCoulomb, ElasticFastPathGivesTheUpdatesBits) {
  // MohrCoulombLaw::evaluate writes a trial that passes the invariant screen straight into the
  // state; it must be the same bits as mohr_coulomb_update's elastic result (and its energy the
  // same trapezoid work), and most of these small increments from a confined state take it.
  const MohrCoulombMaterial m = mohr_coulomb_material(MohrCoulombParameters{});
  std::mt19937_64 generator(5);
  std::uniform_real_distribution<double> small(-2e-5, 2e-5);
  const double sigma0[6] = {-6e6, -5e6, -7e6, 4e5, -2e5, 1e5};
  int screened = 0;
  for (int sample = 0; sample < 200; ++sample) {
    MohrCoulombLaw::State committed = MohrCoulombLaw::initial_state(m, sigma0, 1.0);
    for (int c = 0; c < 6; ++c) committed.strain[c] = small(generator);
    committed.effective_stress = isotropic_stress(m.lambda, m.shear_modulus, committed.strain);
    for (int c = 0; c < 6; ++c) {
      committed.effective_stress[c] += sigma0[c];
      committed.stress[c] = committed.effective_stress[c];
    }
    double strain[6];
    Voigt increment;
    for (int c = 0; c < 6; ++c) {
      strain[c] = committed.strain[c] + small(generator);
      increment[c] = strain[c] - committed.strain[c];
    }
    const PointStrain point{strain, sigma0, 1.0};
    MohrCoulombLaw::State trial;
    const PointEnergy energy = MohrCoulombLaw::evaluate(m, committed, point, trial);
    const MohrCoulombStep step = mohr_coulomb_update(m, committed, increment);
    ASSERT_EQ(step.region, ReturnRegion::elastic);
    Voigt trial_effective = committed.effective_stress;
    const Voigt change = isotropic_stress(m.lambda, m.shear_modulus, increment);
    for (int c = 0; c < 6; ++c) trial_effective[c] += change[c];
    if (elastic_by_invariants(m, trial_effective)) ++screened;
    double work = 0.0;
    for (int c = 0; c < 6; ++c) {
      EXPECT_EQ(trial.stress[c], step.state.stress[c]);
      EXPECT_EQ(trial.effective_stress[c], step.state.effective_stress[c]);
      EXPECT_EQ(trial.plastic_strain[c], step.state.plastic_strain[c]);
      work += 0.5 * (committed.stress[c] + step.state.stress[c] - 2.0 * sigma0[c]) * increment[c];
    }
    EXPECT_EQ(trial.damage, step.state.damage);
    EXPECT_EQ(energy.stored, committed.stored + work);
    EXPECT_EQ(energy.dissipation, 0.0);
  }
  EXPECT_GT(screened, 150);  // the fast path was the one taken
}

// ---------------------------------------------------------------- issue 9 reference returns

TEST(MohrCoulomb, IssueReferenceReturns) {
  struct Case {
    Voigt trial;
    std::array<double, 3> expected;  // MPa, descending
    double t;
    ReturnRegion region;
  };
  const std::array<Case, 5> cases{{
      {diagonal(-2, -5, -15),
       {-3.588742, -5.204767, -14.230327},
       kInfinity,
       ReturnRegion::main_plane},
      {diagonal(-5, -5, -20),
       {-5.398078, -5.398078, -19.658335},
       kInfinity,
       ReturnRegion::compression_edge},
      {diagonal(-2, -12, -12),
       {-2.798008, -11.858127, -11.858127},
       kInfinity,
       ReturnRegion::extension_edge},
      {diagonal(3, 2.5, 2), {1.732051, 1.732051, 1.732051}, kInfinity, ReturnRegion::apex},
      {diagonal(2, 0, 0), {0.5, -0.5, -0.5}, 0.5, ReturnRegion::tension_plane},
  }};
  int checks = 0;
  for (const Case& c : cases) {
    const MohrCoulombMaterial m = mohr_coulomb_material(issue_parameters(c.t * kMPa));
    Voigt trial = c.trial;
    for (double& x : trial) x *= kMPa;
    const MohrCoulombStep step = return_from_trial(m, trial);
    EXPECT_EQ(step.region, c.region);
    const auto values = principal_stresses(step.state.stress).values;
    for (int k = 0; k < 3; ++k)
      EXPECT_NEAR(values[k] / kMPa, c.expected[k], kReferenceTolerance * std::abs(c.expected[k]));
    EXPECT_LT(std::abs(relative_yield(m, step.state)), kYieldTolerance);
    EXPECT_LE(step.kkt_residual, 1e-12);
    // The trial was diagonal: so is the return (coaxial).
    EXPECT_LT(max_abs({0, 0, 0, step.state.stress[3], step.state.stress[4], step.state.stress[5]}),
              1e-9 * kMPa);
    ++checks;
  }
  EXPECT_EQ(checks, 5);
  // The edges keep the equal pair equal (to round-off, not by a perturbation).
  const MohrCoulombMaterial m = mohr_coulomb_material(issue_parameters());
  const MohrCoulombStep edge = return_from_trial(m, diagonal(-5 * kMPa, -5 * kMPa, -20 * kMPa));
  EXPECT_NEAR(edge.state.stress[0], edge.state.stress[1], 1e-15 * 20 * kMPa);
}

// ---------------------------------------------------------------- stress paths

TEST(MohrCoulomb, TriaxialCompressionReachesAndKeepsStrength) {
  // phi = 30, psi = 10 (issue 9); sigma_axial = p N_phi + 2 c sqrt(N_phi) in magnitude and the
  // plastic volumetric / axial strain ratio 1 - N_psi on the triaxial-compression edge.
  const MohrCoulombMaterial m = mohr_coulomb_material(issue_parameters());
  const double c = 1.0 * kMPa;
  const double n_phi = (1.0 + m.sin_phi) / (1.0 - m.sin_phi);
  const double n_psi = (1.0 + m.sin_psi) / (1.0 - m.sin_psi);
  int confinements = 0;
  for (double p : {1.0 * kMPa, 5.0 * kMPa, 20.0 * kMPa}) {
    int plateau_checks = 0;
    MohrCoulombState state =
        mohr_coulomb_update(m, MohrCoulombState{}, strain_of_stress(m, diagonal(-p, -p, -p))).state;
    const double strength = p * n_phi + 2.0 * c * std::sqrt(n_phi);
    const double axial_step = -strength / m.young_modulus / 50.0;
    double peak = 0.0;
    bool yielded = false;
    for (int k = 0; k < 150; ++k) {
      const MohrCoulombStep step = drive_axisymmetric(m, state, 2, axial_step, -p);
      EXPECT_NEAR(step.state.stress[0], -p, 1e-12 * strength);
      EXPECT_NEAR(step.state.stress[1], -p, 1e-12 * strength);
      EXPECT_GE(step.dissipation, -1e-12 * strength * std::abs(axial_step));
      peak = std::max(peak, -step.state.stress[2]);
      if (step.region != ReturnRegion::elastic) {
        EXPECT_EQ(step.region, ReturnRegion::compression_edge);
        EXPECT_NEAR(-step.state.stress[2], strength, 1e-10 * strength);
        EXPECT_LT(std::abs(relative_yield(m, step.state)), kYieldTolerance);
        yielded = true;
        ++plateau_checks;
      }
      state = step.state;
    }
    EXPECT_TRUE(yielded);
    EXPECT_NEAR(peak, strength, 1e-10 * strength);
    // Ratio over the plateau (the first plastic step lands from inside, same ratio).
    const Voigt& ep = state.plastic_strain;
    const double volumetric = ep[0] + ep[1] + ep[2];
    EXPECT_NEAR(volumetric / ep[2], 1.0 - n_psi, 1e-9);
    EXPECT_NEAR(ep[0], ep[1], 1e-12 * std::abs(ep[2]));
    EXPECT_LT(ep[2], 0.0);
    // Elastic loading takes fewer than 50 of the 150 steps: at least 100 on the plateau.
    EXPECT_GE(plateau_checks, 100);
    ++confinements;
  }
  EXPECT_EQ(confinements, 3);
}

TEST(MohrCoulomb, UniaxialTensionStaysAtCutoff) {
  // Table 1 non-sandstone: uniaxial tension is stopped by the cut-off (t = 0.25 MPa) before the
  // M-C plane (uniaxial M-C tensile strength 2c cos(phi)/(1 + sin(phi)) = 0.44 MPa).
  const MohrCoulombMaterial m = mohr_coulomb_material(soft_rock());
  ASSERT_TRUE(m.tension_cutoff);
  const double t = m.tensile_strength;
  const double yield_strain = t / m.young_modulus;
  const double increment = yield_strain / 20.0;
  MohrCoulombState state;
  double dissipated = 0.0, axial = 0.0;
  int plateau = 0;
  for (int k = 0; k < 100; ++k) {
    const MohrCoulombStep step = drive_axisymmetric(m, state, 0, increment, 0.0);
    axial += increment;
    dissipated += step.dissipation;
    EXPECT_LE(step.state.stress[0], t * (1.0 + 1e-12));
    if (axial > yield_strain * (1.0 + 1e-9)) {
      EXPECT_EQ(step.region, ReturnRegion::tension_plane);
      EXPECT_NEAR(step.state.stress[0], t, 1e-12 * t);
      // Rankine flow is along the axis only: no lateral plastic strain.
      EXPECT_NEAR(step.state.plastic_strain[1], 0.0, 1e-12 * step.state.plastic_strain[0]);
      EXPECT_EQ(step.state.damage_type, DamageType::tension);
      ++plateau;
    } else {
      EXPECT_EQ(step.region, ReturnRegion::elastic);
      EXPECT_NEAR(step.state.stress[0], m.young_modulus * axial, 1e-12 * t);
    }
    state = step.state;
  }
  EXPECT_EQ(plateau, 80);
  // Closed form: the stress is t on the whole plateau, so the dissipated energy is t eps_p.
  EXPECT_NEAR(state.plastic_strain[0], axial - yield_strain, 1e-12 * axial);
  EXPECT_NEAR(dissipated, t * (axial - yield_strain), 1e-10 * t * axial);
}

TEST(MohrCoulomb, TrescaPureShearLimit) {
  // phi = 0: the M-C plane is Tresca, sigma_1 - sigma_3 = 2c, so pure shear saturates at c.
  const double c = 2.0 * kMPa;
  const MohrCoulombMaterial m =
      mohr_coulomb_material(parameters(30.0e9, 0.2, c, 0.0, 0.0, kInfinity));
  EXPECT_FALSE(m.tension_cutoff);
  MohrCoulombState state;
  const double gamma_step = c / m.shear_modulus / 10.0;
  int plateau = 0;
  for (int k = 0; k < 40; ++k) {
    const MohrCoulombStep step = mohr_coulomb_update(m, state, {0, 0, 0, gamma_step, 0, 0});
    if (k >= 10) {  // yield at gamma = c / G, i.e. after the tenth step
      EXPECT_NE(step.region, ReturnRegion::elastic);
      EXPECT_NEAR(step.state.stress[3], c, 1e-12 * c);
      ++plateau;
    }
    for (int i : {0, 1, 2, 4, 5}) EXPECT_NEAR(step.state.stress[i], 0.0, 1e-9 * c);
    // Tresca flow is isochoric and pure shear here.
    const Voigt& ep = step.state.plastic_strain;
    EXPECT_NEAR(ep[0] + ep[1] + ep[2], 0.0, 1e-12 * (std::abs(ep[3]) + 1e-30));
    if (k >= 10) {
      EXPECT_LT(std::abs(relative_yield(m, step.state)), kYieldTolerance);
    }
    state = step.state;
  }
  EXPECT_EQ(plateau, 30);
  EXPECT_NEAR(state.plastic_strain[3], 30 * gamma_step, 1e-10 * state.plastic_strain[3]);
}

TEST(MohrCoulomb, HydrostaticTensionBeyondApex) {
  // Equal principal stresses: without cut-off to the M-C apex c cot(phi), with it to (t, t, t).
  const MohrCoulombMaterial no_cutoff = mohr_coulomb_material(issue_parameters());
  const MohrCoulombMaterial cutoff = mohr_coulomb_material(soft_rock());
  // Table 1 sandstone, psi = 0: the apex return needs the volumetric flow of the Rankine planes
  // through the apex (the M-C flow is purely deviatoric).
  const MohrCoulombMaterial sandstone =
      mohr_coulomb_material(parameters(8.0e9, 0.24, 1.1 * kMPa, 42.0, 0.0, 1.95 * kMPa));
  const double apex = 1.0 * kMPa / std::tan(30.0 * kPi / 180.0);
  int checks = 0;
  for (double load : {2.0, 10.0, 1000.0}) {
    const MohrCoulombStep a =
        return_from_trial(no_cutoff, diagonal(load * kMPa, load * kMPa, load * kMPa));
    EXPECT_EQ(a.region, ReturnRegion::apex);
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(a.state.stress[i], apex, 1e-12 * apex);
    const MohrCoulombStep b =
        return_from_trial(cutoff, diagonal(load * kMPa, load * kMPa, load * kMPa));
    EXPECT_EQ(b.region, ReturnRegion::tension_apex);
    for (int i = 0; i < 3; ++i)
      EXPECT_NEAR(b.state.stress[i], cutoff.tensile_strength, 1e-12 * kMPa);
    EXPECT_EQ(b.state.damage_type, DamageType::tension);
    const MohrCoulombStep c =
        return_from_trial(sandstone, diagonal(load * kMPa, load * kMPa, load * kMPa));
    EXPECT_EQ(c.region, ReturnRegion::apex);
    EXPECT_LE(c.kkt_residual, 1e-12);
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(c.state.stress[i], sandstone.apex, 1e-12 * kMPa);
    ++checks;
  }
  EXPECT_EQ(checks, 3);
}

TEST(MohrCoulomb, EveryReturnRegionFromConstructedTrials) {
  // A trial built as point + sum_a dgamma_a D N_a (dgamma_a > 0) from a point on a face, edge or
  // corner of the elastic domain has that point as its return (the return's conditions hold
  // there). Each region of the cut-off pyramid is built this way, non-associated (psi = 13 <
  // phi = 26), and the return must find it.
  const MohrCoulombMaterial m = mohr_coulomb_material(soft_rock(13.0));
  const double t = m.tensile_strength, sp = m.sin_phi, sd = m.sin_psi, k = m.strength;
  const double low = (t * (1.0 + sp) - k) / (1.0 - sp);  // sigma_3 when sigma_1 = t on M-C
  auto on_plane = [&](double s3) { return (k + s3 * (1.0 - sp)) / (1.0 + sp); };  // sigma_1
  using Flow = std::array<double, 3>;
  const Flow rankine0{1, 0, 0}, rankine1{0, 1, 0}, rankine2{0, 0, 1};
  const Flow mc02{1 + sd, 0, -(1 - sd)}, mc12{0, 1 + sd, -(1 - sd)}, mc01{1 + sd, -(1 - sd), 0};
  struct Case {
    ReturnRegion region;
    std::array<double, 3> point;
    std::vector<Flow> flows;
  };
  const double M = kMPa;
  const std::vector<Case> cases{
      {ReturnRegion::main_plane, {on_plane(-1.0 * M), -0.6 * M, -1.0 * M}, {mc02}},
      {ReturnRegion::compression_edge,
       {on_plane(-2.0 * M), on_plane(-2.0 * M), -2.0 * M},
       {mc02, mc12}},
      {ReturnRegion::extension_edge, {on_plane(-2.0 * M), -2.0 * M, -2.0 * M}, {mc02, mc01}},
      {ReturnRegion::tension_plane, {t, 0.0, -0.05 * M}, {rankine0}},
      {ReturnRegion::tension_edge, {t, t, 0.5 * (t + low)}, {rankine0, rankine1}},
      {ReturnRegion::tension_apex, {t, t, t}, {rankine0, rankine1, rankine2}},
      {ReturnRegion::tension_shear_edge, {t, 0.5 * (t + low), low}, {rankine0, mc02}},
      {ReturnRegion::tension_extension_corner, {t, low, low}, {rankine0, mc02, mc01}},
      {ReturnRegion::tension_compression_corner, {t, t, low}, {rankine0, rankine1, mc02, mc12}},
  };
  int checks = 0;
  for (const Case& c : cases)
    for (double size : {0.01, 0.3, 3.0}) {
      std::array<double, 3> trial = c.point;
      for (std::size_t a = 0; a < c.flows.size(); ++a) {
        const Flow& N = c.flows[a];
        const double volumetric = m.lambda * (N[0] + N[1] + N[2]);
        Flow DN{};
        for (int i = 0; i < 3; ++i) DN[i] = volumetric + 2.0 * m.shear_modulus * N[i];
        const double dgamma =
            size * M * (1.0 + 0.25 * a) / std::sqrt(DN[0] * DN[0] + DN[1] * DN[1] + DN[2] * DN[2]);
        for (int i = 0; i < 3; ++i) trial[i] += dgamma * DN[i];
      }
      const MohrCoulombStep step = return_from_trial(m, diagonal(trial[0], trial[1], trial[2]));
      EXPECT_EQ(step.region, c.region)
          << "region " << static_cast<int>(c.region) << " size " << size;
      EXPECT_LE(step.kkt_residual, 1e-12);
      EXPECT_LT(std::abs(relative_yield(m, step.state)), kYieldTolerance);
      for (int i = 0; i < 3; ++i) EXPECT_NEAR(step.state.stress[i], c.point[i], 1e-11 * M);
      ++checks;
    }
  EXPECT_EQ(checks, 27);
}

// ---------------------------------------------------------------- flow rule

TEST(MohrCoulomb, PlasticFlowFollowsDilationAngle) {
  // Main plane: d_eps_p is along (1 + sin psi, 0, -(1 - sin psi)) in the principal axes, so the
  // plastic volume change per unit of the largest principal plastic strain is 2 sin(psi).
  int checks = 0;
  for (double psi : {0.0, 10.0, 30.0}) {
    const MohrCoulombMaterial m =
        mohr_coulomb_material(parameters(10.0e9, 0.25, 1.0 * kMPa, 30.0, psi, kInfinity));
    const MohrCoulombStep step = return_from_trial(m, diagonal(-2 * kMPa, -5 * kMPa, -15 * kMPa));
    ASSERT_EQ(step.region, ReturnRegion::main_plane);
    const Voigt& ep = step.state.plastic_strain;
    const double s = std::sin(psi * kPi / 180.0);
    EXPECT_GT(ep[0], 0.0);
    EXPECT_NEAR(ep[0] / ep[2], -(1.0 + s) / (1.0 - s), 1e-10);
    EXPECT_NEAR(ep[1], 0.0, 1e-12 * ep[0]);
    EXPECT_NEAR((ep[0] + ep[1] + ep[2]) / (ep[0] - ep[2]), s, 1e-10);
    ++checks;
  }
  EXPECT_EQ(checks, 3);
}

// ---------------------------------------------------------------- consistency and robustness

TEST(MohrCoulomb, ElasticStepsAreExact) {
  const MohrCoulombMaterial m = mohr_coulomb_material(issue_parameters());
  MohrCoulombState state =
      mohr_coulomb_update(m, MohrCoulombState{}, strain_of_stress(m, diagonal(-4e6, -5e6, -6e6)))
          .state;
  const Voigt increment{1e-6, -2e-6, 0.5e-6, 3e-6, -1e-6, 2e-6};
  const MohrCoulombStep step = mohr_coulomb_update(m, state, increment);
  ASSERT_EQ(step.region, ReturnRegion::elastic);
  const Voigt expected = isotropic_stress(m.lambda, m.shear_modulus, increment);
  for (int k = 0; k < 6; ++k) EXPECT_EQ(step.state.stress[k], state.stress[k] + expected[k]);
  EXPECT_EQ(step.state.plastic_strain, state.plastic_strain);
  EXPECT_NEAR(step.dissipation, 0.0, 1e-14 * step.stored_energy);
}

TEST(MohrCoulomb, RandomTrialsSatisfyReturnConditions) {
  // Every trial (random size and direction, from a random admissible state) finds a return whose
  // planes are all satisfied and whose multipliers are all >= 0 (no fallback), for associated,
  // non-associated, Tresca and cut-off materials; and every return region is reached.
  std::vector<MohrCoulombParameters> materials{
      issue_parameters(),
      issue_parameters(0.5 * kMPa),
      soft_rock(0.0),
      soft_rock(13.0),
      soft_rock(26.0),
      parameters(8.0e9, 0.24, 1.1 * kMPa, 42.0, 0.0, 1.95 * kMPa),
      parameters(28.0e9, 0.167, 1.8 * kMPa, 46.0, 46.0, 1.27 * kMPa),
      parameters(30.0e9, 0.2, 2.0 * kMPa, 0.0, 0.0, 1.0 * kMPa),
      parameters(30.0e9, 0.2, 2.0 * kMPa, 0.0, 0.0, kInfinity)};
  std::mt19937_64 generator(2024);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::uniform_real_distribution<double> angle(0.0, 2.0 * kPi);
  std::map<ReturnRegion, int> visits;
  double worst_kkt = 0.0, worst_yield = 0.0;
  int plastic = 0;
  for (const MohrCoulombParameters& p : materials) {
    const MohrCoulombMaterial m = mohr_coulomb_material(p);
    for (int sample = 0; sample < 4000; ++sample) {
      const double size = std::pow(10.0, 2.0 * unit(generator)) * kMPa;
      std::array<double, 3> values{size * unit(generator), size * unit(generator),
                                   size * unit(generator)};
      if (sample % 4 == 1) values[1] = values[0];  // repeated principal values
      if (sample % 4 == 2) values[2] = values[1];
      if (sample % 16 == 3) values = {values[0], values[0], values[0]};
      const Matrix3 R = rotation(angle(generator), angle(generator), angle(generator));
      const Matrix3 D{{{values[0], 0, 0}, {0, values[1], 0}, {0, 0, values[2]}}};
      const Voigt trial = stress_voigt(rotate_tensor(R, D));
      const MohrCoulombStep step = return_from_trial(m, trial);
      ++visits[step.region];
      worst_kkt = std::max(worst_kkt, step.kkt_residual);
      if (step.region == ReturnRegion::elastic) continue;
      ++plastic;
      worst_yield = std::max(worst_yield, std::abs(relative_yield(m, step.state)));
      // From the stress-free state the dissipation is 1/2 sigma : d_eps_p >= 0.
      EXPECT_GE(step.dissipation, 0.0) << "region " << static_cast<int>(step.region);
    }
  }
  EXPECT_LE(worst_kkt, 1e-12);
  EXPECT_LT(worst_yield, kYieldTolerance);
  EXPECT_GT(plastic, 10000);
  for (ReturnRegion r :
       {ReturnRegion::elastic, ReturnRegion::main_plane, ReturnRegion::compression_edge,
        ReturnRegion::extension_edge, ReturnRegion::apex, ReturnRegion::tension_plane,
        ReturnRegion::tension_edge, ReturnRegion::tension_apex, ReturnRegion::tension_shear_edge,
        ReturnRegion::tension_compression_corner, ReturnRegion::tension_extension_corner})
    EXPECT_GT(visits[r], 0) << "region " << static_cast<int>(r) << " never reached";
  std::printf(
      "[ info ] worst kkt residual %.2e, worst relative yield residual %.2e over %d plastic "
      "returns\n",
      worst_kkt, worst_yield, plastic);
}

TEST(MohrCoulomb, ReturnIsContinuousAcrossSectorBoundaries) {
  // Trials on either side of sigma_1 = sigma_2, sigma_2 = sigma_3 and the cut-off corner differ
  // by delta; the returns must differ by O(delta), whichever candidate each one picked.
  const MohrCoulombMaterial m = mohr_coulomb_material(soft_rock(13.0));
  const double M = kMPa;
  const std::array<Voigt, 4> boundaries{
      diagonal(-1.0 * M, -1.0 * M, -4.0 * M), diagonal(-0.2 * M, -2.0 * M, -2.0 * M),
      diagonal(0.8 * M, 0.8 * M, -1.5 * M), diagonal(0.9 * M, -0.9 * M, -0.9 * M)};
  int checks = 0;
  for (const Voigt& base : boundaries)
    for (double delta : {1e-3 * M, 1e-6 * M, 1e-9 * M, 1e-12 * M})
      for (int component = 0; component < 3; ++component) {
        Voigt plus = base, minus = base;
        plus[component] += delta;
        minus[component] -= delta;
        const MohrCoulombStep a = return_from_trial(m, plus);
        const MohrCoulombStep b = return_from_trial(m, minus);
        Voigt difference{};
        for (int k = 0; k < 6; ++k) difference[k] = a.state.stress[k] - b.state.stress[k];
        EXPECT_LE(max_abs(difference), 4.0 * delta + 1e-15 * M);
        EXPECT_LE(a.kkt_residual, 1e-12);
        EXPECT_LE(b.kkt_residual, 1e-12);
        ++checks;
      }
  EXPECT_EQ(checks, 48);
}

TEST(MohrCoulomb, ReturnCommutesWithRotation) {
  // Objectivity: rotating the old state and the strain increment rotates the new state.
  MohrCoulombParameters p = soft_rock(13.0);
  p.damage_max = 0.9;
  const MohrCoulombMaterial m = mohr_coulomb_material(p);
  std::mt19937_64 generator(99);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::uniform_real_distribution<double> angle(0.0, 2.0 * kPi);
  int checks = 0;
  for (int sample = 0; sample < 200; ++sample) {
    const Voigt old_stress{0.1e6 * unit(generator) - 0.3e6, 0.1e6 * unit(generator) - 0.3e6,
                           0.1e6 * unit(generator) - 0.3e6, 0.05e6 * unit(generator),
                           0.05e6 * unit(generator),        0.05e6 * unit(generator)};
    MohrCoulombState old;
    old.stress = old.effective_stress = old_stress;
    ASSERT_LT(mohr_coulomb_yield(m, principal_stresses(old_stress).values), 0.0);
    Voigt increment{};
    for (double& x : increment) x = 1e-3 * unit(generator);
    const Matrix3 R = rotation(angle(generator), angle(generator), angle(generator));
    MohrCoulombState rotated_old = old;
    rotated_old.stress = rotated_old.effective_stress =
        stress_voigt(rotate_tensor(R, tensor_from_stress_voigt(old_stress)));
    const Voigt rotated_increment =
        strain_voigt(rotate_tensor(R, tensor_from_strain_voigt(increment)));
    const MohrCoulombStep a = mohr_coulomb_update(m, old, increment);
    const MohrCoulombStep b = mohr_coulomb_update(m, rotated_old, rotated_increment);
    const Voigt expected_stress =
        stress_voigt(rotate_tensor(R, tensor_from_stress_voigt(a.state.stress)));
    const Voigt expected_plastic =
        strain_voigt(rotate_tensor(R, tensor_from_strain_voigt(a.state.plastic_strain)));
    const double stress_scale = std::max(max_abs(a.state.stress), 1e3);
    const double strain_scale = std::max(max_abs(a.state.plastic_strain), 1e-12);
    for (int k = 0; k < 6; ++k) {
      EXPECT_NEAR(b.state.stress[k], expected_stress[k], 1e-11 * stress_scale);
      EXPECT_NEAR(b.state.plastic_strain[k], expected_plastic[k], 1e-10 * strain_scale);
    }
    EXPECT_NEAR(b.state.damage, a.state.damage, 1e-12);
    EXPECT_EQ(b.region, a.region);
    checks += a.region != ReturnRegion::elastic;
  }
  EXPECT_GT(checks, 150);  // the sizes above make almost every step plastic
}

// ---------------------------------------------------------------- damage and energy

TEST(MohrCoulomb, DamageFollowsAccumulatedPlasticStrain) {
  // Uniaxial tension on the cut-off with damage: d = d_max (1 - exp(-kappa / kappa_ref)) with
  // kappa = sqrt(2/3) eps_p,axial (Rankine flow along the axis), nominal stress (1 - d) t.
  MohrCoulombParameters p = soft_rock();
  p.damage_max = 0.9;
  p.damage_plastic_strain = 2e-4;
  const MohrCoulombMaterial m = mohr_coulomb_material(p);
  const double t = m.tensile_strength;
  MohrCoulombState state;
  double previous = 0.0;
  int checks = 0;
  for (int k = 0; k < 200; ++k) {
    const MohrCoulombStep step = drive_axisymmetric(m, state, 0, 5e-6, 0.0);
    state = step.state;
    EXPECT_GE(state.damage, previous);
    EXPECT_LT(state.damage, 1.0);
    previous = state.damage;
    if (state.plastic_strain[0] <= 0.0) continue;
    const double kappa = std::sqrt(2.0 / 3.0) * state.plastic_strain[0];
    EXPECT_NEAR(state.kappa_tension, kappa, 1e-10 * kappa);
    EXPECT_NEAR(state.damage, 0.9 * (1.0 - std::exp(-kappa / 2e-4)), 1e-10);
    EXPECT_NEAR(state.stress[0], (1.0 - state.damage) * t, 1e-10 * t);
    EXPECT_NEAR(state.effective_stress[0], t, 1e-10 * t);
    EXPECT_EQ(state.damage_type, DamageType::tension);
    EXPECT_GE(step.dissipation, 0.0);
    ++checks;
  }
  EXPECT_GT(checks, 150);
  EXPECT_GT(state.damage, 0.8);
  // Shear path: the M-C planes alone, the type is shear.
  const MohrCoulombStep shear =
      return_from_trial(m, diagonal(-0.2 * kMPa, -1.0 * kMPa, -3.0 * kMPa));
  EXPECT_EQ(shear.region, ReturnRegion::main_plane);
  EXPECT_EQ(shear.state.damage_type, DamageType::shear);
  EXPECT_GT(shear.state.damage, 0.0);
  EXPECT_EQ(shear.state.kappa_tension, 0.0);
}

TEST(MohrCoulomb, CrackBandMakesSofteningAFunctionOfThePlasticDisplacement) {
  // A softening band one cell wide opens by w = h eps_p. With damage_plastic_displacement u_ref
  // the damage is d_max (1 - exp(-sqrt(2/3) w / u_ref)) whatever the cell size h, so a bar's
  // nominal stress at a given opening, and the work it does on the opening per unit area, are
  // properties of the rock, not of the mesh; with kappa_ref fixed (no crack band) the damage at
  // the same opening falls with h and the work grows with it. Uniaxial tension on the cut-off
  // (soft rock), strain steps of dw / h for every h.
  MohrCoulombParameters p = soft_rock();
  p.damage_max = 0.9;
  p.damage_plastic_strain = 2e-4;
  MohrCoulombParameters band = p;
  band.damage_plastic_displacement = 2e-4;  // m: kappa_ref = 2e-4 at h = 1 m
  const MohrCoulombMaterial plain = mohr_coulomb_material(p), m = mohr_coulomb_material(band);
  const double t = m.tensile_strength, u_ref = band.damage_plastic_displacement;
  const std::array<double, 4> sizes{0.5, 1.0, 2.0, 4.0};
  std::array<double, 4> band_work{}, plain_work{}, plain_damage{};
  int checks = 0;
  for (int i = 0; i < 4; ++i) {
    const double h = sizes[i];
    EXPECT_NEAR(damage_strain_scale(m, h), u_ref / h, 1e-15);
    EXPECT_EQ(damage_strain_scale(plain, h), 2e-4);
    for (const MohrCoulombMaterial* law : {&m, &plain}) {
      MohrCoulombState state;
      double work = 0.0;  // of the nominal stress on the opening: sum of sigma_avg dw (J/m^2)
      // Up to the cut-off, then on to an opening of 3 u_ref.
      for (int k = 0; h * state.plastic_strain[0] < 3.0 * u_ref && k < 100000; ++k) {
        const MohrCoulombStep step = drive_axisymmetric(*law, state, 0, u_ref / 400.0 / h, 0.0, h);
        EXPECT_GE(step.dissipation, -1e-12 * step.stored_energy);  // round-off while elastic
        work += 0.5 * (state.stress[0] + step.state.stress[0]) * h *
                (step.state.plastic_strain[0] - state.plastic_strain[0]);
        state = step.state;
        const double w = h * state.plastic_strain[0];
        if (law == &m && w > 0.0) {
          const double d = 0.9 * (1.0 - std::exp(-std::sqrt(2.0 / 3.0) * w / u_ref));
          EXPECT_NEAR(state.damage, d, 1e-10);
          EXPECT_NEAR(state.stress[0], (1.0 - d) * t, 1e-9 * t);
          ++checks;
        }
      }
      const double w = h * state.plastic_strain[0];
      ASSERT_GE(w, 3.0 * u_ref);
      ASSERT_LT(w, 3.0 * u_ref * (1.0 + 1e-2));
      ASSERT_GT(state.damage, 0.3);  // the band did soften
      (law == &m ? band_work : plain_work)[i] = work;
      if (law == &plain) plain_damage[i] = state.damage;
    }
  }
  EXPECT_GT(checks, 4 * 1000);
  for (int i = 0; i < 4; ++i)
    std::printf("[ info ] h = %.1f m: work on the opening %.2f J/m^2 with the band, %.2f without "
                "(damage %.3f)\n", sizes[i], band_work[i], plain_work[i], plain_damage[i]);
  for (int i = 1; i < 4; ++i) {
    // The same up to where the last step stops past 3 u_ref (< 1 % of it, at the residual stress).
    EXPECT_NEAR(band_work[i] / band_work[0], 1.0, 2e-3) << "h = " << sizes[i];
    EXPECT_LT(plain_damage[i], plain_damage[i - 1]);  // without: less damage in larger cells
  }
  EXPECT_GT(plain_work[3] / plain_work[0], 1.5);  // without: the work grows with h
}

TEST(MohrCoulomb, EnergyAccountAlongCyclicPath) {
  // A cyclic shear-compression path with damage: per step W_n+1 - W_n + dissipation equals the
  // trapezoid work; every step dissipates >= 0; without damage the dissipation equals the
  // trapezoid integral of sigma : d_eps_p computed from the stored plastic strains.
  int checks = 0;
  for (double damage_max : {0.0, 0.9}) {
    MohrCoulombParameters p = soft_rock(13.0);
    p.damage_max = damage_max;
    p.damage_plastic_strain = 1e-3;
    const MohrCoulombMaterial m = mohr_coulomb_material(p);
    MohrCoulombState state =
        mohr_coulomb_update(m, MohrCoulombState{}, strain_of_stress(m, diagonal(-1e6, -1e6, -1e6)))
            .state;
    double work = 0.0, stored_change = 0.0, dissipated = 0.0, plastic_work = 0.0;
    const double W0 = mohr_coulomb_stored_energy(m, state);
    for (int k = 0; k < 4000; ++k) {
      const double phase = 2.0 * kPi * k / 500.0;
      // Shear strain amplitude about 5e-3, several times the yield strain at this confinement.
      const Voigt increment{2e-5 * std::cos(phase),     -1e-5 * std::cos(phase),
                            0.3e-5 * std::sin(phase),   6e-5 * std::cos(phase),
                            1e-5 * std::sin(2 * phase), 0.0};
      const MohrCoulombStep step = mohr_coulomb_update(m, state, increment);
      double step_work = 0.0, step_plastic = 0.0;
      for (int i = 0; i < 6; ++i) {
        step_work += 0.5 * (state.stress[i] + step.state.stress[i]) * increment[i];
        step_plastic += 0.5 * (state.stress[i] + step.state.stress[i]) *
                        (step.state.plastic_strain[i] - state.plastic_strain[i]);
      }
      // >= 0 up to the round-off of W_n+1 - W_n (a difference of two stored energies).
      EXPECT_GE(step.dissipation, -1e-13 * step.stored_energy);
      work += step_work;
      dissipated += step.dissipation;
      plastic_work += step_plastic;
      stored_change = step.stored_energy - W0;
      state = step.state;
      ++checks;
    }
    EXPECT_GT(dissipated, 0.1 * std::abs(work));  // the path is far in the plastic range
    EXPECT_NEAR(stored_change + dissipated, work, 1e-10 * dissipated);
    if (damage_max == 0.0) {
      EXPECT_NEAR(dissipated, plastic_work, 1e-9 * dissipated);
    } else {
      EXPECT_GT(state.damage, 0.1);
    }
    std::printf("[ info ] damage_max %.1f: work %.6e J/m^3, dissipated %.6e, damage %.3f\n",
                damage_max, work, dissipated, state.damage);
  }
  EXPECT_EQ(checks, 8000);
}

TEST(MohrCoulomb, RejectsInvalidParameters) {
  auto expect_throw = [](MohrCoulombParameters p) {
    EXPECT_THROW(mohr_coulomb_material(p), std::invalid_argument);
  };
  MohrCoulombParameters p;
  p.dilation_angle = 50.0;  // > phi
  expect_throw(p);
  p = {};
  p.friction_angle = 90.0;
  expect_throw(p);
  p = {};
  p.tensile_strength = -1.0;
  expect_throw(p);
  p = {};
  p.friction_angle = 0.0;
  p.dilation_angle = 0.0;
  p.cohesion = 0.0;
  expect_throw(p);
  p = {};
  p.damage_max = 1.0;
  expect_throw(p);
  p = {};
  p.damage_plastic_displacement = -1e-3;
  expect_throw(p);
  // Table 1 sandstone: t = 1.95 MPa exceeds the apex c cot(phi) = 1.22 MPa, no cut-off.
  const MohrCoulombMaterial sandstone = mohr_coulomb_material(MohrCoulombParameters{});
  EXPECT_FALSE(sandstone.tension_cutoff);
  EXPECT_NEAR(sandstone.apex, 1.10e6 / std::tan(42.0 * kPi / 180.0), 1e-6);
}

// The cheapest elastic screen (elastic_by_invariants) is an upper bound of the yield function:
// it never calls elastic a stress that the exact principal stresses put on or outside the
// surface, and it does recognise the confined states that most points of a deep model are in.
TEST(MohrCoulomb, InvariantScreenNeverAcceptsAYieldingStress) {
  std::mt19937_64 generator(7);
  std::uniform_real_distribution<double> angle(0.0, 2.0 * kPi);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  int accepted = 0, yielding = 0, inside = 0;
  for (const MohrCoulombMaterial& m :
       {mohr_coulomb_material(issue_parameters()), mohr_coulomb_material(soft_rock()),
        mohr_coulomb_material(parameters(30.0e9, 0.2, 2.0 * kMPa, 0.0, 0.0, kInfinity))}) {
    for (int sample = 0; sample < 20000; ++sample) {
      // Principal stresses around the surface: mean from -20 to +2 MPa, deviator up to 15 MPa.
      const double mean = -9.0 * kMPa + 11.0 * kMPa * unit(generator);
      const double spread = 7.5 * kMPa * (1.0 + unit(generator));
      const Matrix3 D{{{mean + spread * unit(generator), 0.0, 0.0},
                       {0.0, mean + spread * unit(generator), 0.0},
                       {0.0, 0.0, mean + spread * unit(generator)}}};
      const Voigt s = stress_voigt(
          rotate_tensor(rotation(angle(generator), angle(generator), angle(generator)), D));
      const double f = mohr_coulomb_yield(m, principal_stresses(s).values);
      const bool screened = elastic_by_invariants(m, s);
      if (f >= 0.0) {
        ++yielding;
        EXPECT_FALSE(screened) << "f = " << f;
      } else {
        ++inside;
      }
      accepted += screened;
    }
  }
  EXPECT_GT(yielding, 1000);  // the samples do cross the surface
  EXPECT_GT(accepted, inside / 4);  // and the screen does its job on a good share of the rest
  // The states of a deep model at rest: 8 MPa confinement with a 3 MPa deviator.
  const MohrCoulombMaterial rock = mohr_coulomb_material(issue_parameters());
  EXPECT_TRUE(elastic_by_invariants(rock, {-8.0 * kMPa, -8.0 * kMPa, -11.0 * kMPa, 0.0, 0.0, 0.0}));
  // Exactly on the surface (main plane, sigma_2 on the compression meridian) is not elastic.
  const double k = rock.strength, sp = rock.sin_phi;
  const double s3 = -10.0 * kMPa, s1 = (k + s3 * (1.0 - sp)) / (1.0 + sp);
  EXPECT_NEAR(mohr_coulomb_yield(rock, {s1, s1, s3}), 0.0, 1e-9 * kMPa);
  EXPECT_FALSE(elastic_by_invariants(rock, {s1, s1, s3, 0.0, 0.0, 0.0}));
}
