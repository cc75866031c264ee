"""The one place pyfem imports gmsh: ``from pyfem._gmsh import gmsh``.

gmsh's Python module (Debian 4.8) sets SIGINT to SIG_DFL when it is imported, so Ctrl-C
would kill the process at once, with no KeyboardInterrupt: run.json would stay "running"
and the histories would be lost. Importing gmsh here puts the previous handler back.
`initialize` does the same around ``gmsh.initialize`` (newer gmsh versions install a
handler there unless told ``interruptible=False``).
"""
from __future__ import annotations

import inspect
import signal
import sys
import threading


def _in_main_thread() -> bool:
    """signal.signal may only be called from the main thread."""
    return threading.current_thread() is threading.main_thread()


def _restore_sigint(handler) -> None:
    """Puts `handler` back as the SIGINT handler (main thread only; None: set outside Python)."""
    if handler is not None and _in_main_thread() and signal.getsignal(signal.SIGINT) is not handler:
        signal.signal(signal.SIGINT, handler)


_already_imported = "gmsh" in sys.modules
_previous_handler = signal.getsignal(signal.SIGINT)
import gmsh  # noqa: E402

if _already_imported and _previous_handler == signal.SIG_DFL:
    # Someone imported gmsh before us (dolfinx.io.gmshio does): the handler it replaced is
    # the one gmsh kept in `oldsig`.
    _previous_handler = getattr(gmsh, "oldsig", None) or _previous_handler
_restore_sigint(_previous_handler)

_INITIALIZE_TAKES_INTERRUPTIBLE = "interruptible" in inspect.signature(gmsh.initialize).parameters


def initialize(**options) -> None:
    """``gmsh.initialize(**options)`` that leaves the SIGINT handler as it was.

    Args:
        options: keyword arguments of ``gmsh.initialize`` (e.g. readConfigFiles=False).
    """
    handler = signal.getsignal(signal.SIGINT)
    if _INITIALIZE_TAKES_INTERRUPTIBLE:
        options.setdefault("interruptible", False)
    gmsh.initialize(**options)
    _restore_sigint(handler)


__all__ = ["gmsh", "initialize"]
