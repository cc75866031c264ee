// Principal values and directions of symmetric 3x3 tensors, and the Voigt conventions shared by
// the material laws (docs/materials.md).
//
// Voigt order [xx, yy, zz, xy, yz, xz] everywhere. Stress-like Voigt vectors hold the tensor
// components; strain-like Voigt vectors hold ENGINEERING shear (gamma_xy = 2 eps_xy), so that
// stress . strain (a plain 6-term dot product) is the double contraction sigma : eps.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>

namespace cavern {

using Voigt = std::array<double, 6>;

/// Damage mechanism of a material point, as reported in monitors and XDMF `damage_type`:
/// 0 none, 1 tension (rock: cut-off planes; concrete: d_t), 2 shear (Mohr-Coulomb; d_c).
enum class DamageType : std::int32_t { none = 0, tension = 1, shear = 2 };
using Matrix3 = std::array<std::array<double, 3>, 3>;

/// Eigenvalues in descending order (values[0] >= values[1] >= values[2]) and the matching unit
/// eigenvectors, vectors[k] belonging to values[k]; the vectors form a right-handed orthonormal
/// basis to round-off.
struct SymmetricEigen {
  std::array<double, 3> values{};
  Matrix3 vectors{};
};

/// Eigen-decomposition of a symmetric 3x3 matrix by cyclic Jacobi rotations (Golub & Van Loan,
/// Matrix Computations, 4th ed., Sec. 8.5; stable rotation of Rutishauser). Jacobi is used
/// rather than the closed-form cubic because it stays accurate for repeated and nearly repeated
/// eigenvalues (the M-C edges and apex, hydrostatic states): every rotation is orthogonal, so
/// the eigenvectors are orthonormal whatever the spectrum, and it converges quadratically
/// (three or four sweeps to round-off for 3x3).
inline SymmetricEigen symmetric_eigen(const Matrix3& matrix) {
  Matrix3 a = matrix;
  Matrix3 v{{{1.0, 0.0, 0.0}, {0.0, 1.0, 0.0}, {0.0, 0.0, 1.0}}};
  double norm = 0.0;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) norm += a[i][j] * a[i][j];
  norm = std::sqrt(norm);
  // An off-diagonal entry this small changes no eigenvalue at double precision.
  const double negligible = 1e-22 * norm;
  constexpr int kPairs[3][2] = {{0, 1}, {0, 2}, {1, 2}};
  for (int sweep = 0; sweep < 32; ++sweep) {
    bool rotated = false;
    for (const auto& pair : kPairs) {
      const int p = pair[0], q = pair[1];
      if (std::abs(a[p][q]) <= negligible) {
        a[p][q] = a[q][p] = 0.0;
        continue;
      }
      rotated = true;
      // Rotation angle theta with t = tan(theta) the smaller root of t^2 + 2 zeta t - 1 = 0.
      const double zeta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
      // (For |zeta| > 1e150, zeta^2 would overflow: t = 1 / (2 zeta) to double precision.)
      const double abs_zeta = std::abs(zeta);
      const double t =
          (zeta >= 0.0 ? 1.0 : -1.0) /
          (abs_zeta > 1e150 ? 2.0 * abs_zeta : abs_zeta + std::sqrt(1.0 + zeta * zeta));
      const double c = 1.0 / std::sqrt(1.0 + t * t);
      const double s = t * c;
      for (int k = 0; k < 3; ++k) {  // A <- A J (columns p, q)
        const double akp = a[k][p], akq = a[k][q];
        a[k][p] = c * akp - s * akq;
        a[k][q] = s * akp + c * akq;
      }
      for (int k = 0; k < 3; ++k) {  // A <- J^T A (rows p, q)
        const double apk = a[p][k], aqk = a[q][k];
        a[p][k] = c * apk - s * aqk;
        a[q][k] = s * apk + c * aqk;
      }
      a[p][q] = a[q][p] = 0.0;       // exact by construction of theta
      for (int k = 0; k < 3; ++k) {  // V <- V J
        const double vkp = v[k][p], vkq = v[k][q];
        v[k][p] = c * vkp - s * vkq;
        v[k][q] = s * vkp + c * vkq;
      }
    }
    if (!rotated) break;
  }
  std::array<int, 3> order{0, 1, 2};
  std::sort(order.begin(), order.end(), [&](int i, int j) { return a[i][i] > a[j][j]; });
  SymmetricEigen result;
  for (int k = 0; k < 3; ++k) {
    result.values[k] = a[order[k]][order[k]];
    for (int i = 0; i < 3; ++i) result.vectors[k][i] = v[i][order[k]];
  }
  // Right-handed basis: e2 = e0 x e1 (only the sign can differ from the Jacobi column).
  const auto& e0 = result.vectors[0];
  const auto& e1 = result.vectors[1];
  const std::array<double, 3> cross{e0[1] * e1[2] - e0[2] * e1[1], e0[2] * e1[0] - e0[0] * e1[2],
                                    e0[0] * e1[1] - e0[1] * e1[0]};
  result.vectors[2] = cross;
  return result;
}

/// cos(acos(r) / 3) for r in [-1, 1], without trigonometric calls: the largest root c in
/// [1/2, 1] of 4 c^3 - 3 c = r (the triple-angle formula), from a degree-8 polynomial in
/// t = sqrt((1 + r) / 2) = cos(acos(r) / 2) with c(0) = 1/2 held exactly (a least-squares fit of
/// c - 1/2 on [0, 1]; c is analytic in t), then one Newton step on the cubic (skipped where its
/// slope vanishes, at the double root r -> -1). Error against std::cos(std::acos(r) / 3): 8e-16
/// for t > 0.05, 3e-14 for t > 1e-3, 6e-12 at worst, exact at r = -1 and r = 1
/// (tests/cpp/test_mohr_coulomb.cpp). acos and two cos took 12 % of a case-study step.
inline double cos_third_of_acos(double r) {
  static constexpr double kFit[9] = {0.5,
                                     0.5773498761953049,
                                     -0.11109787250615882,
                                     0.05330241674893086,
                                     -0.03200716461525087,
                                     0.01976245260868141,
                                     -0.010418899351183557,
                                     0.003761061493294471,
                                     -0.000651873194735815};
  const double t = std::sqrt(0.5 * (1.0 + r));
  // Estrin's scheme: the same polynomial in a dependency chain of depth 4 instead of Horner's 8.
  const double t2 = t * t, t4 = t2 * t2;
  const double p01 = kFit[0] + kFit[1] * t, p23 = kFit[2] + kFit[3] * t;
  const double p45 = kFit[4] + kFit[5] * t, p67 = kFit[6] + kFit[7] * t;
  double c = (p01 + t2 * p23) + t4 * ((p45 + t2 * p67) + t4 * kFit[8]);
  const double slope = 12.0 * c * c - 3.0;  // 0 at the double root c = 1/2
  if (slope > 1e-4) c -= (4.0 * c * c * c - 3.0 * c - r) / slope;
  return c;
}

/// Eigenvalues (descending) of a symmetric 3x3 matrix by the trigonometric closed form
/// (Smith 1961, "Eigenvalues of a symmetric 3x3 matrix", Commun. ACM 4(4) 168). Several times
/// faster than symmetric_eigen but, near repeated eigenvalues, accurate only to about 1e-8 of
/// the deviatoric size |A - tr(A)/3 I| (the cubic's root is double there; cos(acos(r) / 3) by
/// cos_third_of_acos, without trigonometric calls), a few 1e-8 at worst: use it to screen
/// (decide "clearly elastic" with a margin), never for a returned stress.
inline std::array<double, 3> symmetric_eigenvalues_estimate(const Matrix3& a) {
  const double mean = (a[0][0] + a[1][1] + a[2][2]) / 3.0;
  const double off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
  const double d0 = a[0][0] - mean, d1 = a[1][1] - mean, d2 = a[2][2] - mean;
  const double size = std::sqrt((d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * off) / 6.0);
  if (size == 0.0) return {mean, mean, mean};
  const double inverse = 1.0 / size;
  const double b00 = d0 * inverse, b11 = d1 * inverse, b22 = d2 * inverse;
  const double b01 = a[0][1] * inverse, b02 = a[0][2] * inverse, b12 = a[1][2] * inverse;
  const double half_det = 0.5 * (b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) +
                                 b02 * (b01 * b12 - b11 * b02));
  const double c = cos_third_of_acos(std::clamp(half_det, -1.0, 1.0));
  const double largest = mean + 2.0 * size * c;
  // cos(angle + 2 pi / 3) = -c / 2 - sqrt(3) / 2 sin(angle), sin(angle) = sqrt(1 - c^2).
  const double sine = std::sqrt(std::max(1.0 - c * c, 0.0));
  const double smallest = mean + 2.0 * size * (-0.5 * c - 0.86602540378443864676 * sine);
  return {largest, 3.0 * mean - largest - smallest, smallest};
}

/// Eigen-decomposition by the closed form where it is as accurate as symmetric_eigen, else by
/// symmetric_eigen. It works on the deviator scaled to unit size, B = (A - m I) / s (m the mean
/// of the diagonal, s = sqrt(|dev A|^2 / 6)): a rounding of m is a common shift that moves no
/// vector, and B's entries are O(1) whatever the magnitude of A. With the trigonometric
/// eigenvalues (symmetric_eigenvalues_estimate) of a spectrum whose two gaps both exceed
/// kClosedFormGap s, the vectors of the outer values come from the largest cross product of two
/// rows of B - mu I, each refined once (the Rayleigh quotient of B, then the cross product again:
/// vector error about 1e-16 / (gap / s)), the middle one completes the right-handed basis, and
/// each value is m + s times the Rayleigh quotient of its vector. A nearly repeated pair (the
/// Mohr-Coulomb edges) goes to symmetric_eigen_pair_form (the distinct vector by the same cross
/// product, the pair by one 2 x 2 rotation); a zero deviator (hydrostatic), non-finite entries and
/// unsound vectors go to Jacobi, whose vectors stay orthonormal whatever the spectrum. Several
/// times faster than Jacobi.
inline constexpr double kClosedFormGap = 1e-3;

namespace detail {
// Unit vector of the null space of B - mu I (rank 2, B of O(1) entries): the largest of the three
// cross products of its rows, normalised. False when none is of a sound, finite length.
inline bool null_vector(const Matrix3& b, double mu, std::array<double, 3>& out) {
  const std::array<double, 3> r0{b[0][0] - mu, b[0][1], b[0][2]};
  const std::array<double, 3> r1{b[1][0], b[1][1] - mu, b[1][2]};
  const std::array<double, 3> r2{b[2][0], b[2][1], b[2][2] - mu};
  auto cross = [](const std::array<double, 3>& x, const std::array<double, 3>& y) {
    return std::array<double, 3>{x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2],
                                 x[0] * y[1] - x[1] * y[0]};
  };
  const std::array<double, 3> c[3] = {cross(r0, r1), cross(r0, r2), cross(r1, r2)};
  double best = 0.0;
  int k = 0;
  for (int i = 0; i < 3; ++i) {
    const double n = c[i][0] * c[i][0] + c[i][1] * c[i][1] + c[i][2] * c[i][2];
    if (n > best) best = n, k = i;
  }
  // B has unit size, so a sound null vector's cross product is far from under- or overflow.
  if (!(best > 1e-200) || !std::isfinite(best)) return false;
  const double scale = 1.0 / std::sqrt(best);
  for (int i = 0; i < 3; ++i) out[i] = c[k][i] * scale;
  return true;
}

inline double rayleigh(const Matrix3& a, const std::array<double, 3>& v) {
  double sum = 0.0;
  for (int i = 0; i < 3; ++i)
    sum += v[i] * (a[i][0] * v[0] + a[i][1] * v[1] + a[i][2] * v[2]);
  return sum;
}
/// A = mean I + size B: the deviator scaled to unit size (B's values sum to 0, their squares to
/// 6) and the estimated values on B's scale (mu). False for a zero or non-finite deviator.
struct ScaledDeviator {
  double mean = 0.0, size = 0.0;
  Matrix3 b{};
  std::array<double, 3> mu{};
};
inline bool scaled_deviator(const Matrix3& a, const std::array<double, 3>& estimate, ScaledDeviator& s) {
  const double mean = (a[0][0] + a[1][1] + a[2][2]) / 3.0;
  const double d0 = a[0][0] - mean, d1 = a[1][1] - mean, d2 = a[2][2] - mean;
  const double off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
  const double size = std::sqrt((d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * off) / 6.0);
  if (!(size > 0.0) || !std::isfinite(size) || !std::isfinite(mean)) return false;
  const double inverse = 1.0 / size;
  s.mean = mean;
  s.size = size;
  s.mu = {(estimate[0] - mean) * inverse, (estimate[1] - mean) * inverse, (estimate[2] - mean) * inverse};
  s.b = Matrix3{{{d0 * inverse, a[0][1] * inverse, a[0][2] * inverse},
                 {a[1][0] * inverse, d1 * inverse, a[1][2] * inverse},
                 {a[2][0] * inverse, a[2][1] * inverse, d2 * inverse}}};
  return true;
}
}  // namespace detail

/// The closed form alone: true with `out` set when both gaps of the estimated spectrum exceed
/// kClosedFormGap of the deviatoric size and the vectors came out sound; false otherwise (out
/// then unspecified).
inline bool symmetric_eigen_closed_form(const Matrix3& a, const std::array<double, 3>& estimate,
                                        SymmetricEigen& out) {
  detail::ScaledDeviator scaled;
  if (!detail::scaled_deviator(a, estimate, scaled)) return false;
  const double mean = scaled.mean, size = scaled.size;
  const double mu0 = scaled.mu[0], mu1 = scaled.mu[1], mu2 = scaled.mu[2];
  if (!(mu0 - mu1 > kClosedFormGap) || !(mu1 - mu2 > kClosedFormGap)) return false;
  const Matrix3& b = scaled.b;
  std::array<double, 3> v0, v2;
  if (!detail::null_vector(b, mu0, v0) || !detail::null_vector(b, mu2, v2)) return false;
  if (!detail::null_vector(b, detail::rayleigh(b, v0), v0) ||
      !detail::null_vector(b, detail::rayleigh(b, v2), v2))
    return false;
  // v2 orthogonal to v0 (Gram-Schmidt), v1 = v2 x v0 (so that v0 x v1 = v2).
  const double along = v2[0] * v0[0] + v2[1] * v0[1] + v2[2] * v0[2];
  for (int i = 0; i < 3; ++i) v2[i] -= along * v0[i];
  const double n2 = std::sqrt(v2[0] * v2[0] + v2[1] * v2[1] + v2[2] * v2[2]);
  if (!(n2 > 0.5)) return false;
  for (int i = 0; i < 3; ++i) v2[i] /= n2;
  const std::array<double, 3> v1{v2[1] * v0[2] - v2[2] * v0[1], v2[2] * v0[0] - v2[0] * v0[2],
                                 v2[0] * v0[1] - v2[1] * v0[0]};
  SymmetricEigen result;
  result.vectors = {v0, v1, v2};
  for (int k = 0; k < 3; ++k) result.values[k] = mean + size * detail::rayleigh(b, result.vectors[k]);
  if (!(result.values[0] >= result.values[1] && result.values[1] >= result.values[2]))
    return false;
  out = result;
  return true;
}

/// The closed form for a spectrum with a nearly repeated pair (the Mohr-Coulomb edges, a
/// geostatic sigma_xx = sigma_yy state), where symmetric_eigen_closed_form refuses. On the scaled
/// deviator B (unit size: its values sum to 0 and their squares to 6), the value away from the
/// pair is about 3 from both (a repeated pair is {1, 1, -2}), so its vector is the sound cross
/// product of two rows of B - mu I (null_vector; not refined, see below): this is the distinct
/// eigenprojection n n^T = adj(B - mu I) / tr adj(B - mu I), the closed form of (A - l_i I)(A - l_j I) / ((l - l_i)(l - l_j)), and it needs neither value of
/// the pair. The pair's plane is spanned by any orthonormal (u, w) normal to n; B restricted to it
/// is 2 x 2, diagonalised exactly by one Jacobi rotation, which gives the pair's values to the
/// round-off of B's entries (their gap included, down to 0) and orthonormal vectors however close
/// the pair. Values m + s (Rayleigh quotient of n, the rotated block's diagonal). True with `out`
/// set, false for a zero, non-finite or unsound case (out then unspecified).
inline bool symmetric_eigen_pair_form(const Matrix3& a, const std::array<double, 3>& estimate,
                                      SymmetricEigen& out) {
  detail::ScaledDeviator scaled;
  if (!detail::scaled_deviator(a, estimate, scaled)) return false;
  const double mean = scaled.mean, size = scaled.size;
  const double mu0 = scaled.mu[0], mu1 = scaled.mu[1], mu2 = scaled.mu[2];
  // The pair is the closer two; the distinct value is the last (top pair) or the first.
  const bool top_pair = mu0 - mu1 <= mu1 - mu2;
  // Far from both (about 3 when the pair is close; never below 1.5 for the closer pair).
  if (!(std::min(mu0 - mu1, mu1 - mu2) < 0.5 && std::max(mu0 - mu1, mu1 - mu2) > 1.0)) return false;
  const Matrix3& b = scaled.b;
  // The estimate of the distinct value is within round-off (at the double root of the estimate's
  // cubic its error is second order in the pair's), and a vector error e moves the pair's block
  // by e^2 only: no refinement.
  std::array<double, 3> n;
  if (!detail::null_vector(b, top_pair ? mu2 : mu0, n)) return false;
  // u: the coordinate axis least aligned with n, made normal to n (|u| >= sqrt(2/3) before
  // normalising); w = n x u.
  int axis = 0;
  for (int i = 1; i < 3; ++i)
    if (std::abs(n[i]) < std::abs(n[axis])) axis = i;
  std::array<double, 3> u{-n[axis] * n[0], -n[axis] * n[1], -n[axis] * n[2]};
  u[axis] += 1.0;
  const double u_norm = 1.0 / std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
  for (int i = 0; i < 3; ++i) u[i] *= u_norm;
  const std::array<double, 3> w{n[1] * u[2] - n[2] * u[1], n[2] * u[0] - n[0] * u[2],
                                n[0] * u[1] - n[1] * u[0]};
  std::array<double, 3> bu, bw;
  for (int i = 0; i < 3; ++i) {
    bu[i] = b[i][0] * u[0] + b[i][1] * u[1] + b[i][2] * u[2];
    bw[i] = b[i][0] * w[0] + b[i][1] * w[1] + b[i][2] * w[2];
  }
  const double p = u[0] * bu[0] + u[1] * bu[1] + u[2] * bu[2];
  const double q = u[0] * bw[0] + u[1] * bw[1] + u[2] * bw[2];
  const double r = w[0] * bw[0] + w[1] * bw[1] + w[2] * bw[2];
  // [[p, q], [q, r]]: the rotation of symmetric_eigen, t = tan(theta) the smaller root of
  // t^2 + 2 zeta t - 1 = 0; u' = c u - s w has p - t q, w' = s u + c w has r + t q.
  double c = 1.0, s = 0.0, t = 0.0;
  if (q != 0.0) {
    const double zeta = (r - p) / (2.0 * q);
    const double abs_zeta = std::abs(zeta);
    t = (zeta >= 0.0 ? 1.0 : -1.0) /
        (abs_zeta > 1e150 ? 2.0 * abs_zeta : abs_zeta + std::sqrt(1.0 + zeta * zeta));
    c = 1.0 / std::sqrt(1.0 + t * t);
    s = t * c;
  }
  double low = p - t * q, high = r + t * q;
  std::array<double, 3> v_low{c * u[0] - s * w[0], c * u[1] - s * w[1], c * u[2] - s * w[2]};
  std::array<double, 3> v_high{s * u[0] + c * w[0], s * u[1] + c * w[1], s * u[2] + c * w[2]};
  if (low > high) {
    std::swap(low, high);
    std::swap(v_low, v_high);
  }
  auto cross = [](const std::array<double, 3>& x, const std::array<double, 3>& y) {
    return std::array<double, 3>{x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2],
                                 x[0] * y[1] - x[1] * y[0]};
  };
  SymmetricEigen result;
  const double distinct = mean + size * detail::rayleigh(b, n);
  if (top_pair) {  // right-handed: e2 = n, e1 = e2 x e0
    result.values = {mean + size * high, mean + size * low, distinct};
    result.vectors = {v_high, cross(n, v_high), n};
  } else {  // e0 = n, e2 = e0 x e1
    result.values = {distinct, mean + size * high, mean + size * low};
    result.vectors = {n, v_high, cross(n, v_high)};
  }
  if (!(result.values[0] >= result.values[1] && result.values[1] >= result.values[2]))
    return false;
  out = result;
  return true;
}

/// True when both gaps of an estimate (symmetric_eigenvalues_estimate) exceed kClosedFormGap of
/// its deviatoric size: the estimate is then within 1e-12 of max |value| of the exact values
/// (measured worst 6e-13 at the threshold, falling as 1 / gap; tests/cpp/test_mohr_coulomb.cpp),
/// against a few 1e-8 of the deviatoric size near a repeated pair.
inline bool eigenvalues_estimate_separated(const std::array<double, 3>& e) {
  const double mean = (e[0] + e[1] + e[2]) / 3.0;
  const double d0 = e[0] - mean, d1 = e[1] - mean, d2 = e[2] - mean;
  const double gap = kClosedFormGap * std::sqrt((d0 * d0 + d1 * d1 + d2 * d2) / 6.0);
  return e[0] - e[1] > gap && e[1] - e[2] > gap;
}

/// Eigen-decomposition by the closed form (well separated spectra), the pair form (a nearly
/// repeated pair), else (a zero or non-finite deviator, an unsound case) Jacobi.
inline SymmetricEigen symmetric_eigen_fast(const Matrix3& a,
                                           const std::array<double, 3>& estimate) {
  SymmetricEigen result;
  if (symmetric_eigen_closed_form(a, estimate, result)) return result;
  if (symmetric_eigen_pair_form(a, estimate, result)) return result;
  return symmetric_eigen(a);
}

/// 3x3 tensor of a stress-like Voigt vector (tensor shear components).
inline Matrix3 tensor_from_stress_voigt(const Voigt& s) {
  return {{{s[0], s[3], s[5]}, {s[3], s[1], s[4]}, {s[5], s[4], s[2]}}};
}

/// 3x3 tensor of a strain-like Voigt vector (engineering shear: eps_xy = gamma_xy / 2).
inline Matrix3 tensor_from_strain_voigt(const Voigt& e) {
  return {{{e[0], 0.5 * e[3], 0.5 * e[5]},
           {0.5 * e[3], e[1], 0.5 * e[4]},
           {0.5 * e[5], 0.5 * e[4], e[2]}}};
}

/// Principal stresses (descending, tension positive) and directions of a stress Voigt vector.
inline SymmetricEigen principal_stresses(const Voigt& stress) {
  return symmetric_eigen(tensor_from_stress_voigt(stress));
}

/// Principal strains (descending) and directions of a strain Voigt vector (engineering shear).
inline SymmetricEigen principal_strains(const Voigt& strain) {
  return symmetric_eigen(tensor_from_strain_voigt(strain));
}

/// Stress Voigt vector sum_k values[k] n_k (x) n_k with n_k = vectors[k] (tensor shear).
inline Voigt stress_voigt_from_principal(const std::array<double, 3>& values,
                                         const Matrix3& vectors) {
  Voigt s{};
  for (int k = 0; k < 3; ++k) {
    const auto& n = vectors[k];
    const double value = values[k];
    s[0] += value * n[0] * n[0];
    s[1] += value * n[1] * n[1];
    s[2] += value * n[2] * n[2];
    s[3] += value * n[0] * n[1];
    s[4] += value * n[1] * n[2];
    s[5] += value * n[0] * n[2];
  }
  return s;
}

/// Strain Voigt vector (engineering shear) of the tensor sum_k values[k] n_k (x) n_k.
inline Voigt strain_voigt_from_principal(const std::array<double, 3>& values,
                                         const Matrix3& vectors) {
  Voigt e = stress_voigt_from_principal(values, vectors);
  e[3] *= 2.0;
  e[4] *= 2.0;
  e[5] *= 2.0;
  return e;
}

/// sigma : eps for a stress-like and a strain-like (engineering shear) Voigt vector.
inline double double_contraction(const Voigt& stress, const Voigt& strain) {
  double sum = 0.0;
  for (int k = 0; k < 6; ++k) sum += stress[k] * strain[k];
  return sum;
}

/// Isotropic linear elasticity sigma = C : eps (engineering shear strain in, tensor stress out):
/// sigma = lambda tr(eps) I + 2 G eps.
inline Voigt isotropic_stress(double lambda, double shear_modulus, const Voigt& strain) {
  const double volumetric = lambda * (strain[0] + strain[1] + strain[2]);
  const double two_g = 2.0 * shear_modulus;
  return {volumetric + two_g * strain[0], volumetric + two_g * strain[1],
          volumetric + two_g * strain[2], shear_modulus * strain[3],
          shear_modulus * strain[4],      shear_modulus * strain[5]};
}

/// Isotropic compliance eps = C^-1 : sigma (tensor stress in, engineering shear strain out):
/// eps = [(1 + nu) sigma - nu tr(sigma) I] / E, gamma = tau / G.
inline Voigt isotropic_strain(double young_modulus, double poisson_ratio, const Voigt& stress) {
  const double trace = stress[0] + stress[1] + stress[2];
  const double normal = (1.0 + poisson_ratio) / young_modulus;
  const double lateral = poisson_ratio * trace / young_modulus;
  const double shear = 2.0 * normal;  // 1 / G
  return {normal * stress[0] - lateral, normal * stress[1] - lateral,
          normal * stress[2] - lateral, shear * stress[3],
          shear * stress[4],            shear * stress[5]};
}

/// Complementary elastic energy density 1/2 sigma : C^-1 : sigma (J/m^3) of an isotropic
/// material: (1/2E) [(1 + nu) sigma : sigma - nu tr(sigma)^2].
inline double isotropic_complementary_energy(double young_modulus, double poisson_ratio,
                                             const Voigt& stress) {
  const double trace = stress[0] + stress[1] + stress[2];
  const double squares =
      stress[0] * stress[0] + stress[1] * stress[1] + stress[2] * stress[2] +
      2.0 * (stress[3] * stress[3] + stress[4] * stress[4] + stress[5] * stress[5]);
  return 0.5 / young_modulus * ((1.0 + poisson_ratio) * squares - poisson_ratio * trace * trace);
}

}  // namespace cavern
