"""Cost per transient step against basis size and contact elements on the reduced brake.

Usage: python benchmarks/transient_brake.py MODEL.npz [--steps=2000]
(MODEL.npz: out/transient_brake/reduced_model.npz, written by demos/transient_brake.py).

For each basis size m (the leading m vectors of the basis, a Galerkin sub-model) and each
contact discretisation (polar patches n_r × n_θ per pad, or every quadrature point) it times
``steps`` steps of 1 µs from steady sliding plus a push along the most unstable mode (amplitude
1e-3 of the static closure, the nonlinear regime), and prints ms/step, Newton iterations/step
and the projected time of a 100 ms run (1e5 steps).  Serial: the reduced transient runs on one
rank (the others of an MPI job wait), so 1 and 2 ranks cost the same.
"""
from __future__ import annotations

import sys
import time
from dataclasses import replace

import numpy as np

from fem_squeal.reduced.limit_cycle import tangent_eigs
from fem_squeal.reduced.model import ReducedModel
from fem_squeal.reduced.transient import NewmarkHHT, TransientError, from_reduced, run_transient


def truncate(rm: ReducedModel, m: int) -> ReducedModel:
    c = {k: replace(v, Gn=v.Gn[:, :m], Gt=v.Gt[:, :m]) for k, v in rm.contacts.items()}
    sub = lambda A: None if A is None else A[:m, :m]  # noqa: E731
    return replace(rm, K0=rm.K0[:m, :m], Kf1=sub(rm.Kf1), C0=sub(rm.C0),
                   K_parts={k: v[:m, :m] for k, v in rm.K_parts.items()}, contacts=c,
                   f=None if rm.f is None else rm.f[:m], q_static=None if rm.q_static is None else rm.q_static[:m])


def main() -> None:
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    opts = dict(a[2:].split("=", 1) for a in sys.argv[1:] if a.startswith("--") and "=" in a)
    steps = int(opts.get("steps", 2000))
    rm0 = ReducedModel.load(args[0])
    print("| basis m | contact elements | ms/step | Newton it./step | factorisations | 100 ms run [s] |")
    print("|---:|---:|---:|---:|---:|---:|")
    sizes = [s for s in (60, 120, rm0.size) if s <= rm0.size]
    for m in sizes:
        rm = truncate(rm0, m) if m < rm0.size else rm0
        for patches in ((4, 8), (8, 16), (16, 32), None):
            try:
                dm = from_reduced(rm, omega=5.0, cubic_share=0.3, c_max=2e5, depth=1e-6, patches=patches,
                                  f_cut=18e3)
                integ = NewmarkHHT(dm, 1e-6)
                qs = integ.steady_sliding(rm.q_static)
                Kt, Ct = integ.tangent_matrices(qs, np.zeros_like(qs))
                lam, Y = tangent_eigs(Kt, Ct, vectors=True)
                i = int(np.argmax(np.where(lam.imag < 2 * np.pi * 16e3, lam.real, -np.inf)))
                closure = np.median(np.concatenate([cs.d0 + cs.D @ qs for cs in dm.contacts]))
                amp = 1e-3 * closure / max(np.abs(cs.D @ Y[:, i]).max() for cs in dm.contacts)
                t0 = time.perf_counter()
                res = run_transient(dm, qs + (amp * Y[:, i]).real, (amp * lam[i] * Y[:, i]).real,
                                    steps * 1e-6, 1e-6, record_every=10)
                wall = time.perf_counter() - t0
                st = res.stats
                n = sum(cs.size for cs in dm.contacts)
                print(f"| {m} | {n} | {1e3 * wall / steps:.3f} | {st['iterations'] / steps:.2f} | "
                      f"{st['factorisations']} | {wall / steps * 1e5:.0f} |", flush=True)
            except TransientError as e:
                print(f"| {m} | {patches} | failed: {str(e)[:80]} | | | |", flush=True)


if __name__ == "__main__":
    main()
