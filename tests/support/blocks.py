"""Two stacked blocks for interface tests: a lower block (master face on top) and a smaller upper
block whose bottom face (slave) lies on it.  The faces are separate surfaces, meshed independently
(non-matching) or, with ``matching=True``, with the slave mesh copied from an imprinted patch of
the master face (coincident but distinct nodes)."""
from __future__ import annotations

from geometry.gmsh_io import GmshModel, MeshData, to_dolfinx

VOLUMES = {"lower": 1, "upper": 2}
FACES = {"master": 1, "slave": 2, "lower_bottom": 3, "upper_top": 4, "upper_sides": 5}
LOWER = (0.0, 0.0, 0.0, 1.0, 0.8, 0.5)          # x, y, z, dx, dy, dz
UPPER = (0.1, 0.1, 0.5, 0.7, 0.6, 0.4)
CONTACT_AREA = UPPER[3] * UPPER[4]


def two_blocks(comm, h_lower: float = 0.3, h_upper: float = 0.21, order: int = 2,
               matching: bool = False) -> MeshData:
    def build(model):
        import gmsh
        occ = model.occ
        a = occ.addBox(*LOWER)
        b = occ.addBox(*UPPER)
        if matching:
            patch = occ.addRectangle(UPPER[0], UPPER[1], UPPER[2], UPPER[3], UPPER[4])
            out, _ = occ.fragment([(3, a)], [(2, patch)])
            a = [t for d, t in out if d == 3][0]
        occ.synchronize()

        def faces(vol, test):
            return [t for d, t in model.getBoundary([(3, vol)], oriented=False)
                    if test(occ.getCenterOfMass(2, t))]
        z_top = UPPER[2]
        top = faces(a, lambda c: abs(c[2] - z_top) < 1e-9)
        bot = faces(b, lambda c: abs(c[2] - z_top) < 1e-9)
        model.addPhysicalGroup(3, [a], 1)
        model.addPhysicalGroup(3, [b], 2)
        model.addPhysicalGroup(2, top, 1)
        model.addPhysicalGroup(2, bot, 2)
        model.addPhysicalGroup(2, faces(a, lambda c: abs(c[2]) < 1e-9), 3)
        model.addPhysicalGroup(2, faces(b, lambda c: abs(c[2] - UPPER[2] - UPPER[5]) < 1e-9), 4)
        model.addPhysicalGroup(2, faces(b, lambda c: UPPER[2] + 1e-9 < c[2] < UPPER[2] + UPPER[5] - 1e-9), 5)
        model.mesh.setSize(model.getBoundary([(3, a)], recursive=True), h_lower)
        model.mesh.setSize(model.getBoundary([(3, b)], recursive=True), h_upper)
        if matching:
            patch_faces = [t for t in top if abs(occ.getMass(2, t) - CONTACT_AREA) < 1e-9]
            model.mesh.setSize(model.getBoundary([(2, t) for t in patch_faces], recursive=True), h_upper)
            gmsh.model.mesh.setPeriodic(2, bot, patch_faces, [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1])
    return to_dolfinx(comm, GmshModel(build, order, VOLUMES, FACES))
