"""The ``matrices`` stage: a model given as matrices (a scene's ``[matrices]`` section,
:mod:`fem_squeal.app.scene.matrices`) read, its rows dealt to the ranks and its operators M, C, K
formed at the parameters' nominal values as distributed PETSc matrices
(:mod:`fem_squeal.fe.matrix_operators`).  The stage the analyses that run on matrices start from
(``Stage.on_matrices``: real_modes, cea) in place of mesh, operators and preload; it is cached by the
content (SHA-256) of the matrix files, not their paths.

Rank 0 reads each file (:func:`fem_squeal.util.matrix_files.read_matrix`) and sends every rank its rows.
results.json: ``matrices`` {dofs, files {name: {file, format, sha256, nonzeros}}, operators {M, C, K: the
affine form}, parameters {name: nominal value}, ranges, asymmetry {M, C, K: ‖A − Aᵀ‖_F/‖A‖_F at the
nominal point}}."""
from __future__ import annotations

import hashlib
import time
from collections.abc import Mapping
from pathlib import Path

from fem_squeal.app.html import table as _table
from fem_squeal.app.stage import Context, Stage
from fem_squeal.reduced.matrix_model import OPERATORS, MatrixModel, matrix_model
from fem_squeal.util.errors import PipelineError
from fem_squeal.util.matrix_files import matrix_format


def model_of(sec: Mapping) -> MatrixModel:
    """The operators and parameters of a checked ``[matrices]`` section."""
    params = sec["parameters"]
    return matrix_model({op: sec[op] for op in OPERATORS}, list(sec["files"]),
                        {k: p["value"] for k, p in params.items()},
                        {k: tuple(p["range"]) for k, p in params.items() if p["range"] is not None}, "matrices.")


def file_hash(path: str) -> str:
    """SHA-256 of a file's content."""
    h = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
    except OSError as e:
        raise PipelineError(f"matrices.files: cannot read {path} ({e.strerror})") from None
    return h.hexdigest()


def inputs(scene: dict, spec) -> dict:
    """The section, each file counted by its content (SHA-256), format and variable, not by its path."""
    sec = scene.matrices.as_dict()
    sec["files"] = {name: {"sha256": file_hash(f["file"]), "format": matrix_format(f["file"], f["format"]),
                           "variable": f["variable"]} for name, f in sec["files"].items()}
    return sec


def operators(ctx: Context) -> dict:
    """{"M", "C" (damped), "K"}: the operators at the nominal point (PETSc, this run's)."""
    return ctx.products["matrices"]["operators"]


def run(ctx: Context, work: Path, timings: dict) -> dict:
    """Read the matrices (rank 0), deal their rows to the ranks, form M, C, K at the nominal point."""
    from fem_squeal.fe.matrix_operators import operators as petsc_operators  # heavy: FE stack
    from fem_squeal.fe.matrix_operators import scatter_rows, symmetric_part  # heavy: FE stack
    from fem_squeal.util.matrix_files import read_matrix

    comm, sec = ctx.comm, ctx.scene.matrices
    model = model_of(sec)
    t = time.perf_counter()
    n = sec.dofs
    rows, files = {}, {}
    for name, f in sec.files.items():
        A = read_matrix(f.file, f.format, f.variable, name) if comm.rank == 0 else None
        if comm.rank == 0:
            files[name] = {"file": Path(f.file).name, "format": matrix_format(f.file, f.format),
                           "sha256": file_hash(f.file), "nonzeros": int(A.nnz)}
        rows[name] = scatter_rows(A, n, comm, sec.block_size)
    timings["matrices_read"] = time.perf_counter() - t
    t = time.perf_counter()
    ops = petsc_operators(model, rows, comm, bs=sec.block_size)
    asym = {}
    for name, A in ops.items():
        S, skew = symmetric_part(A)
        asym[name] = skew
        if S is not A:
            S.destroy()
    timings["matrices_operators"] = time.perf_counter() - t
    ctx.products["matrices"] = {"model": model, "rows": rows, "operators": ops}
    ctx.say(f"[fem_squeal] {len(rows)} matrices of {n} DOFs on {comm.size} rank(s); operators "
            + ", ".join(f"{k} = {op}" for k, op in model.operators.items()))
    return {"matrices": {"dofs": n, "files": comm.bcast(files, root=0),
                         "operators": {k: str(op) for k, op in model.operators.items()},
                         "parameters": dict(model.nominal),
                         "ranges": {k: list(v) for k, v in model.ranges.items()},
                         "asymmetry": asym}}


def report(res: dict) -> str:
    """The report section (HTML) of this stage from results.json ``res``."""
    if "matrices" not in res:
        return ""
    m = res["matrices"]
    rows = [[k, f["file"], f["format"], f["nonzeros"]] for k, f in m["files"].items()]
    ops = [[k, v, m["asymmetry"].get(k, "")] for k, v in m["operators"].items()]
    return (f"<h2>Model given as matrices</h2><p>{m['dofs']} DOFs; parameters "
            + ", ".join(f"{k} = {v:g}" for k, v in m["parameters"].items()) + "</p>"
            + _table(["matrix", "file", "format", "nonzeros"], rows)
            + _table(["operator", "affine form", "‖A − Aᵀ‖/‖A‖"], ops))


STAGE = Stage("matrices", (), run, "the model given as matrices: read, dealt to the ranks, M, C, K formed",
              inputs=inputs, report=report, memory=True)
