"""The displacement element and rule on native hexahedral meshes (``discretisation.hexahedra``).

Chosen by measurement (``benchmarks/hex_native.py``: the clamped-free annular plate of issue #37, 6 × 96 × 2
C3D20R, against CalculiX 2.20 on the same deck, ten lowest frequencies):

- degree 2: the 20-node serendipity space (basix family "S": the polynomial space of C3D20) with
  2 × 2 × 2 Gauss points, CalculiX's C3D20R: within 1e-7 of it.  Q2 Lagrange (27 nodes) is 0.55 %
  (3 × 3 × 3) or 0.57 % (2 × 2 × 2) above C3D20R; S2 with 3 × 3 × 3 points is C3D20 (3e-6 from ccx's).
- degree 1: Q1 (8 nodes) with 2 × 2 × 2 Gauss points, CalculiX's C3D8 (3e-7); on a C3D8R deck, CalculiX's
  C3D8R: one mean-strain point with hourglass stiffness (:mod:`fem_squeal.fe.c3d8r`).  Degree 2 on an
  8-node deck (S2 on the trilinear geometry) is the accurate choice: both 8-node elements are stiff or
  soft in bending.

The rule is UFL's quadrature degree 3 on hexahedra (basix: 2 points per direction; 5 gives 3 × 3 × 3), set
on the cell integrals of every form whose scene leaves ``discretisation.quadrature_degree`` unset.

The serendipity element's edge degrees of freedom are integral moments, not point values: Dirichlet
values are zero *functions* (dolfinx refuses constants there), and the degrees of freedom's "coordinates"
are the element's interpolant of x (vertices; edge means of x, about the mid-edge points).
"""
from __future__ import annotations

import numpy as np
import ufl
from dolfinx import fem
from petsc4py import PETSc

#: UFL quadrature degree of the 2 × 2 × 2 Gauss rule on hexahedra (basix: (degree + 2) // 2 points per axis).
GAUSS_2X2X2 = 3
#: UFL quadrature degree of the 3 × 3 × 3 Gauss rule (CalculiX C3D20's): a C3D20 deck's rule.
GAUSS_3X3X3 = 5
#: (degree) -> (UFL family, description for the results).
ELEMENTS = {1: ("Q", "Q1 (8 nodes), 2x2x2 Gauss points: CalculiX C3D8"),
            2: ("S", "serendipity S2 (20 nodes), 2x2x2 Gauss points: CalculiX C3D20R")}


def is_hexahedral(mesh) -> bool:
    return mesh.ufl_cell().cellname() == "hexahedron"


def displacement_space(mesh, degree: int) -> fem.FunctionSpace:
    """[P_degree]³ on tetrahedra (as always); on hexahedra the element of :data:`ELEMENTS`."""
    if not is_hexahedral(mesh):
        return fem.VectorFunctionSpace(mesh, ("Lagrange", degree))
    return fem.FunctionSpace(mesh, ufl.VectorElement(ELEMENTS[degree][0], mesh.ufl_cell(), degree))


#: what runs for a C3D8R deck at degree 1 (:mod:`fem_squeal.fe.c3d8r`).
C3D8R = "Q1 (8 nodes), one point (mean strain) with hourglass control: CalculiX C3D8R"


def element_description(V, quadrature_degree: int | None, c3d8r: bool = False) -> str:
    """What runs on a hexahedral mesh, for the results and the log."""
    degree = V.ufl_element().degree()
    if c3d8r:
        return C3D8R
    if quadrature_degree is None:
        return ELEMENTS[degree][1]
    if degree == 2 and quadrature_degree == GAUSS_3X3X3:
        return "serendipity S2 (20 nodes), 3x3x3 Gauss points: CalculiX C3D20"
    return f"{ELEMENTS[degree][1].split(',')[0]}, quadrature degree {quadrature_degree} (discretisation)"


def with_cell_rule(form: ufl.Form, degree: int = GAUSS_2X2X2) -> ufl.Form:
    """``form`` with the 2 × 2 × 2 Gauss rule (or the rule of quadrature ``degree``) on its cell integrals
    when its domain is hexahedral (no rule set there yet); unchanged otherwise."""
    if form.ufl_domain().ufl_cell().cellname() != "hexahedron":
        return form
    return ufl.Form([itg.reconstruct(metadata={"quadrature_degree": degree, **itg.metadata()})
                     if itg.integral_type() == "cell" else itg for itg in form.integrals()])


def point_evaluation(V) -> bool:
    """Whether V's degrees of freedom are point values (Lagrange, Q); not the serendipity element."""
    return V.ufl_element().family() not in ("S", "serendipity")


def zero_condition(V, dofs, sub: int | None = None):
    """The homogeneous Dirichlet condition on ``dofs`` of V (or of its component ``sub``): a zero
    constant where V evaluates at points, a zero function otherwise (dolfinx 0.5.2 accepts constants
    only for point-evaluation elements).  ``dofs`` for a component of a non-point element: the pair
    of :func:`dolfinx.fem.locate_dofs_topological` on (V.sub(i), its collapse)."""
    if point_evaluation(V):
        if sub is None:
            return fem.dirichletbc(np.zeros(3, dtype=PETSc.ScalarType), dofs, V)
        return fem.dirichletbc(PETSc.ScalarType(0), dofs, V.sub(sub))
    if sub is None:
        return fem.dirichletbc(fem.Function(V), dofs)
    return fem.dirichletbc(fem.Function(V.sub(sub).collapse()[0]), dofs, V.sub(sub))


def dof_coordinates(V) -> np.ndarray:
    """Coordinates of V's (blocked) degrees of freedom, local with ghosts: the tabulated ones for
    point-evaluation elements, else V's interpolant of x (vertex values; edge means of x)."""
    if point_evaluation(V):
        return V.tabulate_dof_coordinates()
    f = fem.Function(V)
    f.interpolate(lambda x: x)
    return f.x.array.reshape(-1, 3).copy()
