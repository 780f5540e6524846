"""Plain descriptions of the physics of a model: materials, plates, interfaces, springs, loads.

These are validated values (the scene loader builds them); the assembly turns them into matrices.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fem_squeal.reduced.laws.loss_factor import loss_table
from fem_squeal.util.errors import ModelError


def sliding_speed(x: np.ndarray, speed: float) -> np.ndarray:
    """V = Ω r at the points ``x`` (n, 3): the disc speed Ω times the distance r to the z axis."""
    x = np.asarray(x, float).reshape(-1, 3)
    return speed * np.hypot(x[:, 0], x[:, 1])


def speed_friction(mu: float, law: Any, V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """μ(V) and dμ/dV at the sliding speeds V: the constant ``mu`` (dμ/dV = 0) when ``law`` is None,
    else the speed-dependent law of :mod:`fem_squeal.reduced.laws.friction` (its ``coefficient``:
    the one definition of μ(V) the transient uses too)."""
    V = np.asarray(V, float)
    if law is None:
        return np.full(V.shape, float(mu)), np.zeros(V.shape)
    m, dm = law.coefficient(V)
    return np.broadcast_to(m, V.shape).astype(float), np.broadcast_to(dm, V.shape).astype(float)


def _check_speed_terms(obj) -> None:
    """Shared checks of the friction law and friction damping of a plate or a contact."""
    if not obj.speed >= 0:
        raise ModelError(f"speed: must be >= 0 (got {obj.speed})")
    if obj.law is not None and not hasattr(obj.law, "coefficient"):
        raise ModelError(f"law: a speed-dependent friction law with coefficient(V) (got {type(obj.law).__name__})")
    if obj.law is not None and not obj.speed > 0:
        raise ModelError("speed: must be > 0 with a speed-dependent friction law (μ(V) at V = speed·r)")
    if obj.friction_damping:
        if not obj.speed > 0:
            raise ModelError("speed: must be > 0 with friction_damping")
        if obj.sliding == 0 or (obj.mu == 0 and obj.law is None):
            raise ModelError("friction_damping: needs sliding = ±1 and mu > 0 or a μ(V) law")


#: Abaqus/CalculiX order of the 21 anisotropic constants D_ijkl (TYPE=ANISO), as Voigt pairs of
#: this module's order (xx, yy, zz, yz, xz, xy) = (11, 22, 33, 23, 13, 12)
ANISO_ORDER = ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2), (0, 5), (1, 5), (2, 5), (5, 5), (0, 4), (1, 4),
               (2, 4), (4, 5), (4, 4), (0, 3), (1, 3), (2, 3), (3, 5), (3, 4), (3, 3))
#: the nine orthotropic constants D1111 D1122 D2222 D1133 D2233 D3333 D1212 D1313 D2323 (TYPE=ORTHOTROPIC)
ORTHO_ORDER = ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2), (5, 5), (4, 4), (3, 3))
ENGINEERING_CONSTANTS = ("E1", "E2", "E3", "nu12", "nu13", "nu23", "G12", "G13", "G23")


def orthotropic_compliance(E1, E2, E3, nu12, nu13, nu23, G12, G13, G23) -> np.ndarray:
    """6×6 compliance S (Voigt order xx, yy, zz, yz, xz, xy; engineering shear strains) of the engineering
    constants in the material frame (Abaqus's convention, ν_ij/E_i = ν_ji/E_j):
    S = [[1/E1, −ν12/E1, −ν13/E1], [−ν12/E1, 1/E2, −ν23/E2], [−ν13/E1, −ν23/E2, 1/E3]]
        ⊕ diag(1/G23, 1/G13, 1/G12)."""
    S = np.zeros((6, 6))
    S[:3, :3] = [[1 / E1, -nu12 / E1, -nu13 / E1], [-nu12 / E1, 1 / E2, -nu23 / E2],
                 [-nu13 / E1, -nu23 / E2, 1 / E3]]
    S[3, 3], S[4, 4], S[5, 5] = 1 / G23, 1 / G13, 1 / G12
    return S


def voigt_from_d(d) -> np.ndarray:
    """The symmetric 6×6 stiffness (this module's Voigt order) of the 21 Abaqus ANISO constants D_ijkl
    (:data:`ANISO_ORDER`); 9 values: the orthotropic D's (:data:`ORTHO_ORDER`)."""
    order = ANISO_ORDER if len(d) == 21 else ORTHO_ORDER
    if len(d) != len(order):
        raise ModelError(f"D: 9 (orthotropic) or 21 (anisotropic) constants (got {len(d)})")
    C = np.zeros((6, 6))
    for (i, j), v in zip(order, d):
        C[i, j] = C[j, i] = float(v)
    return C


@dataclass(frozen=True)
class Orientation:
    """The material frame of a part (Abaqus/CalculiX ``*ORIENTATION``), as unit vectors (e₁, e₂, e₃) at x:

    - ``rectangular``: e₁ along a − c, e₃ along (a − c) × (b − c), e₂ = e₃ × e₁ (a on the local 1 axis, b
      in the local 1–2 plane, c the origin; constant);
    - ``cylindrical``: a and b on the axis, e₃ = (b − a)/|b − a| (axial), e₁ radial from the axis through x,
      e₂ = e₃ × e₁ (tangential); varies with x."""

    system: str = "rectangular"
    a: tuple = (1.0, 0.0, 0.0)
    b: tuple = (0.0, 1.0, 0.0)
    c: tuple = (0.0, 0.0, 0.0)

    def __post_init__(self):
        if self.system not in ("rectangular", "cylindrical"):
            raise ModelError(f"orientation.system: must be 'rectangular' or 'cylindrical' (got {self.system!r})")
        for k in ("a", "b", "c"):
            v = getattr(self, k)
            if len(v) != 3 or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
                raise ModelError(f"orientation.{k}: must be three numbers (got {v!r})")
            object.__setattr__(self, k, tuple(float(x) for x in v))
        a, b, c = (np.asarray(getattr(self, k)) for k in "abc")
        if self.system == "rectangular":
            e1 = a - c
            n3 = np.cross(e1, b - c)
            if np.linalg.norm(e1) == 0 or np.linalg.norm(n3) <= 1e-12 * np.linalg.norm(e1) * np.linalg.norm(b - c):
                raise ModelError("orientation: a must differ from c and b must not lie on the line c–a")
        elif np.linalg.norm(b - a) == 0:
            raise ModelError("orientation: a and b must differ (two points of the cylinder axis)")

    def frame(self) -> np.ndarray:
        """Q (3×3), rows e₁, e₂, e₃ in global components (rectangular only: constant)."""
        a, b, c = (np.asarray(getattr(self, k)) for k in "abc")
        e1 = (a - c) / np.linalg.norm(a - c)
        e3 = np.cross(a - c, b - c)
        e3 /= np.linalg.norm(e3)
        return np.array([e1, np.cross(e3, e1), e3])

    def axis(self) -> tuple[np.ndarray, np.ndarray]:
        """(a point of the axis, the unit axial direction) of a cylindrical system."""
        a, b = np.asarray(self.a), np.asarray(self.b)
        return a, (b - a) / np.linalg.norm(b - a)


@dataclass(frozen=True)
class Material:
    """Linear-elastic material with Rayleigh damping C = αM + βK.

    Isotropic (E, ν), or transversely isotropic about the model axis (a friction lining pressed
    through its thickness) when E_axial, nu_axial and G_axial are given: E, ν act in the plane
    normal to the axis, E_axial along it, nu_axial = −ε_plane/ε_axial under axial stress and
    G_axial is the shear modulus of planes containing the axis.

    Orthotropic, in the material frame of ``orientation`` (global axes when None): the nine engineering
    constants E1 … G23 (:func:`orthotropic_compliance`); or anisotropic: ``D``, the 9 orthotropic or 21
    anisotropic stiffness constants D_ijkl of Abaqus/CalculiX (:func:`voigt_from_d`).  E and ν may then
    be left out: they become the material frame's 1/S₁₁ and −S₁₂/S₁₁ (the part's nominal modulus, the one a
    modulus parameter scales)."""

    E: float | None
    nu: float | None
    rho: float
    rayleigh_alpha: float = 0.0
    rayleigh_beta: float = 0.0
    E_axial: float | None = None
    nu_axial: float | None = None
    G_axial: float | None = None
    eta: float = 0.0      # loss factor η: structural damping K(1 + iη) (reduced model; fe.projection.full_modes)
    # η(f, T) (a reduced.laws.loss_factor.LossTable or its scene table); eta is then its nominal value
    eta_table: Any = None
    E1: float | None = None
    E2: float | None = None
    E3: float | None = None
    nu12: float | None = None
    nu13: float | None = None
    nu23: float | None = None
    G12: float | None = None
    G13: float | None = None
    G23: float | None = None
    D: tuple | None = None
    orientation: Orientation | None = None

    @property
    def transversely_isotropic(self) -> bool:
        return self.E_axial is not None

    @property
    def anisotropic(self) -> bool:
        """Orthotropic or anisotropic in a material frame (engineering constants E1 … G23, or D)."""
        return self.E1 is not None or self.D is not None

    def local_stiffness(self) -> np.ndarray:
        """6×6 stiffness in the material frame (Voigt xx, yy, zz, yz, xz, xy) of an anisotropic material."""
        if self.D is not None:
            return voigt_from_d(self.D)
        return np.linalg.inv(orthotropic_compliance(*(getattr(self, k) for k in ENGINEERING_CONSTANTS)))

    def voigt_stiffness(self) -> np.ndarray:
        """6×6 stiffness in Voigt order (xx, yy, zz, yz, xz, xy), engineering shear strains,
        axis = z: the inverse of the compliance
        S = [[1/E, −ν/E, −ν_a/E_a], [−ν/E, 1/E, −ν_a/E_a], [−ν_a/E_a, −ν_a/E_a, 1/E_a]] ⊕
            diag(1/G_a, 1/G_a, 2(1+ν)/E).
        Anisotropic: :meth:`local_stiffness` (in the material frame)."""
        if self.anisotropic:
            return self.local_stiffness()
        E, nu = self.E, self.nu
        Ea, nua, Ga = (self.E_axial, self.nu_axial, self.G_axial) if self.transversely_isotropic else \
            (E, nu, E / (2 * (1 + nu)))
        S = np.zeros((6, 6))
        S[:3, :3] = [[1 / E, -nu / E, -nua / Ea], [-nu / E, 1 / E, -nua / Ea], [-nua / Ea, -nua / Ea, 1 / Ea]]
        S[3, 3] = S[4, 4] = 1 / Ga
        S[5, 5] = 2 * (1 + nu) / E
        return np.linalg.inv(S)

    def _check_anisotropic(self) -> None:
        eng = [getattr(self, k) for k in ENGINEERING_CONSTANTS]
        if any(v is not None for v in eng):
            if any(v is None for v in eng):
                raise ModelError(f"{', '.join(ENGINEERING_CONSTANTS)}: give all nine for an orthotropic material "
                                 f"(missing {[k for k, v in zip(ENGINEERING_CONSTANTS, eng) if v is None]})")
            if self.D is not None:
                raise ModelError("D: give either the engineering constants E1 … G23 or D, not both")
            for k in ("E1", "E2", "E3", "G12", "G13", "G23"):
                if not getattr(self, k) > 0:
                    raise ModelError(f"{k}: must be > 0 (got {getattr(self, k)})")
        if self.D is not None:
            object.__setattr__(self, "D", tuple(float(x) for x in self.D))
            voigt_from_d(self.D)
        if self.transversely_isotropic and self.anisotropic:
            raise ModelError("E_axial, nu_axial, G_axial: not with the orthotropic constants E1 … G23 or D")
        C = self.local_stiffness()
        if np.min(np.linalg.eigvalsh(C)) <= 0:
            what = "D" if self.D is not None else "nu12, nu13, nu23"
            raise ModelError(f"{what}: the constants give a stiffness that is not positive definite "
                             f"(eigenvalues {np.array2string(np.linalg.eigvalsh(C), precision=3)})")
        S = np.linalg.inv(C)
        if self.E is None:
            object.__setattr__(self, "E", float(1 / S[0, 0]))
        if self.nu is None:
            object.__setattr__(self, "nu", float(-S[0, 1] / S[0, 0]))

    def __post_init__(self):
        if self.orientation is not None and not isinstance(self.orientation, Orientation):
            o = dict(self.orientation)
            try:
                object.__setattr__(self, "orientation", Orientation(**o))
            except TypeError:
                raise ModelError(f"orientation: keys system, a, b[, c] (got {sorted(o)})") from None
        if self.anisotropic:
            self._check_anisotropic()
        elif self.orientation is not None:
            raise ModelError("orientation: only for an orthotropic or anisotropic material (E1 … G23 or D)")
        if self.E is None or self.nu is None:
            raise ModelError(f"{'E' if self.E is None else 'nu'}: required (or the orthotropic constants "
                             "E1 … G23, or D)")
        if not self.E > 0:
            raise ModelError(f"E: must be > 0 (got {self.E})")
        if not self.anisotropic and not -1.0 < self.nu < 0.5:
            raise ModelError(f"nu: must be in (-1, 0.5) (got {self.nu})")
        if not self.rho > 0:
            raise ModelError(f"rho: must be > 0 (got {self.rho})")
        if self.rayleigh_alpha < 0 or self.rayleigh_beta < 0:
            raise ModelError("rayleigh_alpha, rayleigh_beta: must be >= 0")
        if not self.eta >= 0:
            raise ModelError(f"eta: must be >= 0 (got {self.eta})")
        if self.eta_table is not None:
            if self.eta != 0:
                raise ModelError("eta_table: give eta or eta_table, not both (eta is then the table's value at "
                                 "its reference point)")
            table = loss_table(self.eta_table, "eta_table")
            object.__setattr__(self, "eta_table", table)
            object.__setattr__(self, "eta", table.nominal)
        ti = (self.E_axial, self.nu_axial, self.G_axial)
        if any(v is not None for v in ti):
            if any(v is None for v in ti):
                raise ModelError("E_axial, nu_axial, G_axial: give all three for a transversely "
                                 "isotropic material")
            if not (self.E_axial > 0 and self.G_axial > 0):
                raise ModelError(f"E_axial, G_axial: must be > 0 (got {self.E_axial}, {self.G_axial})")
            if np.min(np.linalg.eigvalsh(self.voigt_stiffness())) <= 0:
                raise ModelError(f"nu_axial: {self.nu_axial} with E = {self.E}, E_axial = {self.E_axial} and "
                                 f"nu = {self.nu} gives a stiffness that is not positive definite")


@dataclass(frozen=True)
class RigidPlate:
    """A rigid plate pressed on face ``face`` through a penalty layer k_n [N/m³] with friction μ.

    ``sliding`` = +1: the plate slides in +e_θ relative to the body (forward), −1: backward,
    0: no sliding (no friction stiffness).  The friction traction on the body is μ k_n (u·n) s,
    s = sliding·e_θ about the z axis.

    ``kt`` [N/m³]: tangential penalty stiffness (the elastic slip of the friction law; see
    :mod:`fem_squeal.fe.forms`, ``tangential_penalty_form``).  Sliding (``sliding`` ≠ 0): it acts
    only across the sliding direction, along t₂ = n × s; never along s, where the friction force
    stays μ p.  ``sliding`` = 0 (sticking): on the whole tangent plane.  0 (the default) is the
    seed 001 model.

    ``speed`` [rad/s]: the disc speed Ω (sliding speed V = Ω r); ``law``: a speed-dependent friction
    law μ(V) (a :class:`~fem_squeal.reduced.laws.friction.StribeckFriction`; None: the constant
    ``mu``), which then gives μ at every point; ``friction_damping``: the velocity terms of the
    linearised friction force (:func:`fem_squeal.fe.preload.friction_damping`).
    """

    face: str
    kn: float
    mu: float = 0.0
    sliding: int = 1
    kt: float = 0.0
    friction_damping: bool = False
    law: Any = None
    speed: float = 0.0
    name: str = ""       # the scene's interface name (per-interface parameters ``kn.<name>``, ...)

    def __post_init__(self):
        _check_speed_terms(self)
        if not self.kn >= 0:
            raise ModelError(f"kn: must be >= 0 (got {self.kn})")
        if not self.kt >= 0:
            raise ModelError(f"kt: must be >= 0 (got {self.kt})")
        if not self.mu >= 0:
            raise ModelError(f"mu: must be >= 0 (got {self.mu})")
        if self.sliding not in (-1, 0, 1):
            raise ModelError(f"sliding: must be -1, 0 or +1 (got {self.sliding})")

    @property
    def has_friction(self) -> bool:
        return self.mu > 0 and self.sliding != 0 and self.kn > 0


@dataclass(frozen=True)
class GapProfile:
    """A contact's initial gap beyond the geometry's, affine over the slave face:
    g₀(x) += offset + gradient·(x − at), ``at`` the face's area centroid when None.  A pad's taper wear
    (thicker at one end: a gradient along the sliding direction) or a lining that stands proud or sunk
    (an offset, < 0: interference) [m, m/m]."""

    offset: float = 0.0
    gradient: tuple[float, float, float] = (0.0, 0.0, 0.0)
    at: tuple[float, float, float] | None = None

    def __post_init__(self):
        vals = [self.offset, *self.gradient, *(self.at or ())]
        if len(self.gradient) != 3 or (self.at is not None and len(self.at) != 3) or \
                not all(np.isfinite(v) for v in vals):
            raise ModelError("initial_gap: offset, gradient = [gx, gy, gz] and at = [x, y, z] must be finite "
                             f"numbers (got offset {self.offset!r}, gradient {self.gradient!r}, at {self.at!r})")

    def values(self, x: np.ndarray, centroid: np.ndarray | None) -> np.ndarray:
        """The added gap at the points ``x`` (n, 3), ``centroid`` the slave face's (needed when ``at`` is None)."""
        at = np.asarray(centroid if self.at is None else self.at, float)
        return self.offset + (np.asarray(x, float) - at) @ np.asarray(self.gradient, float)


@dataclass(frozen=True)
class Interface:
    """Coupling of two deformable faces through the interface operator G (see ``interface``).

    ``kind``:
      * ``contact``: unilateral penalty k_n [N/m³] on the normal gap, friction μ with the master
        sliding along ``sliding``·e_θ relative to the slave (+1 forward, −1 backward, 0 none);
        k_t [N/m³] the tangential penalty on the closed points: across the sliding direction only
        (along t₂ = n × t₁) when ``sliding`` ≠ 0, on both tangents when ``sliding`` = 0 (stick);
        0 (the default) is the seed 001 model;
      * ``spring``: elastic layer k_n normal, k_t [N/m³] in both tangential directions;
      * ``bonded``: a tie, a spring layer with k_n = k_t (large).
    The slave face carries the quadrature points (the finer or softer side: the lining).
    ``speed``, ``law``, ``friction_damping``: as for :class:`RigidPlate` (contacts only)."""

    name: str
    slave: str
    master: str
    kind: str = "contact"
    kn: float = 0.0
    kt: float = 0.0
    mu: float = 0.0
    sliding: int = 1
    friction_damping: bool = False
    law: Any = None
    speed: float = 0.0
    #: the undeformed surfaces' own gap added to the geometric one (contacts: a pad's taper or wear)
    initial_gap: GapProfile | None = None

    def __post_init__(self):
        _check_speed_terms(self)
        if self.kind != "contact" and self.initial_gap is not None:
            raise ModelError(f"initial_gap: only contact interfaces have a gap (kind {self.kind!r})")
        if self.kind != "contact" and (self.friction_damping or self.law is not None):
            raise ModelError(f"friction_damping, law: only contact interfaces have friction (kind {self.kind!r})")
        if self.kind not in ("contact", "spring", "bonded"):
            raise ModelError(f"kind: must be 'contact', 'spring' or 'bonded' (got {self.kind!r})")
        if not self.kn > 0:
            raise ModelError(f"kn: must be > 0 (got {self.kn})")
        if not self.kt >= 0 or not self.mu >= 0:
            raise ModelError("kt, mu: must be >= 0")
        if self.kind != "contact" and self.mu > 0:
            raise ModelError(f"mu: only contact interfaces have friction (kind {self.kind!r})")
        if self.sliding not in (-1, 0, 1):
            raise ModelError(f"sliding: must be -1, 0 or +1 (got {self.sliding})")

    @property
    def has_friction(self) -> bool:
        return self.kind == "contact" and self.mu > 0 and self.sliding != 0

    def friction_coefficient(self, x: np.ndarray) -> np.ndarray:
        """μ at the points ``x``: ``mu``, or μ(V) of the law at V = speed·r."""
        return speed_friction(self.mu, self.law, sliding_speed(x, self.speed))[0]


AXES = ("x", "y", "z")


@dataclass(frozen=True)
class FixedFace:
    """Zero displacement of the global components ``components`` (a subset of x, y, z) on a face."""

    face: str
    components: tuple[str, ...]

    def __post_init__(self):
        comps = tuple(self.components)
        if not comps or any(c not in AXES for c in comps) or len(set(comps)) != len(comps):
            raise ModelError(f"components: must be a non-empty subset of {list(AXES)} without repeats "
                             f"(got {list(comps)})")
        object.__setattr__(self, "components", comps)

    @property
    def indices(self) -> tuple[int, ...]:
        return tuple(sorted(AXES.index(c) for c in self.components))


@dataclass(frozen=True)
class GroundSpring:
    """Distributed springs from a face to ground [N/m³]: k_axial along the axis, k_transverse across.

    Guide pins and the anchor bracket: the caliper and the pads slide axially (small k_axial)."""

    face: str
    k_axial: float
    k_transverse: float

    def __post_init__(self):
        if self.k_axial < 0 or self.k_transverse < 0 or self.k_axial + self.k_transverse <= 0:
            raise ModelError("k_axial, k_transverse: must be >= 0, not both 0")


@dataclass(frozen=True)
class Pressure:
    """Uniform pressure p [Pa] on a face (pushes along −n, n the face's outward normal)."""

    face: str
    p: float


@dataclass(frozen=True)
class PointLoad:
    """A concentrated force [N] at the mesh node ``point`` (Abaqus ``*CLOAD``): it enters the static
    right-hand side f as F on the three displacement DOFs of that node."""

    name: str
    point: tuple
    force: tuple

    def __post_init__(self):
        for k in ("point", "force"):
            v = getattr(self, k)
            if len(v) != 3:
                raise ModelError(f"{k}: must be three numbers (got {v!r})")
            object.__setattr__(self, k, tuple(float(x) for x in v))


@dataclass(frozen=True)
class ModelSpec:
    """Everything the assembly needs besides the mesh: materials per part, plates, clamps, degree."""

    materials: dict[str, Material]
    plates: tuple[RigidPlate, ...] = ()
    clamped: tuple[str, ...] = ()
    degree: int = 2
    quadrature_degree: int | None = None
    axis: tuple[float, float, float] = field(default=(0.0, 0.0, 1.0))
    interfaces: tuple[Interface, ...] = ()
    ground_springs: tuple[GroundSpring, ...] = ()
    pressures: tuple[Pressure, ...] = ()
    interface_quadrature_degree: int = 4
    fixed: tuple[FixedFace, ...] = ()     # component-wise Dirichlet conditions (clamped: all three)
    point_loads: tuple[PointLoad, ...] = ()
    c3d8r: bool = False                   # CalculiX C3D8R on Q1 hexahedra (fem_squeal.fe.c3d8r)

    def __post_init__(self):
        held: dict[str, set[int]] = {}
        for face in self.clamped:
            if face in held:
                raise ModelError(f"boundary: face {face!r} is clamped twice")
            held[face] = {0, 1, 2}
        for fx in self.fixed:
            twice = held.get(fx.face, set()) & set(fx.indices)
            if twice:
                raise ModelError(f"boundary: face {fx.face!r} has component(s) {[AXES[i] for i in sorted(twice)]} "
                                 "fixed twice (clamped or another fixed entry)")
            held.setdefault(fx.face, set()).update(fx.indices)

    @property
    def has_damping(self) -> bool:
        return any(m.rayleigh_alpha > 0 or m.rayleigh_beta > 0 for m in self.materials.values())

    @property
    def has_friction(self) -> bool:
        return any(p.has_friction for p in self.plates) or \
            any(i.has_friction for i in self.interfaces)

    @property
    def contacts(self) -> tuple[Interface, ...]:
        return tuple(i for i in self.interfaces if i.kind == "contact")


def common_mu(spec: ModelSpec) -> float:
    """The friction coefficient shared by every frictional interface (a μ sweep scales it)."""
    mus = {p.mu for p in spec.plates if p.has_friction}
    mus |= {it.mu for it in spec.interfaces if it.kind == "contact" and it.mu > 0 and it.sliding != 0}
    if len(mus) > 1:
        raise ModelError(f"interfaces: frictional interfaces have different mu {sorted(mus)}; a reduced "
                         "model scales one common friction coefficient")
    return mus.pop() if mus else 0.0
