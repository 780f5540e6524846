"""Native hexahedra (geometry side): the 27-node completion of twenty-node hexahedra, the element
checks and the choice between the native path and the split (:mod:`geometry.hexahedra`)."""
from __future__ import annotations

import numpy as np
import pytest

from geometry.hexahedra import (
    HexFaceIndex,
    HexPathError,
    choose_path,
    complete_hex27,
    hex_quality,
    integration_rule,
)
from geometry.split import reference_nodes

REF20 = reference_nodes("hexahedron20")          # [0, 2]³, VTK order
REF27 = reference_nodes("hexahedron27")


def _two_cells(f):
    """Two twenty-node hexahedra side by side in ξ ∈ [0, 4] × [0, 2]², their nodes at f(ξ); the
    shared face's nodes are one set of points.  Returns points, connectivity and the map."""
    ref = np.vstack([REF20, REF20 + [2.0, 0.0, 0.0]])
    keys, inverse = np.unique(np.round(ref, 9), axis=0, return_inverse=True)
    return f(keys), inverse.reshape(2, 20), ref


def test_completion_is_exact_for_an_affine_element():
    rng = np.random.default_rng(1)
    A, b = np.eye(3) + 0.3 * rng.standard_normal((3, 3)), rng.standard_normal(3)
    pts, conn, _ = _two_cells(lambda x: x @ A.T + b)
    x, c27 = complete_hex27(pts, conn)
    assert c27.shape == (2, 27) and np.array_equal(c27[:, :20], conn)
    assert len(x) == len(pts) + 11 + 2            # 11 distinct faces (one shared), 2 centres
    for e, shift in enumerate(([0.0, 0, 0], [2.0, 0, 0])):
        assert np.allclose(x[c27[e]], (REF27 + shift) @ A.T + b, rtol=0, atol=1e-13)


def test_completion_is_exact_for_a_curved_serendipity_element():
    """Nodes on a map whose components lie in the serendipity space (ξ²η, ξηζ, ξζ², ...): the Q2
    map through the 27 points is that map, at the face and body centres too; the shared face has one
    centre node."""
    def f(p):
        s, t, u = p.T / 2.0
        return np.column_stack([p[:, 0] + 0.2 * s * s * t - 0.1 * s * t * u,
                                p[:, 1] + 0.15 * t * u * u + 0.05 * s * s,
                                p[:, 2] - 0.1 * s * t * u + 0.1 * t * t * s])
    pts, conn, _ = _two_cells(f)       # one map over both cells (the space is invariant under translation)
    x, c27 = complete_hex27(pts, conn)
    for e, shift in enumerate(([0.0, 0, 0], [2.0, 0, 0])):
        assert np.allclose(x[c27[e]], f(REF27 + shift), rtol=0, atol=1e-14)
    shared = set(c27[0, 20:26]) & set(c27[1, 20:26])
    assert len(shared) == 1 and x[shared.pop()][0] == pytest.approx(2.0 + 0.2 * 1 * 0.5 - 0.1 * 0.25)


def test_quality_and_boundary_faces():
    pts, conn, _ = _two_cells(lambda x: x.astype(float))
    x, c27 = complete_hex27(pts, conn)
    ratio, aspect = hex_quality(x, c27)
    assert np.allclose(ratio, 1.0) and np.allclose(aspect, 1.0)
    inverted = x.copy()
    inverted[c27[1, 26]] = [10.0, 1.0, 1.0]           # the centre node far out of its cell
    assert hex_quality(inverted, c27)[0][1] <= 0 < hex_quality(inverted, c27)[0][0]
    index = HexFaceIndex(c27)
    assert len(index.boundary) == 10 and len(index.interior) == 1
    with pytest.raises(ValueError, match="lie between two hexahedra"):
        index.locate(np.array([sorted(index.interior)[0]]), "S")


def test_path_choice_and_its_reasons():
    assert choose_path("auto", ["hexahedron20"] * 2) == (
        "native", "every element is a hexahedron20 and every feature of the scene is supported on hexahedra")
    route, why = choose_path("auto", ["hexahedron20", "tetra10"])
    assert route == "split" and why.startswith("mixed elements ['hexahedron20', 'tetra10']")
    route, why = choose_path("auto", ["hexahedron"], ["interfaces.pad (contact)"])
    assert route == "split" and why.startswith("interfaces.pad (contact) (not supported on hexahedra)")
    assert choose_path("auto", ["hexahedron", "hexahedron20"])[0] == "split"
    assert choose_path("split", ["hexahedron20"]) == ("split", "discretisation.hexahedra = 'split'")
    assert choose_path("auto", ["tetra10"]) == ("split", "no hexahedra in the file")
    with pytest.raises(HexPathError, match=r"discretisation.hexahedra = 'native' is not possible: interfaces.pad "
                                           r"\(contact\) .*use 'auto' or 'split'"):
        choose_path("native", ["hexahedron20"], ["interfaces.pad (contact)"])
    with pytest.raises(HexPathError, match="'native' is not possible: mixed elements"):
        choose_path("native", ["hexahedron20", "wedge15"])
    with pytest.raises(HexPathError, match="must be one of"):
        choose_path("hex", ["hexahedron20"])


@pytest.mark.parametrize("mtype, types, rule, words", [
    ("hexahedron20", ["C3D20R"], "reduced", "2x2x2"),
    ("hexahedron20", ["C3D20", "C3D20"], "full", "3x3x3"),
    ("hexahedron20", ["C3D20", "C3D20R"], "reduced", "quadrature_degree = 5"),
    ("hexahedron20", [], "reduced", "does not name"),
    ("hexahedron", ["C3D8"], "full", "C3D8"),
    ("hexahedron", ["C3D8R"], "one-point", "hourglass"),
    ("hexahedron", ["C3D8", "C3D8R"], "full", "C3D8R only"),
])
def test_the_deck_names_the_cell_rule(mtype, types, rule, words):
    """C3D20R decks run with 2x2x2 Gauss points and C3D20 decks with 3x3x3 (CalculiX's own rules, as
    benchmarks/hex_native.py measures), a deck of both or a file without Abaqus types with 2x2x2,
    saying so; 8-node hexahedra with C3D8's 2x2x2, C3D8R-only decks with C3D8R's one point."""
    got, why = integration_rule(mtype, types)
    assert got == rule and words in why
