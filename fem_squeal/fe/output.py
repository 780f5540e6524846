"""Field output of the finite-element layer: mode shapes and fields as XDMF (collective) and VTU
(gathered on rank 0), on the mesh's coordinate nodes (curved P2 geometry as tetra10), and the
basis field a reduced model carries for its snapshots.  Every file is written atomically.

Mode shapes go to XDMF without ``XDMFFile.write_function``: in dolfinx 0.5.2 that evaluates the
function at every geometry node by a Newton pull-back per point (0.13 s per field at 50k DOFs, 60 %
of a CEA's eigensolve for 55 modes).  A field in the coordinate space already holds those values:
they are taken by the cell-wise map geometry node -> DOF and written collectively with PETSc's HDF5
viewer into the file ``write_mesh`` made, and the XML lists them as dolfinx would (same datasets
``/Function/<name>/<t>``, same grids); tests/unit/fe/test_descriptors_output.py compares both writers."""
from __future__ import annotations

import ctypes
import os
from pathlib import Path

import meshio
import numpy as np
import petsc4py
from dolfinx import cpp, fem
from dolfinx.io import XDMFFile
from petsc4py import PETSc

from fem_squeal.util.atomic import atomic_path, atomic_xdmf, write_npz_atomic
from fem_squeal.util.vtu import add_vtu_field_data


def _coordinate_space(V, scalar: bool):
    """The Lagrange space of the mesh's coordinate degree (V itself when V is that space)."""
    degree, e = V.mesh.geometry.cmap.degree, V.ufl_element()
    if e.family() in ("Lagrange", "P") and e.degree() == degree and len(e.value_shape()) == (0 if scalar else 1):
        return V
    el = ("Lagrange", degree)
    return fem.FunctionSpace(V.mesh, el) if scalar else fem.VectorFunctionSpace(V.mesh, el)


class _NodeValues:
    """Values of vectors on V at the owned geometry nodes of the mesh (rows in the order
    ``XDMFFile.write_mesh`` writes the geometry): interpolated into the coordinate space W (no-op
    when V is W), then gathered through the cell-wise map geometry node -> DOF of W."""

    def __init__(self, V):
        self.V, self.W = V, _coordinate_space(V, scalar=False)
        g = V.mesh.geometry
        node = np.empty(g.x.shape[0], dtype=np.int64)
        node[g.dofmap.array] = self.W.dofmap.list.array   # same local layout: W is the coordinate element
        self.n_owned, self.n_global = g.index_map().size_local, g.index_map().size_global
        self.node = node[: self.n_owned]
        self.src = fem.Function(V)
        self.dst = self.src if self.W is V else fem.Function(self.W)

    def __call__(self, vec) -> np.ndarray:
        """(n_owned_nodes, 3) values of a PETSc vector on V (None: zeros)."""
        if vec is None:
            return np.zeros((self.n_owned, 3))
        self.src.x.array[: vec.getLocalSize()] = vec.array_r
        self.src.x.scatter_forward()
        if self.dst is not self.src:
            self.dst.interpolate(self.src)
        return self.dst.x.array.reshape(-1, 3)[self.node]


def _petsc_library():
    """libpetsc (ctypes) for PetscViewerHDF5PushGroup/PopGroup, which petsc4py 3.18 does not wrap."""
    kind = "complex" if np.dtype(PETSc.ScalarType).kind == "c" else "real"
    return ctypes.CDLL(os.path.join(petsc4py.get_config()["PETSC_DIR"], "lib", f"libpetsc_{kind}.so"))


_MESH = "xpointer(/Xdmf/Domain/Grid[@GridType='Uniform'][1]/*[self::Topology or self::Geometry])"
_GRID = """      <Grid Name="{name}" GridType="Uniform">
        <xi:include xpointer="{mesh}" />
        <Time Value="{t}" />
        <Attribute Name="{name}" AttributeType="Vector" Center="Node">
          <DataItem Dimensions="{n} 3" Format="HDF">{h5}:/Function/{name}/{t}</DataItem>
        </Attribute>
      </Grid>
"""


def write_modes_xdmf(comm, path: Path, V, modes: list[tuple[object, object | None]], names=("re", "im")) -> None:
    """Write mode shapes (real part, imaginary part or None) as a time series t = mode index: fields
    ``mode_<names[0]>`` and ``mode_<names[1]>`` at the mesh's coordinate nodes (module docstring)."""
    values = _NodeValues(V)
    fields = [f"mode_{names[0]}", f"mode_{names[1]}"]
    lib = _petsc_library()
    with atomic_xdmf(comm, path) as tmp:
        with XDMFFile(comm, str(tmp), "w") as xdmf:
            xdmf.write_mesh(V.mesh)
        h5 = tmp.with_suffix(".h5")
        viewer = PETSc.Viewer().createHDF5(str(h5), "a", comm=comm)
        handle = ctypes.c_void_p(viewer.handle)
        try:
            for j, pair in enumerate(modes):
                for name, vec in zip(fields, pair):
                    v = PETSc.Vec().createWithArray(np.ascontiguousarray(values(vec)).ravel(),
                                                    size=(3 * values.n_owned, 3 * values.n_global), bsize=3,
                                                    comm=comm)
                    v.setName(f"{j:g}")
                    if lib.PetscViewerHDF5PushGroup(handle, f"/Function/{name}".encode()):
                        raise RuntimeError("PetscViewerHDF5PushGroup failed")
                    v.view(viewer)
                    lib.PetscViewerHDF5PopGroup(handle)
                    v.destroy()
        finally:
            viewer.destroy()
        if comm.rank == 0:
            grids = "".join(f'    <Grid Name="{name}" GridType="Collection" CollectionType="Temporal">\n'
                            + "".join(_GRID.format(name=name, mesh=_MESH, t=f"{j:g}", n=values.n_global,
                                                   h5=h5.name)
                                      for j in range(len(modes))) + "    </Grid>\n" for name in fields)
            text = tmp.read_text()
            i = text.rindex("  </Domain>")
            tmp.write_text(text[:i] + grids + text[i:])


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
    kinds = {4: "tetra", 10: "tetra10", 8: "hexahedron", 27: "hexahedron27"}
    return points, np.concatenate(cells), kinds[per_cell]


def field_rows(V, vectors, scalar: bool = False):
    """Interpolate PETSc vectors (or Functions, or arrays of owned values) on V into the coordinate
    space W; yields W, then the owned rows (n_owned, 3 or 1) of each."""
    W = _coordinate_space(V, scalar)
    yield W
    src = fem.Function(V)
    dst = src if W is V else fem.Function(W)      # V is the coordinate space: owned values as they are
    for vec in vectors:
        if isinstance(vec, fem.Function):
            if W is V and vec.function_space is V:
                yield _owned_values(W, vec)
                continue
            dst.interpolate(vec)
        else:
            arr = vec if isinstance(vec, np.ndarray) else vec.array_r     # owned values on V
            src.x.array[: len(arr)] = arr
            if dst is not src:
                src.x.scatter_forward()
                dst.interpolate(src)
        yield _owned_values(W, dst)


def write_vtu(comm, path: Path, V, point_data: dict[str, object], field_data: dict | None = None,
              scalars: dict[str, object] | None = None) -> tuple | None:
    """One VTU file (meshio, rank 0, atomic) with vector fields ``point_data`` (PETSc vectors or
    Functions on V) and scalar Functions ``scalars``, on the mesh's coordinate nodes (curved P2
    geometry as tetra10).  ``field_data``: name -> numbers (e.g. the frequencies).  Returns what it
    wrote on rank 0, ``(points, cells, kind, data)`` (data: name -> gathered rows; None elsewhere),
    for other views of the same fields (the report's mode pictures)."""
    rows = field_rows(V, point_data.values())
    W = next(rows)
    layout = vtu_mesh(comm, W)
    data = {name: _gather_rows(comm, W, r) for name, r in zip(point_data, rows)}
    for name, f in (scalars or {}).items():
        srows = field_rows(f.function_space, [f], scalar=True)
        gathered = _gather_rows(comm, next(srows), next(srows))
        if gathered is not None:
            data[name] = gathered[:, 0]
    written = None
    if comm.rank == 0:
        points, cells, kind = layout
        with atomic_path(path) as tmp:
            # uncompressed binary: zlib took 90 % of the writing (4.8 of 5.3 s for 108 modes at 50k DOFs)
            # for files 1.6x smaller (mode shapes compress poorly)
            meshio.write(tmp, meshio.Mesh(points, [(kind, cells)], point_data=data), file_format="vtu",
                         compression=None)
            add_vtu_field_data(tmp, field_data or {})
        written = (points, cells, kind, data)
    comm.barrier()
    return written


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
