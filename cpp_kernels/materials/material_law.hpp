// What an element loop hands a material law at one integration point, and what it gets back
// (internal_force.hpp runs the loop; one header per law in this directory).
//
// A law is a struct with
//   struct Parameters { ... };                       // constants of one region
//   struct State { Voigt stress; ... };   // per point, trivially copyable; stress[c] (total, Pa)
//   static constexpr const char* kName;              // the name Python selects it by
//   static Parameters parameters_from(const ParameterMap&);   // throws std::invalid_argument
//   static State initial_state(const Parameters&, const double initial_stress[6],
//                              double characteristic_length);
//   static ElasticModuli elastic_moduli(const Parameters&);   // initial (undamaged) moduli
//   static PointEnergy evaluate(const Parameters&, const State& committed,
//                               const PointStrain& point, State& trial);
//   static PointOutput output(const State&);        // damage, its type, plastic, crack strain
//   static void rebase(const Parameters&, State&);   // the state as the zero strain of a new run
// initial_state is the state at zero dynamic strain. Its stress is sigma0 when sigma0 is
// admissible; a law with a strength returns a sigma0 that violates it to the yield surface (or
// damages it) there, so the cell starts out of balance and releases the excess dynamically
// from t = 0 (the static state was not one this strength can carry). The characteristic length
// is that of PointStrain (the crack band of a damage that starts at the initial state).
// evaluate computes the trial state at the total strain of `point` from the committed state and
// writes nothing else: it is called concurrently for different points, again for the same
// step (reset_energy computes without committing) and its trial is committed only when the
// step is accepted. It must be deterministic (no static or thread-local scratch).
//
// Conventions (those of principal.hpp): symmetric tensors are 6 numbers in the Voigt order xx,
// yy, zz, xy, yz, xz (as the monitor columns); stresses hold tensor components, strains
// ENGINEERING shear (gamma_xy = 2 eps_xy), so sigma : eps is the plain 6-term dot product
// (stress_dot_strain). Stress is total: it includes the static stress sigma0 of the point; the
// element force uses sigma - sigma0 (sigma0 is in equilibrium with loads outside the dynamic
// problem). Strain is that of the dynamic displacement u (zero at sigma0). Tension positive, SI.
//
// Energy the stepper's balance needs (stepper.hpp): per point and step, the scheme does the
// internal work w = 1/2 (sigma_c + sigma_t - 2 sigma0) : (eps_t - eps_c) (c committed, t trial;
// times the point's weight). The balance closes to round-off when the law's stored energy psi
// and dissipation increment delta satisfy psi_t - psi_c + delta = w. Defining
// delta = w - (psi_t - psi_c) satisfies it by construction (mohr_coulomb.hpp does so); a law
// with its own delta shows its energy error in the balance (e.g. delta = sigma_t : d eps_p is
// off by 1/2 (sigma_t - sigma_c) : d eps_p per step). Closed forms that satisfy it:
//   elastic:      psi = 1/2 eps : C : eps, delta = 0;
//   elastoplastic (sigma = sigma0 + C : (eps - eps_p)):
//                 psi = 1/2 (eps - eps_p) : C : (eps - eps_p) - sigma0 : eps_p,
//                 delta = 1/2 (sigma_c + sigma_t) : (eps_p,t - eps_p,c)   (trapezoid, not
//                 sigma_t : d eps_p, which is off by 1/2 (sigma_t - sigma_c) : d eps_p);
//   scalar damage (sigma = sigma0 + (1 - d) C : eps):
//                 psi = 1/2 (1 - d) eps : C : eps, delta = (d_t - d_c) 1/2 eps_c : C : eps_t.
// The "- sigma0 : eps_p" term is the static stress's work released by plastic flow (the static
// loads are not in the dynamic problem).
#pragma once

#include <cmath>
#include <cstdint>
#include <map>
#include <stdexcept>
#include <string>

namespace cavern {

/// Index of each component in the 6-vector of a symmetric tensor.
enum TensorComponent : int { kXX = 0, kYY = 1, kZZ = 2, kXY = 3, kYZ = 4, kXZ = 5 };

/// Named parameters of a law as Python gives them (SI units).
using ParameterMap = std::map<std::string, double>;

/// What the element loop gives the law at one integration point (all borrowed).
struct PointStrain {
  const double* strain = nullptr;          // (6) total small strain of u, engineering shear
  const double* initial_stress = nullptr;  // (6) static stress sigma0 (Pa), zeros without one
  double characteristic_length = 0.0;      // (m) cube root of the cell volume (crack band)
};

/// Isotropic elastic moduli (Pa): the initial stiffness of a law, which stiffness-proportional
/// damping uses.
struct ElasticModuli {
  double lame_lambda = 0.0;
  double shear_modulus = 0.0;
};

/// What a law reports of a committed state (monitors, fields, run.json).
struct PointOutput {
  double damage = 0.0;            // scalar damage d in [0, 1)
  std::int32_t damage_type = 0;   // 0 none, 1 tension, 2 shear (principal.hpp DamageType)
  double plastic_strain = 0.0;    // equivalent plastic strain sqrt(2/3) sum |d eps_p| (-)
  double crack_strain = 0.0;      // tensile crack strain at its largest (-): the inelastic part
                                  // d_t kappa_t of the tensile equivalent strain; times the
                                  // crack band's width h, the crack's opening (0 without cracks)
};

/// Energy densities of a trial state (J/m^3).
struct PointEnergy {
  double stored = 0.0;       // psi at the trial state
  double dissipation = 0.0;  // delta from the committed to the trial state, >= 0
};

/// sigma : eps of a stress (tensor components) and a strain (engineering shear), Voigt order.
inline double stress_dot_strain(const double* sigma, const double* eps) {
  return sigma[0] * eps[0] + sigma[1] * eps[1] + sigma[2] * eps[2] + sigma[3] * eps[3] +
         sigma[4] * eps[4] + sigma[5] * eps[5];
}

/// psi_t and delta of a trial point by the rule above, for a law with a closed-form stored energy
/// W (Lemaitre: W of the state's elastic part) and psi = W - W_offset - sigma0 : eps:
///   history unchanged (no plastic flow, no damage growth): psi_t = psi_c + w, delta = 0;
///   otherwise: psi_t = W_t - W_offset - sigma0 : eps, delta = w - (psi_t - psi_c).
/// W_offset is the W of the state at zero strain (W(sigma0) at construction, W at a rebase).
/// Writes psi_t into trial_stored and returns both.
inline PointEnergy history_point_energy(bool history_changed, double work, double committed_stored,
                                        double trial_W, double energy_offset,
                                        const PointStrain& point, double& trial_stored) {
  PointEnergy energy;
  if (!history_changed) {
    trial_stored = committed_stored + work;
  } else {
    trial_stored =
        trial_W - energy_offset - stress_dot_strain(point.initial_stress, point.strain);
    energy.dissipation = work - (trial_stored - committed_stored);
  }
  energy.stored = trial_stored;
  return energy;
}

/// The value of `key` in `parameters`; throws std::invalid_argument naming the law and the key.
/// Throws std::invalid_argument "NAME = VALUE must be ALLOWED" unless ok (a law's parameter check).
inline void require_parameter(bool ok, const char* name, double value, const char* allowed) {
  if (!ok)
    throw std::invalid_argument(std::string(name) + " = " + std::to_string(value) + " must be " +
                                allowed);
}

/// Lame's constants of isotropic elasticity: lambda = E nu / ((1 + nu)(1 - 2 nu)), G = E / (2 (1 + nu)) (Pa).
struct LameConstants {
  double lambda = 0.0;
  double shear_modulus = 0.0;
};
inline LameConstants lame_constants(double young_modulus, double poisson_ratio) {
  return {young_modulus * poisson_ratio / ((1.0 + poisson_ratio) * (1.0 - 2.0 * poisson_ratio)),
          young_modulus / (2.0 * (1.0 + poisson_ratio))};
}

/// The elastic constants every law checks: E finite > 0 (Pa), nu in (-1, 0.5).
inline void require_elastic_constants(double young_modulus, double poisson_ratio) {
  require_parameter(std::isfinite(young_modulus) && young_modulus > 0.0, "young_modulus", young_modulus,
                    "finite and > 0 (Pa)");
  require_parameter(std::isfinite(poisson_ratio) && poisson_ratio > -1.0 && poisson_ratio < 0.5,
                    "poisson_ratio", poisson_ratio, "in (-1, 0.5)");
}

inline double required_parameter(const ParameterMap& parameters, const char* law, const char* key) {
  const auto found = parameters.find(key);
  if (found == parameters.end())
    throw std::invalid_argument(std::string("law ") + law + ": parameter '" + key + "' missing");
  return found->second;
}

/// The value of `key` in `parameters`, or `fallback` when it is not given.
inline double optional_parameter(const ParameterMap& parameters, const char* key,
                                 double fallback) {
  const auto found = parameters.find(key);
  return found == parameters.end() ? fallback : found->second;
}

/// Throws std::invalid_argument naming the first key of `parameters` not in `known`.
template <std::size_t N>
void check_parameter_names(const ParameterMap& parameters, const char* law,
                           const char* const (&known)[N]) {
  for (const auto& [key, value] : parameters) {
    bool found = false;
    for (const char* name : known) found = found || key == name;
    if (!found) {
      std::string allowed;
      for (const char* name : known) allowed += std::string(allowed.empty() ? "" : ", ") + name;
      throw std::invalid_argument(std::string("law ") + law + ": unknown parameter '" + key +
                                  "' (allowed: " + allowed + ")");
    }
  }
}

}  // namespace cavern
