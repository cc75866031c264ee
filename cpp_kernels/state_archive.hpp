// Named byte blocks of the kernel objects' state, for checkpoint and resume (docs/checkpoint.md).
// Each stateful object (Stepper, ContactPairs, the internal-force components) writes what a run
// needs to continue bit for bit and reads it back into objects built from the same scene; a
// block of the wrong size or a missing block is an error, never a silent partial state.
#pragma once

#include <cstdint>
#include <cstring>
#include <map>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

namespace cavern {

class StateArchive {
 public:
  using Blocks = std::map<std::string, std::vector<std::uint8_t>>;

  StateArchive() = default;
  explicit StateArchive(Blocks blocks) : blocks_(std::move(blocks)) {}

  /// Stores the bytes of `values` under `name` (replacing a block of that name).
  template <class T>
  void put(const std::string& name, const std::vector<T>& values) {
    static_assert(std::is_trivially_copyable_v<T>, "state blocks hold trivially copyable values");
    const auto* bytes = reinterpret_cast<const std::uint8_t*>(values.data());
    blocks_[name].assign(bytes, bytes + values.size() * sizeof(T));
  }

  template <class T>
  void put_value(const std::string& name, const T& value) {
    put(name, std::vector<T>{value});
  }

  /// Reads the block `name` into `values`, whose size (already that of the object being
  /// restored) must match. Throws std::invalid_argument for a missing block or another size.
  template <class T>
  void get(const std::string& name, std::vector<T>& values) const {
    static_assert(std::is_trivially_copyable_v<T>, "state blocks hold trivially copyable values");
    const std::vector<std::uint8_t>& block = find(name);
    if (block.size() != values.size() * sizeof(T))
      throw std::invalid_argument("checkpoint block '" + name + "' holds " +
                                  std::to_string(block.size()) + " bytes, the model needs " +
                                  std::to_string(values.size() * sizeof(T)) +
                                  " (a checkpoint of another model?)");
    if (!block.empty()) std::memcpy(values.data(), block.data(), block.size());
  }

  /// Reads the block `name` into `values`, resized to the block (for state whose size the
  /// restored object does not know beforehand). Throws std::invalid_argument for a missing block
  /// or one that is not a whole number of values.
  template <class T>
  void get_resized(const std::string& name, std::vector<T>& values) const {
    const std::vector<std::uint8_t>& block = find(name);
    if (block.size() % sizeof(T) != 0)
      throw std::invalid_argument("checkpoint block '" + name + "' holds " +
                                  std::to_string(block.size()) + " bytes, not whole values of " +
                                  std::to_string(sizeof(T)));
    values.resize(block.size() / sizeof(T));
    get(name, values);
  }

  void put_text(const std::string& name, const std::string& text) {
    put(name, std::vector<char>(text.begin(), text.end()));
  }

  std::string text(const std::string& name) const {
    const std::vector<std::uint8_t>& block = find(name);
    return std::string(block.begin(), block.end());
  }

  template <class T>
  void get_value(const std::string& name, T& value) const {
    std::vector<T> one(1);
    get(name, one);
    value = one[0];
  }

  bool contains(const std::string& name) const { return blocks_.count(name) != 0; }
  const Blocks& blocks() const { return blocks_; }

  /// false: a sample's state, not a checkpoint's: the objects leave out (and do not read) their
  /// per-point and per-node blocks (the element loop's points and initial stress, the stepper's
  /// nodal internal force) and keep the rest (energy account, reactions, contact pairs). Under
  /// mpirun the ranks merge this at every output sample and the whole state only where fields
  /// or a checkpoint are written (pyfem/distributed_model.py).
  bool per_point() const { return per_point_; }
  void set_per_point(bool per_point) { per_point_ = per_point; }

 private:
  const std::vector<std::uint8_t>& find(const std::string& name) const {
    const auto found = blocks_.find(name);
    if (found == blocks_.end())
      throw std::invalid_argument("checkpoint has no block '" + name +
                                  "' (a checkpoint of another model or build?)");
    return found->second;
  }

  Blocks blocks_;
  bool per_point_ = true;
};

}  // namespace cavern
