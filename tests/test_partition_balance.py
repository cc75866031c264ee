"""Weighted partitions for MPI runs (pyfem/distributed.py `node_work`, `bisection` with weights,
docs/scaling.md "Weighted partitions"): a rank's share of a step follows its nodes' work, not their
count. Without MPI: the partition is computed from the replicated model, the same on every rank
(tests/test_mpi.py runs the partitions under mpirun against the serial run)."""
import numpy as np
import pytest

from pyfem import distributed, solver
from pyfem.scene import parse_scene


def test_weighted_bisection_cuts_at_half_the_weight():
    points = np.column_stack([np.arange(10.0), np.zeros(10), np.zeros(10)])
    weights = np.ones(10)
    weights[0] = 9.0  # half of the total (18) on the first point
    assert distributed.bisection(points, 2).tolist() == [0] * 5 + [1] * 5
    assert distributed.bisection(points, 2, weights).tolist() == [0] + [1] * 9
    line = np.column_stack([np.arange(12.0), np.zeros(12), np.zeros(12)])
    three = distributed.bisection(line, 3, np.ones(12))
    assert three.tolist() == [0] * 4 + [1] * 4 + [2] * 4  # unit weights: the count's cuts
    assert np.array_equal(three, distributed.bisection(line, 3))


@pytest.mark.parametrize("integration", ["full", "reduced"])
def test_a_plastic_layer_in_one_half_is_shared_by_work(integration):
    """A column whose lower quarter is a Mohr-Coulomb layer (the element loop: ~2.3 matrix rows per
    point): cut by node count along its height, one rank gets the whole layer; cut by work, the
    ranks' modelled work is within 5 % of each other. With one point per cell the layer's cells count
    ONE_POINT_CELL_POINTS points each (their gather and scatter), not one."""
    scene = parse_scene({
        "mesh": {"builder": "box", "size": [12.0, 6.0, 48.0], "h": 2.0, "order": 1,
                 "layers": [{"material": "soft", "thickness": 12.0}, {"material": "rock", "thickness": 36.0}]},
        "materials": {"soft": {"E": 2.0e9, "nu": 0.3, "rho": 2400.0,
                               "plasticity": {"cohesion": 1.0e6, "friction_angle": 30.0, "tensile_strength": 1.0e5,
                                              "damage_max": 0.9, "damage_plastic_strain": 0.005,
                                              "integration": integration}},
                      "rock": {"E": 8.0e9, "nu": 0.24, "rho": 2600.0}},
        "time": {"duration": 0.01},
    }, source="test")
    simulation = solver.prepare(scene, solve_static=False)
    work = distributed.node_work(simulation)
    cells = simulation.nonlinear.arrays["soft"].cells.size
    points = 8 if integration == "full" else distributed.ONE_POINT_CELL_POINTS
    assert np.sum(work - 1.0) == pytest.approx(distributed.POINT_WORK * points * cells, rel=1e-12)
    assert work.max() > (10 if integration == "full" else 3) * work.min()  # the layer's nodes carry the element loop
    ratios = {}
    for weighted in (False, True):
        per_rank = distributed.rank_work(simulation, distributed.partition(simulation, 2, weighted=weighted))
        ratios[weighted] = per_rank.max() / per_rank.mean()
    print("max / mean work, by count and by work:", ratios)
    assert ratios[False] > 1.3 and ratios[True] < 1.05
