"""Atomic result files: JSON written by rank 0 through a temporary file and ``os.replace``;
XDMF written collectively into a temporary folder that rank 0 moves into place."""
from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np


def _clean(o):
    if isinstance(o, dict):
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


def _write_atomic(path: Path, write, mode: str = "w") -> None:
    """Write ``path`` through :func:`atomic_path` with ``write(file)``, synced before the rename."""
    with atomic_path(path) as tmp, open(tmp, mode) as f:
        write(f)
        f.flush()
        os.fsync(f.fileno())


def write_json_atomic(path: Path, data: dict) -> None:
    """Write ``data`` as JSON to ``path`` atomically (call on one rank only)."""
    _write_atomic(path, lambda f: json.dump(_clean(data), f, indent=1))


def write_npz_atomic(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write ``arrays`` to a ``.npz`` atomically (call on one rank only)."""
    _write_atomic(path, lambda f: np.savez(f, **arrays), "wb")


@contextmanager
def _atomic_xdmf(comm, path: Path):
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


def _coordinate_space(V, scalar: bool):
    from dolfinx import fem

    el = ("Lagrange", V.mesh.geometry.cmap.degree)
    return fem.FunctionSpace(V.mesh, el) if scalar else fem.VectorFunctionSpace(V.mesh, el)


def write_modes_xdmf(comm, path: Path, V, modes: list[tuple[object, object | None]], names=("re", "im")) -> None:
    """Write mode shapes (real part, imaginary part or None) as a time series t = mode index.

    Functions are interpolated into the mesh's coordinate space (XDMF needs that degree)."""
    from dolfinx import fem
    from dolfinx.io import XDMFFile

    W = _coordinate_space(V, scalar=False)
    src = fem.Function(V)
    fr, fi = fem.Function(W, name=f"mode_{names[0]}"), fem.Function(W, name=f"mode_{names[1]}")
    with _atomic_xdmf(comm, path) as tmp, XDMFFile(comm, str(tmp), "w") as xdmf:
        xdmf.write_mesh(V.mesh)
        for j, (xr, xi) in enumerate(modes):
            for vec, f in ((xr, fr), (xi, fi)):
                if vec is None:
                    f.x.array[:] = 0.0
                else:
                    src.x.array[: vec.getLocalSize()] = vec.array_r
                    src.x.scatter_forward()
                    f.interpolate(src)
                xdmf.write_function(f, float(j))


def write_fields_xdmf(comm, path: Path, fields: dict[str, object]) -> None:
    """Write dolfinx Functions (any Lagrange degree, same mesh) into one XDMF file at t = 0."""
    from dolfinx import fem
    from dolfinx.io import XDMFFile

    first = next(iter(fields.values()))
    mesh = first.function_space.mesh
    with _atomic_xdmf(comm, path) as tmp, XDMFFile(comm, str(tmp), "w") as xdmf:
        xdmf.write_mesh(mesh)
        for name, f in fields.items():
            W = _coordinate_space(f.function_space, scalar=len(f.ufl_shape) == 0)
            g = fem.Function(W, name=name)
            g.interpolate(f)
            xdmf.write_function(g, 0.0)


def save_figure_atomic(fig, path: Path, dpi: int = 120) -> None:
    """Save a matplotlib figure through a temporary file and ``os.replace`` (rank 0 only)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        fig.savefig(tmp, dpi=dpi)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
