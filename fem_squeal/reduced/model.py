"""Parametric (affine) reduced model of λ²M + λC + K on a mass-orthonormal basis.

K(p) = K₀ + Σᵢ (θᵢ − 1) Kᵢ + μ K_f¹          θᵢ = Eᵢ / Eᵢ⁰ (part i's Young's modulus scale)
C(p) = C₀ + Σᵢ βᵢ (θᵢ − 1) Kᵢ                 (stiffness-proportional damping follows E)
M    = I                                       (the basis is M-orthonormal)

K₀ is the frictionless stiffness at the nominal parameters (elasticity, springs, closed contact),
Kᵢ the elastic stiffness of part i at its nominal modulus, K_f¹ the friction stiffness for μ = 1
in the scene's sliding direction, so that a signed μ (sign(v)μ, seed 001 Fig. 8) covers forward
(> 0) and backward (< 0) sliding.  Scaling "E" of a part scales its whole elasticity tensor.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from fem_squeal.util.atomic import write_npz_atomic
from fem_squeal.util.errors import ModelError, UnknownNameError

MU = "mu"


def e_param(part: str) -> str:
    """Name of the parameter that sets part ``part``'s Young's modulus [Pa]."""
    return f"E.{part}"


def format_point(point: Mapping[str, float]) -> str:
    """A parameter point for people: ``sign(v)μ = −1.000, E(disc) = 100 GPa`` (units by parameter)."""
    out = []
    for name, value in point.items():
        value = float(value)
        if name == MU:
            out.append(f"sign(v)μ = {value:+.3f}")
        elif name.startswith("E."):
            out.append(f"E({name[2:]}) = {value / 1e9:.4g} GPa")
        else:
            out.append(f"{name} = {value:.4g}")
    return ", ".join(out)


@dataclass
class ContactRestriction:
    """A contact interface's operator G restricted to the basis: rows are slave quadrature points,
    in a rank-independent order (sorted by coordinates)."""

    Gn: np.ndarray        # (n_points, m) normal gap rate per basis vector
    Gt: np.ndarray        # (n_points, m) along the sliding direction
    weight: np.ndarray    # (n_points,) quadrature weights [m²]
    kn: float             # penalty [N/m³]
    mu: float
    sliding: float
    gap: np.ndarray       # (n_points,) static gap at the preload (< 0: closed)
    active: np.ndarray    # (n_points,) closed at the preload
    gap0: np.ndarray | None = None   # (n_points,) gap of the undeformed geometry
    x: np.ndarray | None = None      # (n_points, 3) slave point coordinates
    pressure: np.ndarray | None = None  # (n_points,) contact pressure at the preload [Pa]


@dataclass
class ReducedModel:
    """Reduced matrices (m × m NumPy arrays) and the affine parameter map; see module docstring."""

    K0: np.ndarray
    Kf1: np.ndarray | None = None
    C0: np.ndarray | None = None
    K_parts: dict[str, np.ndarray] = field(default_factory=dict)
    E0: dict[str, float] = field(default_factory=dict)        # nominal modulus of each part [Pa]
    beta: dict[str, float] = field(default_factory=dict)      # Rayleigh β of each part [s]
    mu0: float = 0.0                                          # the scene's (signed) μ
    contacts: dict[str, ContactRestriction] = field(default_factory=dict)
    info: dict = field(default_factory=dict)                  # basis description (sizes, timings)
    f: np.ndarray | None = None                               # Φᵀ f: the static load (preload)
    q_static: np.ndarray | None = None                        # ΦᵀM u_s: the preload displacement

    def __post_init__(self):
        m = self.K0.shape[0]
        if self.K0.shape != (m, m):
            raise ModelError(f"K0: must be square (got {self.K0.shape})")
        for name, A in [("Kf1", self.Kf1), ("C0", self.C0), *self.K_parts.items()]:
            if A is not None and A.shape != (m, m):
                raise ModelError(f"{name}: must be {m}×{m} like K0 (got {A.shape})")
        missing = sorted(set(self.K_parts) - set(self.E0))
        if missing:
            raise ModelError(f"E0: no nominal modulus for part(s) {missing}")

    @property
    def size(self) -> int:
        return self.K0.shape[0]

    @property
    def parameters(self) -> list[str]:
        """Names of the parameters this model can vary."""
        return ([MU] if self.Kf1 is not None else []) + [e_param(p) for p in self.K_parts]

    @property
    def damped(self) -> bool:
        return self.C0 is not None or any(self.beta.get(p, 0.0) > 0 for p in self.K_parts)

    def _check(self, names) -> None:
        unknown = sorted(set(names) - set(self.parameters))
        if unknown:
            raise UnknownNameError(f"{unknown[0]}: not a parameter of this reduced model; "
                                   f"parameters: {self.parameters}")

    def coefficients(self, points: Mapping[str, np.ndarray], n: int) -> tuple[np.ndarray, np.ndarray]:
        """Affine coefficients of K and C for ``n`` points: arrays (n, 1 + n_terms)."""
        self._check(points)
        parts = list(self.K_parts)
        ck = np.zeros((n, 2 + len(parts)))
        cc = np.zeros((n, len(parts)))
        ck[:, 0] = 1.0
        mu = np.broadcast_to(np.asarray(points.get(MU, self.mu0), float), (n,))
        ck[:, 1] = mu
        for j, part in enumerate(parts):
            E = np.broadcast_to(np.asarray(points.get(e_param(part), self.E0[part]), float), (n,))
            if np.any(~(E > 0)):
                raise ModelError(f"{e_param(part)}: must be > 0 (got {E.min()})")
            ck[:, 2 + j] = E / self.E0[part] - 1.0
            cc[:, j] = self.beta.get(part, 0.0) * ck[:, 2 + j]
        return ck, cc

    def stiffness_terms(self) -> np.ndarray:
        """(2 + n_parts, m, m): K0, K_f¹ (zero when frictionless), K_i."""
        m = self.size
        Kf = self.Kf1 if self.Kf1 is not None else np.zeros((m, m))
        return np.stack([self.K0, Kf, *self.K_parts.values()])

    def matrices(self, points: Mapping[str, np.ndarray] | None = None, n: int = 1
                 ) -> tuple[np.ndarray, np.ndarray | None]:
        """K(p) and C(p) (None if undamped) as (n, m, m) stacks for ``n`` points."""
        points = points or {}
        ck, cc = self.coefficients(points, n)
        K = np.tensordot(ck, self.stiffness_terms(), axes=1)
        if not self.damped:
            return K, None
        C = np.broadcast_to(self.C0 if self.C0 is not None else np.zeros((self.size,) * 2),
                            K.shape).copy()
        if self.K_parts:
            C += np.tensordot(cc, np.stack(list(self.K_parts.values())), axes=1)
        return K, C

    def frictionless_frequencies(self) -> np.ndarray:
        """√eig(K₀)/2π [Hz] of the nominal frictionless reduced model, ascending (the parents)."""
        w2 = np.linalg.eigvalsh(0.5 * (self.K0 + self.K0.T))
        return np.sign(w2) * np.sqrt(np.abs(w2)) / (2 * np.pi)

    def save(self, path) -> None:
        """Write every array to a ``.npz`` (atomically)."""

        arrays = {"K0": self.K0, "mu0": np.array(self.mu0)}
        for name in ("f", "q_static"):
            if getattr(self, name) is not None:
                arrays[name] = getattr(self, name)
        if self.Kf1 is not None:
            arrays["Kf1"] = self.Kf1
        if self.C0 is not None:
            arrays["C0"] = self.C0
        for p, A in self.K_parts.items():
            arrays[f"K_part/{p}"] = A
            arrays[f"E0/{p}"] = np.array(self.E0[p])
            arrays[f"beta/{p}"] = np.array(self.beta.get(p, 0.0))
        for name, c in self.contacts.items():
            for f in ("Gn", "Gt", "weight", "gap", "active", "gap0", "x", "pressure"):
                if getattr(c, f) is not None:
                    arrays[f"contact/{name}/{f}"] = getattr(c, f)
            for f in ("kn", "mu", "sliding"):
                arrays[f"contact/{name}/{f}"] = np.array(getattr(c, f))
        write_npz_atomic(path, arrays)

    @classmethod
    def load(cls, path) -> ReducedModel:
        with np.load(path) as z:
            d = {k: z[k] for k in z.files}
        parts = sorted(k.split("/", 1)[1] for k in d if k.startswith("K_part/"))
        contacts = {}
        for name in sorted({k.split("/")[1] for k in d if k.startswith("contact/")}):
            g = {f: d.get(f"contact/{name}/{f}") for f in ("Gn", "Gt", "weight", "gap", "active", "gap0", "x",
                                                          "pressure")}
            s = {f: float(d[f"contact/{name}/{f}"]) for f in ("kn", "mu", "sliding")}
            contacts[name] = ContactRestriction(**g, **s)
        return cls(K0=d["K0"], Kf1=d.get("Kf1"), C0=d.get("C0"),
                   K_parts={p: d[f"K_part/{p}"] for p in parts}, E0={p: float(d[f"E0/{p}"]) for p in parts},
                   beta={p: float(d[f"beta/{p}"]) for p in parts}, mu0=float(d["mu0"]), contacts=contacts,
                   f=d.get("f"), q_static=d.get("q_static"))
