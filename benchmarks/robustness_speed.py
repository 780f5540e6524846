"""Speed of the Monte Carlo robustness study on a reduced model of brake size.

Target of the issue: 10⁴ samples of a 250-vector brake basis in ≤ 2 min on a quiet 2-core machine.
The model is synthetic unless ``--model`` names a ``reduced_model.npz`` (e.g. the one the demo
``demos/brake_robustness.py`` writes): 250 mass-orthonormal vectors, frequencies 50 Hz – 25 kHz
(the modes up to 2.5 × a 10 kHz band), a dense friction stiffness coupling neighbouring modes
(K_f¹ of the brake: unsymmetric, a few flutter pairs at μ = 0.4), two parts (disc, lining) whose
stiffness splits K₀, undamped like the brake scenes (the dense solve is then the m × m eigenvalue
problem of K; a damped model solves the 2m companion form, ≈ 8× the time).  Samples:
μ ~ N(0.4, 0.04), E_disc ~ U(±10 %), E_lining ~ lognormal(8 GPa, 10 %).

    mpirun -n 2 .venv/bin/python benchmarks/robustness_speed.py [--samples 10000] [--size 250] [--model PATH]

Writes benchmarks/out/robustness_speed_<synthetic|model>_<ranks>ranks.json and .md.
"""
from __future__ import annotations

import argparse
import json
import platform
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def synthetic_brake(m: int = 250, seed: int = 0):
    """A brake-like undamped reduced model of ``m`` vectors (module docstring)."""
    from fem_squeal.reduced.model import ReducedModel

    rng = np.random.default_rng(seed)
    f = np.sort(np.concatenate([np.repeat(rng.uniform(50, 25000, m // 4), 2),     # disc doublets, split
                                rng.uniform(50, 25000, m - 2 * (m // 4))]))
    f *= 1 + 2e-3 * rng.standard_normal(m)
    w2 = (2 * np.pi * np.sort(f)) ** 2
    S = rng.standard_normal((m, m))
    K0 = np.diag(w2) + 1e-3 * np.sqrt(np.outer(w2, w2)) * (S + S.T) / np.sqrt(m)
    share = rng.uniform(0.2, 0.8, m)                                # disc share of each mode's stiffness
    Kd = np.diag(share * w2)
    Kl = np.diag(0.1 * (1 - share) * w2)
    G = rng.standard_normal((m, m)) * np.exp(-np.abs(np.subtract.outer(np.arange(m), np.arange(m))) / 3.0)
    Kf = 3e-3 * np.sqrt(np.outer(w2, w2)) * G
    return ReducedModel(K0=K0, Kf1=Kf, K_parts={"disc": Kd, "lining": Kl}, E0={"disc": 125e9, "lining": 8e9},
                        mu0=0.4)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--samples", type=int, default=10000)
    ap.add_argument("--size", type=int, default=250)
    ap.add_argument("--model", type=Path, default=None, help="a reduced_model.npz instead of the synthetic one")
    ap.add_argument("--band", type=float, nargs=2, default=(0.0, 10000.0))
    args = ap.parse_args()
    from mpi4py import MPI

    from fem_squeal.reduced.model import ReducedModel
    from fem_squeal.reduced.robustness import Distribution, run_robustness
    from fem_squeal.reduced.stability_map import equal_bands
    from fem_squeal.util.blas import limit_threads_for

    comm = MPI.COMM_WORLD
    limit_threads_for(comm)
    model = ReducedModel.load(args.model) if args.model else synthetic_brake(args.size)
    dists = {"mu": Distribution("normal", 0.4, 0.04)}
    for part, d in (("disc", Distribution("uniform", 0.9, 1.1)), ("lining", Distribution("lognormal", 1.0, 0.1))):
        if part in model.K_parts:
            E0 = model.E0[part]
            dists[f"E.{part}"] = Distribution(d.kind, d.a * E0, d.b * E0)
    band = tuple(args.band)
    comm.Barrier()
    res = run_robustness(model, dists, args.samples, 1, band, equal_bands(band, 6),
                         comm=comm if comm.size > 1 else None)
    p = res.probability()
    out = {"model": str(args.model) if args.model else f"synthetic {model.size}", "size": model.size,
           "damped": model.damped, "samples": args.samples, "ranks": comm.size, "seconds": res.seconds,
           "ms_per_sample_per_rank": 1e3 * res.seconds * comm.size / args.samples,
           "probability": p.as_dict(), "families": int(res.nominal.size), "target_s": 120.0,
           "machine": platform.processor() or platform.machine()}
    if comm.rank == 0:
        outdir = ROOT / "benchmarks" / "out"
        outdir.mkdir(parents=True, exist_ok=True)
        stem = outdir / f"robustness_speed_{'model' if args.model else 'synthetic'}_{comm.size}ranks"
        stem.with_suffix(".json").write_text(json.dumps(out, indent=1))
        md = ("| model | size | samples | ranks | time [s] | ms/sample/rank | P(unstable) | target ≤ 120 s |\n"
              "|---|---|---|---|---|---|---|---|\n"
              f"| {out['model']} | {model.size} | {args.samples} | {comm.size} | {res.seconds:.1f} | "
              f"{out['ms_per_sample_per_rank']:.2f} | {p.p:.4f} ± {p.stderr:.4f} | "
              f"{'met' if res.seconds <= 120 else 'missed'} |\n")
        stem.with_suffix(".md").write_text(md)
        print(md)


if __name__ == "__main__":
    main()
