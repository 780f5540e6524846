"""The physics description of a validated scene (:class:`fem_squeal.fe.model.ModelSpec`): materials,
plates, interfaces with their friction laws, boundary conditions, loads and the discretisation, made
from the typed sections.  The validation pass builds it once (:mod:`fem_squeal.app.scene.validation`):
a part's material is checked by making it, and that object is the one the model holds."""
from __future__ import annotations

from collections.abc import Mapping

from fem_squeal.fe.model import (
    FixedFace,
    GapProfile,
    GroundSpring,
    Interface,
    Material,
    ModelSpec,
    PointLoad,
    Pressure,
    RigidPlate,
)
from fem_squeal.reduced.laws.friction import FRICTION_LAWS
from fem_squeal.util.errors import SceneError


def material(part: str, m: Mapping) -> Material:
    """The material of a part from its checked section ``materials.<part>``; what the physics refuses
    (an incomplete transversely isotropic set) is a :class:`SceneError` naming the key."""
    try:
        return Material(**m)
    except ValueError as e:     # ModelError, a ValueError
        raise SceneError(f"materials.{part}.{e}") from None


def _friction_law(t):
    """The μ(V) law of an interface table (None: the constant mu), made by the registry of
    :mod:`fem_squeal.reduced.laws.friction` that the transient uses too."""
    if t.get("friction", "constant") == "constant":
        return None
    return FRICTION_LAWS[t["friction"]].make(float(t["mu"]), t["mu_s"], t["mu_d"], float(t["v_s"]),
                                             float(t["v_d"]), 1.0, 0.0)


def _nominal_mu(t, law) -> float:
    """The interface's μ: mu, or with a μ(V) law its dynamic level μ_d (what a μ sweep scales)."""
    return float(t.get("mu", 0.0)) if law is None else float(law.mu_d)


def _friction(t, speed: float) -> dict:
    """μ, and the friction law, friction damping and disc speed of an interface table (fe.model fields)."""
    if "friction" not in t:
        return {"mu": float(t.get("mu", 0.0))}
    law = _friction_law(t)
    return {"mu": _nominal_mu(t, law), "law": law, "friction_damping": bool(t["friction_damping"]),
            "speed": speed}


def _gap(v: Mapping | None) -> GapProfile | None:
    """An interface's ``initial_gap`` table as a :class:`~fem_squeal.fe.model.GapProfile` (None if not set)."""
    if v is None:
        return None
    return GapProfile(float(v.get("offset", 0.0)), tuple(float(x) for x in v.get("gradient", (0.0, 0.0, 0.0))),
                      tuple(float(x) for x in v["at"]) if "at" in v else None)


def build_model_spec(scene: Mapping, materials: Mapping[str, Material] | None = None) -> ModelSpec:
    """The physics description of a validated finite-element scene; ``materials``: the parts'
    :class:`Material` where they are made already (by the validation pass), else made here."""
    mats = dict(materials) if materials is not None else {p: material(p, m) for p, m in scene["materials"].items()}
    speed = float(scene["operating"]["speed"]) if "operating" in scene else 0.0
    plates = tuple(RigidPlate(t["face"], float(t["kn"]), sliding=int(t["sliding"]), kt=float(t["kt"]),
                              **_friction(t, speed), name=name)
                   for name, t in scene["interfaces"].items() if t["type"] == "rigid_plate")
    interfaces = tuple(
        Interface(name, t["slave"], t["master"], t["type"], float(t["kn"]), float(t.get("kt", 0.0)),
                  sliding=int(t.get("sliding", 0)), **_friction(t, speed), initial_gap=_gap(t.get("initial_gap")))
        for name, t in scene["interfaces"].items() if t["type"] != "rigid_plate")
    springs = tuple(GroundSpring(t["face"], float(t["k_axial"]), float(t["k_transverse"]))
                    for t in scene["boundary"]["ground_springs"].values())
    pressures = tuple(Pressure(t["face"], float(t["p"])) for t in scene["loads"]["pressure"].values())
    points = tuple(PointLoad(n, tuple(t["point"]), tuple(t["force"]))
                   for n, t in scene["loads"].get("point", {}).items())
    d = scene["discretisation"]
    fixed = tuple(FixedFace(t["face"], tuple(t["components"]))
                  for t in scene["boundary"].get("fixed", {}).values())
    return ModelSpec(mats, plates, tuple(scene["boundary"]["clamped"]), d["degree"],
                     d["quadrature_degree"], interfaces=interfaces, ground_springs=springs,
                     pressures=pressures, interface_quadrature_degree=d["interface_quadrature_degree"],
                     fixed=fixed, point_loads=points)

