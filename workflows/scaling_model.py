"""The MPI scaling model of docs/scaling.md: per rank and per step, the work of the explicit
step against the bytes and messages of the ghost exchange, for a mesh partitioned into compact
subdomains of N nodes each: the model for 100+ ranks; workflows/strong_scaling.py measures
this machine's 2 cores.

    work      t_work = 3 N c                      c: kernel seconds per dof and step on one core
    ghosts    G = s N^(2/3)                        s ~ 6 for a cube-like subdomain (6 faces)
    exchange  t_x = m L + 48 G / B                 m neighbour messages, L latency, B bandwidth,
                                                   48 bytes = v, a (6 doubles) per ghost node
    share     t_x / t_work, and with the exchange overlapped by the interior product:
              max(0, t_x - t_interior) / t_work, t_interior = 3 (N - G) c

Usage: /usr/bin/python3 workflows/scaling_model.py [--cost NS_PER_DOF] [--element-loop FACTOR]
prints the markdown table of docs/scaling.md.
"""
import argparse

# Interconnects: (name, latency s, bandwidth bytes/s). Typical published figures, not measured here.
NETWORKS = (("InfiniBand HDR", 1.5e-6, 20.0e9), ("10 GbE, TCP", 30.0e-6, 1.1e9),
            ("shared memory (one machine)", 0.5e-6, 8.0e9))
SURFACE_FACTOR = 6.0      # ghost nodes G = s N^(2/3) of a cube-like subdomain
NEIGHBOURS = 14           # messages per step: faces and edges of a graph partition (26 at most)
BYTES_PER_GHOST = 48.0    # v_{n+1}, a_{n+1}: 6 float64 per ghost node (cpp_kernels/mpi_exchange.hpp)


def rows(cost_per_dof: float, element_factor: float, sizes=(1_000, 3_000, 10_000, 30_000, 100_000, 300_000)):
    """(N, G, t_work, {network: (share, overlapped share)}) for each subdomain size N (nodes)."""
    out = []
    for n in sizes:
        ghosts = SURFACE_FACTOR * n ** (2.0 / 3.0)
        work = 3.0 * n * cost_per_dof * element_factor
        interior = 3.0 * max(n - ghosts, 0.0) * cost_per_dof * element_factor
        shares = {}
        for name, latency, bandwidth in NETWORKS:
            exchange = NEIGHBOURS * latency + BYTES_PER_GHOST * ghosts / bandwidth
            shares[name] = (exchange / work, max(0.0, exchange - interior) / work)
        out.append((n, ghosts, work, shares))
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cost", type=float, default=45.0,
                        help="kernel ns per dof and step on one core (README benchmark: 34-51 ns, Q1, one thread)")
    parser.add_argument("--element-loop", type=float, default=1.0,
                        help="work factor of the element loop over nonlinear cells (case 3 at rest: ~4)")
    args = parser.parse_args(argv)
    names = [name for name, _, _ in NETWORKS]
    print("| nodes per rank N | ghost nodes | work ms/step | " + " | ".join(
        f"{name}: exchange / work (overlapped)" for name in names) + " |")
    print("|---:|---:|---:|" + "---:|" * len(names))
    for n, ghosts, work, shares in rows(1e-9 * args.cost, args.element_loop):
        cells = " | ".join(f"{100 * s:.1f} % ({100 * o:.1f} %)" for s, o in shares.values())
        print(f"| {n:,} | {ghosts:,.0f} | {1e3 * work:.3f} | {cells} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
