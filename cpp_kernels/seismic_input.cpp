#include "seismic_input.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace cavern {

namespace {

// Hermite basis at theta in [0, 1).
struct HermiteBasis {
  double h00, h10, h01, h11;
  explicit HermiteBasis(double theta) {
    const double theta2 = theta * theta;
    const double theta3 = theta2 * theta;
    h00 = 2.0 * theta3 - 3.0 * theta2 + 1.0;
    h10 = theta3 - 2.0 * theta2 + theta;
    h01 = -2.0 * theta3 + 3.0 * theta2;
    h11 = theta3 - theta2;
  }
};

// Where t falls in the table: before it, past its last sample, or in interval k at theta.
struct TablePosition {
  enum Kind { kBefore, kAfter, kInside } kind;
  std::int64_t k = 0;
  double theta = 0.0;
};

TablePosition locate(std::int64_t n_samples, double t0, double h, double t) {
  const double s = (t - t0) / h;
  if (!(s >= 0.0)) return {TablePosition::kBefore};
  if (s >= static_cast<double>(n_samples - 1)) return {TablePosition::kAfter};
  TablePosition position{TablePosition::kInside};
  position.k = static_cast<std::int64_t>(s);
  // Round-off at the top of the last interval must not step past it.
  if (position.k > n_samples - 2) position.k = n_samples - 2;
  position.theta = s - static_cast<double>(position.k);
  return position;
}

double interpolate(const double* values, const double* slopes, std::int64_t n_samples, double h,
                   const TablePosition& position) {
  switch (position.kind) {
    case TablePosition::kBefore:
      return 0.0;
    case TablePosition::kAfter:
      return values[n_samples - 1];
    default:
      break;
  }
  const HermiteBasis basis(position.theta);
  const std::int64_t k = position.k;
  return basis.h00 * values[k] + basis.h10 * h * slopes[k] + basis.h01 * values[k + 1] +
         basis.h11 * h * slopes[k + 1];
}

void require(bool condition, const std::string& message) {
  if (!condition) throw std::invalid_argument(message);
}

}  // namespace

double hermite_interpolate(const double* values, const double* slopes, std::int64_t n_samples,
                           double t0, double h, double t) {
  return interpolate(values, slopes, n_samples, h, locate(n_samples, t0, h, t));
}

SeismicInput::SeismicInput(const WaveformTables& tables, const InputEntries& entries)
    : tables_(tables), entries_(entries) {
  require(std::isfinite(tables.table_dt) && tables.table_dt > 0.0,
          "table_dt must be finite and > 0, got " + std::to_string(tables.table_dt));
  require(std::isfinite(tables.table_t0), "table_t0 must be finite");
  require(tables.n_samples >= 2,
          "g must have at least 2 samples per table, got " + std::to_string(tables.n_samples));
  require(entries.node_ptr[0] == 0,
          "node_ptr[0] must be 0, got " + std::to_string(entries.node_ptr[0]));
  for (std::int64_t i = 0; i < entries.n_input_nodes; ++i)
    require(entries.node_ptr[i + 1] >= entries.node_ptr[i],
            "node_ptr must be non-decreasing, but node_ptr[" + std::to_string(i + 1) +
                "] = " + std::to_string(entries.node_ptr[i + 1]) + " < node_ptr[" +
                std::to_string(i) + "] = " + std::to_string(entries.node_ptr[i]));
  require(entries.node_ptr[entries.n_input_nodes] == entries.n_entries,
          "node_ptr[-1] must equal the number of entries " + std::to_string(entries.n_entries) +
              ", got " + std::to_string(entries.node_ptr[entries.n_input_nodes]));
  for (std::int64_t e = 0; e < entries.n_entries; ++e)
    require(entries.table[e] >= 0 && entries.table[e] < tables.n_tables,
            "table[" + std::to_string(e) + "] = " + std::to_string(entries.table[e]) +
                " is not a table index in [0, " + std::to_string(tables.n_tables) + ")");
  for (std::int64_t i = 0; i < entries.n_input_nodes; ++i)
    require(entries.nodes[i] >= 0, "nodes[" + std::to_string(i) +
                                       "] = " + std::to_string(entries.nodes[i]) + " is negative");
  node_forces_.assign(3 * entries.n_input_nodes, 0.0);
}

HermiteValue SeismicInput::waveform(std::int32_t table, double t) const {
  const std::int64_t offset = static_cast<std::int64_t>(table) * tables_.n_samples;
  const TablePosition position = locate(tables_.n_samples, tables_.table_t0, tables_.table_dt, t);
  return {interpolate(tables_.g + offset, tables_.dg + offset, tables_.n_samples, tables_.table_dt,
                      position),
          interpolate(tables_.dg + offset, tables_.ddg + offset, tables_.n_samples,
                      tables_.table_dt, position)};
}

void SeismicInput::forces(double t, double* out) const {
#pragma omp parallel for schedule(static)
  for (std::int64_t i = 0; i < entries_.n_input_nodes; ++i) {
    double f0 = 0.0, f1 = 0.0, f2 = 0.0;
    for (std::int64_t e = entries_.node_ptr[i]; e < entries_.node_ptr[i + 1]; ++e) {
      const HermiteValue w = waveform(entries_.table[e], t - entries_.tau[e]);
      const double* P = entries_.P + 3 * e;
      const double* Q = entries_.Q + 3 * e;
      f0 += P[0] * w.value + Q[0] * w.slope;
      f1 += P[1] * w.value + Q[1] * w.slope;
      f2 += P[2] * w.value + Q[2] * w.slope;
    }
    out[3 * i] = f0;
    out[3 * i + 1] = f1;
    out[3 * i + 2] = f2;
  }
}

void SeismicInput::add_forces(double t, const double* /*u*/, const double* /*v*/, double* f) {
  forces(t, node_forces_.data());
  // Serial scatter: a node may appear twice in `nodes`.
  for (std::int64_t i = 0; i < entries_.n_input_nodes; ++i) {
    double* fi = f + 3 * static_cast<std::int64_t>(entries_.nodes[i]);
    fi[0] += node_forces_[3 * i];
    fi[1] += node_forces_[3 * i + 1];
    fi[2] += node_forces_[3 * i + 2];
  }
}

double SeismicInput::power(const double* v) const {
  double total = 0.0;
  for (std::int64_t i = 0; i < entries_.n_input_nodes; ++i) {
    const double* vi = v + 3 * static_cast<std::int64_t>(entries_.nodes[i]);
    total += node_forces_[3 * i] * vi[0] + node_forces_[3 * i + 1] * vi[1] +
             node_forces_[3 * i + 2] * vi[2];
  }
  return total;
}

void SeismicInput::check_nodes(std::int64_t n_nodes) const {
  for (std::int64_t i = 0; i < entries_.n_input_nodes; ++i)
    if (entries_.nodes[i] >= n_nodes)
      throw std::invalid_argument(
          "SeismicInput nodes[" + std::to_string(i) + "] = " + std::to_string(entries_.nodes[i]) +
          " is not a node of the Stepper (n_nodes = " + std::to_string(n_nodes) + ")");
}

}  // namespace cavern
