"""Shared test helpers: one place for tolerances."""
import numpy as np

ROUNDOFF = 1e-10  # relative agreement expected between two evaluations of the same arithmetic
EXACT = 1e-12  # relative agreement of two arrangements of the same sums over a few hundred steps


def rel_error(a, b):
    """Relative L2 error of `a` against the reference `b` (1 if b is zero and a is not)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    denom = np.linalg.norm(b)
    diff = np.linalg.norm(a - b)
    if denom == 0.0:
        return 0.0 if diff == 0.0 else 1.0
    return diff / denom


def observed_orders(hs, errors):
    """Observed convergence orders log(e_i/e_{i+1}) / log(h_i/h_{i+1}) between successive refinements."""
    hs = np.asarray(hs, dtype=float)
    errors = np.asarray(errors, dtype=float)
    return np.log(errors[:-1] / errors[1:]) / np.log(hs[:-1] / hs[1:])
