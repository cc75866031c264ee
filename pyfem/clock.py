"""The run's clock: its first time, its steps, and where a record's window starts.

Record time is run time: t = 0 is the start of the record's window in monitors, plots, run.json
and `time.duration`; a zero-phase filter's lead-in (its quiet precursor, kept before the window)
runs at negative times, from the run's origin.
"""
from __future__ import annotations

import math


def whole_steps(duration: float, time_step) -> int:
    """The steps of a run: whole output intervals, the last sample on or just after the duration."""
    n_steps = math.ceil(duration / time_step.dt - 1e-9)
    return time_step.steps_per_output * math.ceil(n_steps / time_step.steps_per_output)


def run_origin(lead_in: float, time_step) -> float:
    """The run's first time (s): 0, or with a record's filter lead-in of `lead_in` s before its
    window, minus the whole output intervals that hold it. Record time is run time: t = 0 is the
    start of the record's window in monitors, plots and time.duration. The origin is the same
    product as the time loop's (k steps_per_output dt), so the sample at t = 0 is exactly 0."""
    if lead_in <= 0.0:
        return 0.0
    per_output = time_step.steps_per_output * time_step.dt
    k = math.ceil(lead_in / per_output - 1e-9)
    return -(k * time_step.steps_per_output * time_step.dt)


def run_steps(duration: float, lead_in: float, time_step) -> int:
    """The steps from the run's origin (run_origin) to time.duration, whole output intervals."""
    return whole_steps(duration - run_origin(lead_in, time_step), time_step)


def record_lead_in(record) -> float:
    """The filter lead-in (s) of a processed record (0 without one): its window's start in its own time."""
    return 0.0 if record is None else float(record.record_start)
