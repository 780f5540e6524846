"""The cell rule a native hexahedral deck runs with (fem_squeal.app.analyses.mesh.spec_for_hexahedra)."""
from __future__ import annotations

import pytest

from fem_squeal.app.analyses.mesh import spec_for_hexahedra
from fem_squeal.fe.hexahedra import GAUSS_3X3X3
from fem_squeal.fe.model import Material, ModelSpec

SPEC = ModelSpec({"plate": Material(210e9, 0.3, 7850.0, 0, 0)}, degree=2)


@pytest.mark.parametrize("element,integration,degree,quadrature", [
    ("hexahedron20", "full", 2, GAUSS_3X3X3),     # C3D20: its own 3 x 3 x 3 rule
    ("hexahedron20", "reduced", 2, None),         # C3D20R: 2 x 2 x 2 (the default)
    ("hexahedron", "full", 2, None),              # C3D8 at degree 2: S2 with 2 x 2 x 2, not C3D20's rule
    ("hexahedron", "full", 1, None),              # C3D8 at degree 1: Q1 with 2 x 2 x 2
])
def test_only_a_twenty_node_full_integration_deck_gets_three_points(element, integration, degree, quadrature):
    """"full" integration means 3 × 3 × 3 for a C3D20 deck only: a C3D8 deck's full rule is C3D8's own
    2 × 2 × 2, so at degree 2 it runs S2 with 2 × 2 × 2 (benchmarks/hex_native.py --quick: 3.5e-3 from ccx
    C3D20R, 3.8e-2 when it was given the 3 × 3 × 3 rule)."""
    spec = SPEC if degree == 2 else ModelSpec(SPEC.materials, degree=1)
    out = spec_for_hexahedra(spec, {"path": "native", "element": element, "integration": integration})
    assert out.quadrature_degree == quadrature and not out.c3d8r
