"""A part's loss factor as a table η(f, T) over frequency f [Hz] and temperature T [°C]: a shim or an
insulator (a viscoelastic layer damps strongly, and only in a temperature window), interpolated
bilinearly (:func:`~fem_squeal.reduced.laws.friction.bilinear`, the operating matrix's friction
table's interpolant):

    η(f, T) = η₀₀ + s(η₁₀ − η₀₀) + t(η₀₁ − η₀₀) + st(η₁₁ − η₁₀ − η₀₁ + η₀₀)
    s = (T − T_i)/(T_{i+1} − T_i),  t = (f − f_j)/(f_{j+1} − f_j),  η_ab = η[i+a, j+b]

so that a constant table returns its value bit for bit.  The structural damping of the part is then
K_part(1 + iη(f, T)) at the frequency f of the mode it damps (a fixed point per mode:
:mod:`fem_squeal.reduced.loss_fixed_point`).  An axis of one value means "independent of this
variable"; a point outside an axis of two or more values is a :class:`ModelError` naming the variable,
the value and the range (no extrapolation).

``reference_frequency`` / ``reference_temperature``: the point whose η a constant-η analysis uses
(:attr:`LossTable.nominal`; required along an axis the table varies on).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from fem_squeal.reduced.laws.friction import bilinear
from fem_squeal.util.errors import ModelError

#: the keys of a table in a scene (materials.<part>.eta_table)
TABLE_KEYS = ("frequency", "temperature", "eta", "reference_frequency", "reference_temperature")


@dataclass(frozen=True, eq=False)
class LossTable:
    """η(f, T): ``eta`` has one row per temperature and one column per frequency (module docstring);
    ``name`` prefixes the messages (the scene key).  Compared and hashed by value."""

    frequency: np.ndarray
    temperature: np.ndarray
    eta: np.ndarray
    reference_frequency: float | None = None
    reference_temperature: float | None = None
    name: str = "eta_table"

    def __post_init__(self):
        axes = {}
        for key in ("frequency", "temperature"):
            try:
                a = np.atleast_1d(np.asarray(getattr(self, key), float))
            except (TypeError, ValueError):
                raise ModelError(f"{self.name}.{key}: must be a list of numbers (got {getattr(self, key)!r})") \
                    from None
            if a.ndim != 1 or a.size == 0 or not np.all(np.isfinite(a)):
                raise ModelError(f"{self.name}.{key}: must be a non-empty list of finite numbers "
                                 f"(got {a.tolist()})")
            if np.any(np.diff(a) <= 0):
                raise ModelError(f"{self.name}.{key}: must be strictly increasing (got {a.tolist()})")
            axes[key] = a
        f, T = axes["frequency"], axes["temperature"]
        if f[0] < 0:
            raise ModelError(f"{self.name}.frequency: must be >= 0 [Hz] (got {f.tolist()})")
        try:
            eta = np.asarray(self.eta, float)
        except (TypeError, ValueError):
            raise ModelError(f"{self.name}.eta: must be numbers, one row per temperature (got {self.eta!r})") \
                from None
        if eta.ndim == 1 and 1 in (T.size, f.size) and eta.size == T.size * f.size:
            eta = eta.reshape(T.size, f.size)
        if eta.shape != (T.size, f.size):
            raise ModelError(f"{self.name}.eta: must have one row per temperature and one column per frequency, "
                             f"shape ({T.size}, {f.size}) (got {eta.shape})")
        if not np.all(np.isfinite(eta)) or np.any(eta < 0):
            raise ModelError(f"{self.name}.eta: must be finite and >= 0 (got {np.min(eta):g})")
        for key, axis, ref in (("frequency", f, self.reference_frequency),
                               ("temperature", T, self.reference_temperature)):
            varies = np.any(np.diff(eta, axis=1 if key == "frequency" else 0) != 0)
            if ref is None:
                if varies:
                    raise ModelError(f"{self.name}.reference_{key}: required, the table varies with the {key} "
                                     "(the point whose η the constant-η analyses use)")
                continue
            self._check_axis(key, axis, np.asarray(float(ref)), f"reference_{key}")
        object.__setattr__(self, "frequency", f)
        object.__setattr__(self, "temperature", T)
        object.__setattr__(self, "eta", eta)

    def _check_axis(self, key: str, axis: np.ndarray, x: np.ndarray, what: str) -> None:
        if axis.size > 1:
            out = (x < axis[0]) | (x > axis[-1]) | ~np.isfinite(x)
            if np.any(out):
                raise ModelError(f"{self.name}: {what} {np.ravel(x[out])[0]:g} is outside the table's range "
                                 f"[{axis[0]:g}, {axis[-1]:g}]")

    def _key(self) -> tuple:
        return (self.frequency.tobytes(), self.temperature.tobytes(), self.eta.tobytes(), self.eta.shape,
                self.reference_frequency, self.reference_temperature, self.name)

    def __eq__(self, other) -> bool:
        return isinstance(other, LossTable) and self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    @property
    def constant(self) -> float | None:
        """η when the table depends on neither f nor T (every entry equal), else None."""
        return float(self.eta.flat[0]) if np.all(self.eta == self.eta.flat[0]) else None

    @property
    def varies_with_frequency(self) -> bool:
        return bool(np.any(np.diff(self.eta, axis=1) != 0))

    @property
    def nominal(self) -> float:
        """η of the constant-η analyses: the constant, else η at the reference point."""
        c = self.constant
        if c is not None:
            return c
        f = self.frequency[0] if self.reference_frequency is None else self.reference_frequency
        T = self.temperature[0] if self.reference_temperature is None else self.reference_temperature
        return float(self.value(f, T))

    def check_range(self, frequency=None, temperature=None) -> None:
        """Refuse points outside the table (ModelError naming the variable, the value and the range);
        None: not checked."""
        if frequency is not None:
            self._check_axis("frequency", self.frequency, np.asarray(frequency, float), "frequency")
        if temperature is not None:
            self._check_axis("temperature", self.temperature, np.asarray(temperature, float), "temperature")

    def value(self, frequency, temperature) -> np.ndarray:
        """η(f, T) (arrays broadcast together); the range is checked first."""
        f, T = np.broadcast_arrays(np.asarray(frequency, float), np.asarray(temperature, float))
        self.check_range(f, T)
        return bilinear(self.temperature, self.frequency, self.eta, T, f)

    def at_temperature(self, temperature: float):
        """η(f) at one temperature, a function of f (checked at T now, at each f when called)."""
        self.check_range(temperature=temperature)
        return lambda f: self.value(f, temperature)


def loss_table(spec, name: str) -> LossTable:
    """A :class:`LossTable` from a scene table {frequency, temperature, eta, reference_frequency,
    reference_temperature} (``frequency`` and ``temperature`` default to one value: independent)."""
    if isinstance(spec, LossTable):
        return spec
    if not isinstance(spec, Mapping):
        raise ModelError(f"{name}: must be a table {{frequency, temperature, eta}} (got {spec!r})")
    unknown = sorted(set(spec) - set(TABLE_KEYS))
    if unknown:
        raise ModelError(f"{name}.{unknown[0]}: unknown key; allowed: {list(TABLE_KEYS)}")
    if "eta" not in spec:
        raise ModelError(f"{name}.eta: required")
    refs = {k: (None if spec.get(k) is None else float(spec[k])) for k in TABLE_KEYS[3:]}
    return LossTable(spec.get("frequency", [0.0]), spec.get("temperature", [20.0]), spec["eta"], **refs,
                     name=name)
