// Rock: Mohr-Coulomb elastoplasticity with a Rankine tension cut-off and a scalar damage driven
// by the accumulated plastic strain, at one integration point (docs/materials.md; Zhao et al.
// 2021 Sec. 4.2 and Table 1; the paper's rock law is its reference [19], formulas not given).
//
// Conventions: small strain, 3D, Voigt [xx, yy, zz, xy, yz, xz] (principal.hpp): stresses hold
// tensor components, strains engineering shear. Tension positive, Pa. Principal stresses are
// ordered sigma_1 >= sigma_2 >= sigma_3 (sigma_3 the most compressive).
//
// Usage by an explicit integrator: keep the committed state of every point; per step call
// mohr_coulomb_update(material, old_state, strain_increment) for the trial; use step.state.stress
// for the internal force; commit (copy step.state over the old state) only when the step is
// accepted. The update is a pure function: nothing is written through its arguments.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

#include "material_law.hpp"
#include "principal.hpp"

namespace cavern {

/// User parameters of the rock law (the `[materials.X.plasticity]` table). Defaults: sandstone of
/// Zhao et al. 2021 Table 1. Angles in degrees as in the scene file.
struct MohrCoulombParameters {
  double young_modulus = 8.0e9;      // E (Pa), > 0
  double poisson_ratio = 0.24;       // nu, in (-1, 0.5)
  double cohesion = 1.10e6;          // c (Pa), >= 0 (> 0 when friction_angle = 0)
  double friction_angle = 42.0;      // phi (deg), in [0, 90)
  double dilation_angle = 0.0;       // psi (deg), in [0, phi]
  double tensile_strength = 1.95e6;  // t (Pa), >= 0; +inf or >= c cot(phi): no cut-off
  // Damage d = damage_max (1 - exp(-kappa / kappa_ref)), kappa the accumulated equivalent
  // plastic strain; stress = (1 - d) effective stress. damage_max = 0: no damage.
  // kappa_ref = damage_plastic_strain, or, with damage_plastic_displacement u_ref > 0, the crack
  // band's u_ref / h (h the cell's characteristic length, the cube root of its volume): the
  // softening then follows the plastic displacement across a band one cell wide, h kappa, and
  // the energy a softening band dissipates per unit area does not depend on the cell size.
  double damage_max = 0.9;                  // in [0, 1)
  double damage_plastic_strain = 0.005;     // kappa_ref, > 0
  double damage_plastic_displacement = 0.0;  // u_ref (m), >= 0; 0: kappa_ref the same in every cell
};

namespace detail {
/// A plane of the yield surface in principal stress space, N . s <= bound, with its flow
/// direction and D N (D the principal-space elasticity): mohr_coulomb.cpp's return mapping.
struct MohrCoulombPlane {
  std::array<double, 3> normal{};
  double bound = 0.0;
  std::array<double, 3> flow{};
  std::array<double, 3> elastic_flow{};  // D N, D = lambda 1 1^T + 2 G I
  double elastic_flow_norm = 0.0;        // |D N|
  bool tension = false;
};
/// The six Mohr-Coulomb planes, then the three Rankine ones when the cut-off or the apex needs
/// them (count 6 or 9); built once per material by mohr_coulomb_material.
struct MohrCoulombPlanes {
  std::array<MohrCoulombPlane, 9> planes{};
  int count = 6;
};
}  // namespace detail

/// Constants of the return mapping, computed once per region by mohr_coulomb_material().
struct MohrCoulombMaterial {
  double young_modulus, poisson_ratio;
  double lambda, shear_modulus;  // Lame constants (Pa)
  double sin_phi, sin_psi;       // friction and dilation
  double strength;               // k = 2 c cos(phi): M-C plane (s1 - s3) + (s1 + s3) sin(phi) = k
  double tensile_strength;       // min(t, apex): the Rankine planes s_i <= this
  bool tension_cutoff;           // t < apex: the Rankine planes cut the M-C pyramid
  double apex;                   // c cot(phi) (+inf for phi = 0)
  double damage_max, damage_plastic_strain, damage_plastic_displacement;
  detail::MohrCoulombPlanes planes;  // the yield surface's planes (a return mapping reads them)
};

/// Validates the parameters (throws std::invalid_argument naming the first bad one) and
/// precomputes the constants. A tensile strength t >= c cot(phi) cuts nothing off the
/// Mohr-Coulomb pyramid (Table 1 sandstone: t = 1.95 MPa > c cot(phi) = 1.22 MPa); it is then
/// lowered to the apex, where the Rankine planes only supply the volumetric plastic flow that
/// the apex return needs when psi = 0 (the M-C potential then has purely deviatoric flow).
MohrCoulombMaterial mohr_coulomb_material(const MohrCoulombParameters& parameters);

/// The damage's plastic strain scale kappa_ref at a point of characteristic length h (m):
/// damage_plastic_displacement / h with the crack band (u_ref > 0 and h > 0), else
/// damage_plastic_strain.
inline double damage_strain_scale(const MohrCoulombMaterial& m, double characteristic_length) {
  return m.damage_plastic_displacement > 0.0 && characteristic_length > 0.0
             ? m.damage_plastic_displacement / characteristic_length
             : m.damage_plastic_strain;
}

/// Per-integration-point state (owned by the caller, 22 doubles + type).
struct MohrCoulombState {
  Voigt stress{};              // nominal stress (1 - d) effective_stress (Pa), the force's stress
  Voigt effective_stress{};    // stress of the undamaged skeleton, on or inside the yield surface
  Voigt plastic_strain{};      // accumulated plastic strain (engineering shear)
  double kappa_tension = 0.0;  // accumulated equivalent plastic strain of the cut-off planes
  double kappa_shear = 0.0;    // accumulated equivalent plastic strain of the M-C planes
  double damage = 0.0;         // d in [0, damage_max], never decreases
  DamageType damage_type = DamageType::none;  // the mechanism with the larger kappa
};

/// The return region of a step: which yield planes were active (sigma_1 >= sigma_2 >= sigma_3).
enum class ReturnRegion : std::int32_t {
  elastic = 0,
  main_plane,                  // Mohr-Coulomb plane (1, 3)
  compression_edge,            // sigma_1 = sigma_2 (triaxial compression edge)
  extension_edge,              // sigma_2 = sigma_3 (triaxial extension edge)
  apex,                        // Mohr-Coulomb apex, sigma = c cot(phi) (no cut-off)
  tension_plane,               // sigma_1 = t
  tension_edge,                // sigma_1 = sigma_2 = t
  tension_apex,                // sigma_1 = sigma_2 = sigma_3 = t
  tension_shear_edge,          // sigma_1 = t on the M-C plane
  tension_compression_corner,  // sigma_1 = sigma_2 = t on the M-C plane
  tension_extension_corner,    // sigma_1 = t, sigma_2 = sigma_3 on the M-C plane
};

/// Result of one trial update: the candidate new state and the energy terms of the step.
struct MohrCoulombStep {
  MohrCoulombState state;
  double stored_energy = 0.0;  // W(new state) (J/m^3), mohr_coulomb_stored_energy
  double dissipation = 0.0;    // work of the step minus the change of W (J/m^3)
  ReturnRegion region = ReturnRegion::elastic;
  double kkt_residual = 0.0;  // largest violation of the return's conditions / stress scale
};

/// Stored (recoverable) energy density of a state (J/m^3):
///   W = (1 - d) 1/2 sigma_eff : C^-1 : sigma_eff
/// (Lemaitre's strain equivalence: the damaged stiffness is (1 - d) C).
double mohr_coulomb_stored_energy(const MohrCoulombMaterial& material,
                                  const MohrCoulombState& state);

/// Largest yield function of a principal stress triple (any order), Pa: the maximum over the six
/// Mohr-Coulomb planes (s_i - s_j) + (s_i + s_j) sin(phi) - 2 c cos(phi) and, with the cut-off,
/// the three Rankine planes s_i - t. <= 0 inside the elastic domain.
double mohr_coulomb_yield(const MohrCoulombMaterial& material,
                          const std::array<double, 3>& principal);

/// True when the stress (Voigt, tensor shear components) is certainly inside the yield surface
/// with a round-off margin, from an upper bound of mohr_coulomb_yield in the invariants p and
/// sqrt(J2) (no eigenvalues): the update's cheapest elastic screen. False says nothing.
/// Inline: it screens every point of every step.
inline bool elastic_by_invariants(const MohrCoulombMaterial& m, const Voigt& s) {
  // p the mean stress, r = sqrt(J2). The deviatoric principal values d1 >= d2 >= d3 obey
  // d1 - d3 <= 2 r, |d2| <= r / sqrt(3) and d1 <= 2 r / sqrt(3), so the worst M-C plane
  //   (s1 - s3) + (s1 + s3) sin(phi) - k = (d1 - d3) + (2 p - d2) sin(phi) - k
  //     <= (2 + sin(phi) / sqrt(3)) r - (k - 2 p sin(phi)),
  // and the cut-off s1 - t <= 2 / sqrt(3) r - (t - p). Both are compared squared (no root),
  // with a round-off margin of some ulps of the terms, far below the return's tolerance.
  constexpr double kInvRoot3 = 0.57735026918962576451;
  const double p = (s[0] + s[1] + s[2]) / 3.0;
  const double d0 = s[0] - p, d1 = s[1] - p, d2 = s[2] - p;
  const double J2 =
      (0.5 * (d0 * d0 + d1 * d1 + d2 * d2) + s[3] * s[3] + s[4] * s[4] + s[5] * s[5]) * (1.0 + 1e-12);
  const double margin = 1e-13 * (m.strength + 4.0 * std::abs(p));
  const double shear_room = m.strength - 2.0 * p * m.sin_phi - margin;
  const double shear_slope = 2.0 + kInvRoot3 * m.sin_phi;
  if (!(shear_room > 0.0 && shear_slope * shear_slope * J2 < shear_room * shear_room)) return false;
  if (std::isfinite(m.tensile_strength)) {
    const double tension_room = m.tensile_strength - p - margin;
    if (!(tension_room > 0.0 && (4.0 / 3.0) * J2 < tension_room * tension_room)) return false;
  }
  return true;
}

/// One strain-driven step of the rock law (pure: the old state is only read).
///   trial:    sigma_tr = sigma_eff,n + C : d_eps (clearly elastic trials are recognised by
///             elastic_by_invariants, then symmetric_eigenvalues_estimate, without
///             eigenvectors; a trial near the surface too when the estimate's spectrum is well
///             separated; the others take symmetric_eigen_fast: closed form, the pair form at
///             the edges)
///   return:   closed form in principal stresses, de Souza Neto, Peric & Owen (2008) Sec. 8.2 and
///             Box 8.5 (main plane, both edges, apex), extended by the Rankine planes
///             s_i <= t and their corners with the M-C plane. Each candidate set of active planes
///             A gives sigma = sigma_tr - sum_{a in A} dgamma_a D N_a with every plane of A
///             satisfied; the first candidate with all dgamma_a >= 0 and all nine planes
///             satisfied (relative tolerance 1e-12) is accepted. Flow N_a from the plastic
///             potential with psi in place of phi (non-associated); Rankine flow associated.
///   plastic:  d_eps_p = C^-1 : (sigma_tr - sigma_eff,n+1), coaxial with the trial.
///   damage:   kappa += sqrt(2/3) |d_eps_p| (split into tension and shear by the active planes),
///             d = max(d_n, d_max (1 - exp(-(kappa_t + kappa_s) / kappa_ref))), kappa_ref =
///             damage_strain_scale(material, characteristic_length) (0: no crack band),
///             sigma_n+1 = (1 - d) sigma_eff,n+1.
///   energy:   dissipation = 1/2 (sigma_n + sigma_n+1) : d_eps - (W_n+1 - W_n), so that
///             W + dissipation equals the trapezoid work of an explicit integrator exactly; it
///             equals sigma_avg : d_eps_p + plastic and damage terms (>= 0 for the small steps
///             of explicit dynamics; see docs/materials.md).
/// strain_increment: engineering shear.
MohrCoulombStep mohr_coulomb_update(const MohrCoulombMaterial& material,
                                    const MohrCoulombState& old_state,
                                    const Voigt& strain_increment,
                                    double characteristic_length = 0.0);

/// mohr_coulomb_update after its first screen: trial_effective_stress = old.effective_stress +
/// C : strain_increment, for which elastic_by_invariants was false (the same result as
/// mohr_coulomb_update, without computing the trial and the screen twice).
MohrCoulombStep mohr_coulomb_update_screened(const MohrCoulombMaterial& material,
                                             const MohrCoulombState& old_state,
                                             const Voigt& strain_increment,
                                             const Voigt& trial_effective_stress,
                                             double characteristic_length = 0.0);

/// The rock law in the element loop (material_law.hpp), law name "mohr_coulomb".
///
/// The law is incremental; the loop gives the total strain eps of the dynamic displacement, so
/// the state keeps the committed eps and each step hands the law d_eps = eps_trial -
/// eps_committed. The static stress sigma0 is the initial stress (and effective stress) of the
/// state, so the strength is checked against the total stress sigma0 + C : (eps - eps_p) (times
/// 1 - d). A sigma0 outside the yield surface is returned to it by initial_state (one return
/// from sigma0 as the trial, plastic strain and damage kept); the cell then starts out of
/// balance and the excess is released dynamically from t = 0.
///
/// Energy (material_law.hpp): the scheme's work of a step is w = 1/2 (sigma_c + sigma_t -
/// 2 sigma0) : d_eps. With W the law's stored energy (mohr_coulomb_stored_energy),
///   psi = W - W(sigma0) - sigma0 : eps,   W(sigma0) = 1/2 sigma0 : C^-1 : sigma0
/// (after a rebase, sigma0 is the committed stress and W(sigma0) the W of that state: the
/// state's energy_offset),
/// is 0 at an admissible initial state and 1/2 eps : C : eps while elastic. A plastic step sets
/// psi to this closed form and delta = w - (psi_t - psi_c) (mohr_coulomb_update's dissipation,
/// W_t - W_c + delta = 1/2 (sigma_c + sigma_t) : d_eps, rewritten with sigma0). An elastic step
/// sets delta = 0 and psi_t = psi_c + w: the closed form would give the same up to round-off of
/// W(sigma0) (geostatic W is large next to the dynamic energy), which would show as dissipation
/// noise of either sign in elastic runs.
struct MohrCoulombLaw {
  static constexpr const char* kName = "mohr_coulomb";

  using Parameters = MohrCoulombMaterial;

  struct State : MohrCoulombState {
    Voigt strain{};       // committed total strain of the dynamic displacement (engineering shear)
    double stored = 0.0;  // psi (J/m^3)
    double energy_offset = 0.0;  // W at zero strain: W(sigma0) at construction, W at a rebase
  };

  /// Keys: young_modulus, poisson_ratio (Pa, -), cohesion (Pa), friction_angle (deg),
  /// tensile_strength (Pa; a value >= c cot(phi), or inf, cuts nothing off) required;
  /// dilation_angle (deg, default 0), damage_max (0.9), damage_plastic_strain (0.005),
  /// damage_plastic_displacement (m, 0: no crack band) optional (MohrCoulombParameters). Ranges
  /// as mohr_coulomb_material.
  static Parameters parameters_from(const ParameterMap& parameters) {
    static constexpr const char* kKnown[] = {
        "young_modulus",  "poisson_ratio",    "cohesion",   "friction_angle",
        "dilation_angle", "tensile_strength", "damage_max", "damage_plastic_strain",
        "damage_plastic_displacement"};
    check_parameter_names(parameters, kName, kKnown);
    MohrCoulombParameters p;
    p.young_modulus = required_parameter(parameters, kName, "young_modulus");
    p.poisson_ratio = required_parameter(parameters, kName, "poisson_ratio");
    p.cohesion = required_parameter(parameters, kName, "cohesion");
    p.friction_angle = required_parameter(parameters, kName, "friction_angle");
    p.tensile_strength = required_parameter(parameters, kName, "tensile_strength");
    p.dilation_angle = optional_parameter(parameters, "dilation_angle", 0.0);
    p.damage_max = optional_parameter(parameters, "damage_max", p.damage_max);
    p.damage_plastic_strain =
        optional_parameter(parameters, "damage_plastic_strain", p.damage_plastic_strain);
    p.damage_plastic_displacement = optional_parameter(parameters, "damage_plastic_displacement",
                                                       p.damage_plastic_displacement);
    try {
      return mohr_coulomb_material(p);
    } catch (const std::invalid_argument& error) {
      throw std::invalid_argument(std::string("law mohr_coulomb: ") + error.what());
    }
  }

  static ElasticModuli elastic_moduli(const Parameters& m) { return {m.lambda, m.shear_modulus}; }

  static State initial_state(const Parameters& m, const double initial_stress[6],
                             double characteristic_length) {
    State state;
    for (int c = 0; c < 6; ++c) state.stress[c] = state.effective_stress[c] = initial_stress[c];
    // A zero increment: sigma0 itself when admissible (bit for bit), else its return.
    const MohrCoulombStep step = mohr_coulomb_update(m, state, Voigt{}, characteristic_length);
    Voigt sigma0;
    for (int c = 0; c < 6; ++c) sigma0[c] = initial_stress[c];
    state.energy_offset = isotropic_complementary_energy(m.young_modulus, m.poisson_ratio, sigma0);
    if (step.region != ReturnRegion::elastic) {
      static_cast<MohrCoulombState&>(state) = step.state;
      state.stored = step.stored_energy - state.energy_offset;
    }
    return state;
  }

  /// The committed state as the zero of a new run (InternalForceComponent::rebase): strain 0,
  /// psi 0, the closed form's offset W of the state; stress, plastic strain, damage kept.
  static void rebase(const Parameters& m, State& state) {
    state.strain = Voigt{};
    state.stored = 0.0;
    state.energy_offset = mohr_coulomb_stored_energy(m, state);
  }

  static PointEnergy evaluate(const Parameters& m, const State& committed,
                              const PointStrain& point, State& trial) {
    Voigt increment, sigma0;
    for (int c = 0; c < 6; ++c) {
      increment[c] = point.strain[c] - committed.strain[c];
      sigma0[c] = point.initial_stress[c];
    }
    // Most points of a seismic run pass mohr_coulomb_update's first screen: the same trial,
    // written straight into the trial state (the same bits as the update's elastic result),
    // without the update's stored-energy terms, which an elastic step does not use.
    const Voigt stress_increment = isotropic_stress(m.lambda, m.shear_modulus, increment);
    Voigt trial_effective;
    for (int c = 0; c < 6; ++c)
      trial_effective[c] = committed.effective_stress[c] + stress_increment[c];
    if (elastic_by_invariants(m, trial_effective)) {
      trial = committed;
      trial.effective_stress = trial_effective;
      double work = 0.0;
      for (int c = 0; c < 6; ++c) {
        trial.stress[c] = (1.0 - committed.damage) * trial_effective[c];
        trial.strain[c] = point.strain[c];
        work += 0.5 * (committed.stress[c] + trial.stress[c] - 2.0 * sigma0[c]) * increment[c];
      }
      return history_point_energy(false, work, committed.stored, 0.0, committed.energy_offset,
                                  point, trial.stored);
    }
    const MohrCoulombStep step = mohr_coulomb_update_screened(m, committed, increment,
                                                              trial_effective,
                                                              point.characteristic_length);
    static_cast<MohrCoulombState&>(trial) = step.state;
    trial.energy_offset = committed.energy_offset;
    double work = 0.0;
    for (int c = 0; c < 6; ++c) {
      trial.strain[c] = point.strain[c];
      work += 0.5 * (committed.stress[c] + trial.stress[c] - 2.0 * sigma0[c]) * increment[c];
    }
    return history_point_energy(step.region != ReturnRegion::elastic, work, committed.stored,
                                step.stored_energy, committed.energy_offset, point, trial.stored);
  }

  /// Damage d, its mechanism, and kappa_t + kappa_s (sqrt(2/3) sum |d eps_p|).
  static PointOutput output(const State& state) {
    return {state.damage, static_cast<std::int32_t>(state.damage_type),
            state.kappa_tension + state.kappa_shear};
  }
};

}  // namespace cavern
