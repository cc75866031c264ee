// A whole model cut into MPI ranks' shares for the kernel tests (docs/scaling.md "The distributed
// step"): owned nodes first, then ghosts, and the ranks run as threads that meet at a barrier.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <vector>

#include "random_system.hpp"

namespace cavern::testing {

/// Both threads wait here until both have arrived (reusable).
class Barrier {
 public:
  void arrive_and_wait() {
    std::unique_lock<std::mutex> lock(mutex_);
    const int generation = generation_;
    if (++arrived_ == 2) {
      arrived_ = 0;
      ++generation_;
      condition_.notify_all();
    } else {
      condition_.wait(lock, [&] { return generation_ != generation; });
    }
  }

 private:
  std::mutex mutex_;
  std::condition_variable condition_;
  int arrived_ = 0, generation_ = 0;
};

/// One share of a whole model: owned nodes first, then ghosts, both ascending.
struct Share {
  std::vector<std::int64_t> nodes;  // global node of each local node
  std::int64_t n_owned = 0;
  BlockSystem system;               // blocks with an owned index (and the ghosts' diagonal)
};

/// The share owning `owned` (ascending global nodes): its ghosts are the owned rows' columns.
inline Share make_share(const BlockSystem& whole, const std::vector<std::int64_t>& owned) {
  const std::int64_t n = whole.n_nodes;
  Share share;
  std::vector<char> is_local(n, 0);
  for (const std::int64_t i : owned) {
    share.nodes.push_back(i);
    is_local[i] = 1;
  }
  share.n_owned = static_cast<std::int64_t>(owned.size());
  for (const std::int64_t i : owned)  // ghosts: the owned rows' columns
    for (std::int64_t k = whole.indptr[i]; k < whole.indptr[i + 1]; ++k)
      if (!is_local[whole.indices[k]]) is_local[whole.indices[k]] = 2;
  for (std::int64_t j = 0; j < n; ++j)
    if (is_local[j] == 2) share.nodes.push_back(j);
  const std::int64_t m = static_cast<std::int64_t>(share.nodes.size());
  share.system.n_nodes = m;
  share.system.dense.assign(9 * m * m, 0.0);
  std::vector<char> pattern(m * m, 0);
  std::vector<std::int64_t> local(n, -1);
  for (std::int64_t l = 0; l < m; ++l) local[share.nodes[l]] = l;
  for (std::int64_t i = 0; i < n; ++i)
    for (std::int64_t k = whole.indptr[i]; k < whole.indptr[i + 1]; ++k) {
      const std::int64_t li = local[i], lj = local[whole.indices[k]];
      if (li < 0 || lj < 0 || (li >= share.n_owned && lj >= share.n_owned && li != lj)) continue;
      pattern[li * m + lj] = 1;
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c)
          share.system.dense[(3 * li + r) * 3 * m + 3 * lj + c] =
              whole.dense[(3 * i + r) * 3 * n + 3 * whole.indices[k] + c];
    }
  compress(share.system, pattern);
  for (const std::int64_t node : share.nodes) share.system.mass.push_back(whole.mass[node]);
  return share;
}

/// The share owning the nodes [first, end).
inline Share make_share(const BlockSystem& whole, std::int64_t first, std::int64_t end) {
  std::vector<std::int64_t> owned;
  for (std::int64_t i = first; i < end; ++i) owned.push_back(i);
  return make_share(whole, owned);
}

}  // namespace cavern::testing
