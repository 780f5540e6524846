"""Physical-group tags, defined once and imported by both ``geometry`` and the physics code.

Each geometry has a mapping ``name -> tag`` for its volumes (cell tags) and its faces
(facet tags).  Scenes refer to faces by *name*; the physics looks the number up here.
"""
from __future__ import annotations

from types import MappingProxyType

#: Annular disc (ring) between two rigid plates (seed 003).
ANNULAR_DISC_VOLUMES = MappingProxyType({"disc": 1})
ANNULAR_DISC_FACES = MappingProxyType({"top": 11, "bottom": 12, "inner": 13, "outer": 14})

GEOMETRY_TAGS = MappingProxyType({
    "annular_disc": (ANNULAR_DISC_VOLUMES, ANNULAR_DISC_FACES),
})


def face_tag(builder: str, name: str) -> int:
    """Facet tag of face ``name`` of geometry ``builder``; raises ``KeyError`` naming the options."""
    faces = GEOMETRY_TAGS[builder][1]
    if name not in faces:
        raise KeyError(f"face {name!r} is not a face of {builder!r}; available: {sorted(faces)}")
    return faces[name]
