"""The ``preload`` stage: the static contact state under the loads and the operators linearised about it."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
from mpi4py import MPI

from fem_squeal.app import plots, resources
from fem_squeal.app.analyses import pressure_continuation
from fem_squeal.app.html import table as _table
from fem_squeal.app.stage import Context, Stage


def _preload_outputs(comm, outdir: Path, ops, pre, title: str, keep_files: bool = True) -> dict[str, Any]:
    """Summary of the preload for results.json; pressure PNG and the fields (pressure, displacement) as
    XDMF and VTU, kept in the cache and published unless --no-fields."""
    from dolfinx import fem  # heavy: FE stack

    from fem_squeal.fe.hexahedra import point_evaluation  # heavy: FE stack
    from fem_squeal.fe.interface import project_to_nodes  # heavy: FE stack
    from fem_squeal.fe.output import write_fields_xdmf, write_vtu  # heavy: FE stack

    summary: dict[str, Any] = {}
    plot_data = {}
    for it, op in ops.contacts:
        p = pre.pressure[it.name]
        area = op.area(comm)
        summary[it.name] = {
            "normal_force": pre.normal_force[it.name], "friction_force": pre.friction_force[it.name],
            "contact_area": pre.contact_area[it.name], "area": area,
            "closed_share": pre.contact_area[it.name] / area if area > 0 else 0.0,
            "peak_pressure": comm.allreduce(float(np.max(p, initial=0.0)), op=MPI.MAX),
        }
        xs, ps = comm.gather(op.x, root=0), comm.gather(p, root=0)
        if comm.rank == 0:
            plot_data[it.name] = (np.concatenate(xs), np.concatenate(ps))
    if comm.rank == 0:
        plots.contact_pressure(outdir / "contact_pressure.png", plot_data, title)
    if not keep_files:
        return summary
    V = ops.V
    if point_evaluation(V):
        S = fem.FunctionSpace(V.mesh, ("Lagrange", V.ufl_element().degree()))
    else:   # native hexahedra, serendipity: the scalar space of V's element (the pressure's L² projection)
        S = fem.FunctionSpace(V.mesh, V.ufl_element().sub_elements()[0])
    if S.dofmap.index_map.size_local != V.dofmap.index_map.size_local:
        raise RuntimeError("contact pressure output: scalar and vector spaces number their nodes differently")
    p_h = fem.Function(S, name="contact_pressure")
    for it, op in ops.contacts:
        dofs, vals = project_to_nodes(op, pre.pressure[it.name], comm)
        p_h.vector.setValues(dofs.astype(np.int32), vals)
    p_h.vector.assemble()
    p_h.x.scatter_forward()
    u = fem.Function(V, name="preload_displacement")
    u.x.array[: pre.u.getLocalSize()] = pre.u.array_r
    u.x.scatter_forward()
    write_fields_xdmf(comm, outdir / "preload.xdmf", {"preload_displacement": u, "contact_pressure": p_h})
    write_vtu(comm, outdir / "preload.vtu", V, {"preload_displacement": u}, scalars={"contact_pressure": p_h})
    return summary


def _add_friction_damping(ctx: Context, ops, lin, pre, out: dict):
    """``lin`` with the friction-damping matrix (interfaces.<name>.friction_damping) added to its C, about
    the preload ``pre`` (a model without contacts: the linear static displacement K u = f of ``ops``)."""
    spec = ctx.spec
    if not (any(p.friction_damping for p in spec.plates) or any(i.friction_damping for i in spec.interfaces)):
        return lin
    from fem_squeal.fe.preload import friction_damping, static_displacement  # heavy: FE stack

    u = pre.u if pre is not None else None
    if u is None and any(p.friction_damping for p in spec.plates):
        u = static_displacement(ops, ctx.scene.solver.petsc_options)
    Cd = friction_damping(ops, ctx.products["mesh"], spec, u, pre.pressure if pre is not None else None)
    if pre is None and u is not None:
        u.destroy()
    if Cd is None:
        return lin
    out["friction_damping"] = {"norm": Cd.norm(), "speed": ctx.scene.operating.speed}
    ctx.say(f"[fem_squeal] friction damping at {ctx.scene.operating['speed']:g} rad/s: ‖C_d‖ = {Cd.norm():.3g}")
    if lin.C is None:
        return lin._replace(C=Cd, Cd=Cd)
    C = lin.C.copy()
    C.axpy(1.0, Cd, structure=Cd.Structure.DIFFERENT_NONZERO_PATTERN)   # C_d: facets only
    return lin._replace(C=C, Cd=Cd)     # Cd apart too: the reduced basis adds its static corrections


def operating(ctx: Context):
    """The disc's rotation and stress stiffening per unit speed (:class:`fem_squeal.fe.assembly.
    OperatingTerms`) about this preload, assembled once for the CEA and the reduced model; None
    when the scene asks for neither (operating.gyroscopic, preload.geometric_stiffness)."""
    scene = ctx.scene
    if not (scene.operating.gyroscopic or scene.preload.geometric_stiffness):
        return None
    if "operating" not in ctx.products:
        from fem_squeal.fe.assembly import operating_terms  # heavy: FE stack

        pre = ctx.products.get("preload")
        ctx.products["operating"] = operating_terms(
            ctx.products["linear"], ctx.products["mesh"], ctx.spec, gyroscopic=scene.operating.gyroscopic,
            rotating_parts=scene.operating.rotating_parts, stress_stiffening=scene.preload.geometric_stiffness,
            u_static=pre.u if pre is not None else None, options=scene.solver.petsc_options)
    return ctx.products["operating"]


def _jacobian(ctx: Context, ops) -> str:
    """preload.jacobian with "auto" resolved by the memory model (:func:`fem_squeal.app.resources.
    preload_jacobian`: "symmetric" where the model put the LU's factors out of core and the Cholesky fits
    in core), warning where an explicit "symmetric" is predicted not to fit."""
    from fem_squeal.fe.factorisation import out_of_core_by_the_model  # heavy: FE stack

    options = ctx.scene.solver.petsc_options
    jacobian, warning = resources.preload_jacobian(ctx.scene.preload["jacobian"], ops.K.getSize()[0],
                                                   ctx.comm.size, resources.machines_of(ctx.comm),
                                                   out_of_core_by_the_model("preload_", options),
                                                   bool(pressure_continuation.scales(ctx.scene)))
    if warning:
        ctx.say(f"[fem_squeal] warning: {warning}")
    return jacobian


def run(ctx: Context, work: Path, timings: dict) -> dict:
    """Static contact state (nonlinear, or every point closed) and the linearisation about it."""
    from fem_squeal.fe.assembly import linearise  # heavy: FE stack

    ops = ctx.products["operators"]
    out: dict[str, Any] = {}
    pre = None
    if ops.contacts:
        pl = ctx.scene.preload
        t = time.perf_counter()
        if pl["mode"] == "nonlinear":
            from fem_squeal.fe.preload import NewtonFactor, solve_preload  # heavy: FE stack

            settings = dict(friction=pl["friction"], tol=pl["tol"], max_iterations=pl["max_iterations"],
                            options=ctx.scene.solver.petsc_options, jacobian=_jacobian(ctx, ops),
                            max_factorisations=pl["max_factorisations"])
            other = pressure_continuation.scales(ctx.scene)    # the operating matrix's other pressures
            factor = NewtonFactor() if other else None
            pre = solve_preload(ops, **settings, factor=factor,
                                progress=lambda line: ctx.say(f"[fem_squeal] {line}"))
            lin = linearise(ops, pre.active)
            timings["preload"] = time.perf_counter() - t
            if other:
                t = time.perf_counter()
                more = pressure_continuation.run(ctx, ops, pre, factor, work, settings)
                timings["preload_continuation"] = time.perf_counter() - t
            out["preload"] = {"mode": "nonlinear", "iterations": pre.iterations, "history": pre.history,
                              "jacobian": pre.jacobian, "factorisations": pre.factorisations,
                              "update_columns": pre.update_columns, "krylov_iterations": pre.krylov_iterations,
                              "interfaces": _preload_outputs(ctx.comm, work, ops, pre,
                                                             ctx.scene.title, ctx.keep_files)}
            if other:
                out["preload"]["pressure_continuation"] = more
            ctx.say(f"[fem_squeal] preload: {pre.iterations} Newton iterations "
                    f"({pre.factorisations} factorisations, {pre.update_columns} update columns, "
                    f"{pre.krylov_iterations} GMRES iterations), "
                    + ", ".join(f"{k} N = {v['normal_force']:.4g} N, closed {100 * v['closed_share']:.1f} %"
                                for k, v in out["preload"]["interfaces"].items())
                    + f"; {timings['preload']:.2f} s")
        else:
            lin = linearise(ops, None)
            timings["preload"] = time.perf_counter() - t
            out["preload"] = {"mode": "all_closed"}
        lin = _add_friction_damping(ctx, ops, lin, pre, out)
        ops.K.destroy()
        ops = lin
    else:
        ops = _add_friction_damping(ctx, ops, ops, pre, out)
    ctx.products["preload"] = pre
    ctx.products["linear"] = ops
    return out


def report(res: dict) -> str:
    """The report section (HTML) of this stage from results.json ``res``."""
    if not (res.get("preload", {}).get("interfaces")):
        return ""
    rows = [[k, v["normal_force"], v["friction_force"], v["contact_area"] * 1e4, 100 * v["closed_share"],
             v["peak_pressure"] / 1e6] for k, v in res["preload"]["interfaces"].items()]
    return ("<h2>Preload</h2>" + _table(
        ["interface", "normal force [N]", "friction force [N]", "contact area [cm²]", "closed [%]",
         "peak pressure [MPa]"], rows))


STAGE = Stage("preload", ("operators",), run, "static contact state and the linearisation about it",
              inputs=lambda scene, spec: pressure_continuation.key_inputs(scene), report=report, memory=True,
              fields=True)
