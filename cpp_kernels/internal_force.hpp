// Internal forces computed element by element, for the regions whose material is not linear
// elastic (docs/ARCHITECTURE.md "Kernel"). The linear regions stay in the stiffness matrix; the
// stepper adds the forces of these components to its block-CSR product.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "materials/material_law.hpp"
#include "state_archive.hpp"
#include "tensor_q2.hpp"

namespace cavern {

/// Energies (J) of a component's trial state.
struct InternalEnergy {
  double stored = 0.0;                 // sum_points w psi at the trial state
  double dissipation_increment = 0.0;  // sum_points w delta from the committed to the trial state
};

/// A set of cells whose internal force f_int(u) the stepper adds to K u.
///
/// compute() evaluates a trial state from the committed one and never changes the committed
/// state, so it may be called any number of times (the stepper calls it once per step and once
/// in reset_energy); commit() accepts the last trial. The stepper's balance uses stored_energy()
/// and dissipation() (stepper.hpp: with the internal work W_int it closes the account exactly).
class InternalForceComponent {
 public:
  virtual ~InternalForceComponent() = default;

  /// Adds f_int(u) = sum_cells sum_points w B^T (sigma_trial - sigma0) to out_force (3 n_nodes,
  /// dof = 3 node + component), computing the trial state at the displacement u (3 n_nodes)
  /// from the committed state. Returns the trial energies. May run OpenMP loops itself; the
  /// result does not depend on the number of threads.
  virtual InternalEnergy compute(const double* u, double* out_force) = 0;

  /// Makes the trial state of the last compute() the committed state (stored energy and
  /// accumulated dissipation included). Throws std::logic_error without a compute() since the
  /// last commit().
  virtual void commit() = 0;

  /// Adds beta K0 v to out_force (3 n_nodes): the stiffness-proportional Rayleigh damping force
  /// of these cells, K0 their initial elastic stiffness (the cells are not in the matrix that
  /// the stepper damps). A damping force: no state, in the stepper's damping work.
  virtual void add_stiffness_damping(const double* v, double beta, double* out_force) = 0;

  /// Makes the committed state the reference of a new run (the static stage's hand-over,
  /// pyfem/static.py): its stress becomes the initial stress sigma0, its strain the zero of the
  /// next run's displacement, its stored energy 0; history (plastic strain, damage) and the
  /// accumulated dissipation are kept. The next compute() must be at a displacement measured
  /// from the state that was committed (u = 0 of the new run). A pending trial (compute()
  /// without commit()) is discarded.
  virtual void rebase() = 0;

  /// Writes the committed state (per point, the initial stress, the energies) under `prefix`
  /// (checkpoint, docs/checkpoint.md); load_state reads it back into a component built from the
  /// same cells and law, the trial state reset to the committed one. An archive that is not
  /// per_point() holds the energies only. Throws std::invalid_argument for a missing block or
  /// one of another size.
  virtual void save_state(StateArchive& archive, const std::string& prefix) const = 0;
  virtual void load_state(const StateArchive& archive, const std::string& prefix) = 0;

  /// Stored energy of the committed state (J).
  virtual double stored_energy() const = 0;

  /// Dissipation accumulated over all commits since construction (J), >= 0 for a sound law.
  virtual double dissipation() const = 0;

  /// Distinct nodes the component loads, sorted (the local stepper's rows of its level).
  virtual const std::vector<std::int32_t>& nodes() const = 0;

  /// Throws std::invalid_argument naming a node outside [0, n_nodes).
  virtual void check_nodes(std::int64_t n_nodes) const = 0;

  /// Short name used in messages.
  virtual std::string name() const = 0;
};

/// Borrowed element arrays of hexahedral cells (Q1: k = 8, Q2: k = 27) or tetrahedral cells (P1:
/// k = 4 with one point, P2: k = 10 with four), from pyfem/elements.py.
/// The basis gradients dphi_a/dx at the points come in one of three forms:
///   dense:     gradients (c, q, k, 3) (one-point cells with their mean gradients);
///   reference: the reference gradients dphi_a/dX (q, k, 3), the same for every cell (copied),
///              and the inverse Jacobians (c, q, 3, 3) dX_m/dx_l: the element loop streams 9
///              numbers per point instead of 3 k (72 B against 192 B for Q1, 648 B for Q2) and
///              applies J^-1 to the 3x3 reference gradient of u and to the point's flux;
///   tensor:    (Q2 with its 27-point Gauss rule) the cell type's TensorQ2 (tensor_q2.hpp) and
///              the inverse Jacobians: the reference gradients by sum factorisation, about a
///              third of the dense arithmetic.
/// Exactly one of gradients, (reference_gradients, inverse_jacobians) and (tensor,
/// inverse_jacobians) is set.
struct HexahedronGeometry {
  std::int64_t n_cells = 0;
  std::int64_t n_points = 0;                 // q, quadrature points per cell
  std::int64_t n_basis = 0;                  // k, nodes per cell
  const std::int32_t* cell_nodes = nullptr;  // (c, k) node of each basis function
  const double* gradients = nullptr;         // (c, q, k, 3) dphi/dx at the points (1/m), or null
  const double* weights = nullptr;           // (c, q) quadrature weight x det J (m^3), > 0
  const TensorQ2* tensor = nullptr;          // the tensor form, or null
  const double* inverse_jacobians = nullptr;  // (c, q, 3, 3) dX_m/dx_l (1/m), reference/tensor form
  const double* reference_gradients = nullptr;  // (q, k, 3) dphi/dX, reference form, or null
};

/// Options of the element loop.
struct ElementOptions {
  /// Mean dilatation (B-bar) against volumetric locking of Q1 with plastic flow: the
  /// volumetric strain at every point is replaced by its cell mean,
  ///   eps_bar = eps + 1/3 (theta_bar - tr eps) I,  theta_bar = sum_q w_q tr eps_q / sum_q w_q,
  /// and the force is its exact derivative, f_a = sum_q w_q [s grad phi_a + 1/3 tr(s)
  /// (mean grad phi_a - grad phi_a)], s = sigma - sigma0. Exact for linear displacements.
  bool mean_dilatation = false;
  /// Below this many cells the loop runs on one thread (a parallel region costs more).
  std::int64_t min_cells_for_threads = 512;
  /// Reference and tensor forms: the inverse Jacobians held as float32 (36 B per point instead of
  /// 72; the component owns the rounded copy). The strain and the force then carry a relative
  /// error of about 6e-8 (float32's unit round-off) of the geometry; the state stays double.
  bool single_geometry = false;
};

/// The law-independent part of the hexahedron loop: geometry, the node gather, energies.
///
/// Threading: each cell writes its element force to its own slot of an owned buffer (c, k, 3);
/// a second loop gives each node the sum of its slots in a fixed order (cell, then local
/// index). Nothing is summed by atomics or per-thread buffers, so the force, the stress and
/// the energies are the same bits for any number of threads.
class HexahedronElementsBase : public InternalForceComponent {
 public:
  /// Throws std::invalid_argument for k not in {4, 10, 8, 27}, a negative node, a non-finite gradient
  /// or a weight <= 0, or an initial_stress that is not finite. initial_stress (c, q, 6) is
  /// copied (null: zero).
  HexahedronElementsBase(const HexahedronGeometry& geometry, const ElementOptions& options,
                         const double* initial_stress);

  void commit() override;
  void rebase() override;
  void save_state(StateArchive& archive, const std::string& prefix) const override;
  void load_state(const StateArchive& archive, const std::string& prefix) override;
  double stored_energy() const override { return stored_energy_; }
  double dissipation() const override { return dissipation_; }
  void check_nodes(std::int64_t n_nodes) const override;

  std::int64_t n_cells() const { return geometry_.n_cells; }
  std::int64_t n_points() const { return geometry_.n_points; }
  std::int64_t n_basis() const { return geometry_.n_basis; }
  const ElementOptions& options() const { return options_; }
  /// Cube root of each cell's volume sum_q w_q (m), the law's characteristic length (the same
  /// formula for tetrahedra: the cube root of the tetrahedron's volume).
  const std::vector<double>& characteristic_length() const { return characteristic_length_; }
  /// Distinct nodes of the cells, sorted.
  const std::vector<std::int32_t>& nodes() const override { return unique_nodes_; }

  /// Committed total stress (c, q, 6) into out (Pa, order of material_law.hpp).
  virtual void stress(double* out) const = 0;
  /// Committed total stress of the n points `points` (flat index cell * q + point, each in
  /// [0, c q), checked by the caller) into out (n, 6).
  virtual void stress_at(const std::int64_t* points, std::int64_t n, double* out) const = 0;
  /// The law's report (material_law.hpp PointOutput) of the committed state of the n points
  /// `points` (null: all c q points, n ignored) into damage, damage_type, plastic_strain and
  /// crack_strain (each (n,) or (c, q)); a null output is skipped.
  virtual void point_output(const std::int64_t* points, std::int64_t n, double* damage,
                            std::int32_t* damage_type, double* plastic_strain,
                            double* crack_strain = nullptr) const = 0;
  /// Quadrature weight x det J of every point (c, q) (m^3), borrowed.
  const double* weights() const { return geometry_.weights; }
  /// Bytes of the state, buffers and adjacency this component owns (geometry is borrowed).
  virtual std::int64_t owned_bytes() const;
  /// sizeof the law's state of one point (one copy).
  virtual std::int64_t state_bytes() const = 0;
  /// Bytes of geometry the loop reads per point: 3 k doubles of gradients (dense form) or the 9
  /// of J^-1 (double or float), and the weight.
  std::int64_t geometry_bytes() const {
    const std::int64_t weight = sizeof(double);
    if (geometry_.gradients) return 3 * geometry_.n_basis * sizeof(double) + weight;
    return 9 * (single_inverses_.empty() ? sizeof(double) : sizeof(float)) + weight;
  }

 protected:
  // Adds the element forces of the last cell loop to out_force, node by node, in a fixed order.
  void add_element_forces(double* out_force) const;
  // add_element_forces, then sums the per-cell energies in cell order and marks the trial
  // ready for commit().
  InternalEnergy gather(double* out_force);
  // Swaps the committed and trial state arrays of the law.
  virtual void swap_states() = 0;
  // The law's per-point state: committed into the archive; back, trial = committed.
  virtual void save_points(StateArchive& archive, const std::string& name) const = 0;
  virtual void load_points(const StateArchive& archive, const std::string& name) = 0;
  // Law::rebase of every committed point, the committed stress into sigma0 (c, q, 6), trial = committed.
  virtual void rebase_states(double* initial_stress) = 0;
  const double* initial_stress_of(std::int64_t cell, std::int64_t point) const {
    return initial_stress_.empty()
               ? kZeroStress
               : initial_stress_.data() + 6 * (cell * geometry_.n_points + point);
  }
  bool threaded() const { return geometry_.n_cells >= options_.min_cells_for_threads; }

  static constexpr double kZeroStress[6] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
  // Forms of the geometry in the cell loop: dense gradients, or J^-1 in double or float.
  static constexpr int kDense = 0, kDoubleInverse = 1, kSingleInverse = 2;
  static constexpr int kMaxBasis = 27;

  HexahedronGeometry geometry_;  // its tensor and reference gradients, if any, point to the copies
  TensorQ2 tensor_{};
  std::vector<double> reference_gradients_;   // (q, k, 3) of the reference form, or empty
  std::vector<float> single_inverses_;        // (c, q, 9) single_geometry's J^-1, or empty
  ElementOptions options_;
  std::vector<double> initial_stress_;         // (c, q, 6) or empty
  std::vector<double> characteristic_length_;  // (c)
  std::vector<double> mean_gradients_;         // (c, k, 3) cell means of grad phi_a (B-bar)
  std::vector<double> element_force_;          // (c, k, 3) of the last cell loop
  std::vector<double> cell_energy_;            // (c, 2): stored, dissipation increment
  std::vector<std::int32_t> unique_nodes_;     // sorted
  std::vector<std::int64_t> node_ptr_;         // (unique + 1) slots of each node
  std::vector<std::int64_t> node_slots_;       // cell * k + local index, increasing per node
  bool trial_ready_ = false;
  InternalEnergy trial_energy_;
  double stored_energy_ = 0.0;
  double dissipation_ = 0.0;
};

/// Hexahedral cells of one region with the material law `Law` (material_law.hpp) at every
/// quadrature point:
///   eps_q = sym(sum_a u_a (x) grad phi_a(x_q)) (engineering shear),
///   (sigma_q, psi_q, delta_q) = Law::evaluate(committed_q, eps_q),
///   f_a = sum_q w_q (sigma_q - sigma0_q) grad phi_a(x_q)   (+ the mean-dilatation term).
/// With LinearElastic this is K_cells u of the same quadrature, to round-off.
template <class Law>
class HexahedronElements final : public HexahedronElementsBase {
 public:
  HexahedronElements(const HexahedronGeometry& geometry, const typename Law::Parameters& parameters,
                     const ElementOptions& options, const double* initial_stress)
      : HexahedronElementsBase(geometry, options, initial_stress),
        parameters_(parameters),
        moduli_(Law::elastic_moduli(parameters)) {
    const std::int64_t n = geometry.n_cells * geometry.n_points;
    committed_.resize(n);
    for (std::int64_t cell = 0; cell < geometry.n_cells; ++cell)
      for (std::int64_t q = 0; q < geometry.n_points; ++q)
        committed_[cell * geometry.n_points + q] =
            Law::initial_state(parameters_, initial_stress_of(cell, q),
                               characteristic_length_[cell]);
    trial_ = committed_;
  }

  InternalEnergy compute(const double* u, double* out_force) override {
    dispatch(u, false);
    return gather(out_force);
  }

  void add_stiffness_damping(const double* v, double beta, double* out_force) override {
    beta_ = beta;
    dispatch(v, true);
    add_element_forces(out_force);
  }

  void stress(double* out) const override {
    const std::int64_t n = geometry_.n_cells * geometry_.n_points;
    for (std::int64_t p = 0; p < n; ++p)
      for (int c = 0; c < 6; ++c) out[6 * p + c] = committed_[p].stress[c];
  }

  void stress_at(const std::int64_t* points, std::int64_t n, double* out) const override {
    for (std::int64_t j = 0; j < n; ++j)
      for (int c = 0; c < 6; ++c) out[6 * j + c] = committed_[points[j]].stress[c];
  }

  void point_output(const std::int64_t* points, std::int64_t n, double* damage,
                    std::int32_t* damage_type, double* plastic_strain,
                    double* crack_strain = nullptr) const override {
    if (!points) n = geometry_.n_cells * geometry_.n_points;
    for (std::int64_t j = 0; j < n; ++j) {
      const PointOutput report = Law::output(committed_[points ? points[j] : j]);
      if (damage) damage[j] = report.damage;
      if (damage_type) damage_type[j] = report.damage_type;
      if (plastic_strain) plastic_strain[j] = report.plastic_strain;
      if (crack_strain) crack_strain[j] = report.crack_strain;
    }
  }

  std::int64_t owned_bytes() const override {
    return HexahedronElementsBase::owned_bytes() +
           static_cast<std::int64_t>(2 * committed_.size() * sizeof(typename Law::State));
  }

  std::int64_t state_bytes() const override { return sizeof(typename Law::State); }

  std::string name() const override {
    return std::string(geometry_.n_basis == 4 || geometry_.n_basis == 10 ? "tetrahedra/" : "hexahedra/") +
           Law::kName;
  }
  const typename Law::Parameters& parameters() const { return parameters_; }
  const std::vector<typename Law::State>& committed_state() const { return committed_; }

 private:
  void swap_states() override { std::swap(committed_, trial_); }

  void save_points(StateArchive& archive, const std::string& name) const override {
    archive.put(name, committed_);
  }

  void load_points(const StateArchive& archive, const std::string& name) override {
    archive.get(name, committed_);
    trial_ = committed_;
  }

  void rebase_states(double* initial_stress) override {
    for (std::size_t p = 0; p < committed_.size(); ++p) {
      Law::rebase(parameters_, committed_[p]);
      for (int c = 0; c < 6; ++c) initial_stress[6 * p + c] = committed_[p].stress[c];
    }
    trial_ = committed_;
  }

  // The cell loop compiled for the cell's node count (P1 and P2 tetrahedra, Q1 and Q2
  // hexahedra) and the form of its geometry (kDense, or J^-1 in double or float).
  void dispatch(const double* x, bool damping) {
    switch (geometry_.n_basis) {
      case 4: return dispatch_form<4>(x, damping);
      case 10: return dispatch_form<10>(x, damping);
      case 8: return dispatch_form<8>(x, damping);
      default: return dispatch_form<27>(x, damping);
    }
  }

  template <int kBasis>
  void dispatch_form(const double* x, bool damping) {
    if (geometry_.gradients) return cell_loop<kBasis, kDense>(x, damping);
    if (!single_inverses_.empty()) return cell_loop<kBasis, kSingleInverse>(x, damping);
    return cell_loop<kBasis, kDoubleInverse>(x, damping);
  }

  template <int kBasis, int kForm>
  void cell_loop(const double* x, bool damping) {
    const std::int64_t n_cells = geometry_.n_cells;
    // Dynamic chunks: a yielding point costs ~6x an elastic one and the yielding cells cluster
    // (around the cavern, contiguous in the numbering), so static halves left one thread with
    // all of them. Each cell writes only its own slots: the result does not depend on the order.
#pragma omp parallel for schedule(dynamic, 64) if (threaded())
    for (std::int64_t cell = 0; cell < n_cells; ++cell) {
      if (damping)
        cell_damping<kBasis, kForm>(cell, x);
      else
        cell_force<kBasis, kForm>(cell, x);
    }
  }

  // Trial states, energies and element force of one cell at the displacement u.
  template <int kBasis, int kForm>
  void cell_force(std::int64_t cell, const double* u) {
    double stored = 0.0, dissipation = 0.0;
    integrate_cell<kBasis, kForm>(cell, u, [&](std::int64_t q, const double* strain, double* s) {
      const std::int64_t p = cell * geometry_.n_points + q;
      const double* sigma0 = initial_stress_of(cell, q);
      const PointStrain point{strain, sigma0, characteristic_length_[cell]};
      const PointEnergy energy = Law::evaluate(parameters_, committed_[p], point, trial_[p]);
      const double w = geometry_.weights[p];
      stored += w * energy.stored;
      dissipation += w * energy.dissipation;
      for (int c = 0; c < 6; ++c) s[c] = trial_[p].stress[c] - sigma0[c];
    });
    cell_energy_[2 * cell] = stored;
    cell_energy_[2 * cell + 1] = dissipation;
  }

  // Element force beta C0 : eps(v) of one cell (C0 the law's initial elastic moduli).
  template <int kBasis, int kForm>
  void cell_damping(std::int64_t cell, const double* v) {
    const double beta_lambda = beta_ * moduli_.lame_lambda;
    const double beta_G = beta_ * moduli_.shear_modulus;
    integrate_cell<kBasis, kForm>(cell, v, [&](std::int64_t, const double* strain, double* s) {
      const double trace_term = beta_lambda * (strain[0] + strain[1] + strain[2]);
      for (int c = 0; c < 3; ++c) s[c] = trace_term + 2.0 * beta_G * strain[c];
      for (int c = 3; c < 6; ++c) s[c] = beta_G * strain[c];  // engineering shear
    });
  }

  // f_a = sum_q w_q [s_q grad phi_a + (mean dilatation) 1/3 tr(s_q) (mean grad phi_a -
  // grad phi_a)] into element_force_ of the cell, with s_q = stress_of(q, eps_q) (Voigt).
  // Dense form: grad phi_a read per point. Reference form: grad phi_a = R_a J^-1 formed per point
  // (R_a = dphi_a/dX, the same for every cell, J^-1 = dX/dx of the point): 9 numbers streamed per
  // point instead of 3 k.
  template <int kBasis, int kForm, class StressOf>
  void integrate_cell(std::int64_t cell, const double* x, StressOf&& stress_of) {
    using Inverse = std::conditional_t<kForm == kSingleInverse, float, double>;
    const std::int64_t n_points = geometry_.n_points;
    [[maybe_unused]] const Inverse* cell_inverses = nullptr;
    if constexpr (kForm != kDense) {
      cell_inverses = inverse_table<Inverse>() + cell * n_points * 9;
      if constexpr (kBasis == 27) {
        if (geometry_.tensor) return integrate_cell_tensor(cell, x, cell_inverses, stress_of);
      }
    }
    const std::int32_t* nodes = geometry_.cell_nodes + cell * kBasis;
    const double* cell_gradients =
        kForm == kDense ? geometry_.gradients + cell * n_points * kBasis * 3 : nullptr;
    const double* weights = geometry_.weights + cell * n_points;
    double x_cell[kBasis][3];
    for (int a = 0; a < kBasis; ++a)
      for (int i = 0; i < 3; ++i) x_cell[a][i] = x[3 * static_cast<std::int64_t>(nodes[a]) + i];

    // Mean dilatation: the cell means of grad phi_a (geometry, computed at construction) and of
    // tr eps.
    const bool mean_dilatation = options_.mean_dilatation;
    const double* mean_gradient = mean_dilatation ? mean_gradients_.data() + cell * kBasis * 3
                                                  : nullptr;
    double mean_trace = 0.0;
    if (mean_dilatation)
      for (int a = 0; a < kBasis; ++a)
        for (int i = 0; i < 3; ++i) mean_trace += x_cell[a][i] * mean_gradient[3 * a + i];

    double force[kBasis][3] = {};
    double trace_sum = 0.0;  // mean dilatation: sum_q 1/3 tr(s_q), the weight of the mean gradient
    for (std::int64_t q = 0; q < n_points; ++q) {
      // dphi_a/dx_l of the point: read (dense form), or R_a J^-1 formed in L1 from the
      // reference gradients, shared by the cells, and the point's J^-1 (reference form).
      [[maybe_unused]] double formed[kBasis * 3];
      const double* G = formed;
      if constexpr (kForm == kDense) {
        G = cell_gradients + q * kBasis * 3;
      } else {
        const double* R = reference_gradients_.data() + q * kBasis * 3;
        const Inverse* inverse = cell_inverses + 9 * q;
        double J[9];
        for (int j = 0; j < 9; ++j) J[j] = inverse[j];
        for (int a = 0; a < kBasis; ++a)
          for (int l = 0; l < 3; ++l)
            formed[3 * a + l] = R[3 * a] * J[l] + R[3 * a + 1] * J[3 + l] + R[3 * a + 2] * J[6 + l];
      }
      // H_il = dx_i/dx_l = sum_a x_a,i dphi_a/dx_l
      double H[3][3] = {};
      for (int a = 0; a < kBasis; ++a)
        for (int i = 0; i < 3; ++i)
          for (int l = 0; l < 3; ++l) H[i][l] += x_cell[a][i] * G[3 * a + l];
      // Engineering shear (material_law.hpp).
      double strain[6] = {H[0][0],           H[1][1],           H[2][2],
                          H[0][1] + H[1][0], H[1][2] + H[2][1], H[0][2] + H[2][0]};
      if (mean_dilatation) {
        const double correction = (mean_trace - (H[0][0] + H[1][1] + H[2][2])) / 3.0;
        for (int c = 0; c < 3; ++c) strain[c] += correction;
      }
      double voigt[6];
      stress_of(q, strain, voigt);
      const double w = weights[q];
      double s[3][3];
      s[0][0] = w * voigt[kXX];
      s[1][1] = w * voigt[kYY];
      s[2][2] = w * voigt[kZZ];
      s[0][1] = s[1][0] = w * voigt[kXY];
      s[1][2] = s[2][1] = w * voigt[kYZ];
      s[0][2] = s[2][0] = w * voigt[kXZ];
      if (mean_dilatation) {
        // 1/3 tr(s) (mean grad phi_a - grad phi_a): the point's part by the deviator of s
        // below, the mean gradient's once per cell after the loop.
        const double third_trace = (s[0][0] + s[1][1] + s[2][2]) / 3.0;
        trace_sum += third_trace;
        for (int i = 0; i < 3; ++i) s[i][i] -= third_trace;
      }
      for (int a = 0; a < kBasis; ++a)
        for (int i = 0; i < 3; ++i)
          force[a][i] += s[i][0] * G[3 * a] + s[i][1] * G[3 * a + 1] + s[i][2] * G[3 * a + 2];
    }
    if (mean_dilatation)
      for (int a = 0; a < kBasis; ++a)
        for (int i = 0; i < 3; ++i) force[a][i] += trace_sum * mean_gradient[3 * a + i];
    double* out = element_force_.data() + cell * kBasis * 3;
    for (int a = 0; a < kBasis; ++a)
      for (int i = 0; i < 3; ++i) out[3 * a + i] = force[a][i];
  }

  // integrate_cell of a Q2 cell in the tensor form (no mean dilatation): with R = dphi/dX by
  // sum factorisation (tensor_q2.hpp) and J^-1 = dX/dx at the point,
  //   du_i/dx_l = sum_m (dU_i/dX_m) J^-1_ml,  f_n,i = sum_q sum_m dphi_n/dX_m(q) t_im(q),
  //   t_im = w_q sum_l s_il J^-1_ml.
  template <class Inverse, class StressOf>
  void integrate_cell_tensor(std::int64_t cell, const double* x, const Inverse* inverses,
                             StressOf& stress_of) {
    const TensorQ2& tensor = *geometry_.tensor;
    const std::int32_t* nodes = geometry_.cell_nodes + cell * 27;
    const double* weights = geometry_.weights + cell * 27;
    double U[3][27];
    for (int n = 0; n < 27; ++n) {
      const std::int64_t node = nodes[tensor.node_order[n]];
      for (int i = 0; i < 3; ++i) U[i][n] = x[3 * node + i];
    }
    double reference[3][3][27];  // [i][m][point] dU_i/dX_m
    for (int i = 0; i < 3; ++i) tensor_q2_gradient(tensor, U[i], reference[i]);
    double flux[3][3][27];  // [i][m][point] t_im
    for (int p = 0; p < 27; ++p) {
      const int q = tensor.point_order[p];
      double inverse[9];
      for (int j = 0; j < 9; ++j) inverse[j] = inverses[9 * q + j];
      double H[3][3];
      for (int i = 0; i < 3; ++i)
        for (int l = 0; l < 3; ++l)
          H[i][l] = reference[i][0][p] * inverse[l] + reference[i][1][p] * inverse[3 + l] +
                    reference[i][2][p] * inverse[6 + l];
      double strain[6] = {H[0][0],           H[1][1],           H[2][2],
                          H[0][1] + H[1][0], H[1][2] + H[2][1], H[0][2] + H[2][0]};
      double voigt[6];
      stress_of(q, strain, voigt);
      const double w = weights[q];
      const double s[3][3] = {{w * voigt[kXX], w * voigt[kXY], w * voigt[kXZ]},
                              {w * voigt[kXY], w * voigt[kYY], w * voigt[kYZ]},
                              {w * voigt[kXZ], w * voigt[kYZ], w * voigt[kZZ]}};
      for (int i = 0; i < 3; ++i)
        for (int m = 0; m < 3; ++m)
          flux[i][m][p] = s[i][0] * inverse[3 * m] + s[i][1] * inverse[3 * m + 1] +
                          s[i][2] * inverse[3 * m + 2];
    }
    double force[3][27];
    for (int i = 0; i < 3; ++i) tensor_q2_divergence(tensor, flux[i], force[i]);
    double* out = element_force_.data() + cell * 27 * 3;
    for (int n = 0; n < 27; ++n)
      for (int i = 0; i < 3; ++i) out[3 * tensor.node_order[n] + i] = force[i][n];
  }

  // The inverse Jacobians of the reference and tensor forms, as held.
  template <class Inverse>
  const Inverse* inverse_table() const {
    if constexpr (std::is_same_v<Inverse, float>)
      return single_inverses_.data();
    else
      return geometry_.inverse_jacobians;
  }

  typename Law::Parameters parameters_;
  ElasticModuli moduli_;  // initial elastic moduli (stiffness-proportional damping)
  double beta_ = 0.0;
  std::vector<typename Law::State> committed_, trial_;  // (c, q)
};

/// The component for a law given by name (LinearElastic::kName, ...) and its named parameters.
/// Throws std::invalid_argument naming an unknown law (and the known ones) or a bad parameter.
std::shared_ptr<HexahedronElementsBase> make_hexahedron_elements(const std::string& law,
                                                                 const ParameterMap& parameters,
                                                                 const HexahedronGeometry& geometry,
                                                                 const ElementOptions& options,
                                                                 const double* initial_stress);

/// Names of the laws make_hexahedron_elements knows.
std::vector<std::string> known_laws();

}  // namespace cavern
