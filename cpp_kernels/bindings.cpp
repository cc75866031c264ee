// Python module pyfem._kernels: the only file that includes pybind11. Every array is checked
// for type, dtype, shape and C-contiguity; nothing is converted, so borrowed arrays are the
// caller's own objects (kept alive with keep_alive) and in-place arrays cannot be copies.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "bsr.hpp"
#include "contact.hpp"
#include "held_force.hpp"
#include "internal_force.hpp"
#include "local_stepper.hpp"
#include "mpi_exchange.hpp"
#include "parallel.hpp"
#include "seismic_input.hpp"
#include "stable_step.hpp"
#include "stepper.hpp"
#include "support.hpp"

namespace py = pybind11;
using namespace cavern;

namespace {

constexpr py::ssize_t kAny = -1;

std::string shape_text(const std::vector<py::ssize_t>& shape) {
  std::ostringstream text;
  text << "(";
  for (std::size_t k = 0; k < shape.size(); ++k) {
    if (k) text << ", ";
    if (shape[k] == kAny)
      text << "any";
    else
      text << shape[k];
  }
  if (shape.size() == 1) text << ",";
  text << ")";
  return text.str();
}

template <typename T>
const char* dtype_name() {
  if constexpr (std::is_same_v<T, double>) return "float64";
  if constexpr (std::is_same_v<T, std::int32_t>) return "int32";
  if constexpr (std::is_same_v<T, std::int64_t>) return "int64";
}

/// The numpy array `object` as array_t<T> after checking dtype, shape (kAny: any extent),
/// C-contiguity and, when `writeable`, writeability. Raises ValueError naming `name`.
template <typename T>
py::array_t<T> checked_array(const py::object& object, const char* name,
                             const std::vector<py::ssize_t>& shape, bool writeable = false) {
  const std::string expected = std::string(dtype_name<T>()) + " array of shape " +
                               shape_text(shape) + ", C-contiguous" +
                               (writeable ? ", writeable" : "");
  if (!py::isinstance<py::array>(object))
    throw py::value_error(std::string(name) + ": expected a numpy " + expected + "; got " +
                          std::string(py::str(py::type::of(object).attr("__name__"))));
  auto array = py::reinterpret_borrow<py::array>(object);
  std::vector<py::ssize_t> got(array.shape(), array.shape() + array.ndim());
  bool shape_ok = static_cast<std::size_t>(array.ndim()) == shape.size();
  for (std::size_t k = 0; shape_ok && k < shape.size(); ++k)
    shape_ok = shape[k] == kAny || shape[k] == got[k];
  const bool dtype_ok = py::isinstance<py::array_t<T>>(array);
  const bool contiguous = (array.flags() & py::array::c_style) != 0;
  if (!dtype_ok || !shape_ok || !contiguous || (writeable && !array.writeable())) {
    std::string problem = !dtype_ok     ? "dtype"
                          : !shape_ok   ? "shape"
                          : !contiguous ? "layout"
                                        : "flags";
    throw py::value_error(std::string(name) + ": expected " + expected + "; got " +
                          std::string(py::str(array.dtype())) + " array of shape " +
                          shape_text(got) + (contiguous ? "" : ", not C-contiguous") +
                          (array.writeable() ? "" : ", read-only") + " (wrong " + problem + ")");
  }
  return py::reinterpret_borrow<py::array_t<T>>(array);
}

/// Checks the block CSR arrays against each other and returns a view on them.
BlockCsrView checked_block_csr(const py::object& indptr_object, const py::object& indices_object,
                               const py::object& blocks_object, std::int64_t n_nodes) {
  auto indptr = checked_array<std::int64_t>(indptr_object, "indptr", {n_nodes + 1});
  auto indices = checked_array<std::int32_t>(indices_object, "indices", {kAny});
  const py::ssize_t nnzb = indices.shape(0);
  auto blocks = checked_array<double>(blocks_object, "blocks", {nnzb, 3, 3});
  const std::int64_t* row_start = indptr.data();
  if (row_start[0] != 0)
    throw py::value_error("indptr[0] must be 0, got " + std::to_string(row_start[0]));
  for (std::int64_t i = 0; i < n_nodes; ++i)
    if (row_start[i + 1] < row_start[i])
      throw py::value_error("indptr must be non-decreasing; indptr[" + std::to_string(i + 1) +
                            "] = " + std::to_string(row_start[i + 1]) + " < " +
                            std::to_string(row_start[i]));
  if (row_start[n_nodes] != nnzb)
    throw py::value_error("indptr[-1] = " + std::to_string(row_start[n_nodes]) +
                          " must equal len(indices) = " + std::to_string(nnzb));
  const std::int32_t* column = indices.data();
  for (py::ssize_t k = 0; k < nnzb; ++k)
    if (column[k] < 0 || column[k] >= n_nodes)
      throw py::value_error("indices[" + std::to_string(k) + "] = " + std::to_string(column[k]) +
                            " is not a block column in [0, " + std::to_string(n_nodes) + ")");
  BlockCsrView view;
  view.n_block_rows = n_nodes;
  view.indptr = row_start;
  view.indices = column;
  view.blocks = blocks.data();
  return view;
}

std::int64_t node_count(const py::object& mass_object) {
  auto mass = checked_array<double>(mass_object, "mass", {kAny});
  return mass.shape(0);
}

/// int64 flat point indices (n,) of a component, each checked to lie in [0, c q).
py::array_t<std::int64_t> checked_points(const HexahedronElementsBase& elements,
                                         const py::object& points_object) {
  auto points = checked_array<std::int64_t>(points_object, "points", {kAny});
  const std::int64_t n_points = elements.n_cells() * elements.n_points();
  for (py::ssize_t j = 0; j < points.shape(0); ++j)
    if (points.data()[j] < 0 || points.data()[j] >= n_points)
      throw py::value_error("points[" + std::to_string(j) + "] = " +
                            std::to_string(points.data()[j]) + " is not a point index in [0, " +
                            std::to_string(n_points) + ")");
  return points;
}

/// One of the law's reports (0 damage, 1 damage_type, 2 plastic_strain, 3 crack_strain) of all
/// points (c, q) or of the given flat indices (n,).
template <typename T>
py::array_t<T> point_output(const HexahedronElementsBase& elements,
                            const py::object& points_object, int which) {
  py::array_t<std::int64_t> points;
  std::vector<py::ssize_t> shape{static_cast<py::ssize_t>(elements.n_cells()),
                                 static_cast<py::ssize_t>(elements.n_points())};
  if (!points_object.is_none()) {
    points = checked_points(elements, points_object);
    shape = {points.shape(0)};
  }
  const std::int64_t n = points_object.is_none() ? 0 : points.shape(0);
  const std::int64_t* indices = points_object.is_none() ? nullptr : points.data();
  py::array_t<T> out(shape);
  T* data = out.mutable_data();
  if constexpr (std::is_same_v<T, std::int32_t>) {
    elements.point_output(indices, n, nullptr, data, nullptr);
  } else {
    elements.point_output(indices, n, which == 0 ? data : nullptr, nullptr,
                          which == 2 ? data : nullptr, which == 3 ? data : nullptr);
  }
  return out;
}

/// The run() of Stepper and LocalStepper: checks u, v, a (writeable float64 (n_dofs,), three
/// different arrays) and n_steps >= 0, then advances the state in place without the GIL.
template <class Kernel>
double run_in_place(Kernel& kernel, py::ssize_t n_dofs, const py::object& u_object,
                    const py::object& v_object, const py::object& a_object, std::int64_t n_steps,
                    double t0) {
  auto u = checked_array<double>(u_object, "u", {n_dofs}, true);
  auto v = checked_array<double>(v_object, "v", {n_dofs}, true);
  auto a = checked_array<double>(a_object, "a", {n_dofs}, true);
  if (n_steps < 0) throw py::value_error("n_steps must be >= 0, got " + std::to_string(n_steps));
  double* u_data = u.mutable_data();
  double* v_data = v.mutable_data();
  double* a_data = a.mutable_data();
  if (u_data == v_data || u_data == a_data || v_data == a_data)
    throw py::value_error("u, v and a must be three different arrays");
  py::gil_scoped_release release;
  return kernel.run(u_data, v_data, a_data, n_steps, t0);
}

/// The set_dashpots() of Stepper and LocalStepper: nodes int32 (k,), C float64 (k, 3, 3).
template <class Kernel>
void set_dashpots_checked(Kernel& kernel, const py::object& nodes_object,
                          const py::object& C_object) {
  auto nodes = checked_array<std::int32_t>(nodes_object, "nodes", {kAny});
  auto C = checked_array<double>(C_object, "C", {nodes.shape(0), 3, 3});
  kernel.set_dashpots(nodes.data(), nodes.shape(0), C.data());
}

/// A StateArchive as a dict of named byte blocks (save_state of the bindings), and back.
py::dict archive_dict(const StateArchive& archive) {
  py::dict out;
  for (const auto& [name, block] : archive.blocks())
    out[py::str(name)] = py::bytes(reinterpret_cast<const char*>(block.data()),
                                   static_cast<py::ssize_t>(block.size()));
  return out;
}

StateArchive dict_archive(const py::dict& blocks) {
  StateArchive::Blocks copy;
  for (const auto& [name, value] : blocks) {
    const std::string bytes = py::cast<py::bytes>(value);
    copy[py::cast<std::string>(name)] = std::vector<std::uint8_t>(bytes.begin(), bytes.end());
  }
  return StateArchive(std::move(copy));
}

/// A stepper's save_state(points) / load_state(dict, points) (Stepper, LocalStepper): points false
/// is a sample's state (StateArchive::per_point; the MPI ranks' light merge, pyfem/distributed_model.py).
template <class T>
auto sample_save_state() {
  return [](const T& stepper, bool points) {
    StateArchive archive;
    archive.set_per_point(points);
    stepper.save_state(archive);
    return archive_dict(archive);
  };
}

template <class T>
auto sample_load_state() {
  return [](T& stepper, const py::dict& blocks, bool points) {
    StateArchive archive = dict_archive(blocks);
    archive.set_per_point(points);
    stepper.load_state(archive);
  };
}

/// A new float64 array (n,) holding a copy of `values` (the per-pair outputs of ContactPairs).
py::array_t<double> array_copy(const std::vector<double>& values) {
  py::array_t<double> out(static_cast<py::ssize_t>(values.size()));
  std::copy(values.begin(), values.end(), out.mutable_data());
  return out;
}

py::array_t<double> vector_array(const std::vector<double>& values) {
  py::array_t<double> out(static_cast<py::ssize_t>(values.size()));
  std::copy(values.begin(), values.end(), out.mutable_data());
  return out;
}

py::dict phase_dict(const PhaseTimes& times) {
  py::dict phases;
  phases["update"] = times.update;
  phases["element_loop"] = times.element_loop;
  phases["input_forces"] = times.input_forces;
  phases["stiffness"] = times.stiffness;
  phases["contact"] = times.contact;
  phases["exchange"] = times.exchange;
  phases["steps"] = times.steps;
  return phases;
}

/// save_state() / load_state(dict) on a bound class whose C++ type has save_state(archive, prefix)
/// and load_state(archive, prefix) (ContactPairs, the element-loop components): the blocks a
/// Stepper checkpoint holds for the object, under no prefix.
template <class Bound>
Bound def_state_methods(Bound bound) {
  using T = typename Bound::type;
  bound.def(
      "save_state",
      [](const T& object) {
        StateArchive archive;
        object.save_state(archive, "");
        return archive_dict(archive);
      },
      "The object's state as a dict of named byte blocks (the blocks a Stepper checkpoint holds for "
      "it), a copy.");
  bound.def(
      "load_state", [](T& object, const py::dict& blocks) { object.load_state(dict_archive(blocks), ""); },
      py::arg("state"),
      "Restores save_state's dict (of an object of the same size; ValueError names a block that does "
      "not fit).");
  return bound;
}

}  // namespace

PYBIND11_MODULE(_kernels, m) {
  m.doc() =
      "Explicit time-stepping kernels (C++/OpenMP) of the cavern program: block-CSR stiffness, "
      "velocity-Verlet stepper, seismic input forces, critical-step estimates.";

  py::class_<ForceProvider, std::shared_ptr<ForceProvider>>(m, "ForceProvider",
                                                            "Base of the force providers.");

  py::class_<SeismicInput, ForceProvider, std::shared_ptr<SeismicInput>>(
      m, "SeismicInput",
      R"(Equivalent nodal forces of the seismic free field (paper Eq. 6).

f_node(t) = sum over entries e of the node: P_e g_{table_e}(t - tau_e) + Q_e g'_{table_e}(t - tau_e)
g by cubic Hermite interpolation of (g, dg), g' of (dg, ddg), at s = (t - tau - table_t0)/table_dt;
zero before the table start, held at the last samples after its end.

Args:
    table_t0: time of the first table sample (s).
    table_dt: table sample spacing (s), > 0.
    g, dg, ddg: float64 (n_tables, n_samples): g (m or normalised), g' (1/s), g'' (1/s^2). Borrowed.
    node_ptr: int64 (n_input_nodes + 1,) entry ranges per input node. Borrowed.
    nodes: int32 (n_input_nodes,) node of each input node. Borrowed.
    table: int32 (n_entries,) waveform table of each entry. Borrowed.
    tau: float64 (n_entries,) delay (s). Borrowed.
    P: float64 (n_entries, 3) force per unit g (N/m). Borrowed.
    Q: float64 (n_entries, 3) force per unit g' (N s/m). Borrowed.
Borrowed arrays are kept alive by this object and must not be modified while it is in use.)")
      .def(py::init([](double table_t0, double table_dt, const py::object& g_object,
                       const py::object& dg_object, const py::object& ddg_object,
                       const py::object& node_ptr_object, const py::object& nodes_object,
                       const py::object& table_object, const py::object& tau_object,
                       const py::object& P_object, const py::object& Q_object) {
             auto g = checked_array<double>(g_object, "g", {kAny, kAny});
             auto dg = checked_array<double>(dg_object, "dg", {g.shape(0), g.shape(1)});
             auto ddg = checked_array<double>(ddg_object, "ddg", {g.shape(0), g.shape(1)});
             auto nodes = checked_array<std::int32_t>(nodes_object, "nodes", {kAny});
             auto node_ptr =
                 checked_array<std::int64_t>(node_ptr_object, "node_ptr", {nodes.shape(0) + 1});
             auto table = checked_array<std::int32_t>(table_object, "table", {kAny});
             const py::ssize_t n_entries = table.shape(0);
             auto tau = checked_array<double>(tau_object, "tau", {n_entries});
             auto P = checked_array<double>(P_object, "P", {n_entries, 3});
             auto Q = checked_array<double>(Q_object, "Q", {n_entries, 3});
             WaveformTables tables{table_t0, table_dt,  g.shape(0), g.shape(1),
                                   g.data(), dg.data(), ddg.data()};
             InputEntries entries{nodes.shape(0), n_entries,  node_ptr.data(), nodes.data(),
                                  table.data(),   tau.data(), P.data(),        Q.data()};
             return std::make_shared<SeismicInput>(tables, entries);
           }),
           py::arg("table_t0"), py::arg("table_dt"), py::arg("g"), py::arg("dg"), py::arg("ddg"),
           py::arg("node_ptr"), py::arg("nodes"), py::arg("table"), py::arg("tau"), py::arg("P"),
           py::arg("Q"), py::keep_alive<1, 4>(), py::keep_alive<1, 5>(), py::keep_alive<1, 6>(),
           py::keep_alive<1, 7>(), py::keep_alive<1, 8>(), py::keep_alive<1, 9>(),
           py::keep_alive<1, 10>(), py::keep_alive<1, 11>(), py::keep_alive<1, 12>())
      .def(
          "forces",
          [](const SeismicInput& input, double t) {
            py::array_t<double> out(
                {static_cast<py::ssize_t>(input.n_input_nodes()), static_cast<py::ssize_t>(3)});
            input.forces(t, out.mutable_data());
            return out;
          },
          py::arg("t"),
          "Forces (N) of every input node at time t (s): new float64 array (n_input_nodes, 3).")
      .def_property_readonly("n_input_nodes", &SeismicInput::n_input_nodes);

  py::class_<HeldForce, ForceProvider, std::shared_ptr<HeldForce>>(
      m, "HeldForce",
      R"(A constant nodal force (the static stage's loads and hand-over force): f = s(t) F at the
nodes, s = 1 (ramp = 0) or the smoothstep 3 x^2 - 2 x^3 of x = clamp(t / ramp, 0, 1).

Args:
    nodes: int32 (k,) distinct nodes.
    forces: float64 (k, 3) force per node (N), copied.
    ramp: rise time (s), >= 0; 0: held from the start.)")
      .def(py::init([](const py::object& nodes_object, const py::object& forces_object, double ramp) {
             auto nodes = checked_array<std::int32_t>(nodes_object, "nodes", {kAny});
             auto forces = checked_array<double>(forces_object, "forces", {nodes.shape(0), 3});
             return std::make_shared<HeldForce>(nodes.data(), nodes.shape(0), forces.data(), ramp);
           }),
           py::arg("nodes"), py::arg("forces"), py::arg("ramp") = 0.0)
      .def("factor", &HeldForce::factor, py::arg("t"), "The factor s(t) of the forces.");

  def_state_methods(py::class_<ContactPairs, std::shared_ptr<ContactPairs>>(
      m, "ContactPairs",
      R"(Interlayer contact node pairs (paper Sec. 3, Eqs. 12-20; Liu & Sharan 1995).

Pair p joins node i = pairs[p, 0] and node j = pairs[p, 1] (the paper's i') at the same place on
the two sides of an interface. Each step, after the stepper's velocity update without contact,
the force R (on i; -R on j) that keeps the pair stuck is
    R_stick = W [n n^T Delta_pred + P_t (Delta_pred - Delta_{n+1})] / dt^2,
    W^-1 = Atilde_i^-1 + Atilde_j^-1  (W = M_i M_j / (M_i + M_j) I without damping),
Delta = u_j - u_i, Delta_pred its prediction at n+2 without contact. With the total force
F = F0 + R, N = -n.F (compression > 0), T = P_t F:
    tension: stick while the bond is intact and -N <= t_s D A, else separate (F = 0) for good;
    compression: stick while |T| <= mu_s N D + (bond intact: c D A), else slip with
    |T| = mu_d N D (bond lost for good). A separated pair carries nothing until its gap closes.
D = 1, or D(t) = eta(t) gamma(dv_t) after set_deterioration (Eqs. 8-11).
States: 0 bonded, 1 stick (bond lost), 2 sliding, 3 separated.

Args:
    pairs: int32 (n_pairs, 2) node indices (i, j). Copied.
    area: float64 (n_pairs,) lumped interface area of the pair (m^2), > 0. Copied.
    normal: float64 (n_pairs, 3) unit normal from side i towards side j. Copied.
    static_force: float64 (n_pairs, 3) F0 = A sigma0 n, the static force of side j on node i (N);
        node j gets -F0. Copied.
    cohesion: c (Pa), >= 0.
    tensile_strength: t_s (Pa), >= 0.
    friction_static: mu_s = tan(static friction angle), >= 0.
    friction_dynamic: mu_d = tan(dynamic friction angle), >= 0.)"))
      .def(
          py::init([](const py::object& pairs_object, const py::object& area_object,
                      const py::object& normal_object, const py::object& static_force_object,
                      double cohesion, double tensile_strength, double friction_static,
                      double friction_dynamic) {
            auto pairs = checked_array<std::int32_t>(pairs_object, "pairs", {kAny, 2});
            const py::ssize_t n_pairs = pairs.shape(0);
            auto area = checked_array<double>(area_object, "area", {n_pairs});
            auto normal = checked_array<double>(normal_object, "normal", {n_pairs, 3});
            auto static_force =
                checked_array<double>(static_force_object, "static_force", {n_pairs, 3});
            ContactGeometry geometry{n_pairs, pairs.data(), area.data(), normal.data(),
                                     static_force.data()};
            ContactStrength strength{cohesion, tensile_strength, friction_static, friction_dynamic};
            return std::make_shared<ContactPairs>(geometry, strength);
          }),
          py::arg("pairs"), py::arg("area"), py::arg("normal"), py::arg("static_force"),
          py::arg("cohesion"), py::arg("tensile_strength"), py::arg("friction_static"),
          py::arg("friction_dynamic"))
      .def(
          "set_deterioration",
          [](ContactPairs& contact, double R0, double lam, double duration, double m_, double n_,
             double p_, double start) {
            contact.set_deterioration(DeteriorationParameters{R0, lam, duration, m_, n_, p_, start});
          },
          py::arg("R0"), py::arg("lam"), py::arg("duration"), py::arg("m"), py::arg("n"),
          py::arg("p"), py::arg("start") = 0.0,
          R"(Switches the deterioration D(t) = eta(t) gamma(dv_t) on (Eqs. 8-11):
eta = R0 + (1 - R0) exp(-lam t_e / duration), gamma = m (|dv_t| + n)^(-p), t_e = t - start the
stepper time since the earthquake's start clamped at 0, dv_t = |P_t (v_j - v_i)| (m/s) at the
previous step (after its contact force).

Args:
    R0: limit of eta, in (0, 1].  lam: decay rate, >= 0.  duration: t_s (s), > 0.
    m: > 0.  n: slip-rate offset (m/s), > 0.  p: exponent, >= 0.
    start: stepper time (s) of the earthquake's start (the record window's start), finite.)")
      .def("set_normal_lag", &ContactPairs::set_normal_lag, py::arg("length"), py::arg("velocity"),
           R"(Switches the normal-stress lag of the friction on (Prakash & Clifton; Cochard & Rice
2000): each pair's effective normal force N* follows N as dN*/dt = -(|dv_t| + velocity) / length
(N* - N), integrated exactly over a step; the friction limit and the sliding force use max(N*, 0).
N* starts at the current N.

Args:
    length: L (m), > 0.  velocity: V* (m/s), >= 0.)")
      .def("set_release_time", &ContactPairs::set_release_time, py::arg("seconds"),
           R"(Switches the gradual release of a broken bond on (time-weakening, Andrews 2004): a pair
whose bond breaks at t_b keeps w = max(0, 1 - (t - t_b)/seconds) of its cohesion and tensile
strength; in tension it holds -N <= t_s D A w or opens carrying t_s D A w along n, in compression
it sticks while |T| <= mu_s N D + c D A w and slides with mu_d N D + c D A w. The work of the
weakening force over the slip or opening is counted in friction_dissipation. Pairs already broken
have nothing left. No stiffness, no dashpot: the stable time step is unchanged.

Args:
    seconds: the release time (s), finite and > 0.)")
      .def(
          "effective_normal",
          [](const ContactPairs& contact) { return array_copy(contact.effective_normal()); },
          "N* of every pair (N) with the normal lag on, else an empty array.")
      .def(
          "rebase",
          [](ContactPairs& contact, const py::object& u_object) {
            auto u = checked_array<double>(u_object, "u", {kAny});
            contact.check_nodes(u.shape(0) / 3);
            if (u.shape(0) % 3 != 0)
              throw py::value_error("u: length " + std::to_string(u.shape(0)) + " is not 3 n_nodes");
            contact.rebase(u.data());
          },
          py::arg("u"),
          R"(Makes the current state the static state of a new run (the static stage's hand-over):
F0 becomes the total force F0 + R of the last step, R 0, the normal gap n.(u_j - u_i) at u
(3 n_nodes,) is kept as the pair's gap offset (the new run's displacement starts from 0), the
slip rate 0; states, bonds and deterioration settings kept.)")
      .def(
          "gap_offset",
          [](const ContactPairs& contact) { return array_copy(contact.gap_offset()); },
          "Normal gap at u = 0 of every pair (m; 0 unless rebased): new float64 array (n_pairs,).")
      .def(
          "static_force",
          [](const ContactPairs& contact) {
            const auto n = static_cast<py::ssize_t>(contact.n_pairs());
            py::array_t<double> out({n, py::ssize_t(3)});
            for (py::ssize_t p = 0; p < n; ++p)
              for (int c = 0; c < 3; ++c) out.mutable_at(p, c) = contact.static_force()[3 * p + c];
            return out;
          },
          "Static force F0 of every pair (N, side j on node i): new float64 array (n_pairs, 3).")
      .def(
          "state",
          [](const ContactPairs& contact) {
            const auto& state = contact.state();
            py::array_t<std::int8_t> out(static_cast<py::ssize_t>(state.size()));
            std::copy(state.begin(), state.end(), out.mutable_data());
            return out;
          },
          "State of each pair: new int8 array (n_pairs,): 0 bonded, 1 stick, 2 sliding, "
          "3 separated.")
      .def(
          "bond_intact",
          [](const ContactPairs& contact) {
            const auto& bond = contact.bond_intact();
            py::array_t<bool> out(static_cast<py::ssize_t>(bond.size()));
            bool* data = out.mutable_data();
            for (std::size_t p = 0; p < bond.size(); ++p) data[p] = bond[p] != 0;
            return out;
          },
          "Whether cohesion and tensile strength are intact: new bool array (n_pairs,).")
      .def(
          "normal_force",
          [](const ContactPairs& contact) { return array_copy(contact.normal_force()); },
          "Total (static + dynamic) normal force N = -n.F on node i (N), compression positive: "
          "new float64 array (n_pairs,).")
      .def(
          "tangential_force",
          [](const ContactPairs& contact) {
            const auto& T = contact.tangential_force();
            py::array_t<double> out(
                {static_cast<py::ssize_t>(contact.n_pairs()), static_cast<py::ssize_t>(3)});
            std::copy(T.begin(), T.end(), out.mutable_data());
            return out;
          },
          "Total tangential force T = P_t F on node i (N): new float64 array (n_pairs, 3).")
      .def(
          "contact_force",
          [](const ContactPairs& contact) {
            const auto& R = contact.contact_force();
            py::array_t<double> out(
                {static_cast<py::ssize_t>(contact.n_pairs()), static_cast<py::ssize_t>(3)});
            std::copy(R.begin(), R.end(), out.mutable_data());
            return out;
          },
          "Dynamic contact force R on node i of the last step (N; node j got -R), the total "
          "force being F0 + R: new float64 array (n_pairs, 3).")
      .def(
          "deterioration",
          [](const ContactPairs& contact) { return array_copy(contact.deterioration()); },
          "Deterioration coefficient D of the last step (1 before any step or when off): new "
          "float64 array (n_pairs,).")
      .def(
          "relative_displacement",
          [](const ContactPairs& contact, const py::object& u_object) {
            auto u = checked_array<double>(u_object, "u", {kAny});
            const auto& nodes = contact.unique_nodes();
            const py::ssize_t needed = nodes.empty() ? 0 : 3 * (nodes.back() + 1);
            if (u.shape(0) % 3 != 0 || u.shape(0) < needed)
              throw py::value_error(
                  "u: expected float64 array of shape (3 n_nodes,) with "
                  "3 n_nodes >= " +
                  std::to_string(needed) + "; got length " + std::to_string(u.shape(0)));
            py::array_t<double> out(
                {static_cast<py::ssize_t>(contact.n_pairs()), static_cast<py::ssize_t>(3)});
            contact.relative_displacement(u.data(), out.mutable_data());
            return out;
          },
          py::arg("u"),
          "Delta = u_j - u_i (m) of every pair from the displacement u (3 n_nodes,) (read only): "
          "new float64 array (n_pairs, 3). Normal gap n.Delta (> 0 open), slip P_t Delta.")
      .def(
          "state_counts",
          [](const ContactPairs& contact) {
            py::array_t<std::int64_t> out(static_cast<py::ssize_t>(4));
            contact.state_counts(out.mutable_data());
            return out;
          },
          "Number of pairs in each state 0..3: new int64 array (4,).")
      .def_property_readonly("n_pairs", &ContactPairs::n_pairs);

  py::class_<InternalForceComponent, std::shared_ptr<InternalForceComponent>>(
      m, "InternalForceComponent",
      R"(Base of the internal-force components: cells whose force f_int(u) the Stepper adds to
K u (add_internal_force). compute() evaluates a trial state without changing the committed one;
commit() accepts it (the Stepper does both once per step).)")
      .def(
          "compute",
          [](InternalForceComponent& component, const py::object& u_object,
             const py::object& force_object) {
            auto u = checked_array<double>(u_object, "u", {kAny});
            auto force = checked_array<double>(force_object, "force", {u.shape(0)}, true);
            if (u.shape(0) % 3 != 0)
              throw py::value_error("u: length " + std::to_string(u.shape(0)) +
                                    " is not 3 n_nodes");
            component.check_nodes(u.shape(0) / 3);
            double* force_data = force.mutable_data();
            const double* u_data = u.data();
            InternalEnergy energy;
            {
              py::gil_scoped_release release;
              energy = component.compute(u_data, force_data);
            }
            py::dict result;
            result["stored"] = energy.stored;
            result["dissipation_increment"] = energy.dissipation_increment;
            return result;
          },
          py::arg("u"), py::arg("force").noconvert(),
          R"(Adds f_int(u) (N) to force and computes the trial state at u (committed state unchanged).

Args:
    u: float64 (3 n_nodes,) displacement (m), read only.
    force: float64 (3 n_nodes,) modified in place (added to).
Returns:
    dict: stored (J) and dissipation_increment (J) of the trial state.)")
      .def("commit", &InternalForceComponent::commit,
           "Makes the trial state of the last compute() the committed one (RuntimeError "
           "without one).")
      .def("rebase", &InternalForceComponent::rebase,
           R"(Makes the committed state the reference of a new run (the static stage's hand-over):
its stress becomes the initial stress sigma0 (zero force at u = 0), its strain the zero of the
next displacement, its stored energy 0; plastic strain, damage and dissipation kept.)")
      .def("stored_energy", &InternalForceComponent::stored_energy,
           "Stored energy of the committed state (J).")
      .def("dissipation", &InternalForceComponent::dissipation,
           "Dissipation accumulated over all commits (J).")
      .def_property_readonly("name", &InternalForceComponent::name);

  def_state_methods(py::class_<HexahedronElementsBase, InternalForceComponent,
             std::shared_ptr<HexahedronElementsBase>>(
      m, "HexahedronElements",
      R"(Hexahedral or tetrahedral cells of one region integrated point by point with a material law.

At each quadrature point q of cell c: eps = sym(sum_a u_a (x) gradients[c, q, a]) (engineering
shear, Voigt order xx, yy, zz, xy, yz, xz), the law gives the trial stress sigma (total, Pa) from
the committed state, and f_a += weights[c, q] (sigma - sigma0) gradients[c, q, a]. With
law="linear_elastic" this is the cells' stiffness matrix times u, to round-off.
Deterministic: the same bits for any number of threads.

Args:
    cell_nodes: int32 (c, k) node of each basis function, k = 8 (Q1) or 27 (Q2) hexahedra,
        4 (P1) or 10 (P2) tetrahedra. Borrowed.
    gradients: float64 (c, q, k, 3) basis gradients dphi/dx at the points (1/m); or the
        reference form, a tuple (inverse_jacobians float64 (c, q, 3, 3) dX_m/dx_l,
        reference_gradients float64 (q, k, 3) dphi/dX, the same for every cell): 9 numbers per
        point streamed instead of 3 k; or for Q2
        cells with the 27-point Gauss rule the tensor form, a tuple (inverse_jacobians float64
        (c, q, 3, 3) dX_m/dx_l, node_order int32 (27,), point_order int32 (27,), basis float64
        (3, 3), derivative float64 (3, 3)): lexicographic node/point 9 i + 3 j + k -> element
        index, and the 1D Lagrange values/derivatives [Gauss point, node] (sum factorisation,
        cpp_kernels/tensor_q2.hpp). Borrowed (the tables copied).
    weights: float64 (c, q) quadrature weight x |det J| (m^3), > 0. Borrowed.
    law: material law name (known_laws()).
    parameters: dict name -> float of the law's parameters (SI, angles in deg):
        linear_elastic: lame_lambda, shear_modulus (Pa);
        mohr_coulomb: young_modulus, poisson_ratio, cohesion, friction_angle, tensile_strength,
            optional dilation_angle (0), damage_max (0.9), damage_plastic_strain (0.005),
            damage_plastic_displacement (m; 0: no crack band, kappa_ref = u_ref / h otherwise);
        concrete_damage: young_modulus, poisson_ratio, tensile_strength, cohesion,
            friction_angle, optional fracture_energy (120 N/m), A_t, B_t, A_c, B_c,
            stiffness_recovery, damage_max (docs/materials.md).
    initial_stress: None or float64 (c, q, 6) static stress sigma0 (Pa, Voigt order). Copied.
        The laws see the total stress sigma0 + the dynamic part; a sigma0 beyond a law's
        strength is returned (damaged) at construction and released from t = 0.
    mean_dilatation: replace the volumetric strain by its cell mean (B-bar, for Q1 plasticity).
    min_cells_for_threads: below this many cells the loops run on one thread.
    single_geometry: the reference or tensor form's inverse Jacobians held as float32 (a copy,
        36 B per point instead of 72; the strain and force carry ~6e-8 relative error).
Borrowed arrays are kept alive by this object and must not be modified while it is in use.)"))
      .def(py::init([](const py::object& cell_nodes_object, const py::object& gradients_object,
                       const py::object& weights_object, const std::string& law,
                       const ParameterMap& parameters, const py::object& initial_stress_object,
                       bool mean_dilatation, std::int64_t min_cells_for_threads,
                       bool single_geometry) {
             auto cell_nodes = checked_array<std::int32_t>(cell_nodes_object, "cell_nodes",
                                                           {kAny, kAny});
             const py::ssize_t n_cells = cell_nodes.shape(0), n_basis = cell_nodes.shape(1);
             auto weights = checked_array<double>(weights_object, "weights", {n_cells, kAny});
             const py::ssize_t n_points = weights.shape(1);
             // Dense (c, q, k, 3), the reference form or the tensor form of Q2
             // (internal_force.hpp).
             const bool tuple_form = py::isinstance<py::tuple>(gradients_object);
             const bool reference_form =
                 tuple_form && gradients_object.cast<py::tuple>().size() == 2;
             const bool tensor_form = tuple_form && !reference_form;
             py::array_t<double> gradients, inverse_jacobians, reference_gradients;
             TensorQ2 tensor{};
             if (reference_form) {
               const auto parts = gradients_object.cast<py::tuple>();
               inverse_jacobians = checked_array<double>(parts[0], "inverse_jacobians",
                                                         {n_cells, n_points, 3, 3});
               reference_gradients = checked_array<double>(parts[1], "reference_gradients",
                                                           {n_points, n_basis, 3});
             } else if (tensor_form) {
               const auto parts = gradients_object.cast<py::tuple>();
               if (parts.size() != 5)
                 throw std::invalid_argument(
                     "gradients: a (c, q, k, 3) array, the reference form (inverse_jacobians, "
                     "reference_gradients) or the tensor form (inverse_jacobians, "
                     "node_order, point_order, basis, derivative)");
               inverse_jacobians = checked_array<double>(parts[0], "inverse_jacobians",
                                                         {n_cells, n_points, 3, 3});
               auto node_order = checked_array<std::int32_t>(parts[1], "node_order", {27});
               auto point_order = checked_array<std::int32_t>(parts[2], "point_order", {27});
               auto basis = checked_array<double>(parts[3], "basis", {3, 3});
               auto derivative = checked_array<double>(parts[4], "derivative", {3, 3});
               std::copy_n(node_order.data(), 27, tensor.node_order);
               std::copy_n(point_order.data(), 27, tensor.point_order);
               std::copy_n(basis.data(), 9, tensor.basis);
               std::copy_n(derivative.data(), 9, tensor.derivative);
             } else {
               gradients = checked_array<double>(gradients_object, "gradients",
                                                 {n_cells, n_points, n_basis, 3});
             }
             const double* initial_stress = nullptr;
             py::array_t<double> initial_stress_array;
             if (!initial_stress_object.is_none()) {
               initial_stress_array = checked_array<double>(
                   initial_stress_object, "initial_stress", {n_cells, n_points, 6});
               initial_stress = initial_stress_array.data();
             }
             HexahedronGeometry geometry{n_cells,
                                         n_points,
                                         n_basis,
                                         cell_nodes.data(),
                                         tuple_form ? nullptr : gradients.data(),
                                         weights.data(),
                                         tensor_form ? &tensor : nullptr,
                                         tuple_form ? inverse_jacobians.data() : nullptr,
                                         reference_form ? reference_gradients.data() : nullptr};
             ElementOptions options;
             options.mean_dilatation = mean_dilatation;
             options.min_cells_for_threads = min_cells_for_threads;
             options.single_geometry = single_geometry;
             return make_hexahedron_elements(law, parameters, geometry, options, initial_stress);
           }),
           py::arg("cell_nodes"), py::arg("gradients"), py::arg("weights"),
           py::arg("law"), py::arg("parameters"),
           py::arg("initial_stress") = py::none(), py::arg("mean_dilatation") = false,
           py::arg("min_cells_for_threads") = ElementOptions{}.min_cells_for_threads,
           py::arg("single_geometry") = false,
           py::keep_alive<1, 2>(), py::keep_alive<1, 3>(), py::keep_alive<1, 4>())
      .def(
          "stress",
          [](const HexahedronElementsBase& elements, const py::object& points_object) {
            if (points_object.is_none()) {
              py::array_t<double> out({static_cast<py::ssize_t>(elements.n_cells()),
                                       static_cast<py::ssize_t>(elements.n_points()),
                                       static_cast<py::ssize_t>(6)});
              elements.stress(out.mutable_data());
              return out;
            }
            auto points = checked_points(elements, points_object);
            py::array_t<double> out({points.shape(0), static_cast<py::ssize_t>(6)});
            elements.stress_at(points.data(), points.shape(0), out.mutable_data());
            return out;
          },
          py::arg("points") = py::none(),
          R"(Committed total stress at the quadrature points (Pa, tension positive, Voigt order
xx, yy, zz, xy, yz, xz).

Args:
    points: None (all) or int64 (n,) flat indices cell * q + point (read only).
Returns:
    new float64 array (c, q, 6), or (n, 6) for the given points.)")
      .def(
          "damage",
          [](const HexahedronElementsBase& elements, const py::object& points_object) {
            return point_output<double>(elements, points_object, 0);
          },
          py::arg("points") = py::none(),
          "Scalar damage d in [0, 1) of the committed state: new float64 array (c, q), or (n,) "
          "for int64 flat indices `points` (cell * q + point).")
      .def(
          "damage_type",
          [](const HexahedronElementsBase& elements, const py::object& points_object) {
            return point_output<std::int32_t>(elements, points_object, 1);
          },
          py::arg("points") = py::none(),
          "Damage mechanism of the committed state, 0 none, 1 tension, 2 shear: new int32 "
          "array (c, q), or (n,) for int64 flat indices `points`.")
      .def(
          "plastic_strain",
          [](const HexahedronElementsBase& elements, const py::object& points_object) {
            return point_output<double>(elements, points_object, 2);
          },
          py::arg("points") = py::none(),
          "Equivalent plastic strain sqrt(2/3) sum |d eps_p| (-) of the committed state (0 for "
          "laws without plastic strain): new float64 array (c, q), or (n,) for int64 flat "
          "indices `points`.")
      .def(
          "crack_strain",
          [](const HexahedronElementsBase& elements, const py::object& points_object) {
            return point_output<double>(elements, points_object, 3);
          },
          py::arg("points") = py::none(),
          "Tensile crack strain d_t kappa_t (-) at its largest so far (the concrete law; 0 for "
          "laws without cracks); times characteristic_length(), the crack band's opening (m): "
          "new float64 array (c, q), or (n,) for int64 flat indices `points`.")
      .def(
          "weights",
          [](const HexahedronElementsBase& elements) {
            py::array_t<double> out({static_cast<py::ssize_t>(elements.n_cells()),
                                     static_cast<py::ssize_t>(elements.n_points())});
            std::copy(elements.weights(), elements.weights() + out.size(), out.mutable_data());
            return out;
          },
          "Quadrature weight x |det J| of every point (m^3): new float64 array (c, q).")
      .def(
          "characteristic_length",
          [](const HexahedronElementsBase& elements) {
            const auto& h = elements.characteristic_length();
            py::array_t<double> out(static_cast<py::ssize_t>(h.size()));
            std::copy(h.begin(), h.end(), out.mutable_data());
            return out;
          },
          "Cube root of each cell's volume (m), the law's characteristic length: new (c,) array.")
      .def(
          "nodes",
          [](const HexahedronElementsBase& elements) {
            const auto& nodes = elements.nodes();
            py::array_t<std::int32_t> out(static_cast<py::ssize_t>(nodes.size()));
            std::copy(nodes.begin(), nodes.end(), out.mutable_data());
            return out;
          },
          "Distinct nodes of the cells, sorted: new int32 array.")
      .def_property_readonly("n_cells", &HexahedronElementsBase::n_cells)
      .def_property_readonly("n_points", &HexahedronElementsBase::n_points)
      .def_property_readonly("n_basis", &HexahedronElementsBase::n_basis)
      .def_property_readonly("mean_dilatation",
                             [](const HexahedronElementsBase& elements) {
                               return elements.options().mean_dilatation;
                             })
      .def_property_readonly("owned_bytes", &HexahedronElementsBase::owned_bytes,
                             "Bytes of state and buffers owned (the borrowed geometry excluded).")
      .def_property_readonly("state_bytes", &HexahedronElementsBase::state_bytes,
                             "Bytes of the law's state of one point (one copy; the loop keeps a "
                             "committed and a trial copy).")
      .def_property_readonly("geometry_bytes", &HexahedronElementsBase::geometry_bytes,
                             "Bytes of geometry the loop reads per point: the gradients (dense "
                             "form) or J^-1 (double or float32), and the weight.");

  def_state_methods(py::class_<GroutedBolts, InternalForceComponent, std::shared_ptr<GroutedBolts>>(
      m, "GroutedBolts",
      R"(A group of rock bolts / anchor cables (cpp_kernels/support.hpp, docs/method.md "Rock bolts
and cables"): chains of two-node axial bars tied to the rock by a grout bond lumped at the bolt
nodes, their own displacements condensed (solved at each compute() from the rock's; no mass).

Args:
    bolt_offsets: int64 (b + 1,) bolt j has the bolt nodes [offsets[j], offsets[j + 1]), >= 2,
        head first.
    arc_length: float64 (m,) s of each bolt node from its head (m), 0 at the head, increasing.
    directions: float64 (b, 3) unit axis of each bolt, head to tip.
    host_nodes: int32 (m, k) rock nodes of the host cell of each bolt node.
    host_weights: float64 (m, k) interpolation weights N_a(x) at the bolt node.
    axial_stiffness: EA (N). yield_force: N, perfectly plastic in tension and compression.
    bond_stiffness: N/m per m. bond_strength: N/m. pretension: N in the free length's segments
    (needs head_stiffness > 0). free_length: m, ungrouted from the head (on a bolt node).
    head_stiffness: N/m, head plate spring to the rock (0: none).
    tolerance: relative equilibrium residual of each bolt; max_iterations: Newton's limit.
All arrays copied.)"))
      .def(py::init([](const py::object& offsets_object, const py::object& s_object,
                       const py::object& directions_object, const py::object& nodes_object,
                       const py::object& weights_object, double axial_stiffness,
                       double yield_force, double bond_stiffness, double bond_strength,
                       double pretension, double free_length, double head_stiffness,
                       double tolerance, int max_iterations) {
             auto offsets = checked_array<std::int64_t>(offsets_object, "bolt_offsets", {kAny});
             if (offsets.shape(0) < 1) throw py::value_error("bolt_offsets: needs b + 1 >= 1 entries");
             const py::ssize_t n_bolts = offsets.shape(0) - 1;
             auto s = checked_array<double>(s_object, "arc_length", {kAny});
             const py::ssize_t m = s.shape(0);
             if (offsets.data()[n_bolts] != m)
               throw py::value_error("bolt_offsets: last entry " +
                                     std::to_string(offsets.data()[n_bolts]) +
                                     " is not the number of bolt nodes " + std::to_string(m));
             auto directions = checked_array<double>(directions_object, "directions", {n_bolts, 3});
             auto nodes = checked_array<std::int32_t>(nodes_object, "host_nodes", {m, kAny});
             auto weights = checked_array<double>(weights_object, "host_weights", {m, nodes.shape(1)});
             BoltGeometry geometry{n_bolts, nodes.shape(1), offsets.data(), s.data(),
                                   directions.data(), nodes.data(), weights.data()};
             BoltParameters parameters{axial_stiffness, yield_force, bond_stiffness,
                                       bond_strength, pretension, free_length, head_stiffness,
                                       tolerance, max_iterations};
             return std::make_shared<GroutedBolts>(geometry, parameters);
           }),
           py::arg("bolt_offsets"), py::arg("arc_length"), py::arg("directions"),
           py::arg("host_nodes"), py::arg("host_weights"), py::kw_only(),
           py::arg("axial_stiffness"), py::arg("yield_force"), py::arg("bond_stiffness"),
           py::arg("bond_strength"), py::arg("pretension") = 0.0, py::arg("free_length") = 0.0,
           py::arg("head_stiffness") = 0.0, py::arg("tolerance") = 1e-12,
           py::arg("max_iterations") = 200)
      .def("add_stiffness_damping",
           [](GroutedBolts& bolts, const py::object& v_object, double beta,
              const py::object& force_object) {
             auto v = checked_array<double>(v_object, "v", {kAny});
             auto force = checked_array<double>(force_object, "force", {v.shape(0)}, true);
             bolts.check_nodes(v.shape(0) / 3);
             bolts.add_stiffness_damping(v.data(), beta, force.mutable_data());
           },
           py::arg("v"), py::arg("beta"), py::arg("force").noconvert(),
           "Adds beta K0 v (K0 the condensed elastic stiffness) to force (3 n_nodes).")
      .def("axial_force", [](const GroutedBolts& b) { return vector_array(b.axial_force()); },
           "Committed axial force of each segment (N, tension positive), bolt by bolt: new array.")
      .def("peak_axial_force", [](const GroutedBolts& b) { return vector_array(b.peak_axial_force()); },
           "Largest |axial force| of each segment over the commits (N): new array.")
      .def("bond_slip", [](const GroutedBolts& b) { return vector_array(b.bond_slip()); },
           "Committed slip w - ubar of each bolt node along the bolt (m): new array.")
      .def("plastic_slip", [](const GroutedBolts& b) { return vector_array(b.plastic_slip()); },
           "Committed plastic bond slip of each bolt node (m): new array.")
      .def("plastic_strain", [](const GroutedBolts& b) { return vector_array(b.plastic_strain()); },
           "Committed plastic axial strain of each segment: new array.")
      .def("bolt_displacement", [](const GroutedBolts& b) { return vector_array(b.bolt_displacement()); },
           "Committed axial displacement w of each bolt node (m): new array.")
      .def("bond_length", [](const GroutedBolts& b) { return vector_array(b.bond_length()); },
           "Tributary grouted length of each bolt node (m): new array.")
      .def_property_readonly("last_iterations", &GroutedBolts::last_iterations,
                             "Newton iterations of the last compute(), summed over the bolts.")
      .def_property_readonly("n_bolts", &GroutedBolts::n_bolts)
      .def_property_readonly("n_bolt_nodes", &GroutedBolts::n_bolt_nodes)
      .def_property_readonly("n_segments", &GroutedBolts::n_segments);

  m.def("known_laws", &known_laws, "Names of the material laws HexahedronElements accepts.");
  m.def(
      "wear_factor",
      [](double R0, double lam, double duration, double m_, double n_, double p_, double start,
         double t) {
        const DeteriorationParameters d{R0, lam, duration, m_, n_, p_, start};
        check_deterioration(d);
        return wear_factor(d, t);
      },
      py::arg("R0"), py::arg("lam"), py::arg("duration"), py::arg("m"), py::arg("n"), py::arg("p"),
      py::arg("start"), py::arg("t"),
      R"(eta(t) of Eq. 9 as the contact pairs use it: R0 + (1 - R0) exp(-lam t_e / duration),
t_e = t - start clamped at 0. The arguments are set_deterioration's, then the stepper time t (s).)");

  py::class_<MpiNodeExchange, std::shared_ptr<MpiNodeExchange>>(
      m, "MpiNodeExchange",
      "The ghost exchange of one MPI rank (cpp_kernels/mpi_exchange.hpp, pyfem/distributed_model.py).")
      .def(py::init([](long fortran_comm, std::vector<int> neighbours,
                       std::vector<std::vector<std::int32_t>> send_nodes,
                       std::vector<std::vector<std::int32_t>> recv_nodes, std::int64_t n_nodes) {
             return std::make_shared<MpiNodeExchange>(
                 MPI_Comm_f2c(static_cast<MPI_Fint>(fortran_comm)), std::move(neighbours),
                 std::move(send_nodes), std::move(recv_nodes), n_nodes);
           }),
           py::arg("comm_f2c"), py::arg("neighbours"), py::arg("send_nodes"),
           py::arg("recv_nodes"), py::arg("n_nodes"),
           "comm_f2c: mpi4py's comm.py2f(); per neighbour rank the local owned nodes it ghosts "
           "and the local ghosts it owns, in ascending global order.")
      .def_property_readonly("bytes_sent_per_step", &MpiNodeExchange::bytes_sent_per_step,
                             "Bytes of one exchange of v and a (the Stepper's, once per step; half with v only).");

  py::class_<Stepper>(m, "Stepper", R"(Velocity-Verlet central difference with lumped mass.

Per step: v_half = v + dt/2 a; u += dt v_half; f = f_ext(t_{n+1});
r = f - K (u + beta v_half); (M (1 + dt/2 alpha) I + dt/2 C) v = M v_half + dt/2 r;
a = (r - (alpha M + C) v) / M.

Args:
    indptr: int64 (n_nodes + 1,) block-row pointers of K. Borrowed.
    indices: int32 (nnzb,) block columns. Borrowed.
    blocks: float64 (nnzb, 3, 3) blocks of K (N/m), symmetric K. Borrowed.
    mass: float64 (n_nodes,) lumped nodal mass (kg), > 0. Borrowed.
    dt: time step (s).
    alpha: mass-proportional Rayleigh coefficient (1/s), implicit.
    beta: stiffness-proportional Rayleigh coefficient (s), explicit on v_half.
    symmetric_storage: True (default) keeps an owned copy of the upper triangle of K and
        streams about half the bytes per step; False fuses the full block-CSR product into
        the update (K need not be symmetric then, but the energy identity needs it).
    single_precision_blocks: True stores the upper triangle's blocks as float32 (half the
        block bytes; state, sums and energy stay float64; needs symmetric_storage).
Borrowed arrays are kept alive by this object and must not be modified while it is in use.)")
      .def(
          py::init([](const py::object& indptr, const py::object& indices, const py::object& blocks,
                      const py::object& mass, double dt, double alpha, double beta,
                      bool symmetric_storage, bool single_precision_blocks) {
            const std::int64_t n_nodes = node_count(mass);
            const BlockCsrView K = checked_block_csr(indptr, indices, blocks, n_nodes);
            auto mass_array = checked_array<double>(mass, "mass", {n_nodes});
            return std::make_unique<Stepper>(
                K, mass_array.data(),
                StepperParameters{dt, alpha, beta, symmetric_storage, single_precision_blocks});
          }),
          py::arg("indptr"), py::arg("indices"), py::arg("blocks"), py::arg("mass"), py::arg("dt"),
          py::arg("alpha") = 0.0, py::arg("beta") = 0.0, py::arg("symmetric_storage") = true,
          py::arg("single_precision_blocks") = false,
          py::keep_alive<1, 2>(),
          py::keep_alive<1, 3>(), py::keep_alive<1, 4>(), py::keep_alive<1, 5>())
      .def(
          "set_dashpots",
          &set_dashpots_checked<Stepper>,
          py::arg("nodes"), py::arg("C"),
          R"(Implicit per-node dashpots, replacing any previous set.

Args:
    nodes: int32 (k,) nodes; a node listed twice gets the sum. Copied.
    C: float64 (k, 3, 3) symmetric positive semi-definite dashpot matrices (N s/m). Copied.)")
      .def(
          "set_constraints",
          [](Stepper& stepper, const py::object& nodes_object, const py::object& P_object) {
            auto nodes = checked_array<std::int32_t>(nodes_object, "nodes", {kAny});
            auto P = checked_array<double>(P_object, "projection", {nodes.shape(0), 3, 3});
            stepper.set_constraints(nodes.data(), nodes.shape(0), P.data());
          },
          py::arg("nodes"), py::arg("projection"),
          R"(Kinematic constraints (fixed, roller), replacing any previous set.

Node k moves only in the range of the orthogonal projection P_k: zeros hold it (fixed),
I - n n^T holds its normal component (roller). The held part of the force goes to the support
(reactions()); velocities and accelerations of held components stay zero.

Args:
    nodes: int32 (k,) distinct nodes. Copied.
    projection: float64 (k, 3, 3) symmetric idempotent matrices P. Copied.)")
      .def(
          "save_state", sample_save_state<Stepper>(),
          R"(The run's state beyond u, v, a, t (checkpoint, docs/checkpoint.md): a dict of named
byte blocks (the energy account, the last internal force and reactions, the contact pairs'
and every internal-force component's state), a copy.

points false: a sample's state, not a checkpoint's: without the per-point and per-node blocks
(the element loop's points and initial stress, the nodal forces); the energy account, reactions
and contact pairs as with true. Under mpirun the ranks' samples are merged so (pyfem/distributed_model.py).)",
          py::arg("points") = true)
      .def(
          "load_state", sample_load_state<Stepper>(),
          py::arg("state"), py::arg("points") = true,
          R"(Restores save_state's dict into a stepper built from the same scene (same dt, damping,
dofs, providers, pairs and components, in the same order). ValueError names the first block that
does not fit; then nothing may be assumed about the stepper's state. points false: a dict of
save_state(points=False), the per-point and per-node state left as it was.)")
      .def("set_mass_damping", &Stepper::set_mass_damping, py::arg("alpha"),
           "Changes the mass-proportional damping alpha (1/s, >= 0) for the following steps "
           "(dynamic relaxation of the static stage adapts it). ValueError for a bad alpha.")
      .def(
          "reactions",
          [](const Stepper& stepper) {
            const std::vector<double>& values = stepper.reactions();
            py::array_t<double> out({static_cast<py::ssize_t>(values.size() / 3), py::ssize_t(3)});
            std::copy(values.begin(), values.end(), out.mutable_data());
            return out;
          },
          "Reactions (k, 3) of the constraints at the last step (N), in set_constraints order (a copy).")
      .def(
          "add_provider",
          [](Stepper& stepper, std::shared_ptr<ForceProvider> provider) {
            stepper.add_provider(std::move(provider));
          },
          py::arg("provider"), py::keep_alive<1, 2>(),
          "Adds a force provider (SeismicInput, HeldForce; kept alive). ValueError names a node "
          "outside the model.")
      .def(
          "add_contact",
          [](Stepper& stepper, std::shared_ptr<ContactPairs> contact) {
            stepper.set_contact(std::move(contact));
          },
          py::arg("contact"), py::keep_alive<1, 2>(),
          "Attaches the interlayer ContactPairs (shared: query it during the run; kept alive). "
          "One per Stepper. ValueError names a pair node outside the model or a pair joining a "
          "node to itself. Without it contact costs nothing.")
      .def(
          "add_internal_force",
          [](Stepper& stepper, std::shared_ptr<InternalForceComponent> component,
             bool count_energy) { stepper.add_internal_force(std::move(component), count_energy); },
          py::arg("component"), py::arg("count_energy") = true, py::keep_alive<1, 2>(),
          R"(Adds an internal-force component (e.g. HexahedronElements; shared, kept alive).

Its cells must not be in the stiffness matrix: r = f - K u - sum_components f_int(u). The energy
account restarts at the next run() unless reset_energy is called after this; energy() then has
internal_stored, internal_dissipation and internal_work. ValueError names a node outside the
model. Without components nothing changes (not one operation per node). count_energy=False:
its forces act, its stored energy and dissipation stay out of this account (an MPI rank's copy
of cells another rank counts).)")
      .def(
          "set_partition",
          [](Stepper& stepper, std::int64_t n_owned, std::shared_ptr<MpiNodeExchange> exchange) {
            stepper.set_partition(n_owned, std::move(exchange));
          },
          py::arg("n_owned"), py::arg("exchange"), py::keep_alive<1, 3>(),
          R"(One MPI rank's share of a distributed model (pyfem/distributed_model.py): the first n_owned
nodes are this rank's, the others ghosts; the energy account sums the owned nodes only and after
every step `exchange` (an MpiNodeExchange, or None) overwrites the ghosts' v and a.)")
      .def(
          "run",
          [](Stepper& stepper, const py::object& u, const py::object& v, const py::object& a,
             std::int64_t n_steps, double t0) {
            return run_in_place(stepper, stepper.n_dofs(), u, v, a, n_steps, t0);
          },
          py::arg("u").noconvert(), py::arg("v").noconvert(), py::arg("a").noconvert(),
          py::arg("n_steps"), py::arg("t0"),
          R"(Advances the state n_steps steps from t0 and returns the end time (s).

Args:
    u, v, a: float64 (3 n_nodes,) displacement (m), velocity (m/s), acceleration (m/s^2) at t0,
        dof = 3 node + component. Modified in place (no conversion is ever made).
    n_steps: number of steps.
    t0: time of the given state (s).
The GIL is released while stepping.)")
      .def(
          "energy",
          [](const Stepper& stepper) {
            const EnergyReport report = stepper.energy();
            py::dict result;
            result["kinetic"] = report.kinetic;
            result["strain"] = report.strain;
            result["total"] = report.total;
            result["initial"] = report.initial;
            result["external_work"] = report.external_work;
            result["damping_work"] = report.damping_work;
            result["contact_work"] = report.contact_work;
            result["friction_dissipation"] = report.friction_dissipation;
            if (report.has_internal) {
              result["internal_stored"] = report.internal_stored;
              result["internal_dissipation"] = report.internal_dissipation;
              result["internal_work"] = report.internal_work;
            }
            result["balance"] = report.balance;
            py::dict provider_work;
            for (std::size_t k = 0; k < report.provider_work.size(); ++k)
              provider_work[py::str(report.provider_names[k] + "_" + std::to_string(k))] =
                  report.provider_work[k];
            result["provider_work"] = provider_work;
            return result;
          },
          R"(Energy account (J) of the current state: dict with kinetic (1/2 v.Mv), strain (1/2 u.Ku),
total (H_n = kinetic + strain - dt^2/8 a.Ma + dt^2/4 F.a), initial (H_0), external_work,
damping_work (dissipated), contact_work (work of the dynamic contact forces R on the mesh,
trapezoid), friction_dissipation (>= 0, work of the slip forces over the slip),
balance = H_n - H_0 - external_work + damping_work - contact_work (zero to round-off for linear
problems) and provider_work {name_index: work} (sums to external_work).
With internal-force components also internal_stored (Psi_n, their stored energy, included in
total and, at the reset, in initial), internal_dissipation (D since the reset, added to balance)
and internal_work (W_int, the trapezoid sum of 1/2 (g_n + g_{n+1}).(u_{n+1} - u_n), which the
scheme balances exactly: balance - (Psi_n - Psi_0 + D - W_int) is round-off; the difference
is the laws' own energy error, round-off for linear_elastic).)")
      .def(
          "reset_energy",
          [](Stepper& stepper, const py::object& u_object, const py::object& v_object,
             const py::object& a_object, double t0) {
            const py::ssize_t n_dofs = stepper.n_dofs();
            auto u = checked_array<double>(u_object, "u", {n_dofs});
            auto v = checked_array<double>(v_object, "v", {n_dofs});
            auto a = checked_array<double>(a_object, "a", {n_dofs});
            stepper.reset_energy(u.data(), v.data(), a.data(), t0);
          },
          py::arg("u"), py::arg("v"), py::arg("a"), py::arg("t0"),
          "Sets H_0 from the state (u, v, a) at t0 (read only) and zeroes the accumulated work.")
      .def(
          "phase_seconds", [](const Stepper& stepper) { return phase_dict(stepper.phase_times()); },
          "Wall time (s) of each part of the steps since construction or reset_phase_seconds(): "
          "update (pass A), element_loop (internal-force components), input_forces (force providers "
          "and their work), stiffness (pass B: K u and the velocity update), contact, exchange (the MPI "
          "ghost exchange); and steps.")
      .def("reset_phase_seconds", &Stepper::reset_phase_times, "Zeroes the phase times.")
      .def_property_readonly("dt", &Stepper::dt, "Time step (s).")
      .def_property_readonly("n_nodes", &Stepper::n_nodes)
      .def_property_readonly("n_dofs", &Stepper::n_dofs);

  m.def(
      "gershgorin_bound",
      [](const py::object& indptr, const py::object& indices, const py::object& blocks,
         const py::object& mass_object) {
        const std::int64_t n_nodes = node_count(mass_object);
        const BlockCsrView K = checked_block_csr(indptr, indices, blocks, n_nodes);
        auto mass = checked_array<double>(mass_object, "mass", {n_nodes});
        return gershgorin_bound(K, mass.data());
      },
      py::arg("indptr"), py::arg("indices"), py::arg("blocks"), py::arg("mass"),
      "Upper bound of omega_max^2 (1/s^2) of M^-1 K: max over dof rows of (1/m) sum |K_rc|.");

  m.def(
      "power_iteration",
      [](const py::object& indptr, const py::object& indices, const py::object& blocks,
         const py::object& mass_object, int iterations, std::uint64_t seed) {
        const std::int64_t n_nodes = node_count(mass_object);
        const BlockCsrView K = checked_block_csr(indptr, indices, blocks, n_nodes);
        auto mass = checked_array<double>(mass_object, "mass", {n_nodes});
        if (iterations < 1)
          throw py::value_error("iterations must be >= 1, got " + std::to_string(iterations));
        py::gil_scoped_release release;
        return power_iteration(K, mass.data(), iterations, seed);
      },
      py::arg("indptr"), py::arg("indices"), py::arg("blocks"), py::arg("mass"),
      py::arg("iterations") = 50, py::arg("seed") = 1,
      "Estimate (from below) of omega_max^2 (1/s^2): Rayleigh quotient of power iteration on "
      "M^-1/2 K M^-1/2.");

  py::class_<LocalStepper>(m, "LocalStepper", R"(Multi-rate explicit stepping (docs/local_stepping.md):
each node steps at dt_fine 2^level; one run step is dt_fine 2^max(level). Stiffness (split by
columns), mass-proportional damping, dashpots, SeismicInput providers and element-loop
components at their own levels (split by cells), ContactPairs at theirs; no constraints yet. One level gives
Stepper's steps.

Args:
    indptr, indices, blocks: the full block-CSR K (borrowed).
    mass: float64 (n_nodes,) lumped masses (borrowed).
    node_level: int32 (n_nodes,) rate level of each node, 0 the finest (copied).
    dt_fine: step of level 0 (s).
    alpha: mass-proportional Rayleigh coefficient (1/s).
    max_level: the largest level (-1: the nodes' largest; an MPI rank's share passes the whole
        model's, set_partition).)")
      .def(py::init([](const py::object& indptr, const py::object& indices, const py::object& blocks,
                       const py::object& mass, const py::object& level_object, double dt_fine,
                       double alpha, int max_level) {
             const std::int64_t n_nodes = node_count(mass);
             const BlockCsrView K = checked_block_csr(indptr, indices, blocks, n_nodes);
             auto mass_array = checked_array<double>(mass, "mass", {n_nodes});
             auto levels = checked_array<std::int32_t>(level_object, "node_level", {n_nodes});
             return std::make_unique<LocalStepper>(K, mass_array.data(), levels.data(), dt_fine, alpha,
                                                   max_level);
           }),
           py::arg("indptr"), py::arg("indices"), py::arg("blocks"), py::arg("mass"),
           py::arg("node_level"), py::arg("dt_fine"), py::arg("alpha") = 0.0, py::arg("max_level") = -1,
           py::keep_alive<1, 2>(),
           py::keep_alive<1, 3>(), py::keep_alive<1, 4>(), py::keep_alive<1, 5>())
      .def(
          "set_dashpots",
          &set_dashpots_checked<LocalStepper>,
          py::arg("nodes"), py::arg("C"), "Implicit per-node dashpots (Stepper.set_dashpots).")
      .def(
          "set_constraints",
          [](LocalStepper& stepper, const py::object& nodes_object, const py::object& P_object) {
            auto nodes = checked_array<std::int32_t>(nodes_object, "nodes", {kAny});
            auto P = checked_array<double>(P_object, "projection", {nodes.shape(0), 3, 3});
            stepper.set_constraints(nodes.data(), nodes.shape(0), P.data());
          },
          py::arg("nodes"), py::arg("projection"),
          "Kinematic constraints (fixed, roller; Stepper.set_constraints): every kick of a constrained "
          "node projected.")
      .def(
          "reactions",
          [](const LocalStepper& stepper) {
            const std::vector<double>& r = stepper.reactions();
            py::array_t<double> out({static_cast<py::ssize_t>(r.size() / 3), static_cast<py::ssize_t>(3)});
            std::copy(r.begin(), r.end(), out.mutable_data());
            return out;
          },
          "The supports' reactions (k, 3) at the end of the last run (N), as Stepper.reactions.")
      .def(
          "add_provider",
          [](LocalStepper& stepper, std::shared_ptr<ForceProvider> provider) {
            stepper.add_provider(std::move(provider));
          },
          py::arg("provider"), py::keep_alive<1, 2>(),
          "Adds a force provider (SeismicInput, HeldForce) that lists its nodes.")
      .def(
          "add_internal_force",
          [](LocalStepper& stepper, std::shared_ptr<InternalForceComponent> component, int level,
             bool count_energy) { stepper.add_internal_force(std::move(component), level, count_energy); },
          py::arg("component"), py::arg("level"), py::arg("count_energy") = true, py::keep_alive<1, 2>(),
          "Adds an internal-force component (HexahedronElements, GroutedBolts) whose cells or bolts step at "
          "dt_fine 2^level (their nodes then drift at that "
          "level or a finer one): its force is computed and committed in the level's end kicks. "
          "count_energy=False: its energy stays out of this account (an MPI rank's halo cells).")
      .def(
          "set_partition",
          [](LocalStepper& stepper, std::int64_t n_owned,
             std::vector<std::shared_ptr<MpiNodeExchange>> exchanges) {
            stepper.set_partition(n_owned, std::vector<std::shared_ptr<NodeExchange>>(exchanges.begin(),
                                                                                      exchanges.end()));
          },
          py::arg("n_owned"), py::arg("exchanges"), py::keep_alive<1, 3>(),
          R"(One MPI rank's share of a distributed model under the row split (pyfem/distributed_model.py): the
first n_owned nodes are this rank's, the others ghosts; exchanges[k] (an MpiNodeExchange of the
level-k ghosts, or None) gives them their owners' velocity before every level-k drift; the energy
account sums the owned nodes and counted components only.)")
      .def_property_readonly("n_owned_nodes", &LocalStepper::n_owned_nodes)
      .def(
          "add_contact",
          [](LocalStepper& stepper, std::shared_ptr<ContactPairs> pairs, int level) {
            stepper.add_contact(std::move(pairs), level);
          },
          py::arg("pairs"), py::arg("level"), py::keep_alive<1, 2>(),
          "Adds ContactPairs whose nodes step and drift at rate level `level`, corrected by an impulse "
          "before each of the level's drifts; their rows step at that level (step_rows_at_drift_level). "
          "Checked at the first run (ValueError naming the node).")
      .def(
          "step_rows_at_drift_level",
          [](LocalStepper& stepper, const py::object& nodes_object) {
            auto nodes = checked_array<std::int32_t>(nodes_object, "nodes", {kAny});
            stepper.step_rows_at_drift_level(
                std::vector<std::int32_t>(nodes.data(), nodes.data() + nodes.shape(0)));
          },
          py::arg("nodes"),
          "Steps the nodes' whole stiffness rows at their drift level (add_contact does it for pair nodes); "
          "each node must step at its drift level itself (checked at the first run).")
      .def("set_row_split", &LocalStepper::set_row_split, py::arg("on"),
           "The row split (nodal subcycling) instead of the column split: each node at its own level with "
           "its whole row, a coarser neighbour read along its drift (docs/local_stepping.md \"The scheme: the row "
           "split\"). Before the first run.")
      .def_property_readonly("row_split", &LocalStepper::row_split)
      .def("phase_seconds", [](const LocalStepper& stepper) { return phase_dict(stepper.phase_times()); },
           "Wall time (s) of each part of the steps (Stepper.phase_seconds; update: the drifts, stiffness: "
           "the kicks); steps counts fine steps.")
      .def("reset_phase_seconds", &LocalStepper::reset_phase_times, "Zeroes the phase times.")
      .def(
          "run",
          [](LocalStepper& stepper, const py::object& u, const py::object& v, const py::object& a,
             std::int64_t n_steps, double t0) {
            return run_in_place(stepper, 3 * stepper.n_nodes(), u, v, a, n_steps, t0);
          },
          py::arg("u").noconvert(), py::arg("v").noconvert(), py::arg("a").noconvert(),
          py::arg("n_steps"), py::arg("t0"),
          "Advances n_steps global steps of dt() from t0 (u, v, a in place); returns the end time.")
      .def(
          "save_state", sample_save_state<LocalStepper>(),
          R"(The run's state beyond u, v, a, t (checkpoint, docs/checkpoint.md): a dict of named
byte blocks (each level's last force, the energy account, every level's components and contact
pairs), a copy. points false: a sample's state (no per-row and per-point blocks: the levels'
forces, the element loop's points), as Stepper.save_state.)",
          py::arg("points") = true)
      .def(
          "load_state", sample_load_state<LocalStepper>(),
          py::arg("state"), py::arg("points") = true,
          R"(Restores save_state's dict into a stepper built from the same scene (same levels, dt_fine,
damping, providers, components and pairs at the same levels in the same order); the next run
continues without initialising. ValueError names the first block that does not fit.)")
      .def_property_readonly("dt", &LocalStepper::dt, "Global step dt_fine 2^max_level (s).")
      .def_property_readonly("dt_fine", &LocalStepper::dt_fine)
      .def_property_readonly("max_level", &LocalStepper::max_level)
      .def("work_fraction", &LocalStepper::work_fraction,
           "Stiffness blocks multiplied per simulated second relative to global stepping at dt_fine.")
      .def("energy", [](const LocalStepper& stepper) {
        const LocalStepper::Energy e = stepper.energy();
        py::dict out;
        out["kinetic"] = e.kinetic;
        out["strain"] = e.strain;
        out["initial"] = e.initial;
        out["external_work"] = e.external_work;
        out["damping_work"] = e.damping_work;
        out["internal_stored"] = e.internal_stored;
        out["internal_dissipation"] = e.internal_dissipation;
        out["contact_work"] = e.contact_work;
        out["friction_dissipation"] = e.friction_dissipation;
        out["balance"] = e.balance;
        return out;
      }, "Plain energies and works of the last run (the balance is O(dt^2), not round-off).");

  m.def(
      "set_num_threads",
      [](int n) {
        if (n < 1) throw py::value_error("n must be >= 1, got " + std::to_string(n));
        set_num_threads(n);
      },
      py::arg("n"), "Number of OpenMP threads for later kernel calls.");
  m.def("max_threads", &max_threads, "Number of OpenMP threads a kernel call would use now.");
  m.def(
      "stream_triad",
      [](const py::object& a_object, const py::object& b_object, const py::object& c_object,
         double s) {
        auto a = checked_array<double>(a_object, "a", {kAny}, true);
        const py::ssize_t n = a.shape(0);
        auto b = checked_array<double>(b_object, "b", {n});
        auto c = checked_array<double>(c_object, "c", {n});
        double* a_data = a.mutable_data();
        py::gil_scoped_release release;
        stream_triad(a_data, b.data(), c.data(), s, n);
      },
      py::arg("a").noconvert(), py::arg("b"), py::arg("c"), py::arg("s"),
      "Bandwidth probe a = b + s c (a modified in place; float64 1-D, same length).");
}
