"""Memory pages of NumPy's arrays.

NumPy asks the kernel for transparent huge pages (``madvise(MADV_HUGEPAGE)``) on every array above
4 MB.  Where the kernel's THP ``defrag`` setting is ``madvise`` (Debian's default), a page fault in
such an array may compact memory first to find a free 2 MB page, and that stall grows as the
process's memory fragments: on this project's VM the first touch of a fresh array cost up to
1.2 ms per MB with huge pages against 0.33 ms with 4 kB pages.  Work that creates many short-lived
arrays of tens of MB (the orthonormalisation of a reduced basis: 50k × 172 doubles per block) pays
it on each: :func:`small_pages`."""
from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

try:   # NumPy ≥ 1.20 (the switch behind NUMPY_MADVISE_HUGEPAGE)
    from numpy.core.multiarray import _get_madvise_hugepage, _set_madvise_hugepage
except ImportError:   # pragma: no cover - an older or newer NumPy without it: nothing to switch
    _get_madvise_hugepage = _set_madvise_hugepage = None


@contextmanager
def small_pages() -> Iterator[None]:
    """NumPy's new arrays on 4 kB pages inside the block (no ``MADV_HUGEPAGE``), then as before
    (also on an exception); nothing where this NumPy has no such switch.  Numbers do not change:
    only where the memory comes from.  Measured on the 50k-DOF brake's reduced basis (one rank):
    8.0 → 7.0 s, the CEA it is compared with unchanged."""
    if _set_madvise_hugepage is None:
        yield
        return
    old = bool(_get_madvise_hugepage())
    _set_madvise_hugepage(False)
    try:
        yield
    finally:
        _set_madvise_hugepage(old)
