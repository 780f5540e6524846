"""A pytest-xdist worker off the main thread.

execnet (pytest-xdist's transport) can start a worker's session on a thread other than the process's
main thread (execnet issue 96: a start-up race, seen here as one fresh-clone CI run in seven), and
``signal.signal`` may only be called from the main thread.  gmsh's Python module calls it when it is
imported (it sets SIGINT to the default while loading its library, keeping the old handler in
``gmsh.oldsig``) and again in ``gmsh.finalize`` (restoring that handler when it is not None), so on
such a worker the first ``import gmsh`` of the session raised ValueError and took a test file down."""
from __future__ import annotations

import signal
import threading
from types import ModuleType


def import_gmsh() -> ModuleType:
    """``import gmsh`` on any thread.  Off the main thread ``signal.signal`` is a no-op for the
    import (returning None), so gmsh keeps no old handler and ``gmsh.finalize`` restores none: the
    process's SIGINT handling is what it was.  On the main thread a plain import."""
    if threading.current_thread() is threading.main_thread():
        import gmsh
        return gmsh
    real = signal.signal
    signal.signal = lambda *args: None
    try:
        import gmsh
    finally:
        signal.signal = real
    return gmsh
