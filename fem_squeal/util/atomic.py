"""Atomic result files: nothing is ever half-written.

A file is written to a temporary name in its folder and renamed over the target with ``os.replace``
(readers see the old file or the whole new one); a collective XDMF write goes into a temporary
folder that rank 0 moves into place.  JSON, npz, figures and any text go through :func:`atomic_path`."""
from __future__ import annotations

import csv
import json
import math
import os
import shutil
import tempfile
from collections.abc import Mapping
from contextlib import contextmanager
from pathlib import Path

import numpy as np


def _clean(o):
    if isinstance(o, Mapping):      # dicts and the scene's typed sections
        return {str(k): _clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean(v) for v in o]
    if isinstance(o, np.ndarray):
        return _clean(o.tolist())
    if isinstance(o, (np.floating, float)):
        f = float(o)
        return f if math.isfinite(f) else str(f)
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, complex):
        return {"re": o.real, "im": o.imag}
    return o


def jsonable(o):
    """``o`` as it reads back from JSON: arrays to lists, non-finite floats to strings."""
    return _clean(o)


@contextmanager
def atomic_path(path: str | os.PathLike):
    """Yield a temporary file name next to ``path`` (same suffix) to write; on success it replaces
    ``path`` with ``os.replace``, so readers see the old file or the whole new one, never a part
    (call on one rank only).  On failure the temporary file is removed."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_atomic(path: Path, write, mode: str = "w") -> None:
    """Write ``path`` through :func:`atomic_path` with ``write(file)``, synced before the rename."""
    with atomic_path(path) as tmp, open(tmp, mode) as f:
        write(f)
        f.flush()
        os.fsync(f.fileno())


def write_json_atomic(path: Path, data: dict) -> None:
    """Write ``data`` as JSON to ``path`` atomically (call on one rank only)."""
    write_atomic(path, lambda f: json.dump(_clean(data), f, indent=1))


def write_npz_atomic(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write ``arrays`` to a ``.npz`` atomically (call on one rank only)."""
    write_atomic(path, lambda f: np.savez(f, **arrays), "wb")


@contextmanager
def atomic_xdmf(comm, path: Path):
    """Yield a temporary path for a collective XDMF write; rank 0 moves .xdmf/.h5 into place."""
    path = Path(path)
    tmpdir = None
    if comm.rank == 0:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmpdir = tempfile.mkdtemp(prefix=".xdmf.", dir=path.parent)
    tmpdir = Path(comm.bcast(tmpdir, root=0))
    try:
        yield tmpdir / path.name
        comm.barrier()
        if comm.rank == 0:
            for suffix in (".xdmf", ".h5"):
                p = tmpdir / (path.stem + suffix)
                if p.exists():
                    os.replace(p, path.with_suffix(suffix))
    finally:
        comm.barrier()
        if comm.rank == 0:
            shutil.rmtree(tmpdir, ignore_errors=True)


def save_figure_atomic(fig, path: Path, dpi: int = 120) -> None:
    """Save a matplotlib figure through :func:`atomic_path` (rank 0 only)."""
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi)


def columns_of(rows: list[list], width: int) -> list[list]:
    """The columns of a table given by its rows (``width`` values each), as :func:`write_csv_atomic`
    takes them; ``width`` empty columns for no rows."""
    return [list(c) for c in zip(*rows)] if rows else [[] for _ in range(width)]


def write_csv_atomic(path: Path, header: list[str], columns: list, fmt: str = "%.9g") -> None:
    """Columns of equal length (numbers or texts) as CSV with a header line, atomically (rank 0)."""
    cols = [np.asarray(c) for c in columns]
    if all(c.dtype.kind in "biuf" for c in cols):
        n = len(cols[0]) if cols else 0
        data = np.column_stack([c.astype(float) for c in cols]) if n else np.empty((0, len(cols)))
        row = ",".join([fmt] * len(cols))        # one formatting per row, one write: 2x numpy.savetxt
        text = "\n".join([",".join(header), *(row % tuple(r) for r in data.tolist())]) + "\n"
        write_atomic(path, lambda f: f.write(text))
        return

    def text(x) -> str:
        return fmt % x if isinstance(x, (float, np.floating)) else str(x)

    def write(f) -> None:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(header)
        w.writerows([text(x) for x in row] for row in zip(*(c.tolist() for c in cols)))

    write_atomic(path, write)
