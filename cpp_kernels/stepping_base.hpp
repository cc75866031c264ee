// What global stepping (Stepper) and local stepping (LocalStepper) share, written once: the
// matrix and mass they borrow, the nodal effects (dashpots and constraints, with the strong
// guarantee), the constraints' reactions, the force providers, an MPI rank's partition and the
// check that every effect sits on owned nodes, the phase clock, and the element-loop components'
// blocks of a checkpoint. Each scheme keeps its own step, energy account and checkpoint layout.
#pragma once

#include <cmath>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "bsr.hpp"
#include "contact.hpp"
#include "force_provider.hpp"
#include "nodal_effects.hpp"
#include "state_archive.hpp"

namespace cavern {

/// Wall time of each part of the steps run so far (s): where the time goes. Two clock reads per
/// phase per step (omp_get_wtime, ~20 ns each), nothing per node.
struct PhaseTimes {
  double update = 0.0;         // pass A: v_{n+1/2}, u_{n+1} (and the components' g_n.v bookkeeping)
  double element_loop = 0.0;   // the internal-force components: g(u_{n+1}), its power, commit
  double input_forces = 0.0;   // the force providers (seismic input, held forces) and their work
  double stiffness = 0.0;      // pass B: K u (+ beta K v) and the per-node velocity/energy update
  double contact = 0.0;        // the contact pairs' correction
  double exchange = 0.0;       // the ghost exchange between MPI ranks (NodeExchange)
  std::int64_t steps = 0;      // steps timed
};

/// The nodes a rank shares with other ranks (MPI, docs/scaling.md "The distributed step"): a
/// rank numbers its owned nodes first, then its ghosts (the other ranks' nodes its matrix rows
/// and cells touch). After every step, exchange() sends v_{n+1} and a_{n+1} of the owned nodes
/// other ranks ghost and overwrites this rank's ghost rows with their owners' values; the next
/// pass A then gives the ghosts the owners' u_{n+2} bit for bit. A serial run has none.
class NodeExchange {
 public:
  virtual ~NodeExchange() = default;
  /// v, a: (3 n_nodes) of this rank, owned first. a null: v only (LocalStepper::set_partition).
  virtual void exchange(double* v, double* a) = 0;
};

class SteppingBase {
 public:
  virtual ~SteppingBase() = default;

  /// Implicit 3x3 dashpots C (count, 3, 3) at nodes (count); replaces any previous set. A node
  /// listed twice gets the sum of its dashpots. Strong guarantee: on a bad entry (a node outside
  /// the model, an asymmetric or indefinite C) std::invalid_argument names it and nothing changes.
  void set_dashpots(const std::int32_t* nodes, std::int64_t count, const double* C) {
    change_effects([&] { effects_.set_dashpots(nodes, count, C); }, false);
  }

  /// Kinematic constraints (constraints.hpp): node k moves only in the range of the orthogonal
  /// projection P_k (count, 3, 3); P = 0 holds the node (fixed), I - n n^T holds its normal
  /// component (roller). Replaces any previous set; nodes must be distinct. Strong guarantee as
  /// set_dashpots. The support's reactions are reported by reactions().
  void set_constraints(const std::int32_t* nodes, std::int64_t count, const double* projection) {
    change_effects([&] { effects_.set_constraints(nodes, count, projection); }, true);
    reactions_.assign(3 * count, 0.0);
  }

  /// Reactions (constraints, 3) of the constraints at the end of the last step (N), in
  /// set_constraints order: R = -(I - P)(r - d), the held part of the node's net force.
  const std::vector<double>& reactions() const { return reactions_; }

  /// Wall time per phase of the steps since construction or the last reset_phase_times().
  const PhaseTimes& phase_times() const { return phase_times_; }
  void reset_phase_times() { phase_times_ = PhaseTimes{}; }

  std::int64_t n_nodes() const { return stiffness_.n_block_rows; }
  std::int64_t n_dofs() const { return 3 * stiffness_.n_block_rows; }
  /// Nodes whose u, v, a and energy this stepper keeps: set_partition's n_owned, else every node.
  std::int64_t n_owned_nodes() const { return n_owned_ < 0 ? n_nodes() : n_owned_; }

 protected:
  /// Borrows K and the lumped mass; throws std::invalid_argument for a mass that is not finite
  /// and > 0.
  SteppingBase(const BlockCsrView& stiffness, const double* mass)
      : stiffness_(stiffness), mass_(mass), effects_(stiffness.n_block_rows) {
    for (std::int64_t i = 0; i < stiffness.n_block_rows; ++i)
      if (!(mass[i] > 0.0 && std::isfinite(mass[i])))
        throw std::invalid_argument("mass[" + std::to_string(i) + "] = " + std::to_string(mass[i]) +
                                    " must be finite and > 0");
  }

  /// The scheme's own operators of the nodal effects (its implicit per-node inverses), rebuilt
  /// after a change; constraints: the constraints changed (else the dashpots). May throw: the
  /// change is then undone and the hook called again on the previous effects.
  virtual void nodal_effects_changed(bool constraints) = 0;

  /// One MPI rank's share: the first n_owned nodes are its own. Throws for n_owned outside
  /// [0, n_nodes].
  void set_owned(std::int64_t n_owned) {
    if (n_owned < 0 || n_owned > n_nodes())
      throw std::invalid_argument("n_owned = " + std::to_string(n_owned) + " must be in [0, " +
                                  std::to_string(n_nodes()) + "]");
    n_owned_ = n_owned;
  }

  /// With a partition: throws std::invalid_argument naming the first dashpot, constraint, listed
  /// provider node or pair node on a ghost (a share's effects must be on its own nodes).
  void require_effects_owned(const std::vector<const ContactPairs*>& pairs) const {
    if (n_owned_ < 0) return;
    auto require_owned = [this](const std::vector<std::int32_t>& nodes, const std::string& what) {
      for (const std::int32_t node : nodes)
        if (node >= n_owned_) throw NodalEffects::ghost_error(what, node, n_owned_);
    };
    effects_.require_owned(n_owned_);
    for (const auto& provider : providers_) require_owned(provider->nodes(), provider->name());
    for (const ContactPairs* set : pairs) require_owned(set->unique_nodes(), "a contact pair");
  }

  /// Checks a provider's nodes against the model and keeps it (shared: the caller may query it).
  void attach_provider(std::shared_ptr<ForceProvider> provider) {
    provider->check_nodes(n_nodes());
    providers_.push_back(std::move(provider));
  }

  /// A checkpoint's blocks of element-loop components: each one's name, then its own state.
  template <class Components>
  static void save_components(StateArchive& archive, const std::string& prefix,
                              const Components& components) {
    for (std::size_t k = 0; k < components.size(); ++k) {
      const std::string own = prefix + std::to_string(k) + "/";
      archive.put_text(own + "name", components[k]->name());
      components[k]->save_state(archive, own);
    }
  }
  /// Throws std::invalid_argument naming the first component whose saved name differs (`where`:
  /// how the message names the component's place), reading nothing else.
  template <class Components>
  static void check_component_names(const StateArchive& archive, const std::string& prefix,
                                    const Components& components, const std::string& where) {
    for (std::size_t k = 0; k < components.size(); ++k) {
      const std::string saved = archive.text(prefix + std::to_string(k) + "/name");
      if (saved != components[k]->name())
        throw std::invalid_argument("checkpoint: " + where + "component " + std::to_string(k) +
                                    " is a " + saved + ", the model's is a " + components[k]->name());
    }
  }
  template <class Components>
  static void load_components(const StateArchive& archive, const std::string& prefix,
                              const Components& components) {
    for (std::size_t k = 0; k < components.size(); ++k)
      components[k]->load_state(archive, prefix + std::to_string(k) + "/");
  }

  BlockCsrView stiffness_;
  const double* mass_;
  NodalEffects effects_;               // dashpots and constraints as given, validated
  std::vector<double> reactions_;      // (constraints, 3) of the last step
  std::vector<std::shared_ptr<ForceProvider>> providers_;
  std::int64_t n_owned_ = -1;          // set_owned; -1: every node
  PhaseTimes phase_times_;

 private:
  template <class Change>
  void change_effects(Change change, bool constraints) {
    NodalEffects previous = effects_;
    change();  // (NodalEffects' setters change nothing when they throw)
    try {
      nodal_effects_changed(constraints);
    } catch (...) {
      effects_ = std::move(previous);
      nodal_effects_changed(constraints);
      throw;
    }
  }
};

}  // namespace cavern
