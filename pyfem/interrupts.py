"""Ctrl-C and SIGTERM during a run: stop cleanly, between two samples, and say where.

`StopSignals` makes SIGINT and SIGTERM raise `RunInterrupted` (a KeyboardInterrupt) while
a run is under way, so the solver can close its files and mark run.json "interrupted".
Inside `StopSignals.deferred()` (writing a sample, moving a directory) a signal waits until
the block ends, so the histories hold whole samples only.
"""
from __future__ import annotations

import contextlib
import signal
import threading

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class RunInterrupted(KeyboardInterrupt):
    """A run stopped by a signal.

    Attributes:
        signal_number: the signal (SIGINT 2, SIGTERM 15).
        time_reached: last sampled time (s), None before the first sample.
        out_dir: the run directory holding the partial results, None before it existed.
    """

    def __init__(self, signal_number: int = signal.SIGINT, time_reached: float | None = None, out_dir=None):
        super().__init__(signal.Signals(signal_number).name)
        self.signal_number = int(signal_number)
        self.time_reached = time_reached
        self.out_dir = out_dir

    @property
    def signal_name(self) -> str:
        """SIGINT or SIGTERM."""
        return signal.Signals(self.signal_number).name

    @property
    def exit_status(self) -> int:
        """The shell's status of a process ended by the signal: 128 + its number (130 for SIGINT)."""
        return 128 + self.signal_number


class StopSignals:
    """Context manager: SIGINT and SIGTERM raise RunInterrupted inside it; the previous handlers after.
    always_defer: a signal only marks a stop, acted on at the end of the next deferred block (MPI
    ranks stop together, `stop_together`).

    Only the main thread can receive Python signal handlers: elsewhere it does nothing.
    """

    def __init__(self, always_defer: bool = False):
        self._previous: dict[int, object] = {}
        self._deferring = False
        self._always_defer = always_defer
        self._pending: int | None = None  # a signal received here
        self._agreed: int | None = None  # always_defer: the signal all ranks agreed on (stop_together)

    def __enter__(self) -> "StopSignals":
        if threading.current_thread() is threading.main_thread():
            for number in STOP_SIGNALS:
                self._previous[number] = signal.signal(number, self._handler)
        return self

    def __exit__(self, *exc_info) -> None:
        for number, handler in self._previous.items():
            signal.signal(number, handler if handler is not None else signal.SIG_DFL)
        self._previous.clear()

    def _handler(self, signal_number: int, frame) -> None:
        if self._deferring or self._always_defer:
            self._pending = signal_number
            return
        raise RunInterrupted(signal_number)

    def stop_together(self, comm) -> bool:
        """Under mpirun (always_defer): whether any rank has a stop signal pending; if so every rank
        leaves its deferred block at this sample. A collective: every rank calls it at the same
        point. Only this agreement stops a rank: a signal that reaches a rank after it (while the
        others are already stepping on) waits for the next sample's."""
        from mpi4py import MPI

        agreed = comm.allreduce(self._pending or 0, op=MPI.MAX)
        self._agreed = agreed or None
        return bool(agreed)

    @contextlib.contextmanager
    def deferred(self, reraise: bool = True):
        """A block that a stop signal does not cut: the signal is raised when the block ends
        (dropped with reraise=False, e.g. while the files of an interrupted run are closed)."""
        outer = self._deferring
        self._deferring = True
        try:
            yield
        finally:
            self._deferring = outer
        stop = self._agreed if self._always_defer else self._pending
        if not outer and stop is not None:
            self._pending = self._agreed = None
            if reraise:
                raise RunInterrupted(stop)
