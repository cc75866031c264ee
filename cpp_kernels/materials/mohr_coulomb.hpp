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
#include <cstdint>

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
  // Damage d = damage_max (1 - exp(-kappa / damage_plastic_strain)), kappa the accumulated
  // equivalent plastic strain; stress = (1 - d) effective stress. damage_max = 0: no damage.
  double damage_max = 0.9;               // in [0, 1)
  double damage_plastic_strain = 0.005;  // kappa_ref, > 0
};

/// Constants of the return mapping, computed once per region by mohr_coulomb_material().
struct MohrCoulombMaterial {
  double young_modulus, poisson_ratio;
  double lambda, shear_modulus;  // Lame constants (Pa)
  double sin_phi, sin_psi;       // friction and dilation
  double strength;               // k = 2 c cos(phi): M-C plane (s1 - s3) + (s1 + s3) sin(phi) = k
  double tensile_strength;       // min(t, apex): the Rankine planes s_i <= this
  bool tension_cutoff;           // t < apex: the Rankine planes cut the M-C pyramid
  double apex;                   // c cot(phi) (+inf for phi = 0)
  double damage_max, damage_plastic_strain;
};

/// Validates the parameters (throws std::invalid_argument naming the first bad one) and
/// precomputes the constants. A tensile strength t >= c cot(phi) cuts nothing off the
/// Mohr-Coulomb pyramid (Table 1 sandstone: t = 1.95 MPa > c cot(phi) = 1.22 MPa); it is then
/// lowered to the apex, where the Rankine planes only supply the volumetric plastic flow that
/// the apex return needs when psi = 0 (the M-C potential then has purely deviatoric flow).
MohrCoulombMaterial mohr_coulomb_material(const MohrCoulombParameters& parameters);

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

/// One strain-driven step of the rock law (pure: the old state is only read).
///   trial:    sigma_tr = sigma_eff,n + C : d_eps (clearly elastic trials are recognised from
///             symmetric_eigenvalues_estimate without the Jacobi decomposition)
///   return:   closed form in principal stresses, de Souza Neto, Peric & Owen (2008) Sec. 8.2 and
///             Box 8.5 (main plane, both edges, apex), extended by the Rankine planes
///             s_i <= t and their corners with the M-C plane. Each candidate set of active planes
///             A gives sigma = sigma_tr - sum_{a in A} dgamma_a D N_a with every plane of A
///             satisfied; the first candidate with all dgamma_a >= 0 and all nine planes
///             satisfied (relative tolerance 1e-12) is accepted. Flow N_a from the plastic
///             potential with psi in place of phi (non-associated); Rankine flow associated.
///   plastic:  d_eps_p = C^-1 : (sigma_tr - sigma_eff,n+1), coaxial with the trial.
///   damage:   kappa += sqrt(2/3) |d_eps_p| (split into tension and shear by the active planes),
///             d = max(d_n, d_max (1 - exp(-(kappa_t + kappa_s) / kappa_ref))),
///             sigma_n+1 = (1 - d) sigma_eff,n+1.
///   energy:   dissipation = 1/2 (sigma_n + sigma_n+1) : d_eps - (W_n+1 - W_n), so that
///             W + dissipation equals the trapezoid work of an explicit integrator exactly; it
///             equals sigma_avg : d_eps_p + plastic and damage terms (>= 0 for the small steps
///             of explicit dynamics; see docs/materials.md).
/// strain_increment: engineering shear.
MohrCoulombStep mohr_coulomb_update(const MohrCoulombMaterial& material,
                                    const MohrCoulombState& old_state,
                                    const Voigt& strain_increment);

}  // namespace cavern
