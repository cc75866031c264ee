// The ghost exchange of a distributed run over MPI (docs/scaling.md "The distributed step"):
// the one message per neighbour rank and step that the Stepper's NodeExchange asks for.
// Only the Python module links MPI; the kernel library and its tests stay MPI-free.
#pragma once

#define OMPI_SKIP_MPICXX 1  // the C API only
#include <mpi.h>

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "stepper.hpp"

namespace cavern {

/// Per neighbour rank q: send_nodes[q] are this rank's owned nodes that q holds as ghosts,
/// recv_nodes[q] this rank's ghosts that q owns, both in the order q's lists use (ascending
/// global number), so that message k of one rank is message k of the other.
class MpiNodeExchange : public NodeExchange {
 public:
  MpiNodeExchange(MPI_Comm comm, std::vector<int> neighbours,
                  std::vector<std::vector<std::int32_t>> send_nodes,
                  std::vector<std::vector<std::int32_t>> recv_nodes, std::int64_t n_nodes)
      : neighbours_(std::move(neighbours)),
        send_nodes_(std::move(send_nodes)),
        recv_nodes_(std::move(recv_nodes)) {
    if (send_nodes_.size() != neighbours_.size() || recv_nodes_.size() != neighbours_.size())
      throw std::invalid_argument("one send and one receive list per neighbour rank");
    for (const auto* lists : {&send_nodes_, &recv_nodes_})
      for (const auto& nodes : *lists)
        for (const std::int32_t node : nodes)
          if (node < 0 || node >= n_nodes)
            throw std::invalid_argument("exchange node " + std::to_string(node) +
                                        " is not a node in [0, " + std::to_string(n_nodes) + ")");
    // A communicator of its own: the exchange's messages never meet mpi4py's.
    MPI_Comm_dup(comm, &comm_);
    send_buffers_.resize(neighbours_.size());
    recv_buffers_.resize(neighbours_.size());
    for (std::size_t q = 0; q < neighbours_.size(); ++q) {
      send_buffers_[q].resize(6 * send_nodes_[q].size());
      recv_buffers_[q].resize(6 * recv_nodes_[q].size());
    }
    requests_.resize(2 * neighbours_.size());
  }
  ~MpiNodeExchange() override {
    int finalized = 0;
    MPI_Finalized(&finalized);
    if (!finalized) MPI_Comm_free(&comm_);
  }
  MpiNodeExchange(const MpiNodeExchange&) = delete;
  MpiNodeExchange& operator=(const MpiNodeExchange&) = delete;

  /// a null: v only (3 values per node instead of 6; local time stepping's per-level exchange).
  void exchange(double* v, double* a) override {
    const int n = static_cast<int>(neighbours_.size());
    const int per_node = a ? 6 : 3;
    for (int q = 0; q < n; ++q)
      MPI_Irecv(recv_buffers_[q].data(), per_node * static_cast<int>(recv_nodes_[q].size()), MPI_DOUBLE,
                neighbours_[q], kTag, comm_, &requests_[q]);
    for (int q = 0; q < n; ++q) {
      double* out = send_buffers_[q].data();
      for (const std::int32_t node : send_nodes_[q])
        for (int c = 0; c < 3; ++c) {
          *out++ = v[3 * node + c];
          if (a) *out++ = a[3 * node + c];
        }
      MPI_Isend(send_buffers_[q].data(), per_node * static_cast<int>(send_nodes_[q].size()), MPI_DOUBLE,
                neighbours_[q], kTag, comm_, &requests_[n + q]);
    }
    MPI_Waitall(2 * n, requests_.data(), MPI_STATUSES_IGNORE);
    for (int q = 0; q < n; ++q) {
      const double* in = recv_buffers_[q].data();
      for (const std::int32_t node : recv_nodes_[q])
        for (int c = 0; c < 3; ++c) {
          v[3 * node + c] = *in++;
          if (a) a[3 * node + c] = *in++;
        }
    }
  }

  /// Bytes this rank sends per exchange of v and a (the Stepper's one per step; half with v only).
  std::int64_t bytes_sent_per_step() const { return 48 * sent_nodes(); }

 private:
  static constexpr int kTag = 7301;
  MPI_Comm comm_ = MPI_COMM_NULL;
  std::vector<int> neighbours_;
  std::vector<std::vector<std::int32_t>> send_nodes_, recv_nodes_;
  std::vector<std::vector<double>> send_buffers_, recv_buffers_;
  std::vector<MPI_Request> requests_;

  std::int64_t sent_nodes() const {
    std::int64_t count = 0;
    for (const auto& nodes : send_nodes_) count += static_cast<std::int64_t>(nodes.size());
    return count;
  }
};

}  // namespace cavern
