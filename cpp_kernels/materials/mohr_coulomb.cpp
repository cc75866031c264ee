// Mohr-Coulomb return mapping with tension cut-off in principal stresses (mohr_coulomb.hpp).
#include "materials/mohr_coulomb.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace cavern {

namespace {

constexpr double kPi = 3.14159265358979323846;
// Relative tolerance of the return's conditions (planes satisfied, multipliers non-negative):
// some thousands of ulps of the stress scale, so that round-off never rejects the right candidate
// at a sector boundary and a wrongly accepted candidate is within 1e-12 of the right one (the
// return map is continuous).
constexpr double kTolerance = 1e-12;

using Vector3 = std::array<double, 3>;

double dot(const Vector3& a, const Vector3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
double norm(const Vector3& a) { return std::sqrt(dot(a, a)); }

// A yield plane n . sigma <= bound in principal stress space with plastic flow direction N.
using Plane = detail::MohrCoulombPlane;

// Planes in the order used by the candidates: Mohr-Coulomb (i, j) for the sorted principal
// stresses, then the Rankine planes. kMC01 etc. name them by (i, j).
enum PlaneIndex { kMC02 = 0, kMC12, kMC01, kMC10, kMC20, kMC21, kR0, kR1, kR2, kPlaneCount };

using PlaneSet = detail::MohrCoulombPlanes;

PlaneSet make_planes(const MohrCoulombMaterial& m) {
  PlaneSet set;
  const double sp = m.sin_phi, sd = m.sin_psi;
  const int pairs[6][2] = {{0, 2}, {1, 2}, {0, 1}, {1, 0}, {2, 0}, {2, 1}};
  for (int a = 0; a < 6; ++a) {
    Plane& plane = set.planes[a];
    const int i = pairs[a][0], j = pairs[a][1];
    // (s_i - s_j) + (s_i + s_j) sin(phi) <= 2 c cos(phi); flow with sin(psi).
    plane.normal[i] = 1.0 + sp;
    plane.normal[j] = -(1.0 - sp);
    plane.bound = m.strength;
    plane.flow[i] = 1.0 + sd;
    plane.flow[j] = -(1.0 - sd);
  }
  set.count = 6;
  // Rankine planes s_i <= t: the cut-off, or (t >= apex) three planes through the apex that
  // change no elastic state but give the apex the volumetric flow the M-C potential lacks at
  // psi = 0.
  if (std::isfinite(m.tensile_strength)) {
    for (int i = 0; i < 3; ++i) {
      Plane& plane = set.planes[kR0 + i];
      plane.normal[i] = 1.0;
      plane.bound = m.tensile_strength;
      plane.flow[i] = 1.0;
      plane.tension = true;
    }
    set.count = 9;
  }
  for (int a = 0; a < set.count; ++a) {
    Plane& plane = set.planes[a];
    const double volumetric = m.lambda * (plane.flow[0] + plane.flow[1] + plane.flow[2]);
    for (int i = 0; i < 3; ++i)
      plane.elastic_flow[i] = volumetric + 2.0 * m.shear_modulus * plane.flow[i];
    plane.elastic_flow_norm = norm(plane.elastic_flow);
  }
  return set;
}

// A candidate set of active planes. A point candidate (three or more planes meeting in one
// point) carries the point itself, known in closed form.
struct Candidate {
  ReturnRegion region;
  std::array<int, kPlaneCount> planes;
  int count;
  bool is_point;
  Vector3 point;
};

struct Return {
  Vector3 stress{};
  std::array<double, kPlaneCount> multiplier{};  // dgamma per plane (0 when inactive)
  double violation = std::numeric_limits<double>::infinity();
};

double plane_value(const Plane& plane, const Vector3& s) {
  return dot(plane.normal, s) - plane.bound;
}

// Largest violation, relative to scale, of "all planes satisfied, all multipliers >= 0". The
// multipliers of the planes outside `active` are zero and add nothing; the maximum is taken before
// the one division (division by scale > 0 keeps the order, so the same value as dividing each term).
double violation_of(const PlaneSet& set, const Return& r, const int* active, int count,
                    double scale) {
  double worst = 0.0;
  for (int a = 0; a < set.count; ++a) worst = std::max(worst, plane_value(set.planes[a], r.stress));
  for (int b = 0; b < count; ++b) {
    const int a = active[b];
    worst = std::max(worst, -r.multiplier[a] * set.planes[a].elastic_flow_norm);
  }
  return worst / scale;
}

// The yield function (mohr_coulomb_yield) of sorted principal stresses s0 >= s1 >= s2: the largest
// Mohr-Coulomb plane is then (0, 2) and the largest cut-off plane s0's.
double sorted_yield(const MohrCoulombMaterial& m, const Vector3& s) {
  double worst = (s[0] - s[2]) + (s[0] + s[2]) * m.sin_phi - m.strength;
  if (std::isfinite(m.tensile_strength)) worst = std::max(worst, s[0] - m.tensile_strength);
  return worst;
}

// Solves the m x m system (m <= 3) J x = b by Cramer's rule; false when J is singular relative
// to the size of its columns.
bool solve_small(int m, const double J[3][3], const double b[3], double x[3]) {
  if (m == 1) {
    if (J[0][0] == 0.0) return false;
    x[0] = b[0] / J[0][0];
    return true;
  }
  if (m == 2) {
    const double det = J[0][0] * J[1][1] - J[0][1] * J[1][0];
    const double size = std::hypot(J[0][0], J[1][0]) * std::hypot(J[0][1], J[1][1]);
    if (!(std::abs(det) > 1e-12 * size)) return false;
    x[0] = (b[0] * J[1][1] - J[0][1] * b[1]) / det;
    x[1] = (J[0][0] * b[1] - b[0] * J[1][0]) / det;
    return true;
  }
  const double det = J[0][0] * (J[1][1] * J[2][2] - J[1][2] * J[2][1]) -
                     J[0][1] * (J[1][0] * J[2][2] - J[1][2] * J[2][0]) +
                     J[0][2] * (J[1][0] * J[2][1] - J[1][1] * J[2][0]);
  double size = 1.0;
  for (int c = 0; c < 3; ++c)
    size *= std::sqrt(J[0][c] * J[0][c] + J[1][c] * J[1][c] + J[2][c] * J[2][c]);
  if (!(std::abs(det) > 1e-12 * size)) return false;
  for (int k = 0; k < 3; ++k) {
    double Jk[3][3];
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) Jk[r][c] = (c == k) ? b[r] : J[r][c];
    x[k] = (Jk[0][0] * (Jk[1][1] * Jk[2][2] - Jk[1][2] * Jk[2][1]) -
            Jk[0][1] * (Jk[1][0] * Jk[2][2] - Jk[1][2] * Jk[2][0]) +
            Jk[0][2] * (Jk[1][0] * Jk[2][1] - Jk[1][1] * Jk[2][0])) /
           det;
  }
  return true;
}

// Return onto a plane or a line: sigma = trial - sum dgamma_b D N_b with n_a . sigma = bound_a
// for every active a, i.e. J dgamma = F(trial), J_ab = n_a . D N_b.
Return return_to_planes(const PlaneSet& set, const Candidate& c, const Vector3& trial,
                        double scale) {
  Return r;
  double J[3][3] = {}, b[3] = {}, x[3] = {};
  for (int a = 0; a < c.count; ++a) {
    const Plane& pa = set.planes[c.planes[a]];
    b[a] = plane_value(pa, trial);
    for (int bb = 0; bb < c.count; ++bb)
      J[a][bb] = dot(pa.normal, set.planes[c.planes[bb]].elastic_flow);
  }
  if (!solve_small(c.count, J, b, x)) return r;
  r.stress = trial;
  for (int a = 0; a < c.count; ++a) {
    const Plane& pa = set.planes[c.planes[a]];
    r.multiplier[c.planes[a]] = x[a];
    for (int i = 0; i < 3; ++i) r.stress[i] -= x[a] * pa.elastic_flow[i];
  }
  r.violation = violation_of(set, r, c.planes.data(), c.count, scale);
  return r;
}

// Return onto a corner point: the stress is the point; the return is admissible when
// trial - point lies in the cone of the active planes' D N (Caratheodory: then it lies in the
// cone of some three of them, so three-plane subsets are tried in turn).
Return return_to_point(const PlaneSet& set, const Candidate& c, const Vector3& trial,
                       double scale) {
  const Vector3 step{trial[0] - c.point[0], trial[1] - c.point[1], trial[2] - c.point[2]};
  Return best;
  for (int i = 0; i < c.count; ++i)
    for (int j = i + 1; j < c.count; ++j)
      for (int k = j + 1; k < c.count; ++k) {
        const int chosen[3] = {c.planes[i], c.planes[j], c.planes[k]};
        double M[3][3], b[3], x[3];
        for (int row = 0; row < 3; ++row) {
          b[row] = step[row];
          for (int col = 0; col < 3; ++col) M[row][col] = set.planes[chosen[col]].elastic_flow[row];
        }
        if (!solve_small(3, M, b, x)) continue;
        Return r;
        r.stress = c.point;
        for (int col = 0; col < 3; ++col) r.multiplier[chosen[col]] = x[col];
        r.violation = violation_of(set, r, chosen, 3, scale);
        if (r.violation < best.violation) best = r;
        if (best.violation <= kTolerance) return best;
      }
  return best;
}

// Nominal stress of the new effective stress and damage, and the energy terms of the step.
MohrCoulombStep& finish_step(const MohrCoulombMaterial& m, const MohrCoulombState& old,
                             const Voigt& strain_increment, MohrCoulombStep& step) {
  MohrCoulombState& next = step.state;
  for (int k = 0; k < 6; ++k) next.stress[k] = (1.0 - next.damage) * next.effective_stress[k];
  step.stored_energy = mohr_coulomb_stored_energy(m, next);
  double work = 0.0;
  for (int k = 0; k < 6; ++k) work += 0.5 * (old.stress[k] + next.stress[k]) * strain_increment[k];
  step.dissipation = work - (step.stored_energy - mohr_coulomb_stored_energy(m, old));
  return step;
}

}  // namespace

MohrCoulombMaterial mohr_coulomb_material(const MohrCoulombParameters& p) {
  const auto require = require_parameter;
  require_elastic_constants(p.young_modulus, p.poisson_ratio);
  require(std::isfinite(p.friction_angle) && p.friction_angle >= 0.0 && p.friction_angle < 90.0,
          "friction_angle", p.friction_angle, "in [0, 90) (deg)");
  require(std::isfinite(p.dilation_angle) && p.dilation_angle >= 0.0 &&
              p.dilation_angle <= p.friction_angle,
          "dilation_angle", p.dilation_angle, "in [0, friction_angle] (deg)");
  require(std::isfinite(p.cohesion) && p.cohesion >= 0.0, "cohesion", p.cohesion,
          "finite and >= 0 (Pa)");
  require(p.friction_angle > 0.0 || p.cohesion > 0.0, "cohesion", p.cohesion,
          "> 0 when friction_angle = 0 (no strength otherwise)");
  require(!std::isnan(p.tensile_strength) && p.tensile_strength >= 0.0, "tensile_strength",
          p.tensile_strength, ">= 0 (Pa; +inf for no cut-off)");
  require(std::isfinite(p.damage_max) && p.damage_max >= 0.0 && p.damage_max < 1.0, "damage_max",
          p.damage_max, "in [0, 1)");
  require(std::isfinite(p.damage_plastic_strain) && p.damage_plastic_strain > 0.0,
          "damage_plastic_strain", p.damage_plastic_strain, "finite and > 0");
  require(std::isfinite(p.damage_plastic_displacement) && p.damage_plastic_displacement >= 0.0,
          "damage_plastic_displacement", p.damage_plastic_displacement,
          "finite and >= 0 (m; 0: no crack band)");

  MohrCoulombMaterial m{};
  m.young_modulus = p.young_modulus;
  m.poisson_ratio = p.poisson_ratio;
  const LameConstants lame = lame_constants(p.young_modulus, p.poisson_ratio);
  m.shear_modulus = lame.shear_modulus;
  m.lambda = lame.lambda;
  const double phi = p.friction_angle * kPi / 180.0;
  m.sin_phi = std::sin(phi);
  m.sin_psi = std::sin(p.dilation_angle * kPi / 180.0);
  m.strength = 2.0 * p.cohesion * std::cos(phi);
  m.apex =
      m.sin_phi > 0.0 ? m.strength / (2.0 * m.sin_phi) : std::numeric_limits<double>::infinity();
  m.tension_cutoff = std::isfinite(p.tensile_strength) && p.tensile_strength < m.apex;
  m.tensile_strength = std::min(p.tensile_strength, m.apex);
  m.damage_max = p.damage_max;
  m.damage_plastic_strain = p.damage_plastic_strain;
  m.damage_plastic_displacement = p.damage_plastic_displacement;
  m.planes = make_planes(m);  // once per material, not per return mapping
  return m;
}

double mohr_coulomb_stored_energy(const MohrCoulombMaterial& m, const MohrCoulombState& state) {
  return (1.0 - state.damage) *
         isotropic_complementary_energy(m.young_modulus, m.poisson_ratio, state.effective_stress);
}

double mohr_coulomb_yield(const MohrCoulombMaterial& m, const std::array<double, 3>& s) {
  double worst = -std::numeric_limits<double>::infinity();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j)
      if (i != j) worst = std::max(worst, (s[i] - s[j]) + (s[i] + s[j]) * m.sin_phi - m.strength);
    if (std::isfinite(m.tensile_strength)) worst = std::max(worst, s[i] - m.tensile_strength);
  }
  return worst;
}

MohrCoulombStep mohr_coulomb_update(const MohrCoulombMaterial& m, const MohrCoulombState& old,
                                    const Voigt& strain_increment, double characteristic_length) {
  const Voigt stress_increment = isotropic_stress(m.lambda, m.shear_modulus, strain_increment);
  Voigt trial_tensor = old.effective_stress;
  for (int k = 0; k < 6; ++k) trial_tensor[k] += stress_increment[k];

  // Screens, cheapest first; most points of a seismic run are elastic. (1) An upper bound of
  // the yield function from the invariants alone (one square root): a trial below it by a
  // round-off margin is elastic. (2) (mohr_coulomb_update_screened) A trial clearly inside by
  // the trigonometric eigenvalue estimate (margin 1e-6 of the stress scale, far above the
  // estimate's error). Neither screen accepts a trial that the exact principal stresses would
  // reject.
  if (elastic_by_invariants(m, trial_tensor)) {
    MohrCoulombStep step;
    step.state = old;
    step.state.effective_stress = trial_tensor;
    return finish_step(m, old, strain_increment, step);
  }
  return mohr_coulomb_update_screened(m, old, strain_increment, trial_tensor,
                                      characteristic_length);
}

MohrCoulombStep mohr_coulomb_update_screened(const MohrCoulombMaterial& m,
                                             const MohrCoulombState& old,
                                             const Voigt& strain_increment,
                                             const Voigt& trial_tensor,
                                             double characteristic_length) {
  MohrCoulombStep step;
  step.state = old;
  MohrCoulombState& next = step.state;
  const std::array<double, 3> estimate =
      symmetric_eigenvalues_estimate(tensor_from_stress_voigt(trial_tensor));
  double screen_scale = std::max({std::abs(estimate[0]), std::abs(estimate[2]), m.strength});
  if (std::isfinite(m.tensile_strength)) screen_scale = std::max(screen_scale, m.tensile_strength);
  // With both gaps of the estimate above kClosedFormGap of the deviatoric size, the estimate is
  // within 1e-12 of the scale of the exact values (eigenvalues_estimate_separated), so the
  // yield function within 3e-12 of it: a trial below -1e-9 of the scale is elastic by the exact
  // test below too (the same decision and the same bits; the point sitting near the surface
  // needs no eigenvectors).
  const double estimate_yield = sorted_yield(m, estimate);
  if (estimate_yield < -1e-6 * screen_scale ||
      (estimate_yield < -1e-9 * screen_scale && eigenvalues_estimate_separated(estimate))) {
    next.effective_stress = trial_tensor;
    return finish_step(m, old, strain_increment, step);
  }

  // Closed form where the spectrum is well separated, the pair form near the edges, Jacobi for a
  // hydrostatic trial (principal.hpp).
  const SymmetricEigen eigen =
      symmetric_eigen_fast(tensor_from_stress_voigt(trial_tensor), estimate);
  const Vector3& trial = eigen.values;  // sorted: trial[0] >= trial[1] >= trial[2]

  double scale = std::max({std::abs(trial[0]), std::abs(trial[2]), m.strength});
  if (std::isfinite(m.tensile_strength)) scale = std::max(scale, m.tensile_strength);
  scale = std::max(scale, std::numeric_limits<double>::min());

  if (sorted_yield(m, trial) <= kTolerance * scale) {
    // Elastic step: the trial tensor itself, no round trip through the principal axes.
    next.effective_stress = trial_tensor;
    step.region = ReturnRegion::elastic;
  } else {
    const PlaneSet& set = m.planes;
    const double t = m.tensile_strength;
    const double sp = m.sin_phi;
    std::array<Candidate, 10> candidates;  // the first n are assigned below
    int n = 0;
    candidates[n++] = {ReturnRegion::main_plane, {kMC02}, 1, false, {}};
    if (m.tension_cutoff) candidates[n++] = {ReturnRegion::tension_plane, {kR0}, 1, false, {}};
    candidates[n++] = {ReturnRegion::compression_edge, {kMC02, kMC12}, 2, false, {}};
    candidates[n++] = {ReturnRegion::extension_edge, {kMC02, kMC01}, 2, false, {}};
    if (m.tension_cutoff) {
      // sigma_1 = t on the M-C plane fixes sigma_3 = (t (1 + sin phi) - k) / (1 - sin phi).
      const double low = (t * (1.0 + sp) - m.strength) / (1.0 - sp);
      candidates[n++] = {ReturnRegion::tension_shear_edge, {kR0, kMC02}, 2, false, {}};
      candidates[n++] = {ReturnRegion::tension_edge, {kR0, kR1}, 2, false, {}};
      candidates[n++] = {
          ReturnRegion::tension_extension_corner, {kR0, kMC02, kMC01}, 3, true, {t, low, low}};
      candidates[n++] = {
          ReturnRegion::tension_compression_corner, {kR0, kR1, kMC02, kMC12}, 4, true, {t, t, low}};
      candidates[n++] = {ReturnRegion::tension_apex, {kR0, kR1, kR2}, 3, true, {t, t, t}};
    } else if (sp > 0.0) {
      candidates[n++] = {ReturnRegion::apex,
                         {kMC02, kMC12, kMC01, kMC10, kMC20, kMC21, kR0, kR1, kR2},
                         9,
                         true,
                         {m.apex, m.apex, m.apex}};
    }
    Return accepted;
    ReturnRegion region = ReturnRegion::elastic;
    for (int c = 0; c < n; ++c) {
      const Return r = candidates[c].is_point ? return_to_point(set, candidates[c], trial, scale)
                                              : return_to_planes(set, candidates[c], trial, scale);
      // Keep the least violating candidate: it is the accepted one as soon as it is admissible.
      if (r.violation < accepted.violation) {
        accepted = r;
        region = candidates[c].region;
      }
      if (accepted.violation <= kTolerance) break;
    }
    step.region = region;
    step.kkt_residual = accepted.violation;

    // Plastic strain increment in the principal axes of the trial: C^-1 (trial - sigma).
    const double E = m.young_modulus, nu = m.poisson_ratio;
    const Vector3 drop{trial[0] - accepted.stress[0], trial[1] - accepted.stress[1],
                       trial[2] - accepted.stress[2]};
    const double drop_trace = drop[0] + drop[1] + drop[2];
    Vector3 plastic{};
    for (int i = 0; i < 3; ++i) plastic[i] = ((1.0 + nu) * drop[i] - nu * drop_trace) / E;
    next.effective_stress = stress_voigt_from_principal(accepted.stress, eigen.vectors);
    const Voigt plastic_voigt = strain_voigt_from_principal(plastic, eigen.vectors);
    for (int k = 0; k < 6; ++k) next.plastic_strain[k] += plastic_voigt[k];

    // Equivalent plastic strain sqrt(2/3 eps_p : eps_p) of each mechanism's share of the flow.
    Vector3 tension_flow{}, shear_flow{};
    for (int a = 0; a < set.count; ++a) {
      Vector3& share = set.planes[a].tension ? tension_flow : shear_flow;
      for (int i = 0; i < 3; ++i) share[i] += accepted.multiplier[a] * set.planes[a].flow[i];
    }
    const double root_two_thirds = std::sqrt(2.0 / 3.0);
    next.kappa_tension += root_two_thirds * norm(tension_flow);
    next.kappa_shear += root_two_thirds * norm(shear_flow);
    if (m.damage_max > 0.0) {
      const double kappa = next.kappa_tension + next.kappa_shear;
      next.damage =
          std::max(old.damage, m.damage_max * (1.0 - std::exp(-kappa / damage_strain_scale(
                                                                       m, characteristic_length))));
    }
    if (next.kappa_tension + next.kappa_shear > 0.0)
      next.damage_type =
          next.kappa_tension >= next.kappa_shear ? DamageType::tension : DamageType::shear;
  }

  return finish_step(m, old, strain_increment, step);
}

}  // namespace cavern
