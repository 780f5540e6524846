"""Sparse matrix files of other finite-element codes: Matrix Market (``.mtx``, ``.mm``: Abaqus
``*MATRIX GENERATE`` converted, Nastran DMAP output, SuiteSparse), MATLAB (``.mat``, a named variable:
research models such as TU Berlin's brake) and Harwell–Boeing (``.hb``, ``.rb``, ``.rua``, ``.rsa``:
ANSYS HBMAT), read with SciPy into real CSR matrices, symmetric storage (one triangle on file)
expanded to both triangles.

:func:`matrix_shape` reads only what a file says of its size (the Matrix Market and Harwell–Boeing
headers, MATLAB's variable table), so a scene can be checked before anything is loaded;
:func:`read_matrix` loads one.  Every failure is a :class:`MatrixFileError` whose message starts with
the file.  :func:`write_matrix_market` writes a matrix so that it reads back bit for bit (17
significant digits)."""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import scipy.io as sio
import scipy.sparse as sp

from fem_squeal.util.atomic import atomic_path
from fem_squeal.util.errors import MatrixFileError

#: format name -> file extensions (lower case) that select it when no format is given
FORMATS: dict[str, tuple[str, ...]] = {
    "matrix_market": (".mtx", ".mm"),
    "mat": (".mat",),
    "harwell_boeing": (".hb", ".rb", ".rua", ".rsa", ".hbmat"),
}


def matrix_format(path: str | Path, fmt: str = "") -> str:
    """The format of ``path``: ``fmt`` when given (one of :data:`FORMATS`), else from the extension."""
    if fmt:
        if fmt not in FORMATS:
            raise MatrixFileError(f"{path}: unknown matrix format {fmt!r}; formats: {sorted(FORMATS)}")
        return fmt
    ext = Path(path).suffix.lower()
    for name, exts in FORMATS.items():
        if ext in exts:
            return name
    known = ", ".join(e for exts in FORMATS.values() for e in exts)
    raise MatrixFileError(f"{path}: cannot tell the matrix format from the extension {ext!r} ({known}); "
                          "give format")


def _hb_header(path: Path) -> tuple[str, int, int]:
    """(type code, rows, columns) of a Harwell–Boeing file (its third header line)."""
    try:
        with open(path) as f:
            lines = [f.readline() for _ in range(3)]
    except UnicodeDecodeError:
        raise MatrixFileError(f"{path}: not a Harwell-Boeing file (not text)") from None
    parts = lines[2].split()
    if len(parts) < 3 or len(parts[0]) != 3:
        raise MatrixFileError(f"{path}: not a Harwell-Boeing file (third line {lines[2].strip()!r})")
    try:
        return parts[0].upper(), int(parts[1]), int(parts[2])
    except ValueError:
        raise MatrixFileError(f"{path}: not a Harwell-Boeing file (third line {lines[2].strip()!r})") from None


def _mat_variable(path: Path, variable: str, name: str) -> tuple[str, tuple[int, ...]]:
    """The variable of a MATLAB file that holds the matrix, and its shape: ``variable`` if given, else
    the matrix's ``name`` where the file has it, else the file's only variable."""
    try:
        table = sio.whosmat(str(path))
    except NotImplementedError as e:        # MATLAB v7.3 (HDF5)
        raise MatrixFileError(f"{path}: {e} (save with -v7 or write Matrix Market)") from None
    except (ValueError, TypeError, OSError) as e:
        raise MatrixFileError(f"{path}: not a MATLAB file ({e})") from None
    shapes = {v[0]: tuple(v[1]) for v in table}
    names = sorted(shapes)
    if variable:
        if variable not in shapes:
            raise MatrixFileError(f"{path}: no variable {variable!r}; variables: {names}")
        return variable, shapes[variable]
    if name in shapes:
        return name, shapes[name]
    if len(shapes) == 1:
        return names[0], shapes[names[0]]
    raise MatrixFileError(f"{path}: give variable (no variable {name!r}; variables: {names})")


def _check_file(path: Path) -> None:
    if not path.is_file():
        raise MatrixFileError(f"{path}: no such file")


def matrix_shape(path: str | Path, fmt: str = "", variable: str = "", name: str = "") -> tuple[int, int]:
    """(rows, columns) of the matrix in ``path`` from its header alone (``variable``, ``name``: as for
    :func:`read_matrix`)."""
    path = Path(path)
    _check_file(path)
    fmt = matrix_format(path, fmt)
    if fmt == "matrix_market":
        try:
            rows, cols, _, _, field, _ = sio.mminfo(str(path))
        except (ValueError, UnicodeDecodeError, IndexError) as e:
            raise MatrixFileError(f"{path}: not a Matrix Market file ({e})") from None
        if field not in ("real", "integer"):
            raise MatrixFileError(f"{path}: a {field} Matrix Market matrix; only real matrices are read")
        return int(rows), int(cols)
    if fmt == "harwell_boeing":
        code, rows, cols = _hb_header(path)
        return rows, cols
    _, shape = _mat_variable(path, variable, name)
    if len(shape) != 2:
        raise MatrixFileError(f"{path}: variable holds an array of shape {shape}, not a matrix")
    return int(shape[0]), int(shape[1])


def _expand_triangle(A: sp.spmatrix, path: Path) -> sp.csr_matrix:
    """A symmetric matrix stored as one triangle, with both triangles (the diagonal once)."""
    A = sp.coo_matrix(A)
    if np.any(A.row > A.col) and np.any(A.row < A.col):
        raise MatrixFileError(f"{path}: symmetric storage with entries in both triangles")
    off = A.row != A.col
    T = sp.coo_matrix((A.data[off], (A.col[off], A.row[off])), shape=A.shape)
    return (A.tocsr() + T.tocsr()).tocsr()


def _read_hb(path: Path) -> sp.csr_matrix:
    """A Harwell–Boeing file (SciPy reads unsymmetric assembled ones; a symmetric ``RSA`` file, one
    triangle on file, is read as unsymmetric and expanded)."""
    code, _, _ = _hb_header(path)
    if code[0] not in "R":
        raise MatrixFileError(f"{path}: a {'complex' if code[0] == 'C' else 'pattern-only'} Harwell-Boeing "
                              f"matrix ({code}); only real matrices are read")
    if code[2] != "A":
        raise MatrixFileError(f"{path}: an elemental (unassembled) Harwell-Boeing matrix ({code}); assemble it")
    if code[1] not in "US":
        raise MatrixFileError(f"{path}: Harwell-Boeing type {code} not supported (RUA and RSA are)")
    text = path.read_text()
    if code[1] == "S":
        lines = text.split("\n")
        lines[2] = lines[2].replace(lines[2].split()[0], "RUA", 1)
        text = "\n".join(lines)
    try:
        A = sio.hb_read(io.StringIO(text))
    except (ValueError, IndexError) as e:
        raise MatrixFileError(f"{path}: not a readable Harwell-Boeing file ({e})") from None
    return _expand_triangle(A, path) if code[1] == "S" else A.tocsr()


def _read_coordinate(path: Path) -> sp.coo_matrix | None:
    """A real coordinate Matrix Market file (general, symmetric or skew-symmetric) parsed by NumPy's C
    reader (``loadtxt``: 3× faster than SciPy 1.10's ``mmread``); None for anything else (SciPy reads it)."""
    with open(path, "rb") as f:
        banner = f.readline().decode("ascii", "replace").lower().split()
        if len(banner) != 5 or banner[1:3] != ["matrix", "coordinate"] or banner[3] not in ("real", "integer") \
                or banner[4] not in ("general", "symmetric", "skew-symmetric"):
            return None
        line = f.readline()
        while line.startswith(b"%") or not line.strip():
            line = f.readline()
        rows, cols, nnz = (int(x) for x in line.split())
        values = np.loadtxt(f, dtype=np.float64, comments="%", ndmin=2) if nnz else np.zeros((0, 3))
    if values.shape != (nnz, 3):
        raise MatrixFileError(f"{path}: {values.shape[0]} entries of {values.shape[1]} numbers where the header "
                              f"says {nnz} of 3")
    i, j = values[:, 0].astype(np.int64) - 1, values[:, 1].astype(np.int64) - 1
    if nnz and (i.min() < 0 or j.min() < 0 or i.max() >= rows or j.max() >= cols):
        raise MatrixFileError(f"{path}: an entry outside the {rows}×{cols} matrix")
    A = sp.coo_matrix((values[:, 2], (i, j)), shape=(rows, cols))
    if banner[4] == "general":
        return A
    off = i != j
    sign = -1.0 if banner[4] == "skew-symmetric" else 1.0
    return sp.coo_matrix((np.concatenate([values[:, 2], sign * values[off, 2]]),
                          (np.concatenate([i, j[off]]), np.concatenate([j, i[off]]))), shape=(rows, cols))


def read_matrix(path: str | Path, fmt: str = "", variable: str = "", name: str = "") -> sp.csr_matrix:
    """The real matrix in ``path`` as CSR (float64, duplicates summed, sorted indices), symmetric
    storage expanded.  ``fmt``: one of :data:`FORMATS` ('' = from the extension); ``variable``: the
    variable of a MATLAB file ('' = ``name`` where the file has it, else its only variable)."""
    path = Path(path)
    _check_file(path)
    fmt = matrix_format(path, fmt)
    if fmt == "matrix_market":
        matrix_shape(path, fmt)             # a complex or pattern file is refused by its header
        try:
            A = _read_coordinate(path)
            if A is None:
                A = sio.mmread(str(path))
        except (ValueError, IndexError, UnicodeDecodeError) as e:
            raise MatrixFileError(f"{path}: not a readable Matrix Market file ({e})") from None
    elif fmt == "harwell_boeing":
        A = _read_hb(path)
    else:
        var, _ = _mat_variable(path, variable, name)
        try:
            A = sio.loadmat(str(path), variable_names=[var])[var]
        except (ValueError, TypeError) as e:
            raise MatrixFileError(f"{path}: variable {var!r} cannot be read ({e})") from None
        if not (sp.issparse(A) or (isinstance(A, np.ndarray) and A.ndim == 2 and A.dtype.kind in "biuf")):
            raise MatrixFileError(f"{path}: variable {var!r} is not a real matrix (a "
                                  f"{getattr(A, 'dtype', type(A))} of shape {getattr(A, 'shape', '?')})")
    if np.iscomplexobj(A.data if sp.issparse(A) else A):
        raise MatrixFileError(f"{path}: a complex matrix; only real matrices are read")
    A = sp.csr_matrix(A, dtype=np.float64)
    A.sum_duplicates()
    A.sort_indices()
    if not np.all(np.isfinite(A.data)):
        raise MatrixFileError(f"{path}: entries that are not finite numbers (nan or inf)")
    return A


def write_matrix_market(path: str | Path, A, comment: str = "") -> None:
    """``A`` as a general real coordinate Matrix Market file that reads back bit for bit (17
    significant digits, every stored entry), written atomically."""
    A = sp.coo_matrix(A)
    head = "%%MatrixMarket matrix coordinate real general\n"
    head += "".join(f"%{line}\n" for line in comment.splitlines())
    head += f"{A.shape[0]} {A.shape[1]} {A.nnz}\n"
    with atomic_path(path) as tmp, open(tmp, "w") as f:
        f.write(head)
        for lo in range(0, A.nnz, 1 << 18):          # one formatting call per block of entries
            hi = min(A.nnz, lo + (1 << 18))
            block = np.empty((hi - lo, 3), dtype=object)
            block[:, 0], block[:, 1], block[:, 2] = A.row[lo:hi] + 1, A.col[lo:hi] + 1, A.data[lo:hi].tolist()
            f.write(("%d %d %.17g\n" * (hi - lo)) % tuple(block.ravel().tolist()))
