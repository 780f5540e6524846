"""The mixed hexahedral/tetrahedral brake of ``scenes/hex_brake_mixed.toml`` against its
all-tetrahedral twin (``benchmarks/hex_brake.py``): deck writer checks, a coarse CEA of both (default)
and the full comparison with the refinement estimate of the discretisation error (slow)."""
from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from support.paths import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))

#: corner nodes (0-based) of the Abaqus face labels
FACES = {"hexahedron20": {"S1": [0, 1, 2, 3], "S2": [4, 7, 6, 5], "S3": [0, 4, 5, 1], "S4": [1, 5, 6, 2],
                          "S5": [2, 6, 7, 3], "S6": [3, 7, 4, 0]},
         "tetra10": {"S1": [0, 1, 2], "S2": [0, 3, 1], "S3": [1, 3, 2], "S4": [2, 3, 0]}}


@pytest.mark.parametrize("kind, mirror", [("hex20", False), ("tet10", False), ("tet10", True)])
def test_polar_block_elements_are_positive_and_faces_lie_on_their_sides(kind, mirror):
    from geometry.hex_decks import polar_block

    r, t, z = (0.04, 0.12), (0.3, 1.2), (-0.01, 0.005)
    x, (mtype, conn), faces = polar_block(r, t, z, (2, 3, 2), kind, mirror)
    assert len(conn) == 12 * (1 if kind == "hex20" else 6)
    p = x[conn]
    a, b, c, d = (p[:, i] for i in ((0, 1, 3, 4) if kind == "hex20" else (0, 1, 2, 3)))
    assert np.all(np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) > 0)      # right-handed corners
    rad, ang = np.hypot(x[:, 0], x[:, 1]), np.arctan2(x[:, 1], x[:, 0])
    assert np.allclose(rad.min(), r[0]) and np.allclose(rad.max(), r[1])        # mid-edge nodes on the circles
    value = {"r0": (rad, r[0]), "r1": (rad, r[1]), "t0": (ang, t[0]), "t1": (ang, t[1]), "z0": (x[:, 2], z[0]),
             "z1": (x[:, 2], z[1])}
    area_cells = {"r0": 6, "r1": 6, "t0": 4, "t1": 4, "z0": 6, "z1": 6}
    if kind == "tet10":         # conforming: every triangle interior (twice) or on a side (once)
        tri = np.sort(conn[:, [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]].reshape(-1, 3), axis=1)
        _, count = np.unique(tri, axis=0, return_counts=True)
        assert count.max() == 2 and (count == 1).sum() == 2 * sum(area_cells.values())
    for side, rows in faces.items():
        assert len(rows) == area_cells[side] * (1 if kind == "hex20" else 2)
        for e, lab in rows:
            q, v = value[side]
            assert np.allclose(q[conn[e][FACES[mtype][lab]]], v), (side, e, lab)
            # the face is outward: the element's remaining corners lie inside
            other = np.setdiff1d(conn[e][:8 if kind == "hex20" else 4], conn[e][FACES[mtype][lab]])
            assert np.all(q[other] > v if side.endswith("0") else q[other] < v)


def test_mixed_brake_deck_runs_through_the_cea_like_its_all_tet_twin():
    """Coarse decks (3348 DOFs each): both find the same unstable pairs (measured: one, 6748.1 Hz,
    Re λ 11.76 / 11.26 1/s, one nodal diameter)."""
    import hex_brake

    with tempfile.TemporaryDirectory() as d:
        decks = hex_brake.write_decks(Path(d), 1, **hex_brake.COARSE)
        fast = ["analyses.cea.n_modes=24", "analyses.cea.band_hz=[0.0, 9000.0]"]
        res = {k: hex_brake.run_model(v, Path(d) / k, fast) for k, v in decks.items()}
    mixed, tet = res["mixed"]["unstable"], res["tet"]["unstable"]
    assert len(mixed) == len(tet) >= 1
    for u, v in hex_brake.pair_up(mixed, tet):
        assert v is not None and abs(v["freq_hz"] / u["freq_hz"] - 1) < 1e-3
        assert abs(v["real_part"] / u["real_part"] - 1) < 0.1
        assert u["nodal_diameter"] == v["nodal_diameter"]


@pytest.mark.slow
def test_mixed_brake_agrees_with_its_twins_within_the_discretisation_error():
    """Levels ×1 (10k DOFs) and ×2 (66k) and the gmsh twin (33k), about 4 min.  Against mixed ×2:
    the structured twin ×2 and the gmsh twin find every unstable pair, and differ from it by less
    than the mixed model changes from ×1 to ×2 (the discretisation error of ×1)."""
    import hex_brake

    res = hex_brake.run(quick=False, levels=(1, 2))
    ref = res["against_reference"]
    refinement = ref["mixed x1"]
    assert len(refinement) >= 2
    for twin in ("tet x2", "gmsh tet 10 mm"):
        for r, e in zip(ref[twin], refinement):
            assert r["d_freq_rel"] is not None, (twin, r)
            if e["d_freq_rel"] is not None:
                assert abs(r["d_freq_rel"]) < abs(e["d_freq_rel"])
                assert abs(r["d_real_rel"]) < max(abs(e["d_real_rel"]), 0.05)
    for lv, rows in res["twins"].items():     # at equal resolution the structured twins agree closely
        assert all(r["d_freq_rel"] is not None and abs(r["d_freq_rel"]) < 1e-3 for r in rows), lv
