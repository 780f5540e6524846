"""Shared libraries loaded through ctypes (OpenBLAS for its thread count, METIS for an ordering), and
small C sources of the package compiled once per machine."""
from __future__ import annotations

import ctypes
import ctypes.util
import hashlib
import os
import shutil
import subprocess
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path


def first_library(candidates: Iterable[str | None], symbol: str, search: Iterable[str] = ()) -> ctypes.CDLL | None:
    """The first of ``candidates`` (paths or sonames; None entries skipped), then of the libraries
    ``ctypes.util.find_library`` finds for the names in ``search``, that loads and exports ``symbol``;
    None if none does.  ``search`` is looked up only when no candidate loads: find_library runs the
    compiler or ldconfig, 20 ms each in a fresh process."""
    def names() -> Iterator[str | None]:
        yield from candidates
        for name in search:
            yield ctypes.util.find_library(name)
    for name in names():
        if not name:
            continue
        try:
            lib = ctypes.CDLL(name)
            getattr(lib, symbol)
            return lib
        except (OSError, AttributeError):
            continue
    return None


def address(a) -> ctypes.c_void_p:
    """The address of a NumPy array's data, for a ctypes call."""
    return a.ctypes.data_as(ctypes.c_void_p)


def cache_dir() -> Path:
    """``$XDG_CACHE_HOME/fem_squeal``, else ``~/.cache/fem_squeal`` (beside FFCx's ``fenics``)."""
    root = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(root) / "fem_squeal"


def compiled_library(name: str, source: str, flags: tuple[str, ...] = ("-O2",)) -> ctypes.CDLL | None:
    """``source`` (C) built into a shared library and loaded; None where there is no C compiler or
    the build or load fails (the caller then takes its other path).  The library is kept in
    :func:`cache_dir` under ``name`` and a hash of the source, the flags and the compiler, so it is
    built once per machine; it is written under a temporary name and renamed, so processes that
    build it at the same time never load a half-written file."""
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        return None
    args = [*flags, "-fPIC", "-shared"]
    key = hashlib.sha256("\0".join([source, cc, *args]).encode()).hexdigest()[:16]
    path = cache_dir() / f"{name}_{key}.so"
    if not path.exists():
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryDirectory(dir=path.parent) as tmp:
                src = Path(tmp) / f"{name}.c"
                src.write_text(source)
                out = Path(tmp) / path.name
                subprocess.run([cc, *args, "-o", str(out), str(src)], check=True, capture_output=True)
                os.replace(out, path)
        except (OSError, subprocess.CalledProcessError):
            return None
    try:
        return ctypes.CDLL(str(path))
    except OSError:
        return None
