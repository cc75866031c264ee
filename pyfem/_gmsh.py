"""The one place pyfem imports gmsh: ``from pyfem._gmsh import gmsh``.

gmsh's Python module (Debian 4.8) sets SIGINT to SIG_DFL when it is imported, so Ctrl-C
would kill the process at once, with no KeyboardInterrupt: run.json would stay "running"
and the histories would be lost. Importing gmsh here puts the previous handler back.
`initialize` does the same around ``gmsh.initialize`` (newer gmsh versions install a
handler there unless told ``interruptible=False``).

gmsh 4.8 has no ``isInitialized``, and no API call may probe it: before ``initialize`` every
call reports "not initialized" through Msg::Error, which reads gmsh's option context before
the options exist. That context's AbortOnError is then whatever the heap held, and when it
happens to be 1 gmsh calls exit(1): the process ends with status 1 and prints nothing (a
pytest run stopped that way, valgrind shows the uninitialised reads). So this module counts
instead: ``gmsh.initialize`` and ``gmsh.finalize`` are wrapped, whoever calls them through
the module, and `is_initialized` answers without calling gmsh.
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

# Whether gmsh is initialized: known for certain when this module imported gmsh first; if gmsh
# was imported before, someone may have initialized it already, and `initialize` (a no-op on a
# running gmsh) settles it.
_state = {"initialized": False}
_gmsh_initialize, _gmsh_finalize = gmsh.initialize, gmsh.finalize


def _tracked_initialize(*args, **kwargs):
    _gmsh_initialize(*args, **kwargs)
    _state["initialized"] = True


def _tracked_finalize(*args, **kwargs):
    _gmsh_finalize(*args, **kwargs)
    _state["initialized"] = False


_tracked_initialize.__doc__, _tracked_finalize.__doc__ = _gmsh_initialize.__doc__, _gmsh_finalize.__doc__
gmsh.initialize, gmsh.finalize = _tracked_initialize, _tracked_finalize


def is_initialized() -> bool:
    """Whether gmsh.initialize has run (and finalize not since), without calling gmsh. False
    also when gmsh was initialized before pyfem imported it: `initialize` is then a no-op."""
    return _state["initialized"]


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


__all__ = ["gmsh", "initialize", "is_initialized"]
