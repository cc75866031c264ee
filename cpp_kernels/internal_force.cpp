#include "internal_force.hpp"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "materials/concrete_damage.hpp"
#include "materials/linear_elastic.hpp"
#include "materials/mohr_coulomb.hpp"

namespace cavern {

HexahedronElementsBase::HexahedronElementsBase(const HexahedronGeometry& geometry,
                                               const ElementOptions& options,
                                               const double* initial_stress)
    : geometry_(geometry), options_(options) {
  if (geometry.tensor) {  // owned: the caller's table may go
    tensor_ = *geometry.tensor;
    geometry_.tensor = &tensor_;
  }
  const std::int64_t n_cells = geometry.n_cells, n_points = geometry.n_points, k = geometry.n_basis;
  if (geometry.reference_gradients) {  // owned: the same for every cell, read from cache
    reference_gradients_.assign(geometry.reference_gradients,
                                geometry.reference_gradients + n_points * k * 3);
    geometry_.reference_gradients = reference_gradients_.data();
  }
  if (k != 4 && k != 10 && k != 8 && k != 27)
    throw std::invalid_argument("cell_nodes: " + std::to_string(k) +
                                " nodes per cell; tetrahedra have 4 (P1) or 10 (P2), hexahedra 8 "
                                "(Q1) or 27 (Q2)");
  if (n_cells < 0 || (n_cells > 0 && n_points < 1))
    throw std::invalid_argument("weights: need at least one quadrature point per cell");
  for (std::int64_t j = 0; j < n_cells * k; ++j)
    if (geometry.cell_nodes[j] < 0)
      throw std::invalid_argument("cell_nodes[" + std::to_string(j / k) + ", " +
                                  std::to_string(j % k) +
                                  "] = " + std::to_string(geometry.cell_nodes[j]) + " is negative");
  auto require_finite = [](const double* values, std::int64_t count, const std::string& name) {
    for (std::int64_t j = 0; j < count; ++j)
      if (!std::isfinite(values[j]))
        throw std::invalid_argument(name + ": entry " + std::to_string(j) + " is not finite");
  };
  if (geometry.tensor) {
    if (k != 27 || n_points != 27 || !geometry.inverse_jacobians || geometry.gradients)
      throw std::invalid_argument(
          "gradients: the tensor form is for Q2 cells with 27 points, given with the inverse "
          "Jacobians and without dense gradients");
    if (options.mean_dilatation)
      throw std::invalid_argument("mean_dilatation needs the dense or the reference form, not the tensor form");
    const TensorQ2& t = *geometry.tensor;
    require_finite(t.basis, 9, "tensor basis");
    require_finite(t.derivative, 9, "tensor derivative");
    bool node_seen[27] = {}, point_seen[27] = {};
    for (int j = 0; j < 27; ++j) {
      if (t.node_order[j] < 0 || t.node_order[j] >= 27 || node_seen[t.node_order[j]] ||
          t.point_order[j] < 0 || t.point_order[j] >= 27 || point_seen[t.point_order[j]])
        throw std::invalid_argument("tensor node_order and point_order: permutations of 0..26");
      node_seen[t.node_order[j]] = point_seen[t.point_order[j]] = true;
    }
    require_finite(geometry.inverse_jacobians, n_cells * n_points * 9, "inverse_jacobians");
  } else if (geometry.reference_gradients) {
    if (!geometry.inverse_jacobians || geometry.gradients)
      throw std::invalid_argument(
          "gradients: the reference form is the inverse Jacobians with the reference gradients, "
          "without dense gradients");
    require_finite(geometry.reference_gradients, n_points * k * 3, "reference_gradients");
    require_finite(geometry.inverse_jacobians, n_cells * n_points * 9, "inverse_jacobians");
  } else {
    if (!geometry.gradients || geometry.inverse_jacobians)
      throw std::invalid_argument(
          "gradients: dense gradients, or the inverse Jacobians with the reference gradients or "
          "the tensor tables");
    require_finite(geometry.gradients, n_cells * n_points * k * 3, "gradients");
  }
  if (options.single_geometry) {
    if (!geometry.inverse_jacobians)
      throw std::invalid_argument(
          "single_geometry: needs the inverse Jacobians (the reference or tensor form)");
    single_inverses_.assign(geometry.inverse_jacobians,
                            geometry.inverse_jacobians + n_cells * n_points * 9);
  }
  characteristic_length_.assign(n_cells, 0.0);
  std::vector<double> volumes(n_cells);  // sum_q w_q of each cell
  for (std::int64_t cell = 0; cell < n_cells; ++cell) {
    double& volume = volumes[cell];
    for (std::int64_t q = 0; q < n_points; ++q) {
      const double w = geometry.weights[cell * n_points + q];
      if (!(std::isfinite(w) && w > 0.0))
        throw std::invalid_argument("weights[" + std::to_string(cell) + ", " + std::to_string(q) +
                                    "] = " + std::to_string(w) +
                                    " must be finite and > 0 (weight x det J of a valid cell)");
      volume += w;
    }
    characteristic_length_[cell] = std::cbrt(volume);
  }
  if (initial_stress) {
    initial_stress_.assign(initial_stress, initial_stress + 6 * n_cells * n_points);
    for (std::size_t j = 0; j < initial_stress_.size(); ++j)
      if (!std::isfinite(initial_stress_[j]))
        throw std::invalid_argument("initial_stress: entry " + std::to_string(j) +
                                    " is not finite");
  }
  element_force_.assign(3 * n_cells * k, 0.0);
  cell_energy_.assign(2 * n_cells, 0.0);
  if (options.mean_dilatation && !geometry.tensor) {
    // Cell means of the basis gradients, sum_q w_q grad phi_a(x_q) / sum_q w_q: geometry, once
    // (reference form: grad phi_a = R_a J^-1 with J^-1 as the loop holds it).
    mean_gradients_.assign(3 * n_cells * k, 0.0);
    std::vector<double> G(3 * k);
    for (std::int64_t cell = 0; cell < n_cells; ++cell) {
      double* mean = mean_gradients_.data() + 3 * cell * k;
      for (std::int64_t q = 0; q < n_points; ++q) {
        const std::int64_t point = cell * n_points + q;
        const double w = geometry.weights[point];
        if (geometry.gradients) {
          std::copy_n(geometry.gradients + point * k * 3, 3 * k, G.begin());
        } else {
          const double* R = reference_gradients_.data() + q * k * 3;
          double inverse[9];
          for (int j = 0; j < 9; ++j)
            inverse[j] = single_inverses_.empty() ? geometry.inverse_jacobians[9 * point + j]
                                                  : single_inverses_[9 * point + j];
          for (std::int64_t a = 0; a < k; ++a)
            for (int l = 0; l < 3; ++l)
              G[3 * a + l] = R[3 * a] * inverse[l] + R[3 * a + 1] * inverse[3 + l] +
                             R[3 * a + 2] * inverse[6 + l];
        }
        for (std::int64_t j = 0; j < 3 * k; ++j) mean[j] += w * G[j];
      }
      for (std::int64_t j = 0; j < 3 * k; ++j) mean[j] /= volumes[cell];
    }
  }

  // Node -> slots (cell * k + a) by a counting sort over the slots in increasing order, so each
  // node's slots are increasing and the gather sums in a fixed order.
  const std::int64_t n_slots = n_cells * k;
  std::int32_t max_node = -1;
  for (std::int64_t j = 0; j < n_slots; ++j) max_node = std::max(max_node, geometry.cell_nodes[j]);
  std::vector<std::int64_t> count(static_cast<std::size_t>(max_node) + 1, 0);
  for (std::int64_t j = 0; j < n_slots; ++j) ++count[geometry.cell_nodes[j]];
  std::vector<std::int64_t> index_of_node(count.size(), -1);
  for (std::size_t node = 0; node < count.size(); ++node)
    if (count[node]) {
      index_of_node[node] = static_cast<std::int64_t>(unique_nodes_.size());
      unique_nodes_.push_back(static_cast<std::int32_t>(node));
    }
  node_ptr_.assign(unique_nodes_.size() + 1, 0);
  for (std::size_t m = 0; m < unique_nodes_.size(); ++m)
    node_ptr_[m + 1] = node_ptr_[m] + count[unique_nodes_[m]];
  node_slots_.resize(n_slots);
  std::vector<std::int64_t> next(node_ptr_.begin(), node_ptr_.end() - 1);
  for (std::int64_t j = 0; j < n_slots; ++j)
    node_slots_[next[index_of_node[geometry.cell_nodes[j]]]++] = j;
}

void HexahedronElementsBase::commit() {
  if (!trial_ready_)
    throw std::logic_error(name() + ": commit() without a compute() since the last commit()");
  swap_states();
  stored_energy_ = trial_energy_.stored;
  dissipation_ += trial_energy_.dissipation_increment;
  trial_ready_ = false;
}

void HexahedronElementsBase::rebase() {
  const std::int64_t n = geometry_.n_cells * geometry_.n_points;
  if (initial_stress_.empty()) initial_stress_.assign(6 * n, 0.0);
  rebase_states(initial_stress_.data());
  stored_energy_ = 0.0;
  trial_ready_ = false;
}

void HexahedronElementsBase::save_state(StateArchive& archive, const std::string& prefix) const {
  if (archive.per_point()) {
    archive.put(prefix + "points", std::vector<std::int64_t>{geometry_.n_cells * geometry_.n_points});
    save_points(archive, prefix + "state");
    archive.put(prefix + "initial_stress", initial_stress_);
  }
  archive.put_value(prefix + "stored_energy", stored_energy_);
  archive.put_value(prefix + "dissipation", dissipation_);
}

void HexahedronElementsBase::load_state(const StateArchive& archive, const std::string& prefix) {
  if (archive.per_point()) {
    std::vector<std::int64_t> points{geometry_.n_cells * geometry_.n_points};
    archive.get(prefix + "points", points);
    if (points[0] != geometry_.n_cells * geometry_.n_points)
      throw std::invalid_argument("checkpoint block '" + prefix + "points': " +
                                  std::to_string(points[0]) + " points, the model has " +
                                  std::to_string(geometry_.n_cells * geometry_.n_points));
    load_points(archive, prefix + "state");
    // sigma0 at every point, or none (a component built without initial stress, never rebased).
    archive.get_resized(prefix + "initial_stress", initial_stress_);
    if (!initial_stress_.empty() && initial_stress_.size() != static_cast<std::size_t>(6 * points[0]))
      throw std::invalid_argument("checkpoint block '" + prefix + "initial_stress': " +
                                  std::to_string(initial_stress_.size()) + " values, the model needs 0 or " +
                                  std::to_string(6 * points[0]));
  }
  archive.get_value(prefix + "stored_energy", stored_energy_);
  archive.get_value(prefix + "dissipation", dissipation_);
  // A pending trial state is dropped (commit() now throws); the next compute() starts from the
  // committed points, loaded or, for a sample's archive, as they were.
  trial_ready_ = false;
}

void HexahedronElementsBase::check_nodes(std::int64_t n_nodes) const {
  if (!unique_nodes_.empty() && unique_nodes_.back() >= n_nodes)
    throw std::invalid_argument(name() + ": cell node " + std::to_string(unique_nodes_.back()) +
                                " is not a node in [0, " + std::to_string(n_nodes) + ")");
}

std::int64_t HexahedronElementsBase::owned_bytes() const {
  return static_cast<std::int64_t>(sizeof(double) *
                                       (initial_stress_.size() + characteristic_length_.size() +
                                        element_force_.size() + cell_energy_.size() +
                                        mean_gradients_.size() + reference_gradients_.size()) +
                                   sizeof(float) * single_inverses_.size() +
                                   sizeof(std::int32_t) * unique_nodes_.size() +
                                   sizeof(std::int64_t) * (node_ptr_.size() + node_slots_.size()));
}

void HexahedronElementsBase::add_element_forces(double* out_force) const {
  const std::int64_t n_unique = static_cast<std::int64_t>(unique_nodes_.size());
  const double* element_force = element_force_.data();
#pragma omp parallel for schedule(static) if (threaded())
  for (std::int64_t m = 0; m < n_unique; ++m) {
    double f0 = 0.0, f1 = 0.0, f2 = 0.0;
    for (std::int64_t j = node_ptr_[m]; j < node_ptr_[m + 1]; ++j) {
      const double* slot = element_force + 3 * node_slots_[j];
      f0 += slot[0];
      f1 += slot[1];
      f2 += slot[2];
    }
    double* target = out_force + 3 * static_cast<std::int64_t>(unique_nodes_[m]);
    target[0] += f0;
    target[1] += f1;
    target[2] += f2;
  }
}

InternalEnergy HexahedronElementsBase::gather(double* out_force) {
  add_element_forces(out_force);
  InternalEnergy energy;
  for (std::int64_t cell = 0; cell < geometry_.n_cells; ++cell) {
    energy.stored += cell_energy_[2 * cell];
    energy.dissipation_increment += cell_energy_[2 * cell + 1];
  }
  trial_energy_ = energy;
  trial_ready_ = true;
  return energy;
}

std::shared_ptr<HexahedronElementsBase> make_hexahedron_elements(const std::string& law,
                                                                 const ParameterMap& parameters,
                                                                 const HexahedronGeometry& geometry,
                                                                 const ElementOptions& options,
                                                                 const double* initial_stress) {
  // One line per law (materials/*.hpp).
  if (law == LinearElastic::kName)
    return std::make_shared<HexahedronElements<LinearElastic>>(
        geometry, LinearElastic::parameters_from(parameters), options, initial_stress);
  if (law == MohrCoulombLaw::kName)
    return std::make_shared<HexahedronElements<MohrCoulombLaw>>(
        geometry, MohrCoulombLaw::parameters_from(parameters), options, initial_stress);
  if (law == ConcreteDamageLaw::kName)
    return std::make_shared<HexahedronElements<ConcreteDamageLaw>>(
        geometry, ConcreteDamageLaw::parameters_from(parameters), options, initial_stress);
  std::string known;
  for (const std::string& name : known_laws()) known += (known.empty() ? "" : ", ") + name;
  throw std::invalid_argument("law '" + law + "' is not known; known laws: " + known);
}

std::vector<std::string> known_laws() {
  return {LinearElastic::kName, MohrCoulombLaw::kName, ConcreteDamageLaw::kName};
}

}  // namespace cavern
