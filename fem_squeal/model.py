"""Plain descriptions of the physics of a model: materials, rigid plates, boundary conditions.

These are validated values (the scene loader builds them); the assembly turns them into matrices.
"""
from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Material:
    """Isotropic linear-elastic material with Rayleigh damping C = αM + βK."""

    E: float
    nu: float
    rho: float
    rayleigh_alpha: float = 0.0
    rayleigh_beta: float = 0.0

    def __post_init__(self):
        if not self.E > 0:
            raise ValueError(f"E: must be > 0 (got {self.E})")
        if not -1.0 < self.nu < 0.5:
            raise ValueError(f"nu: must be in (-1, 0.5) (got {self.nu})")
        if not self.rho > 0:
            raise ValueError(f"rho: must be > 0 (got {self.rho})")
        if self.rayleigh_alpha < 0 or self.rayleigh_beta < 0:
            raise ValueError("rayleigh_alpha, rayleigh_beta: must be >= 0")


@dataclass(frozen=True)
class RigidPlate:
    """A rigid plate pressed on face ``face`` through a penalty layer k_n [N/m³] with friction μ.

    ``sliding`` = +1: the plate slides in +e_θ relative to the body (forward), −1: backward,
    0: no sliding (no friction stiffness).  The friction traction on the body is μ k_n (u·n) s,
    s = sliding·e_θ about the z axis.
    """

    face: str
    kn: float
    mu: float = 0.0
    sliding: int = 1

    def __post_init__(self):
        if not self.kn >= 0:
            raise ValueError(f"kn: must be >= 0 (got {self.kn})")
        if not self.mu >= 0:
            raise ValueError(f"mu: must be >= 0 (got {self.mu})")
        if self.sliding not in (-1, 0, 1):
            raise ValueError(f"sliding: must be -1, 0 or +1 (got {self.sliding})")


@dataclass(frozen=True)
class ModelSpec:
    """Everything the assembly needs besides the mesh: materials per part, plates, clamps, degree."""

    materials: dict[str, Material]
    plates: tuple[RigidPlate, ...] = ()
    clamped: tuple[str, ...] = ()
    degree: int = 2
    quadrature_degree: int | None = None
    axis: tuple[float, float, float] = field(default=(0.0, 0.0, 1.0))

    @property
    def has_damping(self) -> bool:
        return any(m.rayleigh_alpha > 0 or m.rayleigh_beta > 0 for m in self.materials.values())

    @property
    def has_friction(self) -> bool:
        return any(p.mu > 0 and p.sliding != 0 and p.kn > 0 for p in self.plates)
