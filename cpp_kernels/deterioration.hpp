// Seismic deterioration of the interlayer strength, D(t) = eta(t) gamma(t) (paper Sec. 2,
// Eqs. 8-11): wear by cyclic shearing (eta) times the loss of strength with slip rate (gamma).
#pragma once

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace cavern {

/// Parameters of Eqs. 9-10 (paper values R0 = 0.75, lambda = 5, m = 0.883, n = 0.02, p = 0.032).
struct DeteriorationParameters {
  double R0 = 1.0;        // limit of eta after the earthquake, (0, 1]
  double lambda = 0.0;    // decay rate of eta per earthquake duration, >= 0
  double duration = 1.0;  // t_s, earthquake duration (s), > 0
  double m = 1.0;         // gamma scale, > 0
  double n = 1.0;         // slip-rate offset (m/s), > 0 (keeps gamma finite at zero slip rate)
  double p = 0.0;         // slip-rate exponent, >= 0
  double start = 0.0;     // stepper time (s) at which the earthquake's clock t of Eq. 9 starts
                          // (the record window's start, after the filter's lead-in), finite
};

/// Throws std::invalid_argument naming the first parameter outside its allowed range.
inline void check_deterioration(const DeteriorationParameters& d) {
  auto require = [](bool ok, const char* name, double value, const char* allowed) {
    if (!ok)
      throw std::invalid_argument(std::string(name) + " = " + std::to_string(value) + " must be " +
                                  allowed);
  };
  require(std::isfinite(d.R0) && d.R0 > 0.0 && d.R0 <= 1.0, "R0", d.R0, "in (0, 1]");
  require(std::isfinite(d.lambda) && d.lambda >= 0.0, "lam", d.lambda, "finite and >= 0");
  require(std::isfinite(d.duration) && d.duration > 0.0, "duration", d.duration,
          "finite and > 0 (s)");
  require(std::isfinite(d.m) && d.m > 0.0, "m", d.m, "finite and > 0");
  require(std::isfinite(d.n) && d.n > 0.0, "n", d.n, "finite and > 0 (m/s)");
  require(std::isfinite(d.p) && d.p >= 0.0, "p", d.p, "finite and >= 0");
  require(std::isfinite(d.start), "start", d.start, "finite (s)");
}

/// Wear factor (Eq. 9): eta = R0 + (1 - R0) exp(-lambda t_e / t_s), t_e = t - start the time
/// since the earthquake's start, clamped at 0 so that a state before it (the static state, the
/// filter's lead-in) is unworn. The wear runs on time, not on shaking: an interface at its limit
/// slides as eta falls even where nothing moves (docs/method.md section 9).
inline double wear_factor(const DeteriorationParameters& d, double t) {
  return d.R0 + (1.0 - d.R0) * std::exp(-d.lambda * std::max(t - d.start, 0.0) / d.duration);
}

/// Slip-rate factor (Eq. 10): gamma = m (|dv_t| + n)^(-p), dv_t the relative tangential
/// velocity of the pair (m/s).
inline double slip_rate_factor(const DeteriorationParameters& d, double slip_rate) {
  return d.m * std::pow(std::abs(slip_rate) + d.n, -d.p);
}

/// Deterioration coefficient (Eq. 11): D(t) = eta(t) gamma(dv_t).
inline double deterioration(const DeteriorationParameters& d, double t, double slip_rate) {
  return wear_factor(d, t) * slip_rate_factor(d, slip_rate);
}

}  // namespace cavern
