"""Size of a mesh before it is built: the element count of each part from its volume, its surface and
its mesh size.

A gmsh tetrahedral mesh of target size h puts about ``TETS_PER_H3`` · V/h³ elements in the bulk of
a part of volume V, and at least about ``TETS_PER_H2`` · A/h² in a part whose thickness is below a
few h (its faces of area A are meshed at size h and the tetrahedra span the thickness): a part gets
the larger of the two.  Calibrated on real meshes (``tests/unit/app/test_resources.py`` re-checks them within
35 %): the ring of ``scenes/ryzhik_ring.toml`` (h = 2 mm: 4,533 cells, estimate 4,525) and the brake
corner, whose graded bore and imprinted pad footprints multiply the count of its surface-dominated
parts by ``BUILDER_FACTOR`` = 1.75: h = 16, 11, 5.6 and 3 mm give 8,570, 15,605, 67,285 and 361,758
cells against estimates of 7,952, 15,513, 66,678 and 410,593 (the bulk-dominated parts were
multiplied too until the 5.6 mm mesh showed 112k estimated for 67k).  It is an estimate for refusing
absurd sizes and warning near the memory limit before gmsh runs, not a mesh count.
"""
from __future__ import annotations

import math

from geometry.brake_corner import BrakeCornerParams, build_brake_corner
from geometry.tags import BRAKE_CORNER_VOLUMES

TETS_PER_H3 = 5.6     # tetrahedra per h³ of volume (bulk)
TETS_PER_H2 = 3.2     # tetrahedra per h² of surface (parts a few elements thick)
BUILDER_FACTOR = {"annular_disc": 1.0, "brake_corner": 1.75}

#: brake-corner part -> its mesh-size group of BrakeCornerParams.sizes()
_BRAKE_SIZE_GROUP = {"disc": "disc", "lining_inner": "pad", "lining_outer": "pad", "backplate_inner": "pad",
                     "backplate_outer": "pad", "piston": "caliper", "caliper": "caliper"}


def part_cells(volume: float, area: float, h: float, surface_factor: float = 1.0) -> float:
    """Expected tetrahedra of a part of ``volume`` and boundary ``area`` meshed at size ``h``: the bulk
    count, or the surface count times ``surface_factor`` (a builder's local refinements) when larger."""
    bulk, surface = TETS_PER_H3 * volume / h ** 3, TETS_PER_H2 * area / h ** 2
    return bulk if bulk >= surface else surface_factor * surface


def annular_disc_cells(*, mean_radius: float, width: float, thickness: float, mesh_size: float,
                       order: int = 2) -> dict[str, float]:
    """Expected cells of the ring: V = 2πRbh, A = 4πRb + 2πh(r_i + r_o)."""
    volume = 2 * math.pi * mean_radius * width * thickness
    area = 4 * math.pi * mean_radius * width + 2 * math.pi * thickness * 2 * mean_radius
    return {"disc": BUILDER_FACTOR["annular_disc"] * part_cells(volume, area, mesh_size)}


def brake_corner_cells(*, order: int = 2, **params) -> dict[str, float]:
    """Expected cells per part of the brake corner from the OCC volume and boundary area of each part
    (the geometry is built, not meshed: about 0.5 s)."""
    import gmsh  # heavy: gmsh (not needed to read mesh files)

    p = BrakeCornerParams(**params)
    sizes = p.sizes()
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("estimate")
        build_brake_corner(gmsh.model, p)
        out = {}
        for part, tag in BRAKE_CORNER_VOLUMES.items():
            entities = gmsh.model.getEntitiesForPhysicalGroup(3, tag)
            volume = sum(gmsh.model.occ.getMass(3, e) for e in entities)
            area = sum(gmsh.model.occ.getMass(2, s) for e in entities
                       for _, s in gmsh.model.getBoundary([(3, e)], oriented=False))
            out[part] = part_cells(volume, area, sizes[_BRAKE_SIZE_GROUP[part]], BUILDER_FACTOR["brake_corner"])
        return out
    finally:
        gmsh.finalize()


#: builder -> its estimator (a mesh file's size is the file's own: no estimate)
ESTIMATORS = {"annular_disc": annular_disc_cells, "brake_corner": brake_corner_cells}
