"""Progress of a run as plain lines, for a log file or a pipe (`python3 -m pyfem run ... > log`).

On a terminal the run shows a tqdm bar on stderr instead (pyfem.solver.run); off a terminal a
bar is noise in a file, so the command line hands the solver a `ProgressLines`, which prints one
flushed line each time the simulated time passes another `step` (5 %) of the duration:

    progress:  25 %  t = 0.5 s of 2 s, wall 12.3 s, estimated end in 36.9 s (at 14:05:31)

The estimate extrapolates the wall time per simulated second of the time loop so far.
"""
from __future__ import annotations

import math
import sys
import time
from typing import TextIO


def format_seconds(seconds: float) -> str:
    """A duration for a person: 4.2 s, 3.5 min, 1.2 h."""
    if seconds >= 3600.0:
        return f"{seconds / 3600.0:.3g} h"
    if seconds >= 60.0:
        return f"{seconds / 60.0:.3g} min"
    return f"{seconds:.3g} s"


class ProgressLines:
    """Prints a progress line every `step` of the simulated duration.

    Args:
        duration: simulated time the run reaches (s), > 0.
        stream: where the lines go (default: sys.stdout); each line is flushed.
        step: fraction of the duration between two lines (0.05: every 5 %).
        clock: wall clock (s), for tests.

    Call `start(t0)` when the time loop starts and the object itself with the simulated time
    reached after each chunk of steps; the last call (t >= duration) always prints. A record's
    lead-in runs at t < 0 (record time): a loop that starts there counts its percentage over the
    lead-in and the duration, so that a long lead-in is not silent (issue 51).
    """

    def __init__(self, duration: float, stream: TextIO | None = None, step: float = 0.05,
                 clock=time.perf_counter):
        self.duration = float(duration)
        self.stream = stream
        self.step = float(step)
        self.clock = clock
        self._t0 = 0.0
        self._origin = 0.0  # where the percentage counts from: min(t0, 0)
        self._wall0 = None
        self._next = 1  # number of the next step to report
        self.lines = 0

    def start(self, t0: float = 0.0) -> None:
        """The time loop starts at simulated time t0 (s) now."""
        self._t0 = float(t0)
        self._origin = min(self._t0, 0.0)
        self._wall0 = self.clock()

    def __call__(self, t: float) -> None:
        """The run reached simulated time t (s)."""
        if self._wall0 is None:
            self.start(0.0)
        span = self.duration - self._origin
        fraction = (t - self._origin) / span if span > 0 else 1.0
        # 1e-9: t is a sum of steps, a hair below the exact multiple of the duration (or its 5 %).
        fraction = 1.0 if fraction > 1.0 - 1e-9 else fraction
        reached = math.floor(fraction / self.step + 1e-9)
        if reached < self._next and fraction < 1.0:
            return
        self._next = reached + 1
        wall = self.clock() - self._wall0
        done = t - self._t0
        remaining = (self.duration - t) * wall / done if done > 0 else math.nan
        if fraction >= 1.0 or not math.isfinite(remaining):
            end = "done" if fraction >= 1.0 else "estimated end: not yet known"
        else:
            finish = time.strftime("%H:%M:%S", time.localtime(time.time() + remaining))
            end = f"estimated end in {format_seconds(remaining)} (at {finish})"
        stream = self.stream if self.stream is not None else sys.stdout
        lead_in = " (the record's lead-in)" if t < 0.0 else ""
        print(f"progress: {100 * fraction:3.0f} %  t = {t:.6g} s{lead_in} of {self.duration:g} s, "
              f"wall {format_seconds(wall)}, {end}", file=stream, flush=True)
        self.lines += 1
