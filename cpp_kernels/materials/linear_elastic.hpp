// Linear isotropic elasticity as a material law (material_law.hpp): the law of the stiffness
// matrix, for a region run through the element loop (exactness test of the loop, reference
// for the nonlinear laws).
#pragma once

#include <cmath>
#include <stdexcept>
#include <string>

#include "material_law.hpp"

namespace cavern {

/// sigma = sigma0 + lambda tr(eps) I + 2 G eps,  psi = 1/2 (sigma - sigma0) : eps,  delta = 0.
struct LinearElastic {
  static constexpr const char* kName = "linear_elastic";

  struct Parameters {
    double lame_lambda = 0.0;    // (Pa)
    double shear_modulus = 0.0;  // G (Pa), > 0
  };

  struct State {
    double stress[6];  // total stress (Pa)
  };

  static Parameters parameters_from(const ParameterMap& parameters) {
    static constexpr const char* kKnown[] = {"lame_lambda", "shear_modulus"};
    check_parameter_names(parameters, kName, kKnown);
    Parameters result;
    result.lame_lambda = required_parameter(parameters, kName, "lame_lambda");
    result.shear_modulus = required_parameter(parameters, kName, "shear_modulus");
    if (!(std::isfinite(result.shear_modulus) && result.shear_modulus > 0.0))
      throw std::invalid_argument("law linear_elastic: shear_modulus must be finite and > 0, got " +
                                  std::to_string(result.shear_modulus));
    // Positive definite C: bulk modulus lambda + 2/3 G > 0.
    if (!(std::isfinite(result.lame_lambda) &&
          result.lame_lambda + 2.0 / 3.0 * result.shear_modulus > 0.0))
      throw std::invalid_argument(
          "law linear_elastic: lame_lambda must be finite with lambda + 2/3 G > 0, got " +
          std::to_string(result.lame_lambda));
    return result;
  }

  static ElasticModuli elastic_moduli(const Parameters& parameters) {
    return {parameters.lame_lambda, parameters.shear_modulus};
  }

  static State initial_state(const Parameters&, const double initial_stress[6],
                             double /*characteristic_length*/) {
    State state;
    for (int c = 0; c < 6; ++c) state.stress[c] = initial_stress[c];
    return state;
  }

  static PointEnergy evaluate(const Parameters& parameters, const State& /*committed*/,
                              const PointStrain& point, State& trial) {
    const double* eps = point.strain;
    const double* sigma0 = point.initial_stress;
    const double lambda_trace = parameters.lame_lambda * (eps[0] + eps[1] + eps[2]);
    const double two_G = 2.0 * parameters.shear_modulus;
    double dynamic[6];
    for (int c = 0; c < 3; ++c) dynamic[c] = lambda_trace + two_G * eps[c];
    for (int c = 3; c < 6; ++c) dynamic[c] = parameters.shear_modulus * eps[c];  // G gamma
    for (int c = 0; c < 6; ++c) trial.stress[c] = sigma0[c] + dynamic[c];
    PointEnergy energy;
    energy.stored = 0.5 * stress_dot_strain(dynamic, eps);
    return energy;
  }

  /// A rebase (InternalForceComponent::rebase) keeps the stress, which becomes sigma0.
  static void rebase(const Parameters&, State&) {}

  static PointOutput output(const State&) { return {}; }
};

}  // namespace cavern
