"""Field output of the finite-element layer: mode shapes and fields as XDMF (collective) and VTU
(gathered on rank 0), on the mesh's coordinate nodes (curved P2 geometry as tetra10), and the
basis field a reduced model carries for its snapshots.  Every file is written atomically."""
from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np
from dolfinx import cpp, fem
from dolfinx.io import XDMFFile

from fem_squeal.util.atomic import atomic_path, atomic_xdmf, write_npz_atomic
from fem_squeal.util.vtu import add_vtu_field_data


def _coordinate_space(V, scalar: bool):
    el = ("Lagrange", V.mesh.geometry.cmap.degree)
    return fem.FunctionSpace(V.mesh, el) if scalar else fem.VectorFunctionSpace(V.mesh, el)


def write_modes_xdmf(comm, path: Path, V, modes: list[tuple[object, object | None]], names=("re", "im")) -> None:
    """Write mode shapes (real part, imaginary part or None) as a time series t = mode index.

    Functions are interpolated into the mesh's coordinate space (XDMF needs that degree)."""
    W = _coordinate_space(V, scalar=False)
    src = fem.Function(V)
    fr, fi = fem.Function(W, name=f"mode_{names[0]}"), fem.Function(W, name=f"mode_{names[1]}")
    with atomic_xdmf(comm, path) as tmp, XDMFFile(comm, str(tmp), "w") as xdmf:
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
    first = next(iter(fields.values()))
    mesh = first.function_space.mesh
    with atomic_xdmf(comm, path) as tmp, XDMFFile(comm, str(tmp), "w") as xdmf:
        xdmf.write_mesh(mesh)
        for name, f in fields.items():
            W = _coordinate_space(f.function_space, scalar=len(f.ufl_shape) == 0)
            g = fem.Function(W, name=name)
            g.interpolate(f)
            xdmf.write_function(g, 0.0)


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
