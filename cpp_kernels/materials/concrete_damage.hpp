// Lining concrete: damage with Mazars' exponential laws (Zhao et al. 2021 Eq. 21, after
// Mazars 1986), tension checked first by the maximum principal strain, then the Mohr-Coulomb
// criterion for compression-shear damage; stiffness recovery on crack closure;
// crack-band regularisation of the tensile softening (Bazant & Oh 1983). One integration point,
// header only. Details and the reading of Eq. 21 in docs/materials.md.
//
// Conventions: small strain, 3D, Voigt [xx, yy, zz, xy, yz, xz] (principal.hpp): stresses hold
// tensor components, strains engineering shear; tension positive; Pa, m, N/m.
//
// The law is secant (total strain in, stress out; sigma = (1 - d) C : eps in purely tensile or
// purely compressive states, d = 1 - (1 - d_c)(1 - d_t) or 1 - (1 - d_c)(1 - s d_t)), eps measured
// from the stress-free state of the concrete (the lining is installed stress-free). The update
// is a pure function: the caller keeps the old state until it commits the new one.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "material_law.hpp"
#include "principal.hpp"

namespace cavern {

/// User parameters (the `[materials.X.damage]` table). Defaults: lining of Zhao et al. 2021
/// Table 1 (E, nu, c, phi, f_t); Mazars (1986) exponential-law constants; fracture energy of
/// the order of fib Model Code 2010 for C25/30 (docs/materials.md). Angle in degrees.
struct ConcreteDamageParameters {
  double young_modulus = 28.0e9;     // E (Pa)
  double poisson_ratio = 0.167;      // nu
  double tensile_strength = 1.27e6;  // f_t (Pa): threshold eps_t^f = f_t / E
  double cohesion = 1.8e6;           // c (Pa) of the compression-shear criterion
  double friction_angle = 46.0;      // phi (deg)
  double fracture_energy = 120.0;    // G_f (N/m); <= 0: no crack band, B_t used as given
  double A_t = 1.0;                  // Eq. 21 tension constants; A_t = 1 with the crack band
  double B_t = 5.0e4;                //   (shape of the softening; G_f sets its length)
  double A_c = 1.4;                  // Eq. 21 compression-shear constants
  double B_c = 1.5e3;
  double stiffness_recovery = 0.0;  // s of Eq. 21 in [0, 1]: share of d_t still acting in
                                    // compression (0: cracks close fully, 1: no recovery)
  double damage_max = 0.9999;       // cap of d_t, d_c and d (a stiffness floor, not physics)
};

/// Constants computed once per region by concrete_damage_material().
struct ConcreteDamageMaterial {
  double young_modulus, poisson_ratio, lambda, shear_modulus;
  double tensile_strength, fracture_energy;
  double threshold_tension;      // eps_t^f = f_t / E
  double threshold_compression;  // eps_c^f = f_c / E, f_c = 2 c cos(phi) / (1 - sin(phi))
  double sin_phi;
  double A_t, B_t, A_c, B_c, stiffness_recovery, damage_max;
  double softening_energy;  // E (eps_t/B_t + 1/B_t^2): energy density of the Eq. 21
                            // tension curve beyond its peak, A_t = 1 (J/m^3)
};

/// Per-integration-point state (owned by the caller; 18 doubles + type).
struct ConcreteDamageState {
  Voigt strain{};                  // total strain of the last committed step (engineering)
  Voigt stress{};                  // (1 - d) C : strain (Pa)
  double kappa_tension = 0.0;      // largest tensile equivalent strain beyond eps_t so far (else 0)
  double kappa_compression = 0.0;  // same for the compression-shear equivalent strain and eps_c
  double damage_tension = 0.0;     // d_t, never decreases
  double damage_compression = 0.0;  // d_c, never decreases
  double damage = 0.0;              // 1 - (1 - d_t)(1 - d_c): the reported damage, never decreases
  DamageType damage_type = DamageType::none;  // the larger of d_t (tension) and d_c (shear)
};

/// Result of one trial update.
struct ConcreteDamageStep {
  ConcreteDamageState state;
  double stored_energy = 0.0;  // 1/2 sigma : eps of the new state (J/m^3)
  double dissipation = 0.0;    // trapezoid work of the step minus the change of stored energy
};

/// Validates (std::invalid_argument naming the first bad parameter) and precomputes.
inline ConcreteDamageMaterial concrete_damage_material(const ConcreteDamageParameters& p) {
  const auto require = require_parameter;
  require_elastic_constants(p.young_modulus, p.poisson_ratio);
  require(std::isfinite(p.tensile_strength) && p.tensile_strength > 0.0, "tensile_strength",
          p.tensile_strength, "finite and > 0 (Pa)");
  require(std::isfinite(p.cohesion) && p.cohesion > 0.0, "cohesion", p.cohesion,
          "finite and > 0 (Pa)");
  require(std::isfinite(p.friction_angle) && p.friction_angle >= 0.0 && p.friction_angle < 90.0,
          "friction_angle", p.friction_angle, "in [0, 90) (deg)");
  require(std::isfinite(p.fracture_energy), "fracture_energy", p.fracture_energy,
          "finite (N/m; <= 0 for no crack band)");
  require(std::isfinite(p.A_t) && p.A_t > 0.0 && p.A_t <= 1.0, "A_t", p.A_t, "in (0, 1]");
  // With A_t < 1 the stress keeps (1 - A_t) f_t forever and no finite energy can be matched.
  require(p.fracture_energy <= 0.0 || p.A_t == 1.0, "A_t", p.A_t,
          "1 when fracture_energy > 0 (a residual tensile stress has unbounded fracture energy)");
  require(std::isfinite(p.B_t) && p.B_t > 0.0, "B_t", p.B_t, "finite and > 0");
  require(std::isfinite(p.A_c) && p.A_c > 0.0, "A_c", p.A_c, "finite and > 0");
  require(std::isfinite(p.B_c) && p.B_c > 0.0, "B_c", p.B_c, "finite and > 0");
  require(std::isfinite(p.stiffness_recovery) && p.stiffness_recovery >= 0.0 &&
              p.stiffness_recovery <= 1.0,
          "stiffness_recovery", p.stiffness_recovery, "in [0, 1]");
  require(std::isfinite(p.damage_max) && p.damage_max >= 0.0 && p.damage_max < 1.0, "damage_max",
          p.damage_max, "in [0, 1)");
  ConcreteDamageMaterial m{};
  m.young_modulus = p.young_modulus;
  m.poisson_ratio = p.poisson_ratio;
  const LameConstants lame = lame_constants(p.young_modulus, p.poisson_ratio);
  m.shear_modulus = lame.shear_modulus;
  m.lambda = lame.lambda;
  m.tensile_strength = p.tensile_strength;
  m.fracture_energy = p.fracture_energy;
  const double phi = p.friction_angle * 3.14159265358979323846 / 180.0;
  m.sin_phi = std::sin(phi);
  m.threshold_tension = p.tensile_strength / p.young_modulus;
  m.threshold_compression = 2.0 * p.cohesion * std::cos(phi) / (1.0 - m.sin_phi) / p.young_modulus;
  m.A_t = p.A_t;
  m.B_t = p.B_t;
  m.A_c = p.A_c;
  m.B_c = p.B_c;
  m.stiffness_recovery = p.stiffness_recovery;
  m.damage_max = p.damage_max;
  m.softening_energy = p.young_modulus * (m.threshold_tension / p.B_t + 1.0 / (p.B_t * p.B_t));
  return m;
}

/// Largest element size (m) the crack band can regularise: the elastic energy density at the
/// peak, f_t^2 / (2E), must stay below G_f / h (Bazant & Oh 1983), so h < 2 E G_f / f_t^2
/// (4.2 m for the defaults). Larger elements would snap back; they get brittle failure.
inline double concrete_maximum_element_size(const ConcreteDamageMaterial& m) {
  if (m.fracture_energy <= 0.0) return std::numeric_limits<double>::infinity();
  return 2.0 * m.young_modulus * m.fracture_energy / (m.tensile_strength * m.tensile_strength);
}

/// Crack-band stretch of the softening branch for an element of size h (m):
///   beta = P / (G_f / h - f_t^2 / (2E)),  P = E (eps_t/B_t + 1/B_t^2),
/// so that f_t^2/(2E) + P / beta = G_f / h: the energy dissipated per unit volume to full
/// damage times h is G_f whatever h (Bazant & Oh 1983). 1 without crack band; +inf for
/// h >= concrete_maximum_element_size (brittle).
inline double concrete_crack_band_stretch(const ConcreteDamageMaterial& m, double element_size) {
  if (m.fracture_energy <= 0.0) return 1.0;
  const double available = m.fracture_energy / element_size -
                           0.5 * m.tensile_strength * m.tensile_strength / m.young_modulus;
  if (!(available > 0.0)) return std::numeric_limits<double>::infinity();
  return m.softening_energy / available;
}

/// Tensile damage (Eq. 21, Mazars 1986) of the history variable kappa, with the softening
/// branch stretched by beta (concrete_crack_band_stretch):
///   kappa_hat = eps_t + beta (kappa - eps_t),
///   d_t = 1 - [(1 - A_t) eps_t + A_t kappa_hat exp(-B_t (kappa_hat - eps_t))] / kappa,
/// i.e. the uniaxial stress E kappa (1 - d_t) is Eq. 21's curve of kappa_hat; beta = 1 gives
/// Eq. 21 exactly. 0 below the threshold eps_t = f_t / E; capped at damage_max.
inline double concrete_tension_damage(const ConcreteDamageMaterial& m, double kappa,
                                      double stretch) {
  const double threshold = m.threshold_tension;
  if (!(kappa > threshold)) return 0.0;
  if (!std::isfinite(stretch)) return m.damage_max;
  const double kappa_hat = threshold + stretch * (kappa - threshold);
  const double secant =
      ((1.0 - m.A_t) * threshold + m.A_t * kappa_hat * std::exp(-m.B_t * (kappa_hat - threshold))) /
      kappa;
  return std::clamp(1.0 - secant, 0.0, m.damage_max);
}

/// Compression-shear damage (Eq. 21, Mazars 1986):
///   d_c = 1 - (1 - A_c) eps_c / kappa - A_c exp(-B_c (kappa - eps_c)),
/// 0 below the threshold eps_c = f_c / E; clamped to [0, damage_max].
inline double concrete_compression_damage(const ConcreteDamageMaterial& m, double kappa) {
  const double threshold = m.threshold_compression;
  if (!(kappa > threshold)) return 0.0;
  const double d =
      1.0 - (1.0 - m.A_c) * threshold / kappa - m.A_c * std::exp(-m.B_c * (kappa - threshold));
  return std::clamp(d, 0.0, m.damage_max);
}

/// Stored energy density of a state (J/m^3): W = (1 - d_c)[(1 - d_t) psi+ + (1 - s d_t) psi-],
/// equal to 1/2 sigma : eps because W is homogeneous of degree 2 in the strain.
inline double concrete_stored_energy(const ConcreteDamageState& state) {
  return 0.5 * double_contraction(state.stress, state.strain);
}

namespace detail {

// Equivalent strains of concrete_damage_update from the principal strains (descending).
struct ConcreteMeasures {
  double tension;                       // eps_t_bar = sqrt(sum <e+_i>^2)
  double shear;                         // eps_c_bar, Mohr-Coulomb equivalent strain
  double largest_stress;                // largest principal effective stress (Pa)
  std::array<double, 3> positive;       // <s_i>, principal effective stresses' positive parts
  double positive_sum, positive_trace;  // sum <s_i>, <tr sigma_e>
  double size;                          // largest |principal strain|
};

inline ConcreteMeasures concrete_measures(const ConcreteDamageMaterial& m,
                                          const std::array<double, 3>& strain) {
  const double E = m.young_modulus, nu = m.poisson_ratio;
  const double trace = strain[0] + strain[1] + strain[2];
  ConcreteMeasures r{};
  std::array<double, 3> effective{};
  for (int i = 0; i < 3; ++i) {
    effective[i] = m.lambda * trace + 2.0 * m.shear_modulus * strain[i];
    r.positive[i] = std::max(effective[i], 0.0);
    r.positive_sum += r.positive[i];
  }
  r.positive_trace = std::max(effective[0] + effective[1] + effective[2], 0.0);
  double squares = 0.0;
  for (int i = 0; i < 3; ++i) {
    const double part = std::max(((1.0 + nu) * r.positive[i] - nu * r.positive_trace) / E, 0.0);
    squares += part * part;
  }
  r.tension = std::sqrt(squares);
  r.shear = ((effective[0] - effective[2]) + (effective[0] + effective[2]) * m.sin_phi) /
            ((1.0 - m.sin_phi) * E);
  r.largest_stress = effective[0];
  r.size = std::max(std::abs(strain[0]), std::abs(strain[2]));
  return r;
}

// Upper bounds of concrete_measures' tension and shear measures from the strain's invariants
// (no eigenvalues). With the trace T and the deviator's norm D of the strain (engineering shear
// halved), every principal strain lies in T/3 +- sqrt(2/3) D and two differ by at most sqrt(2) D,
// so the largest effective stress is at most S = lambda T + 2 mu (T/3 + sqrt(2/3) D), the tension
// measure at most (1 + nu) sqrt(3) <S> / E and the shear measure at most
// (2 sqrt(2) mu D + 2 S sin(phi)) / ((1 - sin(phi)) E); margin: 1e-6 of the strain size, the
// round-off room of the comparison (tests/cpp/test_concrete_damage.cpp checks the bounds).
struct ConcreteBounds {
  double tension, shear, largest_stress, margin;
};

inline ConcreteBounds concrete_invariant_bounds(const ConcreteDamageMaterial& m,
                                                const Voigt& strain) {
  const double T = strain[0] + strain[1] + strain[2];
  const double d0 = strain[0] - T / 3.0, d1 = strain[1] - T / 3.0, d2 = strain[2] - T / 3.0;
  const double D = std::sqrt(d0 * d0 + d1 * d1 + d2 * d2 +
                             0.5 * (strain[3] * strain[3] + strain[4] * strain[4] + strain[5] * strain[5]));
  const double largest_strain = T / 3.0 + std::sqrt(2.0 / 3.0) * D;
  const double S = m.lambda * T + 2.0 * m.shear_modulus * largest_strain;
  ConcreteBounds r;
  r.tension = (1.0 + m.poisson_ratio) * std::sqrt(3.0) * std::max(S, 0.0) / m.young_modulus;
  r.shear = (2.0 * std::sqrt(2.0) * m.shear_modulus * D + 2.0 * S * m.sin_phi) /
            ((1.0 - m.sin_phi) * m.young_modulus);
  r.largest_stress = S;
  r.margin = 1e-6 * (std::abs(T) / 3.0 + std::sqrt(2.0 / 3.0) * D);
  return r;
}

// Energy terms of a step whose new stress and strain are set.
inline ConcreteDamageStep& finish_concrete_step(const ConcreteDamageState& old,
                                                ConcreteDamageStep& step) {
  const ConcreteDamageState& next = step.state;
  step.stored_energy = concrete_stored_energy(next);
  double work = 0.0;
  for (int k = 0; k < 6; ++k)
    work += 0.5 * (old.stress[k] + next.stress[k]) * (next.strain[k] - old.strain[k]);
  step.dissipation = work - (step.stored_energy - concrete_stored_energy(old));
  return step;
}

}  // namespace detail

/// One step of the lining law to the total strain `strain` (engineering shear), element size h
/// (m, for the crack band: the cube root of the element volume for a hexahedron).
///   effective stress   sigma_e = C : eps, principal values s_i (coaxial with eps)
///   energy split       psi+- = [(1 + nu) sum <+-s_i>^2 - nu <+-tr sigma_e>^2] / (2E) >= 0,
///                      psi+ + psi- = 1/2 eps : C : eps, both C^1; tensile strain
///                      e+ = d psi+ / d sigma_e = [(1 + nu) <sigma_e>_+ - nu <tr sigma_e>_+ I] / E
///                      (e+ = eps when no principal stress is compressive, 0 when none is
///                      tensile, so Poisson expansion under compression is not tension).
///   tension first      eps_t_bar = sqrt(sum <e+_i>^2) (the paper's sqrt(sum <eps_i>^2) applied
///                      to e+); eps_t_bar > eps_t: kappa_t = max(kappa_t, eps_t_bar), d_t grows,
///                      and the Mohr-Coulomb check is skipped (Eq. 21 text).
///   else M-C           eps_c_bar = [(s_1 - s_3) + (s_1 + s_3) sin(phi)] / ((1 - sin(phi)) E),
///                      above eps_c = f_c / E exactly when sigma_e violates Mohr-Coulomb (c, phi);
///                      then kappa_c = max(kappa_c, eps_c_bar), d_c grows.
///   stress, recovery   W = (1 - d_c) [(1 - d_t) psi+ + (1 - s d_t) psi-], sigma = dW/d eps
///                        = (1 - d_c) [(1 - s d_t) sigma_e - (1 - s) d_t C : e+],
///                      i.e. the paper's d = 1 - (1 - d_c)(1 - s d_t) in compression and
///                      d = 1 - (1 - d_c)(1 - d_t) in tension (Eq. 21, its misprinted second d_t
///                      read as s acting on d_t), and hyperelastic at fixed damage in between.
///   energy             W = 1/2 sigma : eps; dissipation = 1/2 (sigma_n + sigma_n+1) : d_eps
///                      - (W_n+1 - W_n), exact for the trapezoid work of the integrator.
inline ConcreteDamageStep concrete_damage_update(const ConcreteDamageMaterial& m,
                                                 const ConcreteDamageState& old,
                                                 const Voigt& strain, double element_size) {
  ConcreteDamageStep step;
  ConcreteDamageState& next = step.state;
  next = old;
  next.strain = strain;

  const double nu = m.poisson_ratio;
  const Voigt elastic = isotropic_stress(m.lambda, m.shear_modulus, strain);

  // Screen with the fast eigenvalue estimate: when no damage can grow and no tensile part is
  // needed (undamaged, or every principal stress clearly compressive), the stress needs no
  // principal directions. Margin 1e-6 of the strain size, far above the estimate's error.
  const double tensile_weight_old =
      (1.0 - old.damage_compression) * (1.0 - m.stiffness_recovery) * old.damage_tension;
  // Invariant pre-screen, before any eigenvalue (concrete_invariant_bounds): below both
  // thresholds, with no tensile part to split off (tensile_weight_old = 0), the point is elastic
  // at its damage: the screen below would say the same from the estimate, which costs more (most
  // of the lining at rest).
  if (tensile_weight_old == 0.0) {
    const detail::ConcreteBounds bound = detail::concrete_invariant_bounds(m, strain);
    if (bound.tension + bound.margin < std::max(m.threshold_tension, old.kappa_tension) &&
        bound.shear + bound.margin < std::max(m.threshold_compression, old.kappa_compression)) {
      const double factor =
          (1.0 - old.damage_compression) * (1.0 - m.stiffness_recovery * old.damage_tension);
      for (int k = 0; k < 6; ++k) next.stress[k] = factor * elastic[k];
      return detail::finish_concrete_step(old, step);
    }
  }
  const Matrix3 strain_tensor = tensor_from_strain_voigt(strain);
  const std::array<double, 3> values_estimate = symmetric_eigenvalues_estimate(strain_tensor);
  {
    const detail::ConcreteMeasures estimate = detail::concrete_measures(m, values_estimate);
    const double margin = 1e-6 * estimate.size;
    const bool no_growth =
        estimate.tension + margin < std::max(m.threshold_tension, old.kappa_tension) &&
        estimate.shear + margin < std::max(m.threshold_compression, old.kappa_compression);
    const bool no_tensile_part =
        tensile_weight_old == 0.0 || estimate.largest_stress < -margin * m.young_modulus;
    if (no_growth && no_tensile_part) {
      const double factor =
          (1.0 - old.damage_compression) * (1.0 - m.stiffness_recovery * old.damage_tension);
      for (int k = 0; k < 6; ++k) next.stress[k] = factor * elastic[k];
      return detail::finish_concrete_step(old, step);
    }
    // Every principal effective stress clearly tensile (a cracked point opened at rest): then
    // C : e+ = sigma_e and the stress below is (1 - d_c)(1 - d_t) sigma_e without principal
    // directions (the same to round-off as the split through them).
    const double smallest_stress =
        m.lambda * (values_estimate[0] + values_estimate[1] + values_estimate[2]) +
        2.0 * m.shear_modulus * values_estimate[2];
    if (no_growth && smallest_stress > margin * m.young_modulus) {
      const double factor = (1.0 - old.damage_compression) * (1.0 - old.damage_tension);
      for (int k = 0; k < 6; ++k) next.stress[k] = factor * elastic[k];
      return detail::finish_concrete_step(old, step);
    }
  }

  // Closed form where the spectrum is well separated, the pair form near a repeated pair, Jacobi
  // for a zero deviator (principal.hpp).
  const SymmetricEigen eigen = symmetric_eigen_fast(strain_tensor, values_estimate);
  const detail::ConcreteMeasures measures = detail::concrete_measures(m, eigen.values);
  // "Tension first": above the tensile threshold the Mohr-Coulomb check is skipped.
  if (measures.tension > m.threshold_tension) {
    next.kappa_tension = std::max(old.kappa_tension, measures.tension);
  } else if (measures.shear > m.threshold_compression) {
    next.kappa_compression = std::max(old.kappa_compression, measures.shear);
  }
  const double stretch = concrete_crack_band_stretch(m, element_size);
  next.damage_tension =
      std::max(old.damage_tension, concrete_tension_damage(m, next.kappa_tension, stretch));
  next.damage_compression =
      std::max(old.damage_compression, concrete_compression_damage(m, next.kappa_compression));
  const double d_t = next.damage_tension, d_c = next.damage_compression;
  next.damage = std::max(old.damage, 1.0 - (1.0 - d_t) * (1.0 - d_c));
  if (d_t > 0.0 || d_c > 0.0)
    next.damage_type = d_t >= d_c ? DamageType::tension : DamageType::shear;

  // sigma = (1 - d_c) [(1 - s d_t) C : eps - (1 - s) d_t C : e+], with
  // C : e+ = <sigma_e>_+ + nu / (1 - 2 nu) (sum <s_i> - <tr sigma_e>) I.
  const double s = m.stiffness_recovery;
  for (int k = 0; k < 6; ++k) next.stress[k] = (1.0 - d_c) * (1.0 - s * d_t) * elastic[k];
  const double tensile_weight = (1.0 - d_c) * (1.0 - s) * d_t;
  if (tensile_weight > 0.0 && measures.positive_sum > 0.0) {
    const double hydrostatic =
        nu / (1.0 - 2.0 * nu) * (measures.positive_sum - measures.positive_trace);
    std::array<double, 3> tensile{};
    for (int i = 0; i < 3; ++i) tensile[i] = measures.positive[i] + hydrostatic;
    const Voigt tensile_stress = stress_voigt_from_principal(tensile, eigen.vectors);
    for (int k = 0; k < 6; ++k) next.stress[k] -= tensile_weight * tensile_stress[k];
  }
  return detail::finish_concrete_step(old, step);
}

/// The lining law in the element loop (material_law.hpp), law name "concrete_damage".
///
/// The law is secant in the strain measured from the stress-free state. The static stress
/// sigma0 of a point is that of the strain eps0 = C^-1 : sigma0, so the law is called with
/// eps0 + eps (eps the strain of the dynamic displacement): undamaged, its stress is
/// sigma0 + C : eps (to round-off of C C^-1), and both criteria see the total stress. Damage
/// scales the whole stress, the static part included. A sigma0 that already exceeds a criterion
/// is damaged by initial_state (one update from the stress-free state to eps0); the cell then
/// starts out of balance and releases the excess dynamically from t = 0.
///
/// Energy (material_law.hpp): the scheme's work of a step is w = 1/2 (sigma_c + sigma_t -
/// 2 sigma0) : d_eps. With W = 1/2 sigma : (eps0 + eps) (concrete_stored_energy),
///   psi = W - 1/2 sigma0 : eps0 - sigma0 : eps
/// (eps0 and 1/2 sigma0 : eps0 are the state's reference_strain and energy_offset; a rebase makes
/// them the committed total strain and its W, and sigma0 the committed stress)
/// is 0 at an admissible initial state and 1/2 eps : C : eps while undamaged. A step in which
/// damage grows sets psi to this closed form and delta = w - (psi_t - psi_c) (the law's
/// dissipation rewritten with sigma0); a step at fixed damage sets delta = 0 and psi_t = psi_c + w
/// (the closed form agrees up to round-off of the static energy and, in mixed tension-compression
/// after cracking, the second-order trapezoid error of the split; either would otherwise show as
/// dissipation of either sign without any damage).
struct ConcreteDamageLaw {
  static constexpr const char* kName = "concrete_damage";

  using Parameters = ConcreteDamageMaterial;

  struct State : ConcreteDamageState {  // strain: eps0 + eps of the last commit
    double stored = 0.0;                 // psi (J/m^3)
    Voigt reference_strain{};            // eps0: total strain at zero dynamic strain
    double energy_offset = 0.0;          // W at zero dynamic strain (1/2 sigma0 : eps0)
  };

  /// Keys: young_modulus, poisson_ratio, tensile_strength, cohesion (Pa), friction_angle (deg)
  /// required; fracture_energy (N/m, 120), A_t (1), B_t (5e4), A_c (1.4), B_c (1500),
  /// stiffness_recovery (0), damage_max (0.9999) optional (ConcreteDamageParameters).
  static Parameters parameters_from(const ParameterMap& parameters) {
    static constexpr const char* kKnown[] = {
        "young_modulus", "poisson_ratio", "tensile_strength", "cohesion",
        "friction_angle", "fracture_energy", "A_t", "B_t", "A_c", "B_c",
        "stiffness_recovery", "damage_max"};
    check_parameter_names(parameters, kName, kKnown);
    ConcreteDamageParameters p;
    p.young_modulus = required_parameter(parameters, kName, "young_modulus");
    p.poisson_ratio = required_parameter(parameters, kName, "poisson_ratio");
    p.tensile_strength = required_parameter(parameters, kName, "tensile_strength");
    p.cohesion = required_parameter(parameters, kName, "cohesion");
    p.friction_angle = required_parameter(parameters, kName, "friction_angle");
    p.fracture_energy = optional_parameter(parameters, "fracture_energy", p.fracture_energy);
    p.A_t = optional_parameter(parameters, "A_t", p.A_t);
    p.B_t = optional_parameter(parameters, "B_t", p.B_t);
    p.A_c = optional_parameter(parameters, "A_c", p.A_c);
    p.B_c = optional_parameter(parameters, "B_c", p.B_c);
    p.stiffness_recovery =
        optional_parameter(parameters, "stiffness_recovery", p.stiffness_recovery);
    p.damage_max = optional_parameter(parameters, "damage_max", p.damage_max);
    try {
      return concrete_damage_material(p);
    } catch (const std::invalid_argument& error) {
      throw std::invalid_argument(std::string("law concrete_damage: ") + error.what());
    }
  }

  static ElasticModuli elastic_moduli(const Parameters& m) { return {m.lambda, m.shear_modulus}; }

  static State initial_state(const Parameters& m, const double initial_stress[6],
                             double characteristic_length) {
    State state;
    const Voigt eps0 = static_strain(m, initial_stress);
    const ConcreteDamageStep step =
        concrete_damage_update(m, ConcreteDamageState{}, eps0, characteristic_length);
    static_cast<ConcreteDamageState&>(state) = step.state;
    state.reference_strain = eps0;
    state.energy_offset = 0.5 * stress_dot_strain(initial_stress, eps0.data());
    if (step.state.damage > 0.0) state.stored = step.stored_energy - state.energy_offset;
    return state;
  }

  /// The committed state as the zero of a new run (InternalForceComponent::rebase): its total
  /// strain becomes eps0, its W the offset, psi 0; stress, kappa and damage kept.
  static void rebase(const Parameters&, State& state) {
    state.reference_strain = state.strain;
    state.energy_offset = concrete_stored_energy(state);
    state.stored = 0.0;
  }

  static PointEnergy evaluate(const Parameters& m, const State& committed,
                              const PointStrain& point, State& trial) {
    const Voigt& eps0 = committed.reference_strain;
    Voigt strain;
    for (int c = 0; c < 6; ++c) strain[c] = eps0[c] + point.strain[c];
    const ConcreteDamageStep step =
        concrete_damage_update(m, committed, strain, point.characteristic_length);
    static_cast<ConcreteDamageState&>(trial) = step.state;
    trial.reference_strain = committed.reference_strain;
    trial.energy_offset = committed.energy_offset;
    double work = 0.0;
    for (int c = 0; c < 6; ++c)
      work += 0.5 * (committed.stress[c] + trial.stress[c] - 2.0 * point.initial_stress[c]) *
              (trial.strain[c] - committed.strain[c]);
    const bool damage_grew = trial.kappa_tension != committed.kappa_tension ||
                             trial.kappa_compression != committed.kappa_compression;
    return history_point_energy(damage_grew, work, committed.stored, step.stored_energy,
                                committed.energy_offset, point, trial.stored);
  }

  /// Damage 1 - (1 - d_t)(1 - d_c), its mechanism; no plastic strain (0); the crack strain
  /// d_t kappa_t: under the secant law sigma = (1 - d_t) E eps the inelastic strain is d_t eps, at
  /// its largest at eps = kappa_t. The crack band puts a crack's whole opening into one row of
  /// elements, so h d_t kappa_t is the largest opening the crack reached (it grows on after d_t
  /// saturates, which is what makes it a graded measure of a cracked-through lining).
  static PointOutput output(const State& state) {
    return {state.damage, static_cast<std::int32_t>(state.damage_type), 0.0,
            state.damage_tension * state.kappa_tension};
  }

 private:
  static Voigt static_strain(const Parameters& m, const double* initial_stress) {
    Voigt sigma0;
    for (int c = 0; c < 6; ++c) sigma0[c] = initial_stress[c];
    return isotropic_strain(m.young_modulus, m.poisson_ratio, sigma0);
  }
};

}  // namespace cavern
