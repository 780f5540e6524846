"""``fem-squeal export SCENE DIR``: fem_squeal's own operators written as matrices, with a ``[matrices]``
scene that reads them back (:mod:`fem_squeal.app.scene.matrices`), so a model can go out to another
code and come back.

The model stages of the scene run in memory (mesh, operators with each part's stiffness, preload and
the linearisation about it), then the operators of its CEA are written term by term in the affine
form of the reduced layer (:mod:`fem_squeal.reduced.affine`, the terms of
:class:`fem_squeal.fe.projection.ParametricOperators`), each term a Matrix Market file (17 digits: read
back bit for bit) in PETSc's global row order:

    K = K0 + (mu/μ⁰) Kf + Σ_p (E_p/E_p⁰ − 1) K_p [+ Ks0] [+ speed² K2]
    C = C0 + Σ_p β_p (E_p/E_p⁰ − 1) K_p [+ speed G] [+ (|mu|/|μ⁰|)(Ω₀/speed) − 1) Cd]
    M = M

K0 is the linearised frictionless stiffness (closed contact, springs, clamped rows with a unit
diagonal), Kf the friction stiffness at the scene's μ⁰, K_p part p's elastic stiffness (zero on the
clamped rows), Ks0 the preload's stress stiffening, K2 = K_σc − S and G the turning disc's terms per
unit Ω² and Ω, C0 the damping of the scene (Rayleigh, and the friction damping Cd at the nominal
point).  The parameters: ``mu`` (with friction), ``E_<part>`` (a part's Young's modulus [Pa]) and
``speed`` (where the reduced model has it); at their nominal values the operators are the CEA's.
The written scene asks for the scene's ``real_modes`` and ``cea`` sections (a CEA with its defaults if
it has neither)."""
from __future__ import annotations

from pathlib import Path

from mpi4py import MPI

from fem_squeal.app.analyses import ANALYSES
from fem_squeal.app.analyses.mesh import build_mesh
from fem_squeal.app.analyses.preload import STAGE as PRELOAD
from fem_squeal.app.analyses.preload import operating
from fem_squeal.app.pipeline import scratch
from fem_squeal.app.scene import model_spec
from fem_squeal.app.schema_reference import toml_value
from fem_squeal.app.stage import Context
from fem_squeal.reduced.expressions import compile_operator
from fem_squeal.util.atomic import write_atomic
from fem_squeal.util.errors import SceneError, SolveError
from fem_squeal.util.matrix_files import write_matrix_market

#: the largest relative difference (Frobenius) between the written terms' sum and the CEA's operators
SUM_TOL = 1e-13


def _terms(ctx: Context) -> tuple[list, list, dict[str, float]]:
    """([(name, PETSc matrix, coefficient text)] of K and of C, {parameter: nominal value})."""
    from fem_squeal.fe.model import common_mu  # heavy: FE stack
    from fem_squeal.fe.projection import ParametricOperators  # heavy: FE stack

    ops, spec, scene = ctx.products["linear"], ctx.spec, ctx.scene
    mu0 = common_mu(spec) if ops.Kf is not None else 0.0
    speed0 = float(scene.operating.speed)
    par = ParametricOperators(ops, spec, mu0, sorted(spec.materials), preload=ctx.products["preload"],
                              operating=operating(ctx), speed0=speed0)
    params: dict[str, float] = {}
    K = [("K0", ops.K, "1")]
    C = [("C0", ops.C, "1")] if ops.C is not None else []
    if ops.Kf is not None:
        if mu0 != 0:
            params["mu"] = mu0
            K.append(("Kf", ops.Kf, f"mu/{mu0!r}"))
        else:
            K.append(("Kf", ops.Kf, "1"))
    op = par.operating
    speed = "speed" if par.speed_varies else repr(speed0)
    if par.speed_varies:
        params["speed"] = speed0
    if op is not None and op.Ks0 is not None:
        K.append(("Ks0", op.Ks0, "1"))
    if op is not None and op.G is not None:
        K.append(("K2", par.K2, f"{speed}**2"))
        C.append(("G", op.G, speed))
    if ops.Cd is not None and mu0 != 0:
        scale = f"sqrt(mu**2)/{abs(mu0)!r}" + (f"*({speed0!r}/{speed})" if speed0 else "")
        C.append(("Cd", ops.Cd, f"{scale} - 1"))
    for p in par.parts:
        name, E0 = f"E_{p}", par.E0[p]
        params[name] = E0
        K.append((f"K_{p}", par.K_parts[p], f"({name}/{E0!r} - 1)"))
        if par.beta[p] > 0:
            C.append((f"K_{p}", par.K_parts[p], f"{par.beta[p]!r}*({name}/{E0!r} - 1)"))
    ctx.products["export_par"] = par
    return K, C, params


def _expression(terms: list) -> str:
    return " + ".join(name if coef == "1" else f"{coef}*{name}" for name, _, coef in terms)


def _scene_text(source: str, title: str, K: list, C: list, params: dict, n: int, bs: int, analyses: dict) -> str:
    lines = [f"# Written by fem-squeal export from {source}: fem_squeal's operators as Matrix Market files",
             "# (fem_squeal.app.export); run it with fem-squeal run.", f"title = {toml_value(title)}", "",
             "[matrices]", 'M = "M"']
    if C:
        lines.append(f"C = {toml_value(_expression(C))}")
    lines += [f"K = {toml_value(_expression(K))}", f"dofs = {n}", f"block_size = {bs}", "", "[matrices.files]"]
    names = ["M"] + list(dict.fromkeys(name for name, _, _ in K + C))
    lines += [f"{name} = {toml_value(name + '.mtx')}" for name in names]
    if params:
        lines += ["", "[matrices.parameters]"] + [f"{k} = {{ value = {v!r} }}" for k, v in params.items()]
    for name, sec in analyses.items():
        lines += ["", f"[analyses.{name}]"] + [f"{k} = {toml_value(v)}" for k, v in sec.items()
                                                if v is not None]
    return "\n".join(lines) + "\n"


def _check_sums(ctx: Context, K: list, C: list, params: dict) -> float:
    """The largest ‖Σ c_k(p⁰) A_k − A_CEA‖_F/‖A_CEA‖_F of K and C: the written terms, with the coefficients
    of the written expressions (compiled as the import compiles them) at the nominal point, against the
    CEA's own operators (:func:`fem_squeal.fe.assembly.operating_operators`); raises where it is above
    :data:`SUM_TOL`."""
    from petsc4py import PETSc  # heavy: FE stack

    from fem_squeal.fe.assembly import combination, operating_operators  # heavy: FE stack

    ops, scene = ctx.products["linear"], ctx.scene
    K_cea, C_cea, _ = operating_operators(ops, ctx.products["mesh"], ctx.spec, speed=scene.operating.speed,
                                          terms=operating(ctx))
    worst = 0.0
    for label, terms, ref in (("K", K, K_cea), ("C", C, C_cea)):
        if not terms and ref is None:
            continue
        op = compile_operator(label, _expression(terms), [t[0] for t in terms], list(params))
        coef = dict(zip(op.matrices, (float(c) for c in op.coefficients(params))))
        mats = dict((name, A) for name, A, _ in terms)
        total = combination([(mats[name], coef[name]) for name in op.matrices])
        total.axpy(-1.0, ref, structure=total.Structure.DIFFERENT_NONZERO_PATTERN)
        worst = max(worst, total.norm(PETSc.NormType.FROBENIUS) / ref.norm(PETSc.NormType.FROBENIUS))
        total.destroy()
        if ref is not ops.K and ref is not ops.C:
            ref.destroy()
    if not worst <= SUM_TOL:
        raise SolveError(f"export: the written terms do not sum to the CEA's operators at the nominal point "
                         f"(relative difference {worst:.1e} > {SUM_TOL:.0e})")
    return worst


def export_scene(scene, outdir: str | Path, comm: MPI.Comm = MPI.COMM_WORLD, say=print,
                 source: str = "a scene") -> list[str]:
    """Write the operators of ``scene`` (a finite-element scene) and ``outdir/scene.toml`` (module
    docstring), after checking that the written terms sum to the CEA's operators at the nominal point
    (:func:`_check_sums`); the names of the files written."""
    from fem_squeal.fe.assembly import assemble_operators  # heavy: FE stack
    from fem_squeal.fe.matrix_operators import gather_csr  # heavy: FE stack

    if "geometry" not in scene:
        raise SceneError("export: the scene has no finite-element model (geometry) to export")
    outdir = Path(outdir)
    spec = model_spec(scene)
    ctx = Context(scene, spec, comm, say, False, None, {})
    ctx.keep_files = False
    md = build_mesh(comm, scene)
    ctx.products["mesh"] = md
    ctx.products["operators"] = assemble_operators(md, spec, parts=True)
    with scratch(comm) as work:
        PRELOAD.run(ctx, work, {})
    K, C, params = _terms(ctx)
    difference = _check_sums(ctx, K, C, params)
    n = ctx.products["linear"].M.getSize()[0]
    written: dict[str, object] = {"M": ctx.products["linear"].M}
    for name, A, _ in K + C:
        written.setdefault(name, A)
    files = []
    for name, A in written.items():
        full = gather_csr(A)
        if comm.rank == 0:
            write_matrix_market(outdir / f"{name}.mtx", full, comment=f"{name} of fem-squeal export ({source})")
        files.append(f"{name}.mtx")
    analyses = {k: {f: x for f, x in v.as_dict().items() if f != "describe_part"}    # no parts in matrices
                for k, v in scene.analyses.items() if k in ANALYSES and ANALYSES[k].on_matrices is not None}
    if not analyses:
        analyses = {"cea": {}}
    bs = max(1, ctx.products["linear"].M.getBlockSize())
    text = _scene_text(source, f"{scene.title or 'fem_squeal model'} (exported operators)", K, C, params, n, bs,
                       analyses)
    if comm.rank == 0:
        write_atomic(outdir / "scene.toml", lambda f: f.write(text.encode()), "wb")
    ctx.products["export_par"].destroy()
    comm.barrier()
    say(f"[fem_squeal] exported {len(files)} matrices of {n} DOFs and scene.toml to {outdir} (the terms sum to "
        f"the CEA's K and C within {difference:.1e} relative at the nominal point)")
    return [*files, "scene.toml"]
