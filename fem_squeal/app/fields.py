"""The vocabulary of the scene schema: a typed field with its default and check, the checks every
section uses, and the table checker.  Sections are dicts ``name -> Field``; the model sections live
in :mod:`fem_squeal.app.scene`, each analysis's section in its module of :mod:`fem_squeal.app.analyses`.

A check returns ``None`` when the value is fine, else the reason (``"must be > 0 (got -1)"``); the
table checker prefixes the key path, so every error reads ``analyses.sweep.n: must be >= 2 (got 1)``.
"""
from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from fem_squeal.util.errors import SceneError

REAL = (int, float)


@dataclass(frozen=True)
class Field:
    kind: type | tuple[type, ...]
    default: Any = ...           # ... = required
    check: Callable[[Any], str | None] | None = None
    doc: str = ""


def positive(v):
    return None if v > 0 else f"must be > 0 (got {v})"


def non_negative(v):
    return None if v >= 0 else f"must be >= 0 (got {v})"


def one_of(*choices):
    return lambda v: None if v in choices else f"must be one of {list(choices)} (got {v!r})"


def poisson(v):
    return None if -1.0 < v < 0.5 else f"must be in (-1, 0.5) (got {v})"


def band(v):
    if len(v) != 2 or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
        return f"must be [low, high] in Hz (got {v!r})"
    return None if 0 <= v[0] < v[1] else f"must be increasing and >= 0 (got {v!r})"


def increasing(min_len: int, low: float | None = None):
    def check(v):
        if len(v) < min_len or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
            return f"must be a list of at least {min_len} numbers (got {v!r})"
        if any(b <= a for a, b in zip(v, v[1:])):
            return f"must be increasing (got {v!r})"
        if low is not None and v[0] <= low:
            return f"must be > {low} (got {v!r})"
        return None
    return check


def at_least(n):
    return lambda v: None if v >= n else f"must be >= {n} (got {v})"


def nonempty_str(v):
    return None if v.strip() else "must not be empty"


def dataclass_fields(cls) -> dict[str, Field]:
    """Scene fields of a parameter dataclass: its defaults, its types (None = optional real)."""
    out = {}
    for f in dataclasses.fields(cls):
        d = f.default
        kind = bool if isinstance(d, bool) else REAL if isinstance(d, (int, float)) or d is None else type(d)
        out[f.name] = Field(kind, d, None, f.metadata.get("doc", ""))
    return out


def check_fields(table: Any, fields: dict[str, Field], path: str) -> dict:
    """``table`` checked against ``fields``: unknown keys, types, finite numbers, each field's check;
    defaults filled in.  Errors name the key path ``path.key``."""
    if not isinstance(table, dict):
        raise SceneError(f"{path}: must be a table (got {type(table).__name__})")
    unknown = sorted(set(table) - set(fields))
    if unknown:
        raise SceneError(f"{path}.{unknown[0]}: unknown key; allowed: {sorted(fields)}")
    out = {}
    for name, f in fields.items():
        key = f"{path}.{name}"
        if name not in table:
            if f.default is ...:
                raise SceneError(f"{key}: required" + (f" ({f.doc})" if f.doc else ""))
            out[name] = copy.deepcopy(f.default)
            continue
        v = table[name]
        kinds = f.kind if isinstance(f.kind, tuple) else (f.kind,)
        if (isinstance(v, bool) and bool not in kinds) or not isinstance(v, kinds):
            want = " or ".join(k.__name__ for k in kinds)
            raise SceneError(f"{key}: must be {want} (got {v!r})")
        if isinstance(v, float) and not math.isfinite(v):
            raise SceneError(f"{key}: must be finite (got {v})")
        if f.check is not None:
            msg = f.check(v)
            if msg:
                raise SceneError(f"{key}: {msg}")
        out[name] = v
    return out
