"""The ``[matrices]`` section of a scene: a model given as matrices of another finite-element code.

    [matrices]
    M = "M"
    C = "D1 + W*DG + (1/W - 1)*DR + D4/(2*pi*1600)"       # optional: undamped without it
    K = "K1 + KR + (W**2 - 1)*KGEO"
    files.M = "M.mtx"                                      # Matrix Market, MATLAB or Harwell-Boeing
    files.DG = { file = "damping.mat", variable = "DG" }
    parameters.W = { value = 1.0, range = [0.5, 3.0] }

Checked in the validation pass before anything is computed, each error naming its key: the fields
(:data:`fem_squeal.app.scene.schema.MATRICES`), the names (identifiers, not ``pi`` or a function name,
matrices and parameters distinct), every file there, of a known format, square and of one size n
(read from the headers alone: :func:`fem_squeal.util.matrix_files.matrix_shape`; ``dofs`` if given),
and the operators compiled (:func:`fem_squeal.reduced.matrix_model.matrix_model`: unknown names and
refused constructs are named errors), every named matrix used by one of them."""
from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from fem_squeal.app.analyses.matrices import model_of
from fem_squeal.app.fields import Section, check_fields, freeze, section
from fem_squeal.app.scene.schema import MATRICES, MATRIX_FILE, MATRIX_PARAMETER
from fem_squeal.reduced.expressions import RESERVED
from fem_squeal.util.errors import InputError, MatrixFileError, SceneError
from fem_squeal.util.matrix_files import matrix_shape


def _name(name: str, key: str) -> None:
    if not name.isidentifier() or name.startswith("_") or name in RESERVED:
        raise SceneError(f"{key}: the name {name!r} cannot be used (a name is an identifier not starting with "
                         f"'_', and not one of {sorted(RESERVED)})")


def _files(table: Mapping) -> dict[str, Section]:
    out = {}
    for name, entry in table.items():
        key = f"matrices.files.{name}"
        _name(name, key)
        out[name] = section({"file": entry} if isinstance(entry, str) else entry, MATRIX_FILE, key, "matrix_file")
    return out


def _parameters(table: Mapping, matrices: Mapping) -> dict[str, Section]:
    out = {}
    for name, entry in table.items():
        key = f"matrices.parameters.{name}"
        _name(name, key)
        if name in matrices:
            raise SceneError(f"{key}: also the name of a matrix (matrices.files.{name}); use distinct names")
        plain = isinstance(entry, (int, float)) and not isinstance(entry, bool)
        out[name] = section({"value": entry} if plain else entry, MATRIX_PARAMETER, key, "matrix_parameter")
    return out


def _sizes(files: Mapping[str, Section], dofs: int | None) -> int:
    """n: every matrix square and of one size (``dofs`` when given), read from the file headers."""
    n, first = dofs, None
    for name, f in files.items():
        key = f"matrices.files.{name}"
        if not Path(f.file).is_file():
            raise SceneError(f"{key}: {f.file} does not exist (a relative path in a scene file is taken from its "
                             "folder, in --set from the current folder)")
        try:
            rows, cols = matrix_shape(f.file, f.format, f.variable, name)
        except MatrixFileError as e:
            raise SceneError(f"{key}: {e}") from None
        if rows != cols:
            raise SceneError(f"{key}: {f.file} is {rows}×{cols}, not square")
        if n is None:
            n, first = rows, f"matrices.files.{name} ({Path(f.file).name})"
        elif rows != n:
            raise SceneError(f"{key}: {f.file} is {rows}×{rows}, but "
                             + (f"{first} is {n}×{n}" if first else f"matrices.dofs = {n}"))
    return int(n)


def matrices_section(table: Any) -> Section:
    """The typed ``[matrices]`` section of its raw table (module docstring); raises an error naming the key."""
    t = check_fields(table, MATRICES, "matrices")
    t["files"] = _files(t["files"])
    t["parameters"] = _parameters(t["parameters"], t["files"])
    t["dofs"] = _sizes(t["files"], t["dofs"])
    if t["dofs"] % t["block_size"]:
        raise SceneError(f"matrices.block_size: {t['block_size']} does not divide the size n = {t['dofs']}")
    try:
        model = model_of(t)
    except InputError as e:       # ExpressionError, ModelError: their messages name the key already
        msg = str(e)
        raise SceneError(msg if msg.startswith("matrices.") else f"matrices: {msg}") from e
    unused = [m for m in t["files"] if m not in model.matrices]
    if unused:
        raise SceneError(f"matrices.files.{unused[0]}: not used by the operators M, C or K")
    return freeze(t, MATRICES, "matrices")
