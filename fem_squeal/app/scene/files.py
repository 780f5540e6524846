"""Scene files: the raw table of a TOML file, with ``extends`` resolved (the file's tables merged onto
another scene's) and ``--set key.path=value`` overrides applied.  Nothing here checks a value: the raw
table goes to :func:`fem_squeal.app.scene.validation.validate`, the one pass that types it."""
from __future__ import annotations

import copy
import tomllib
from pathlib import Path
from typing import Any

from fem_squeal.util.errors import SceneError


def parse_value(text: str) -> Any:
    """Parse a --set value as a TOML value, falling back to a bare string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def apply_overrides(raw: dict, overrides: list[str]) -> dict:
    """Apply ``key.path=value`` overrides to a raw scene (a deep copy is returned)."""
    raw = copy.deepcopy(raw)
    for item in overrides:
        if "=" not in item:
            raise SceneError(f"--set {item}: expected key.path=value")
        key, text = item.split("=", 1)
        parts = [p for p in key.strip().split(".")]
        if not all(parts):
            raise SceneError(f"--set {item}: empty key component")
        node = raw
        for i, p in enumerate(parts[:-1]):
            node = node.setdefault(p, {})
            if not isinstance(node, dict):
                raise SceneError(f"{'.'.join(parts[: i + 1])}: is not a table, cannot set {key}")
        node[parts[-1]] = parse_value(text.strip())
    return raw


def merge(base: dict, over: dict) -> dict:
    """``over`` on top of ``base``: tables merge key by key, any other value replaces."""
    out = copy.deepcopy(base)
    for k, v in over.items():
        out[k] = merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else copy.deepcopy(v)
    return out


def read_scene(path: str | Path, _seen: tuple = ()) -> dict:
    """The raw table of a scene file, with ``extends = "other.toml"`` (relative to the file)
    resolved: the file's tables are merged on top of the other scene's."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text())
    except (FileNotFoundError, IsADirectoryError):
        raise SceneError(f"{path}: no such scene file") from None
    except UnicodeDecodeError:
        raise SceneError(f"{path}: not a text file") from None
    except tomllib.TOMLDecodeError as e:
        raise SceneError(f"{path}: not valid TOML ({e})") from None
    geo = raw.get("geometry")
    if isinstance(geo, dict) and isinstance(geo.get("file"), str) and geo["file"].strip():
        geo["file"] = str((path.parent / geo["file"]).resolve())    # relative to the scene that names it
    files = raw.get("matrices", {}).get("files") if isinstance(raw.get("matrices"), dict) else None
    for name, entry in (files.items() if isinstance(files, dict) else ()):     # relative to this scene too
        if isinstance(entry, str) and entry.strip():
            files[name] = str((path.parent / entry).resolve())
        elif isinstance(entry, dict) and isinstance(entry.get("file"), str) and entry["file"].strip():
            entry["file"] = str((path.parent / entry["file"]).resolve())
    base = raw.pop("extends", None)
    if base is None:
        return raw
    if not isinstance(base, str):
        raise SceneError(f"extends: must be a scene file name (got {base!r})")
    base_path = (path.parent / base).resolve()
    if base_path in _seen or base_path == path.resolve():
        raise SceneError(f"extends: {base} is extended in a cycle")
    base_raw = read_scene(base_path, (*_seen, path.resolve()))
    base_builder = base_raw.get("geometry", {}).get("builder")
    if isinstance(geo, dict) and "builder" in geo and geo["builder"] != base_builder:
        base_raw.pop("geometry", None)      # another builder: its parameters replace the base's
    return merge(base_raw, raw)
