"""Native hexahedra (``discretisation.hexahedra``): an all-hexahedral deck runs on dolfinx hexahedra
with the serendipity element S2 and 2 × 2 × 2 Gauss points (CalculiX's C3D20R; the comparison with
ccx on the plate of issue #37 is ``benchmarks/hex_native.py``), a mixed deck keeps the split, and
"native" where it cannot run is a named error.

Analytic check: a bar 0 <= x <= L of 4 × 1 × 1 C3D20R with rollers on its four long faces (the normal
component held), x held at x = 0 and a spring k per area on its end x = L, half of it a rigid plate
(k_n (u·n)(v·n)), half a ground spring across the axis z: its lowest modes are the longitudinal waves
u_x = sin(κx) of the constrained (P-wave) modulus C = E(1 − ν) / ((1 + ν)(1 − 2ν)), C u_x'(L) = −k u_x(L),
so tan κL = −C κ / k; with k = C / L the roots are κL = 2.028758, 4.913180 and f = κ c / 2π, c² = C / ρ.
Every other mode varies across the 0.25 L section (above c_s / 0.5 L).
"""
from __future__ import annotations

import json

import meshio
import numpy as np
import pytest
from mpi4py import MPI

from fem_squeal.app.run import run_scene
from fem_squeal.app.scene import load_scene
from fem_squeal.util.errors import MeshError
from geometry.hex_decks import mixed_block, write_inp
from geometry.mesh_file import prepare

COMM = MPI.COMM_WORLD
L, B = 1.0, 0.25
E, NU, RHO = 210e9, 0.3, 7800.0
C = E * (1 - NU) / ((1 + NU) * (1 - 2 * NU))     # the constrained modulus
QUIET = dict(log=lambda *a: None, report=False)


def _deck(path, tets=()):
    pts, blocks, _, _ = mixed_block((4, 1, 1), (L, B, B), tets=tets, order=2, seed=None, jiggle=0.0)
    sides = {"X0": (0, 0.0), "X1": (0, L), "Y0": (1, 0.0), "Y1": (1, B), "Z0": (2, 0.0), "Z1": (2, B)}
    nsets = {k: np.flatnonzero(np.abs(pts[:, ax] - v) < 1e-12) for k, (ax, v) in sides.items()}
    write_inp(path, pts, blocks, elsets={"BAR": np.arange(sum(len(c) for _, c in blocks))}, nsets=nsets)
    return path


def _scene(tmp, deck, extra=""):
    text = f"""
[geometry]
builder = "mesh_file"
file = "{deck}"
parts = {{ bar = ["BAR"] }}
faces = {{ x0 = ["X0"], x1 = ["X1"], y0 = ["Y0"], y1 = ["Y1"], z0 = ["Z0"], z1 = ["Z1"] }}
[materials.bar]
E = {E}
nu = {NU}
rho = {RHO}
[boundary.fixed]
x0 = {{ face = "x0", components = ["x"] }}
y0 = {{ face = "y0", components = ["y"] }}
y1 = {{ face = "y1", components = ["y"] }}
z0 = {{ face = "z0", components = ["z"] }}
z1 = {{ face = "z1", components = ["z"] }}
[boundary.ground_springs]
end = {{ face = "x1", k_transverse = {C / L / 2} }}
[interfaces.end]
type = "rigid_plate"
face = "x1"
kn = {C / L / 2}
[analyses.real_modes]
n_modes = 2
target_hz = 0.0
{extra}"""
    path = tmp / f"bar{abs(hash(extra))}.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def bar(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("hexbar")
    deck = _deck(tmp / "bar.inp")
    out = tmp / "out"
    run_scene(load_scene(_scene(tmp, deck)), out, COMM, cache=tmp / "cache", write_fields=True, **QUIET)
    return tmp, deck, json.loads((out / "results.json").read_text()), out


def test_all_hex_deck_runs_natively_with_the_bar_frequencies(bar):
    _, _, res, out = bar
    assert res["mesh"]["import"]["hexahedra"]["path"] == "native"
    assert "every element is a hexahedron20" in res["mesh"]["import"]["hexahedra"]["reason"]
    assert res["model"]["element"].startswith("serendipity S2 (20 nodes), 2x2x2 Gauss points: CalculiX C3D20R")
    assert res["mesh"]["import"]["element"] == "hexahedron27"
    f = np.array([m["freq_hz"] for m in res["real_modes"]])
    exact = np.array([2.0287578381104342, 4.913180439434884]) * np.sqrt(C / RHO) / (2 * np.pi * L)
    # measured: 7.6e-5 and 2.8e-3 above the exact values (4 elements along the bar)
    assert np.all(f >= exact * (1 - 1e-9)) and np.all(f / exact - 1 < [2e-4, 5e-3])
    # the mode shapes are written on the 27-node geometry: u_x of the first mode ~ sin(κx)
    m = meshio.read(out / "real_modes.vtu")
    assert m.cells[0].type == "hexahedron27"
    u = m.point_data["mode_0"]
    shape = np.sin(2.0287578381104342 * m.points[:, 0] / L)
    assert abs(np.corrcoef(u[:, 0], shape)[0, 1]) > 0.9999 and np.abs(u[:, 1:]).max() < 1e-6 * np.abs(u).max()


def test_native_with_interfaces_is_a_named_error_and_auto_splits(bar):
    tmp, deck, _, _ = bar
    spring = '[interfaces.tie]\ntype = "spring"\nslave = "y0"\nmaster = "y1"\nkn = 1e9\n'
    scene = load_scene(_scene(tmp, deck, spring), ["discretisation.hexahedra=native"])
    with pytest.raises(MeshError, match=r"^discretisation.hexahedra = 'native' is not possible: interfaces.tie "
                                        r"\(spring\) \(written for triangle facets\).*use 'auto' or 'split'"):
        run_scene(scene, tmp / "bad", COMM, cache=tmp / "cache", write_fields=False, **QUIET)
    faces = {f: [f.upper()] for f in ("x0", "y0", "y1")}
    _, info = prepare(deck, parts={"bar": ["BAR"]}, faces=faces, hexahedra="auto",
                      blockers=["interfaces.tie (spring)"])
    assert info["hexahedra"]["path"] == "split" and info["element"] == "tetra10"
    assert info["hexahedra"]["reason"].startswith("interfaces.tie (spring) (written for triangle facets)")


def test_mixed_deck_keeps_the_split_and_native_names_why_not(tmp_path):
    deck = _deck(tmp_path / "mixed.inp", tets=[(1, 0, 0)])
    faces = {"x0": ["X0"]}
    _, info = prepare(deck, parts={"bar": ["BAR"]}, faces=faces, hexahedra="auto")
    assert info["hexahedra"] == {"path": "split", "reason": "mixed elements ['hexahedron20', 'tetra10']: the "
                                 "conforming split into tetrahedra"}
    assert info["file_elements"] == {"hexahedron20": 3, "tetra10": 6}
    from geometry.mesh_file import MeshImportError
    with pytest.raises(MeshImportError, match="'native' is not possible: mixed elements"):
        prepare(deck, parts={"bar": ["BAR"]}, faces=faces, hexahedra="native")
