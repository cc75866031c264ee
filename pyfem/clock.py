"""The run's clock: its time step (`TimeStep`, chosen by `time_step_from`), its first time, its
steps, where a record's window starts, and a step's wall time split into the kernel's phases
(`phase_split`). Every path (serial, static stage, distributed model) reads it; it imports none.

Record time is run time: t = 0 is the start of the record's window in monitors, plots, run.json
and `time.duration`; a zero-phase filter's lead-in (its quiet precursor, kept before the window)
runs at negative times, from the run's origin.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from pyfem.errors import SceneError


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


@dataclass
class TimeStep:
    """The time step and how it was chosen.

    Attributes:
        dt: step used (s).
        critical: stability limit of central differences with the damping correction (s).
        omega_max: highest circular frequency used for the limit (rad/s).
        reason: a sentence for the plan and run.json.
        steps_per_output: steps between two monitor samples.
    """

    dt: float
    critical: float
    omega_max: float
    reason: str
    steps_per_output: int


# Power iterations of the stable step's estimate (choose_time_step).
POWER_ITERATIONS = 300


def time_step_from(scene: dict, omega2_bound: float, omega2_power: float | None, beta: float) -> TimeStep:
    """The step of `choose_time_step` from its two estimates of omega_max^2: the Gershgorin bound
    and the power iteration's (None: not run); also the distributed model's (pyfem/distributed_model.py)."""
    how = "Gershgorin bound"
    omega2 = omega2_bound
    if omega2_power is not None:
        if 1.05 * omega2_power < omega2_bound:
            omega2 = 1.05 * omega2_power
            how = f"power iteration (+5 %), {math.sqrt(omega2_bound / omega2):.2f}x sharper than Gershgorin"
    omega = math.sqrt(omega2)
    xi = 0.5 * beta * omega
    critical = (2.0 / omega) * (math.sqrt(1.0 + xi * xi) - xi)
    interval = scene["output"]["interval"]
    user_dt = scene["time"].get("dt")
    if user_dt is not None:
        if user_dt > critical:
            raise SceneError("time.dt", user_dt,
                             f"a step at most the stable step {critical:.6g} s "
                             f"(omega_max {omega:.6g} rad/s from the {how})")
        dt_wanted = user_dt
        reason = f"user dt; stable limit {critical:.4g} s from the {how}"
    else:
        dt_wanted = scene["time"]["safety"] * critical
        reason = (f"{scene['time']['safety']:g} x critical {critical:.4g} s "
                  f"(omega_max {omega:.4g} rad/s, {how}" + (f", damping ratio {xi:.3g} at omega_max" if xi else "")
                  + ")")
    steps_per_output = max(1, math.ceil(interval / dt_wanted * (1 - 1e-12)))
    dt = interval / steps_per_output
    if user_dt is not None and abs(dt - user_dt) > 1e-12 * user_dt:
        reason += f"; reduced from {user_dt:.6g} s to divide the output interval {interval:g} s"
    else:
        reason += f"; {steps_per_output} steps per output interval {interval:g} s"
    return TimeStep(dt=dt, critical=critical, omega_max=omega, reason=reason, steps_per_output=steps_per_output)


PHASES = ("update", "element_loop", "input_forces", "stiffness", "contact")
"""The kernel's phases of a step (Stepper.phase_seconds; cpp_kernels/stepper.hpp PhaseTimes)."""


DISTRIBUTED_PHASES = ("exchange",)
"""The distributed model's ghost exchange of every step (pyfem/distributed_model.py); a phase of
every run's split (run.json "time_per_step"), 0 on one rank and on the serial path."""


def phase_split(phase_seconds: dict, loop_seconds: float, output_seconds: float | None = None) -> dict:
    """Per phase of a step: ms per step and share of the time loop.

    Args:
        phase_seconds: Stepper.phase_seconds() (s per phase, and "steps").
        loop_seconds: wall time of the whole loop the steps ran in (s).
        output_seconds: of that, the time spent writing samples (s), None if not measured.

    Returns:
        {phase: {"ms_per_step", "share"}} for PHASES, DISTRIBUTED_PHASES (0 where the stepper has
        no ghosts: one rank, the serial path), "output" (when given) and "other" (the loop's
        remainder: Python between the kernel's calls, progress lines).
    """
    steps = max(1, int(phase_seconds["steps"]))
    seconds = {name: float(phase_seconds[name]) for name in PHASES}
    for name in DISTRIBUTED_PHASES:  # the distributed model's (0 on one rank and on the serial path)
        seconds[name] = float(phase_seconds.get(name, 0.0))
    if output_seconds is not None:
        seconds["output"] = float(output_seconds)
    seconds["other"] = max(0.0, loop_seconds - sum(seconds.values()))
    total = max(loop_seconds, 1e-300)
    return {name: {"ms_per_step": 1e3 * value / steps, "share": value / total} for name, value in seconds.items()}
