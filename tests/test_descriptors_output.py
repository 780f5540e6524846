"""Descriptors on synthetic fields with known answers; atomic writes."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest
from conftest import ring_operators

from fem_squeal.fe.descriptors import CircumferentialBasis
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
def test_nodal_diameter_and_in_plane_share(k):
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
def test_travelling_direction(sign):
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
