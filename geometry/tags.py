"""Physical-group tags, defined once in ``geometry`` (which imports nothing from ``fem_squeal``) and
imported by the physics code.

Each geometry has a mapping ``name -> tag`` for its volumes (cell tags) and its faces
(facet tags).  Scenes refer to faces by *name*; the physics looks the number up here.
"""
from __future__ import annotations

from types import MappingProxyType

#: Annular disc (ring) between two rigid plates (seed 003).
ANNULAR_DISC_VOLUMES = MappingProxyType({"disc": 1})
ANNULAR_DISC_FACES = MappingProxyType({"top": 11, "bottom": 12, "inner": 13, "outer": 14})

#: Brake corner: disc with hat, two pads (lining + backplate), piston, floating caliper.
BRAKE_CORNER_VOLUMES = MappingProxyType({
    "disc": 1, "lining_inner": 2, "lining_outer": 3, "backplate_inner": 4, "backplate_outer": 5,
    "piston": 6, "caliper": 7,
})
BRAKE_CORNER_FACES = MappingProxyType({
    "disc_bolt_face": 21,          # hub-flange bolt face (clamped)
    "disc_friction_inner": 22,     # inboard friction face of the disc (master of the inner lining)
    "disc_friction_outer": 23,     # outboard friction face of the disc (master of the outer lining)
    "lining_inner_contact": 24,    # inner lining face on the disc (slave)
    "lining_outer_contact": 25,    # outer lining face on the disc (slave)
    "piston_front": 26,            # piston face on the inner backplate
    "backplate_inner_back": 27,    # inner backplate back face (piston side)
    "finger_front": 28,            # caliper finger faces on the outer backplate
    "backplate_outer_back": 29,    # outer backplate back face (finger side)
    "piston_back": 30,             # piston bottom face: brake pressure acts here
    "bore_bottom": 31,             # caliper bore bottom: the pressure's reaction acts here
    "piston_side": 32,             # piston cylindrical face (seal)
    "bore_wall": 33,               # caliper bore cylindrical face (seal)
    "caliper_guide": 34,           # caliper guide-pin / mount faces (springs to ground)
    "backplate_abutment": 35,      # backplate end faces on the anchor bracket (springs to ground)
})

#: Components whose strain-energy shares the brake CEA reports (seed 002, Fig. 6).
BRAKE_CORNER_GROUPS = MappingProxyType({
    "disc": ("disc",), "linings": ("lining_inner", "lining_outer"),
    "backplates": ("backplate_inner", "backplate_outer"), "caliper": ("caliper",), "piston": ("piston",),
})
COMPONENT_GROUPS = MappingProxyType({"brake_corner": BRAKE_CORNER_GROUPS})

GEOMETRY_TAGS = MappingProxyType({
    "annular_disc": (ANNULAR_DISC_VOLUMES, ANNULAR_DISC_FACES),
    "brake_corner": (BRAKE_CORNER_VOLUMES, BRAKE_CORNER_FACES),
})


def mesh_file_tags(parts: list[str], faces: list[str]) -> tuple[dict[str, int], dict[str, int]]:
    """Tags of a mesh read from a file (``geometry.builder = "mesh_file"``): the parts of the scene's
    mapping get 1, 2, ... and its faces 101, 102, ..., in the order the scene lists them."""
    if len(parts) > 100:
        raise ValueError(f"geometry.parts: at most 100 parts (got {len(parts)})")
    return {p: 1 + i for i, p in enumerate(parts)}, {f: 101 + i for i, f in enumerate(faces)}


def face_tag(builder: str, name: str) -> int:
    """Facet tag of face ``name`` of geometry ``builder``; raises ``KeyError`` naming the options."""
    faces = GEOMETRY_TAGS[builder][1]
    if name not in faces:
        raise KeyError(f"face {name!r} is not a face of {builder!r}; available: {sorted(faces)}")
    return faces[name]
