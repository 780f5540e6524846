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
    """Save a matplotlib figure through :func:`atomic_path` (rank 0 only)."""
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi)


def _owned_values(W, f) -> np.ndarray:
    """Owned DOF values of a Function on W, (n_owned, block size)."""
    im, bs = W.dofmap.index_map, W.dofmap.index_map_bs
    return f.x.array[: im.size_local * bs].reshape(im.size_local, bs).copy()


def _gather_rows(comm, W, rows: np.ndarray) -> np.ndarray | None:
    """Owned rows of every rank, in global DOF order, on rank 0 (None elsewhere)."""
    parts = comm.gather((W.dofmap.index_map.local_range[0], rows), root=0)
    if comm.rank:
        return None
    n = sum(len(r) for _, r in parts)
    out = np.empty((n, *rows.shape[1:]), dtype=rows.dtype)
    for start, r in parts:
        out[start:start + len(r)] = r
    return out


def vtu_mesh(comm, W) -> tuple[np.ndarray, np.ndarray, str] | None:
    """Points (the DOF coordinates of the mesh's coordinate space W), cells in VTK node order and the
    meshio cell type, gathered on rank 0 (None elsewhere).  Point i is global DOF i of W."""
    from dolfinx import cpp

    mesh = W.mesh
    im = W.dofmap.index_map
    points = _gather_rows(comm, W, W.tabulate_dof_coordinates()[: im.size_local])
    n_cells = mesh.topology.index_map(mesh.topology.dim).size_local
    per_cell = W.dofmap.dof_layout.num_dofs
    local = W.dofmap.list.array.reshape(-1, per_cell)[:n_cells]
    glob = im.local_to_global(local.ravel().astype(np.int32)).reshape(local.shape)
    vtk = np.empty_like(glob)
    vtk[:, cpp.io.perm_vtk(mesh.topology.cell_type, per_cell)] = glob
    cells = comm.gather(vtk, root=0)
    if comm.rank:
        return None
    return points, np.concatenate(cells), {4: "tetra", 10: "tetra10"}[per_cell]


def field_rows(V, vectors, scalar: bool = False):
    """Interpolate PETSc vectors (or Functions, or arrays of owned values) on V into the coordinate
    space W; yields W, then the owned rows (n_owned, 3 or 1) of each."""
    from dolfinx import fem

    W = _coordinate_space(V, scalar)
    yield W
    src, dst = fem.Function(V), fem.Function(W)
    for vec in vectors:
        if isinstance(vec, fem.Function):
            dst.interpolate(vec)
        elif isinstance(vec, np.ndarray):          # owned values on V
            src.x.array[: len(vec)] = vec
            src.x.scatter_forward()
            dst.interpolate(src)
        else:
            src.x.array[: vec.getLocalSize()] = vec.array_r
            src.x.scatter_forward()
            dst.interpolate(src)
        yield _owned_values(W, dst)


def write_vtu(comm, path: Path, V, point_data: dict[str, object], field_data: dict | None = None,
              scalars: dict[str, object] | None = None) -> None:
    """One VTU file (meshio, rank 0, atomic) with vector fields ``point_data`` (PETSc vectors or
    Functions on V) and scalar Functions ``scalars``, on the mesh's coordinate nodes (curved P2
    geometry as tetra10).  ``field_data``: name -> numbers (e.g. the frequencies)."""
    import meshio

    rows = field_rows(V, point_data.values())
    W = next(rows)
    layout = vtu_mesh(comm, W)
    data = {name: _gather_rows(comm, W, r) for name, r in zip(point_data, rows)}
    for name, f in (scalars or {}).items():
        srows = field_rows(f.function_space, [f], scalar=True)
        gathered = _gather_rows(comm, next(srows), next(srows))
        if gathered is not None:
            data[name] = gathered[:, 0]
    if comm.rank == 0:
        points, cells, kind = layout
        with atomic_path(path) as tmp:
            meshio.write(tmp, meshio.Mesh(points, [(kind, cells)], point_data=data), file_format="vtu")
            add_vtu_field_data(tmp, field_data or {})
    comm.barrier()


def add_vtu_field_data(path: Path, arrays: dict[str, object]) -> None:
    """Add ``<FieldData>`` arrays (name -> numbers) to a VTU file; meshio 7.0 reads them but cannot
    write them."""
    from xml.sax.saxutils import quoteattr

    if not arrays:
        return
    body = []
    for name, values in arrays.items():
        v = np.atleast_1d(np.asarray(values))
        kind = "Int64" if np.issubdtype(v.dtype, np.integer) else "Float64"
        text = " ".join(str(int(x)) if kind == "Int64" else repr(float(x)) for x in v.ravel())
        body.append(f'<DataArray type="{kind}" Name={quoteattr(name)} NumberOfTuples="{v.size}" '
                    f'format="ascii">{text}</DataArray>\n')
    text = Path(path).read_text()
    i = text.index(">", text.index("<UnstructuredGrid")) + 1
    Path(path).write_text(text[:i] + "\n<FieldData>\n" + "".join(body) + "</FieldData>" + text[i:])


def write_basis_field(comm, path: Path, V, Phi: np.ndarray) -> None:
    """The basis Φ (owned rows on V, one column per vector) on the mesh's coordinate nodes, for
    field snapshots u = Φ q without dolfinx: ``points``, ``cells``, ``kind`` and ``phi`` (n_points,
    3, m) in float32 (visualisation accuracy), written by rank 0 atomically."""
    rows = field_rows(V, (np.ascontiguousarray(Phi[:, j]) for j in range(Phi.shape[1])))
    W = next(rows)
    layout = vtu_mesh(comm, W)
    cols = [_gather_rows(comm, W, r.astype(np.float32)) for r in rows]
    if comm.rank == 0:
        points, cells, kind = layout
        write_npz_atomic(path, {"points": points, "cells": cells, "kind": np.array(kind),
                                "phi": np.stack(cols, axis=2)})


def write_snapshots(path: Path, basis_field: dict, times: np.ndarray, q: np.ndarray, q_ref: np.ndarray) -> None:
    """Displacement snapshots u_k = Φ (q_k − q_ref) as ``<path>.vtu`` (point data u_<k>, times in the
    field data) and an XDMF time series ``<path>.xdmf`` (meshio, data inline; one process, atomic)."""
    import meshio

    phi = basis_field["phi"]
    cells = [(str(basis_field["kind"]), basis_field["cells"])]
    u = [np.einsum("pcm,m->pc", phi, qk - q_ref) for qk in q]
    with atomic_path(path.with_suffix(".vtu")) as tmp:
        mesh = meshio.Mesh(basis_field["points"], cells, point_data={f"u_{k}": uk for k, uk in enumerate(u)})
        meshio.write(tmp, mesh, file_format="vtu")
        add_vtu_field_data(tmp, {"time": times})
    # inline XML data: meshio 7.0's HDF5 variant needs h5py and writes the .h5 into the working folder
    with atomic_path(path.with_suffix(".xdmf")) as tmp:
        with meshio.xdmf.TimeSeriesWriter(tmp, data_format="XML") as w:
            w.write_points_cells(basis_field["points"], cells)
            for t, uk in zip(times, u):
                w.write_data(float(t), point_data={"u": uk})
