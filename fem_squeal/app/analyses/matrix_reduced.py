"""The reduced model of a model given as matrices (a ``[matrices]`` scene) for the studies that run on
it (analyses.sweep, map, sensitivity, robustness): the basis fields every such section has
(:data:`BASIS`), the reduced model built once per run for each basis setting
(:func:`reduced_model`), the band of the study, the named parameters checked, and the check of the
reduced eigenvalues against the full sparse CEA of the assembled matrices at a point
(:func:`check_point`).

The basis: on one rank the matrices are reduced whole with SciPy
(:func:`fem_squeal.reduced.matrix_reduction.reduce_matrix_model`); on several ranks the modal basis
is built distributed, each rank on its rows, by PETSc/SLEPc (:func:`fem_squeal.fe.matrix_basis.reduce_rows`:
the same subspace, the reduced eigenvalues equal to 1e-9), and so is the snapshot basis (or 'auto' where
M's symmetric part is not positive definite: :func:`fem_squeal.fe.matrix_snapshots.reduce_snapshot_rows`,
the eigenvalues it resolves equal to 1e-11).  Every rank ends with the same reduced model, so serial
and MPI runs give the same study."""
from __future__ import annotations

import time
from collections.abc import Mapping, Sequence

import numpy as np
import scipy.sparse as sp

from fem_squeal.app.analyses.matrices import model_of
from fem_squeal.app.fields import REAL, Field, at_least, band, one_of, positive
from fem_squeal.app.stage import Context
from fem_squeal.reduced.eigensolve import TWO_PI, band_centre_hz, unstable
from fem_squeal.reduced.matrix_reduction import ReducedMatrixModel, reduce_matrix_model
from fem_squeal.reduced.sweep import solve_points
from fem_squeal.util.errors import ModelError, SceneError

#: the basis fields of a study's section on a model given as matrices
BASIS = {
    "basis": Field(str, "auto", one_of("auto", "modes", "snapshots"), "'modes': real modes of the symmetric "
                   "part + static corrections; 'snapshots': eigenvectors of the non-symmetric problem at "
                   "sampled values; 'auto': modes where M's symmetric part is positive definite"),
    "modes": Field(int, 20, at_least(1), "real modes in the basis"),
    "corrections": Field(bool, True, None, "static corrections of the non-symmetric and parameter terms"),
    "snapshots": Field(int, 5, at_least(1), "snapshot basis: parameter values sampled (evenly over the study's "
                       "ranges, all parameters together)"),
    "snapshot_modes": Field(int, 10, at_least(1), "snapshot basis: eigenvectors per value, nearest target_hz"),
    "target_hz": Field(REAL, 0.0, None, "snapshot basis: the frequency the eigenvectors are taken near"),
}
#: :data:`BASIS` as the sections of map, sensitivity and robustness have it (their ``modes`` is another field:
#: the number of real modes is ``basis_modes``)
BASIS_MODES = {("basis_modes" if k == "modes" else k): f for k, f in BASIS.items()}
#: the band and the instability criterion of a study's section on a model given as matrices
STUDY = {
    "band_hz": Field(list, None, band, "[low, high] Hz: the modes studied and checked; not set: "
                     "analyses.cea.band_hz, else up to the highest real mode of the basis"),
    "growth_tol": Field(REAL, 1e-6, positive, "unstable: Re λ > growth_tol |λ|"),
    "tol": Field(REAL, 1e-6, positive, "relative eigenvalue error allowed where the reduced model is checked "
                 "against the full sparse CEA"),
}


def check_parameter(scene, name: str, key: str) -> None:
    """``name`` is one of matrices.parameters, else SceneError at ``key``."""
    params = scene.matrices.parameters
    if not isinstance(name, str) or name not in params:
        raise SceneError(f"{key}: {name!r} is not a parameter of matrices.parameters; parameters: "
                         f"{sorted(params)}")


def parameter_range(scene, name: str, given, key: str) -> tuple[float, float]:
    """[low, high] of parameter ``name``: ``given`` ([low, high]) or its matrices.parameters range, else
    SceneError at ``key``."""
    if given is not None:
        numbers = isinstance(given, (list, tuple)) and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in given)
        if not (numbers and len(given) == 2 and given[0] < given[1]):
            raise SceneError(f"{key}: must be [low, high] with low < high (got {given!r})")
        return float(given[0]), float(given[1])
    r = scene.matrices.parameters[name]["range"]
    if r is None:
        raise SceneError(f"{key}: required: matrices.parameters.{name} has no range")
    return float(r[0]), float(r[1])


def check_finite(scene, values: Mapping[str, np.ndarray], key: str) -> None:
    """Every coefficient of the operators finite at the points ``values`` (others nominal)."""
    model = model_of(scene.matrices)
    try:
        for op in model.operators.values():
            op.coefficients({**model.nominal, **values})
    except ModelError as e:
        raise SceneError(f"{key}: {e}") from None


def diagonal_points(ranges: Mapping[str, tuple[float, float]], k: int) -> list[dict[str, float]]:
    """``k`` points evenly along the diagonal of the box ``ranges`` (every parameter from its low to its
    high value together): the snapshot points of a study."""
    return [{p: float(lo + t * (hi - lo)) for p, (lo, hi) in ranges.items()} for t in np.linspace(0, 1, k)]


def gathered(ctx: Context) -> dict[str, sp.csr_matrix] | None:
    """The named matrices whole on rank 0 (None elsewhere), from the ranks' rows."""
    comm, rows = ctx.comm, ctx.products["matrices"]["rows"]
    if comm.size == 1:
        return dict(rows)
    parts = {k: comm.gather(v, root=0) for k, v in rows.items()}
    return {k: sp.vstack(v, format="csr") for k, v in parts.items()} if comm.rank == 0 else None


def _on_rank0(ctx: Context, s: Mapping, points: Sequence[Mapping[str, float]], basis: str, n_modes: int
              ) -> ReducedMatrixModel:
    model = ctx.products["matrices"]["model"]
    mats = gathered(ctx)
    built = None
    if ctx.comm.rank == 0:
        r = reduce_matrix_model(model, mats, basis=basis, modes=n_modes, corrections=s["corrections"],
                                snapshot_points=list(points), snapshot_modes=s["snapshot_modes"],
                                target_hz=s["target_hz"])
        built = (r.terms, r.info)
    terms, info = ctx.comm.bcast(built, root=0)
    return ReducedMatrixModel(model, terms, info)


def reduced_model(ctx: Context, s: Mapping, points: Sequence[Mapping[str, float]]) -> ReducedMatrixModel:
    """The reduced model of the scene's matrices for the basis fields of section ``s`` (:data:`BASIS` or
    :data:`BASIS_MODES`),
    ``points`` the snapshot points (module docstring); built once per run for each basis setting (a
    modal basis does not depend on the points) and kept in ``ctx.products['matrices']['reduced']``."""
    memo = ctx.products["matrices"].setdefault("reduced", {})
    n_modes = s["basis_modes"] if "basis_modes" in s else s["modes"]
    modal = ("modes", n_modes, s["corrections"])
    snap = ("snapshots", s["snapshot_modes"], s["target_hz"],
            tuple(tuple(sorted(p.items())) for p in points))
    if s["basis"] != "snapshots" and modal in memo:
        return memo[modal]
    if s["basis"] != "modes" and snap in memo:
        return memo[snap]
    red = None
    if ctx.comm.size > 1 and s["basis"] != "snapshots":
        from fem_squeal.fe.matrix_basis import reduce_rows  # heavy: FE stack

        sec = ctx.scene.matrices
        try:
            red = reduce_rows(ctx.products["matrices"]["model"], ctx.products["matrices"]["rows"], ctx.comm,
                              n_modes, s["corrections"], bs=sec.block_size,
                              options=ctx.scene.solver.petsc_options)
        except ModelError:
            if s["basis"] == "modes":
                raise
        basis = "snapshots"
    else:
        basis = s["basis"]
    if red is None and ctx.comm.size > 1:
        from fem_squeal.fe.matrix_snapshots import reduce_snapshot_rows  # heavy: FE stack

        red = reduce_snapshot_rows(ctx.products["matrices"]["model"], ctx.products["matrices"]["rows"], ctx.comm,
                                   list(points), s["snapshot_modes"], s["target_hz"],
                                   bs=ctx.scene.matrices.block_size, options=ctx.scene.solver.petsc_options)
    if red is None:
        red = _on_rank0(ctx, s, points, basis, n_modes)
    memo[modal if red.info["basis"] == "modes" else snap] = red
    return red


def study_band(ctx: Context, s: Mapping, red: ReducedMatrixModel) -> tuple[float, float]:
    """The band of the study: ``band_hz``, else analyses.cea.band_hz, else up to the highest real mode of
    the basis (the highest reduced frequency for snapshots)."""
    if s["band_hz"] is not None:
        return tuple(s["band_hz"])
    if "cea" in ctx.scene.analyses:
        return tuple(ctx.scene.analyses["cea"]["band_hz"])
    if red.info.get("modes_hz"):
        return 0.0, float(red.info["modes_hz"][-1])
    lam = solve_points(red, {})[0]
    return 0.0, float(np.max(lam.imag) / TWO_PI)


def full_cea(ctx: Context, point: Mapping[str, float], band_hz, n: int, prefix: str) -> np.ndarray:
    """The eigenvalues of the full sparse CEA of the assembled matrices at ``point`` (PETSc/SLEPc,
    distributed; at least ``n`` nearest the band's centre, those in the band)."""
    from fem_squeal.fe.eigen import solve_complex_modes  # heavy: FE stack
    from fem_squeal.fe.matrix_operators import operators  # heavy: FE stack

    ops = operators(ctx.products["matrices"]["model"], ctx.products["matrices"]["rows"], ctx.comm, dict(point),
                    bs=ctx.scene.matrices.block_size)
    cm = solve_complex_modes(ops["K"], ops["M"], ops.get("C"), max(n, 4), band_centre_hz(band_hz),
                             band_hz=tuple(band_hz), options=ctx.scene.solver.petsc_options, prefix=prefix)
    for x in (*cm.vectors_re, *cm.vectors_im, *ops.values()):
        x.destroy()
    return np.asarray(cm.eigenvalues)


def check_point(ctx: Context, red: ReducedMatrixModel, point: Mapping[str, float], band_hz, growth_tol: float,
                prefix: str = "matrix_check_") -> dict:
    """The full sparse CEA at ``point`` against the reduced eigenvalues: the worst relative distance of a
    full eigenvalue in the band to the nearest reduced one, and both counts of unstable modes."""
    lam_r = solve_points(red, {k: np.array([v]) for k, v in point.items()})[0]
    f = lam_r.imag / TWO_PI
    inside = lam_r[(f >= band_hz[0]) & (f <= band_hz[1])]
    t = time.perf_counter()
    full = full_cea(ctx, point, band_hz, len(inside) + 2, prefix)
    dist = np.min(np.abs(full[:, None] - lam_r[None, :]), axis=1) if full.size else np.zeros(0)
    err = float(np.max(dist / np.abs(full))) if full.size else 0.0
    return {"point": {k: float(v) for k, v in point.items()}, "n_full": int(full.size),
            "n_reduced": int(inside.size),
            "n_unstable_full": int(unstable(full, growth_tol).sum()),
            "n_unstable_reduced": int(unstable(inside, growth_tol).sum()),
            "max_rel_error": err, "full_cea_s": time.perf_counter() - t}
