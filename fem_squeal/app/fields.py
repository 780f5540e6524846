"""The vocabulary of the scene schema: a typed field with its default and check, the checks every
section uses, and the table checker.  Sections are dicts ``name -> Field``; the model sections live
in :mod:`fem_squeal.app.scene.schema`, each analysis's section in its module of
:mod:`fem_squeal.app.analyses`.

A check returns ``None`` when the value is fine, else the reason (``"must be > 0 (got -1)"``); the
table checker prefixes the key path, so every error reads ``analyses.sweep.n: must be >= 2 (got 1)``.

A table is checked and becomes its typed section in one step (:func:`section`: :func:`check_fields`
then :func:`freeze`): a frozen dataclass made from its field table (:func:`section_type`), read by
attribute (``scene.preload.tol``) or, as the dict it replaces, by key (``scene["preload"]["tol"]``).
``None`` means "not set" (the field's documented fallback applies); a field's ``unset`` names the
value that meant "not set" in the older scene format (``0``), which still reads as ``None``.
"""
from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from functools import cache
from typing import Any

from fem_squeal.util.errors import SceneError

REAL = (int, float)


@dataclass(frozen=True)
class Field:
    kind: type | tuple[type, ...]
    default: Any = ...           # ... = required
    check: Callable[[Any], str | None] | None = None
    doc: str = ""
    #: the value that meant "not set" before None did (e.g. ``0`` for "automatic"): it reads as None
    unset: Any = ...


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
        if f.unset is not ... and not isinstance(v, bool) and v == f.unset:
            out[name] = None
            continue
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


class Section(Mapping):
    """A validated scene table: a frozen dataclass (made by :func:`section_type`) that also reads as
    the read-only mapping it replaces, so ``section.key`` and ``section["key"]`` are the same value."""

    __slots__ = ()

    def __getitem__(self, key: str) -> Any:
        if key not in self.__dataclass_fields__:
            raise KeyError(key)
        return getattr(self, key)

    def __iter__(self) -> Iterator[str]:
        return iter(self.__dataclass_fields__)

    def __len__(self) -> int:
        return len(self.__dataclass_fields__)

    def replace(self, **changes) -> Section:
        """A copy with ``changes`` (the section itself is immutable)."""
        return dataclasses.replace(self, **changes)

    def as_dict(self) -> dict:
        """The section as plain nested dicts (what the cache keys and results.json hold)."""
        return plain(self)


@cache
def _section_type(name: str, names: tuple[str, ...], base: type[Section] = Section) -> type[Section]:
    return dataclasses.make_dataclass(name, [(n, Any) for n in names], bases=(base,), frozen=True,
                                      eq=False)     # equality as mappings (Mapping.__eq__), like the dicts


def section_type(fields: dict[str, Field], name: str = "Section") -> type[Section]:
    """The frozen dataclass of a field table (one class per table and name)."""
    return _section_type(name, tuple(fields))


def _class_name(path: str) -> str:
    return "".join(p[:1].upper() + p[1:] for p in path.replace("_", ".").split(".") if p) or "Section"


def freeze(values: Mapping[str, Any], fields: dict[str, Field] | None = None, path: str = "",
           base: type[Section] = Section) -> Section:
    """A checked table (from :func:`check_fields`) as its typed section (a subclass of ``base``);
    nested plain tables (name -> table maps such as ``boundary.fixed``) stay mappings of their values."""
    names = tuple(fields) if fields is not None else tuple(values)
    return _section_type(_class_name(path), names, base)(**{n: values[n] for n in names})


def section(table: Any, fields: dict[str, Field], path: str, kind: str | None = None) -> Section:
    """``table`` checked against ``fields`` (:func:`check_fields`, errors named ``path.key``) and frozen
    as its typed section in the same step; ``kind`` names the section's type (default ``path``)."""
    return freeze(check_fields(table, fields, path), fields, path if kind is None else kind)


def plain(obj: Any) -> Any:
    """Sections and mappings as plain nested dicts (lists and scalars as they are)."""
    if isinstance(obj, Mapping):
        return {k: plain(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [plain(v) for v in obj]
    return obj
