"""What an `mpirun -n N` launch needs below the distributed model (pyfem/distributed_model.py): the
communicator, this process's rank before MPI starts, threads per rank, ending every rank after a
failure one rank alone saw, the energy of a rank's stepper summed over the ranks, and the per-pair
and per-row state blocks that a checkpoint keyed by position cuts and joins. Imports nothing of
pyfem: every execution path may use it."""
from __future__ import annotations

import os

import numpy as np
import scipy.sparse as sp


def world():
    """The communicator of an `mpirun` launch (one rank: a serial run): mpi4py's COMM_WORLD
    (imported here: `launched_rank` and the command line need no MPI)."""
    from mpi4py import MPI

    return MPI.COMM_WORLD


# Set by the launchers for each rank: Open MPI, PMIx (Open MPI 4+, srun --mpi=pmix), MPICH/Hydra, Slurm.
RANK_VARIABLES = ("OMPI_COMM_WORLD_RANK", "PMIX_RANK", "PMI_RANK", "SLURM_PROCID")


def launched_rank() -> int:
    """This process's rank as its launcher says, without initialising MPI (0: not launched as a rank)."""
    for name in RANK_VARIABLES:
        value = os.environ.get(name, "")
        if value.isdigit():
            return int(value)
    return 0


def threads_per_rank(comm) -> int | None:
    """OpenMP threads for each of the ranks sharing this machine's cores (None: serial, the caller
    decides), unless OMP_NUM_THREADS says otherwise."""
    if comm.size == 1 or os.environ.get("OMP_NUM_THREADS", "").isdigit():
        return None
    on_node = int(os.environ.get("OMPI_COMM_WORLD_LOCAL_SIZE", os.environ.get("MPI_LOCALNRANKS", comm.size)))
    return max(1, min(len(os.sched_getaffinity(0)), (os.cpu_count() or 1) // on_node))


def abort_all(error: BaseException) -> None:
    """After a failure that not every rank shares (a write on rank 0, a kernel error on one rank):
    one line on stderr, then MPI_Abort, which ends every rank of the job (the others would wait
    forever in their next exchange). Exit status 1."""
    import sys
    import traceback

    comm = world()
    traceback.print_exception(error, file=sys.__stderr__)
    print(f"error: rank {comm.rank} of {comm.size}: {type(error).__name__}: {error}; ending every rank",
          file=sys.__stderr__, flush=True)
    comm.Abort(1)


class RankSummed:
    """A rank's kernel LocalStepper (run() in global steps, a collective) whose energy() is the whole
    model's: summed over the ranks, each counting its owned rows and counted cells."""

    def __init__(self, kernel, comm) -> None:
        self.kernel, self.comm = kernel, comm

    def run(self, u, v, a, n_steps: int, t0: float) -> float:
        return self.kernel.run(u, v, a, n_steps, t0)

    def energy(self) -> dict:
        energy = self.kernel.energy()
        keys = ("kinetic", "strain", "internal_stored")
        total = self.comm.allreduce(np.array([energy[key] for key in keys]))
        return dict(zip(keys, total))


def level_bytes_per_fine_step(nodes_per_level: list) -> float:
    """Bytes of the velocity exchanges per fine step, averaged over a global step, for the given
    count of shared nodes at each level k (24 bytes each, at each of the level's 2^(L - k) drifts)."""
    top = len(nodes_per_level) - 1
    return 24.0 * sum(count * 2 ** (top - k) for k, count in enumerate(nodes_per_level)) / 2 ** top


def pair_groups(pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(nodes, group) of every node in a pair: pairs sharing a node form one group."""
    nodes = np.unique(pairs)
    local = np.searchsorted(nodes, pairs)
    graph = sp.coo_matrix((np.ones(len(pairs)), (local[:, 0], local[:, 1])), shape=(len(nodes), len(nodes)))
    _, group = sp.csgraph.connected_components(graph, directed=False)
    return nodes, group


def state_rows(block: bytes, count: int) -> np.ndarray:
    """A block of `count` equal rows as a (count, row bytes) uint8 array."""
    data = np.frombuffer(block, dtype=np.uint8)
    if count == 0:
        return data.reshape(0, 0) if data.size == 0 else data.reshape(0, -1)
    if data.size % count:
        raise ValueError(f"a state block of {data.size} bytes is not {count} equal rows")
    return data.reshape(count, -1)


CONTACT_PAIR_BLOCKS = ("state", "bond_intact", "normal_force", "tangential_force", "contact_force",
                       "deterioration", "slip_rate", "gap_offset", "static_force", "effective_normal")


def pair_blocks(state: dict, prefix: str = "") -> list[str]:
    """The per-pair blocks of CONTACT_PAIR_BLOCKS that a ContactPairs state holds (effective_normal
    only with the normal lag on)."""
    return [name for name in CONTACT_PAIR_BLOCKS if prefix + name in state]


def unique_slots(pair_nodes: np.ndarray, selected: np.ndarray) -> np.ndarray:
    """Rows of the pairs' unique nodes that the selected pairs use (ascending)."""
    unique = np.unique(pair_nodes)
    return np.searchsorted(unique, np.unique(pair_nodes[selected]))


# Coordinates (m) are matched at this resolution (1 um): a node by its position, a cell by its
# quadrature points' mean, so that a checkpoint does not depend on the partition or the rank count.
KEY_RESOLUTION = 1.0e-6


def point_keys(points: np.ndarray) -> np.ndarray:
    """(n, 3) int64 keys of positions (m)."""
    return np.round(np.asarray(points, dtype=np.float64).reshape(-1, 3) / KEY_RESOLUTION).astype(np.int64)


def rows_of(have: np.ndarray, want: np.ndarray, what: str) -> np.ndarray:
    """The row of `have` (n, k keys) holding each key of `want` (m, k); RuntimeError naming `what`
    when one is missing."""
    _, inverse = np.unique(np.concatenate([have, want]), axis=0, return_inverse=True)
    inverse = inverse.ravel()
    row_of_group = np.full(int(inverse.max(initial=-1)) + 1, -1, dtype=np.int64)
    row_of_group[inverse[:len(have)]] = np.arange(len(have))
    rows = row_of_group[inverse[len(have):]]
    if np.any(rows < 0):
        raise RuntimeError(f"checkpoint: {int(np.count_nonzero(rows < 0))} {what} of this model are not in it")
    return rows
