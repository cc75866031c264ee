// Equivalent nodal forces of the seismic free field on the model boundary (paper Eq. 6).
#pragma once

#include <cstdint>
#include <vector>

#include "force_provider.hpp"

namespace cavern {

/// Borrowed waveform tables: n_tables rows of n_samples samples at times
/// table_t0 + k table_dt of g, g' and g'' (row-major (n_tables, n_samples)).
struct WaveformTables {
  double table_t0 = 0.0;
  double table_dt = 0.0;
  std::int64_t n_tables = 0;
  std::int64_t n_samples = 0;
  const double* g = nullptr;
  const double* dg = nullptr;
  const double* ddg = nullptr;
};

/// Borrowed input entries: input node i (global node nodes[i]) owns entries
/// e in [node_ptr[i], node_ptr[i+1]), each with a table, a delay tau and 3-vectors P, Q.
struct InputEntries {
  std::int64_t n_input_nodes = 0;
  std::int64_t n_entries = 0;
  const std::int64_t* node_ptr = nullptr;  // (n_input_nodes + 1)
  const std::int32_t* nodes = nullptr;     // (n_input_nodes)
  const std::int32_t* table = nullptr;     // (n_entries)
  const double* tau = nullptr;             // (n_entries)
  const double* P = nullptr;               // (n_entries, 3)
  const double* Q = nullptr;               // (n_entries, 3)
};

/// Value and slope of a tabulated function.
struct HermiteValue {
  double value;
  double slope;
};

/// Cubic Hermite interpolation of a table of values y_k and slopes y'_k at times t0 + k h:
///   s = (t - t0)/h, k = floor(s), theta = s - k,
///   y(t) = h00 y_k + h10 h y'_k + h01 y_{k+1} + h11 h y'_{k+1},
///   h00 = 2th^3 - 3th^2 + 1, h10 = th^3 - 2th^2 + th, h01 = -2th^3 + 3th^2, h11 = th^3 - th^2.
/// Exact for cubic polynomials. Before the table (s < 0): 0. From the last sample on: y_last.
double hermite_interpolate(const double* values, const double* slopes, std::int64_t n_samples,
                           double t0, double h, double t);

/// Seismic input as a force provider (paper Eq. 6 with the total free field):
///   f_i(t) = K_b u_ff + C_b v_ff + A sigma_ff n
///          = sum_{e in node i} P_e g_{table_e}(t - tau_e) + Q_e g'_{table_e}(t - tau_e),
/// g from the (g, g') tables and g' from the (g', g'') tables by cubic Hermite interpolation.
/// Tables and entries are borrowed; the per-node force buffer is owned.
class SeismicInput : public ForceProvider {
 public:
  /// Throws std::invalid_argument for an inconsistent table or entry list, naming the array.
  SeismicInput(const WaveformTables& tables, const InputEntries& entries);

  /// Forces of every input node at time t into out (n_input_nodes, 3).
  void forces(double t, double* out) const;

  /// g and g' of one table at time t (t already shifted by the delay).
  HermiteValue waveform(std::int32_t table, double t) const;

  void add_forces(double t, const double* u, const double* v, double* f) override;
  double power(const double* v) const override;
  void check_nodes(std::int64_t n_nodes) const override;
  std::string name() const override { return "seismic_input"; }
  std::vector<std::int32_t> nodes() const override {
    return std::vector<std::int32_t>(entries_.nodes, entries_.nodes + entries_.n_input_nodes);
  }

  std::int64_t n_input_nodes() const { return entries_.n_input_nodes; }

 private:
  WaveformTables tables_;
  InputEntries entries_;
  std::vector<double> node_forces_;  // (n_input_nodes, 3) of the last add_forces call
};

}  // namespace cavern
