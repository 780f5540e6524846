"""Shared libraries loaded through ctypes (OpenBLAS for its thread count, METIS for an ordering)."""
from __future__ import annotations

import ctypes
from collections.abc import Iterable


def first_library(candidates: Iterable[str | None], symbol: str) -> ctypes.CDLL | None:
    """The first of ``candidates`` (paths or sonames; None entries skipped) that loads and exports
    ``symbol``; None if none does."""
    for name in candidates:
        if not name:
            continue
        try:
            lib = ctypes.CDLL(name)
            getattr(lib, symbol)
            return lib
        except (OSError, AttributeError):
            continue
    return None
