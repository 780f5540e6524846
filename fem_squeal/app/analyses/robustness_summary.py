"""What the robustness study makes of its section and its Monte Carlo result, for a finite-element model
(:mod:`fem_squeal.app.analyses.robustness`) and a model given as matrices
(:mod:`fem_squeal.app.analyses.matrix_studies`) alike: the distributions of
``analyses.robustness.parameters`` checked, the samples the full CEA checks, results.json
``robustness`` and the files robustness.npz, robustness.json, robustness.png."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from fem_squeal.app import plots
from fem_squeal.reduced.eigensolve import TWO_PI
from fem_squeal.reduced.model import INTERFACE_PREFIXES, PART_PREFIXES, split_param
from fem_squeal.reduced.robustness import KINDS, Distribution
from fem_squeal.util.atomic import write_json_atomic, write_npz_atomic
from fem_squeal.util.errors import ModelError, SceneError

_KEYS = {"uniform": ("lower", "upper"), "normal": ("mean", "std"), "lognormal": ("mean", "std")}


def _tables(params: dict) -> dict[str, Any]:
    """name → table, the nested forms ``E = {disc = {...}}``, ``kn = {pad = {...}}`` (any of E, eta,
    mu, kn, kt) flattened to ``E.disc``, ``kn.pad``; a table-valued entry of ``mu`` is ``mu.<interface>``
    also next to ``mu``'s own distribution keys (``[...parameters.mu]`` and ``[...parameters.mu.pad]``)."""
    out = {}
    for name, t in params.items():
        if name in (*PART_PREFIXES, *INTERFACE_PREFIXES) and isinstance(t, dict) and \
                ("distribution" not in t or any(isinstance(v, dict) for v in t.values())):
            own = {k: v for k, v in t.items() if not isinstance(v, dict)}
            if own:
                out[name] = own
            out.update({f"{name}.{target}": v for target, v in t.items() if isinstance(v, dict)})
        else:
            out[name] = t
    return out


def distributions(section: dict) -> dict[str, Distribution]:
    """The section's distributions (checked: SceneError naming ``analyses.robustness.parameters.<name>.<key>``)."""
    out = {}
    for name, t in _tables(section["parameters"]).items():
        key = f"analyses.robustness.parameters.{name}"
        if not isinstance(t, dict):
            raise SceneError(f"{key}: must be a table with distribution and its bounds or moments (got {t!r})")
        kind = t.get("distribution")
        if kind not in KINDS:
            raise SceneError(f"{key}.distribution: must be one of {list(KINDS)} (got {kind!r})")
        want = _KEYS[kind]
        unknown = sorted(set(t) - {"distribution", *want})
        if unknown:
            raise SceneError(f"{key}.{unknown[0]}: unknown key for a {kind} distribution; allowed: {list(want)}")
        for k in want:
            v = t.get(k)
            if v is None:
                raise SceneError(f"{key}.{k}: required for a {kind} distribution")
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                raise SceneError(f"{key}.{k}: must be a finite number (got {v!r})")
        try:
            d = Distribution(kind, float(t[want[0]]), float(t[want[1]]))
        except ModelError as err:
            raise SceneError(f"{key}.{err}") from None
        prefix = split_param(name)[0]
        if name.startswith("E.") and not d.stays_positive():
            raise SceneError(f"{key}: a Young's modulus must stay > 0 (a normal needs mean > 8 std; "
                             f"or use a lognormal) (got {d.as_dict()})")
        if prefix == "kn" and "." in name and not d.stays_positive():
            raise SceneError(f"{key}: a contact stiffness must stay > 0 (a normal needs mean > 8 std; "
                             f"or use a lognormal) (got {d.as_dict()})")
        if prefix in ("kt", "eta") and not d.stays_non_negative():
            raise SceneError(f"{key}: {'a tangential stiffness' if prefix == 'kt' else 'a loss factor'} must stay "
                             f">= 0 (uniform: lower >= 0; a normal needs mean > 8 std; or use a lognormal) "
                             f"(got {d.as_dict()})")
        out[name] = d
    return out


def _spot_points(res, n: int) -> list[int]:
    """Sample indices for the full CEA: largest and smallest growth rate, then the extremes of
    each parameter (deterministic: the same on every rank)."""
    cand = [int(np.argmax(res.max_growth)), int(np.argmin(res.max_growth))]
    for v in res.samples.values():
        cand += [int(np.argmax(v)), int(np.argmin(v))]
    return list(dict.fromkeys(cand))[:n]


def summary(res, r: dict, dists: dict[str, Distribution], bands) -> dict:
    """results.json ``robustness`` (spot checks aside) of the Monte Carlo result ``res`` of section ``r``."""
    n = res.n
    prob = res.probability()
    fam_p = res.family_probabilities()
    labels = [f"{f:.0f} Hz" for f in res.nominal.imag / TWO_PI]
    families = []
    for j, (lab, p) in enumerate(zip(labels, fam_p)):
        g = res.family_lambda[:, j].real
        q = np.quantile(g, [0.05, 0.5, 0.95])
        fam = {"label": lab, "freq_hz": float(res.nominal[j].imag / TWO_PI),
               "nominal_real_part": float(res.nominal[j].real), **p.as_dict(),
               "growth": {"mean": float(g.mean()), "std": float(g.std()), "min": float(g.min()),
                          "q05": float(q[0]), "median": float(q[1]), "q95": float(q[2]), "max": float(g.max())}}
        if p.p > 0:
            fam["drivers"] = res.drivers(g)
        families.append(fam)
    out = {"n_samples": n, "seed": r["seed"], "ranks": res.ranks, "seconds": res.seconds,
           "seconds_per_sample": res.seconds * res.ranks / n,
           "parameters": {k: d.as_dict() for k, d in dists.items()},
           "probability": prob.as_dict(),
           "bands": [{"band_hz": list(b), **p.as_dict()} for b, p in zip(bands, res.band_probabilities())],
           "families": families, "drivers": res.drivers(), "sobol": res.sobol(),
           "family_assignment": "nearest nominal eigenvalue (Hungarian, |λ − λ⁰|/|λ⁰|)"}
    return out


def write_files(work: Path, res, out: dict, bands, n_histograms: int, title: str) -> None:
    """robustness.npz, robustness.json, robustness.png (rank 0)."""
    fam_p = res.family_probabilities()
    labels = [f"{f:.0f} Hz" for f in res.nominal.imag / TWO_PI]
    families = out["families"]
    write_npz_atomic(work / "robustness.npz", {**{f"sample/{k}": v for k, v in res.samples.items()},
                                               "max_growth": res.max_growth, "band_hits": res.band_hits,
                                               "nominal": res.nominal, "family_lambda": res.family_lambda,
                                               "bands_hz": np.array(bands)})
    write_json_atomic(work / "robustness.json", out)
    top = sorted(range(len(families)), key=lambda j: -fam_p[j].p)[:n_histograms]
    top = [j for j in top if fam_p[j].p > 0] or top[:1]
    plots.robustness(work / "robustness.png", bands, [b["p"] for b in out["bands"]],
                     [b["stderr"] for b in out["bands"]], out["drivers"],
                     [{"label": labels[j], "growth": res.family_lambda[:, j].real} for j in top],
                     title)
