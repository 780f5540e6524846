"""Descriptors on synthetic fields with known answers; atomic writes."""
from __future__ import annotations

import ctypes
import json
import os

import numpy as np
import pytest

from fem_squeal.fe.descriptors import CircumferentialBasis
from fem_squeal.fe.output import write_modes_xdmf
from fem_squeal.util.atomic import write_json_atomic


def cyl_field(ops, fn):
    """Vector from fn(theta) -> (u_r, u_t, u_z) arrays at the owned nodes."""
    n = ops.V.dofmap.index_map.size_local
    x = ops.V.tabulate_dof_coordinates()[:n]
    th = np.arctan2(x[:, 1], x[:, 0])
    ur, ut, uz = fn(th)
    v = ops.K.createVecRight()
    v.array[:] = np.stack([ur * np.cos(th) - ut * np.sin(th), ur * np.sin(th) + ut * np.cos(th), uz], 1).ravel()
    return v


@pytest.mark.parametrize("k", [0, 2, 5])
def test_nodal_diameter_and_in_plane_share(k, ring_operators):
    ops = ring_operators()
    b = CircumferentialBasis(ops.V, ops.M, ops.M_axial)
    z = np.zeros
    d = b.describe(cyl_field(ops, lambda t: (np.cos(k * t), z(t.shape), z(t.shape))))
    assert d.nodal_diameter == k
    assert d.in_plane_share == pytest.approx(1.0, abs=1e-12)
    # a single harmonic carries all the energy (to the P2 interpolation of cos kθ, ~1e-4)
    assert d.nodal_share == pytest.approx(1.0, abs=2e-3)
    d = b.describe(cyl_field(ops, lambda t: (z(t.shape), z(t.shape), np.sin(3 * t))))
    assert d.nodal_diameter == 3 and d.in_plane_share == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("sign", [1, -1])
def test_travelling_direction(sign, ring_operators):
    """x = e^{−i·sign·kθ} e_r: Re(x e^{iωt}) = cos(ωt − sign·kθ) travels towards sign·θ."""
    ops = ring_operators()
    b = CircumferentialBasis(ops.V, ops.M, ops.M_axial)
    k, z = 3, np.zeros
    xr = cyl_field(ops, lambda t: (np.cos(sign * k * t), z(t.shape), z(t.shape)))
    xi = cyl_field(ops, lambda t: (-np.sin(sign * k * t), z(t.shape), z(t.shape)))
    d = b.describe(xr, xi)
    assert d.nodal_diameter == k
    assert d.travelling_direction == sign and d.travelling_index == pytest.approx(sign, abs=1e-3)
    standing = b.describe(xr)
    assert standing.travelling_direction == 0 and abs(standing.travelling_index) < 1e-3


def test_atomic_json_keeps_old_file_on_failure(tmp_path):
    p = tmp_path / "results.json"
    write_json_atomic(p, {"a": 1})

    class Boom:
        pass

    with pytest.raises(TypeError):
        write_json_atomic(p, {"a": Boom()})
    assert json.loads(p.read_text()) == {"a": 1}
    assert os.listdir(tmp_path) == ["results.json"]
    write_json_atomic(p, {"x": np.float64(2.5), "c": complex(1, 2), "inf": float("inf")})
    assert json.loads(p.read_text()) == {"x": 2.5, "c": {"re": 1.0, "im": 2.0}, "inf": "inf"}


def _h5_vector(path, group: str, name: str, n: int):
    """Dataset ``group/name`` of an HDF5 file as a PETSc vector of n 3-vectors (PETSc's HDF5 viewer)."""
    from petsc4py import PETSc

    from fem_squeal.fe.output import _petsc_library

    lib, v = _petsc_library(), PETSc.Vec().createMPI((PETSc.DECIDE, 3 * n), bsize=3)
    viewer = PETSc.Viewer().createHDF5(str(path), "r")
    lib.PetscViewerHDF5PushGroup(ctypes.c_void_p(viewer.handle), group.encode())
    v.setName(name)
    v.load(viewer)
    viewer.destroy()
    return v


def test_modes_xdmf_equals_dolfinx_writer(tmp_path, ring_operators):
    """The mode writer (PETSc HDF5, no per-point evaluation) gives the XML and datasets that
    XDMFFile.write_function gives for the same fields."""
    from dolfinx import fem
    from dolfinx.io import XDMFFile
    from mpi4py import MPI

    ops, z = ring_operators(), np.zeros
    xr = cyl_field(ops, lambda t: (np.cos(2 * t), np.sin(3 * t), z(t.shape)))
    xi = cyl_field(ops, lambda t: (z(t.shape), np.cos(t), np.sin(5 * t)))
    modes = [(xr, xi), (xi, None)]
    write_modes_xdmf(MPI.COMM_WORLD, tmp_path / "fast.xdmf", ops.V, modes)
    fr, fi = fem.Function(ops.V, name="mode_re"), fem.Function(ops.V, name="mode_im")
    with XDMFFile(MPI.COMM_WORLD, str(tmp_path / "ref.xdmf"), "w") as x:
        x.write_mesh(ops.V.mesh)
        for j, pair in enumerate(modes):
            for f, vec in zip((fr, fi), pair):
                f.x.array[:] = 0.0
                if vec is not None:
                    f.x.array[: vec.getLocalSize()] = vec.array_r
                    f.x.scatter_forward()
                x.write_function(f, float(j))
    fast, ref = (tmp_path / "fast.xdmf").read_text(), (tmp_path / "ref.xdmf").read_text()
    assert fast == ref.replace("ref.h5", "fast.h5")
    n = ops.V.mesh.geometry.index_map().size_global
    for name in ("mode_re", "mode_im"):
        for t in ("0", "1"):
            a = _h5_vector(tmp_path / "fast.h5", f"/Function/{name}", t, n)
            b = _h5_vector(tmp_path / "ref.h5", f"/Function/{name}", t, n)
            b.axpy(-1.0, a)
            # dolfinx evaluates each node by a Newton pull-back: equal to round-off
            assert b.norm() <= 1e-12 * max(a.norm(), 1.0)


def test_batched_descriptors_equal_the_per_mode_ones(ring_operators):
    """describe_all / strain_energy_shares_all over more modes than one block (real and complex mixed)
    give each mode's describe / strain_energy_shares."""
    from fem_squeal.fe.descriptors import BLOCK_MODES, strain_energy_shares, strain_energy_shares_all

    ops = ring_operators()
    b = CircumferentialBasis(ops.V, ops.M, ops.M_axial)
    rng = np.random.default_rng(1)
    modes = []
    for j in range(BLOCK_MODES + 3):
        k, c = j % 7, rng.uniform()
        xr = cyl_field(ops, lambda t, k=k, c=c: (np.cos(k * t), c * np.sin(k * t), 0.3 * np.cos((k + 1) * t)))
        xi = cyl_field(ops, lambda t, k=k: (np.sin(k * t), np.zeros_like(t), np.sin(2 * t))) if j % 3 else None
        modes.append((xr, xi))
    parts = {"a": ops.K, "b": ops.M}
    for d, e, (xr, xi) in zip(b.describe_all(modes), strain_energy_shares_all(parts, modes), modes):
        ref, ref_e = b.describe(xr, xi), strain_energy_shares(parts, xr, xi)
        assert d.nodal_diameter == ref.nodal_diameter and d.travelling_direction == ref.travelling_direction
        # the same sums in another blocking of the dense products: round-off only
        assert np.allclose(d, ref, rtol=1e-12, atol=1e-14) and e == pytest.approx(ref_e, rel=1e-12)
