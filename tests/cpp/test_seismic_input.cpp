#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <vector>

#include "seismic_input.hpp"

using namespace cavern;

namespace {

// Tables of g = (t - c)^3 + t^2, g' and g'' sampled exactly at table_t0 + k table_dt.
struct CubicTables {
  double table_t0 = 0.5, table_dt = 0.1, shift = 0.7;
  std::int64_t n_samples = 21;
  std::vector<double> g, dg, ddg;
  double value(double t) const { return std::pow(t - shift, 3) + t * t; }
  double slope(double t) const { return 3.0 * std::pow(t - shift, 2) + 2.0 * t; }
  double curvature(double t) const { return 6.0 * (t - shift) + 2.0; }
  CubicTables() {
    for (std::int64_t k = 0; k < n_samples; ++k) {
      const double t = table_t0 + k * table_dt;
      g.push_back(value(t));
      dg.push_back(slope(t));
      ddg.push_back(curvature(t));
    }
  }
  WaveformTables view() const {
    return {table_t0, table_dt, 1, n_samples, g.data(), dg.data(), ddg.data()};
  }
  double end() const { return table_t0 + (n_samples - 1) * table_dt; }
};

}  // namespace

TEST(Hermite, ExactForCubicsInsideTheTable) {
  const CubicTables tables;
  int checked = 0;
  for (int k = 0; k < 146; ++k) {
    const double t = tables.table_t0 + 0.0137 * k;  // up to 2.4985, inside the table
    ASSERT_LT(t, tables.end());
    const double g = hermite_interpolate(tables.g.data(), tables.dg.data(), tables.n_samples,
                                         tables.table_t0, tables.table_dt, t);
    const double dg = hermite_interpolate(tables.dg.data(), tables.ddg.data(), tables.n_samples,
                                          tables.table_t0, tables.table_dt, t);
    EXPECT_NEAR(g, tables.value(t), 1e-13) << "t = " << t;
    EXPECT_NEAR(dg, tables.slope(t), 1e-13) << "t = " << t;
    ++checked;
  }
  EXPECT_EQ(checked, 146);
}

TEST(Hermite, ZeroBeforeStartHeldAfterEnd) {
  const CubicTables tables;
  const double before =
      hermite_interpolate(tables.g.data(), tables.dg.data(), tables.n_samples, tables.table_t0,
                          tables.table_dt, tables.table_t0 - 1e-9);
  EXPECT_EQ(before, 0.0);
  const double after = hermite_interpolate(tables.g.data(), tables.dg.data(), tables.n_samples,
                                           tables.table_t0, tables.table_dt, tables.end() + 3.0);
  EXPECT_EQ(after, tables.g.back());
}

TEST(SeismicInput, ForcesAreTheDelayedCombinationOfTheTables) {
  const CubicTables tables;
  // Two input nodes: node 4 with two entries, node 1 with one.
  const std::vector<std::int64_t> node_ptr = {0, 2, 3};
  const std::vector<std::int32_t> nodes = {4, 1};
  const std::vector<std::int32_t> table = {0, 0, 0};
  const std::vector<double> tau = {0.0, 0.25, -0.1};
  const std::vector<double> P = {1.0, 2.0, 3.0, -1.0, 0.5, 0.0, 0.0, 0.0, 4.0};
  const std::vector<double> Q = {0.5, 0.0, -2.0, 1.0, 1.0, 1.0, 3.0, 0.0, 0.0};
  InputEntries entries{2,          3,        node_ptr.data(), nodes.data(), table.data(),
                       tau.data(), P.data(), Q.data()};
  SeismicInput input(tables.view(), entries);

  const double t = 1.1;
  auto g = [&](double s) { return s < tables.table_t0 ? 0.0 : tables.value(s); };
  auto dg = [&](double s) { return s < tables.table_t0 ? 0.0 : tables.slope(s); };
  std::vector<double> expected(6, 0.0);
  for (int e = 0; e < 3; ++e) {
    const int i = e < 2 ? 0 : 1;
    for (int c = 0; c < 3; ++c)
      expected[3 * i + c] += P[3 * e + c] * g(t - tau[e]) + Q[3 * e + c] * dg(t - tau[e]);
  }
  std::vector<double> forces(6);
  input.forces(t, forces.data());
  for (int k = 0; k < 6; ++k) EXPECT_NEAR(forces[k], expected[k], 1e-12) << k;

  // add_forces scatters onto the global nodes and power() is f . v there.
  std::vector<double> f(15, 0.0), v(15, 0.0);
  input.add_forces(t, nullptr, nullptr, f.data());
  for (int c = 0; c < 3; ++c) {
    EXPECT_EQ(f[12 + c], forces[c]);
    EXPECT_EQ(f[3 + c], forces[3 + c]);
    v[12 + c] = 1.0 + c;
  }
  EXPECT_NEAR(input.power(v.data()), forces[0] + 2 * forces[1] + 3 * forces[2], 1e-12);
  EXPECT_THROW(input.check_nodes(4), std::invalid_argument);
  EXPECT_NO_THROW(input.check_nodes(5));
}

TEST(SeismicInput, RejectsATableIndexOutOfRange) {
  const CubicTables tables;
  const std::vector<std::int64_t> node_ptr = {0, 1};
  const std::vector<std::int32_t> nodes = {0};
  const std::vector<std::int32_t> table = {1};  // only table 0 exists
  const std::vector<double> tau = {0.0}, P = {1, 0, 0}, Q = {0, 0, 0};
  InputEntries entries{1,          1,        node_ptr.data(), nodes.data(), table.data(),
                       tau.data(), P.data(), Q.data()};
  EXPECT_THROW(SeismicInput(tables.view(), entries), std::invalid_argument);
}
