"""What an NVH engineer reads off the CEA (issue 38): which real modes couple into each complex mode,
which parts carry it, how much it radiates, and which unstable modes to look at first.

* **Mode coupling**: each complex mode's participation of the real modes of the frictionless K, the
  reduced basis's (:mod:`fem_squeal.fe.coupling`: one real-mode solve; for the projected CEA read off
  its basis, no solve: :func:`fem_squeal.fe.projection.projected_cea.modal_coupling`;
  :mod:`fem_squeal.reduced.mode_coupling`), the pair named;
* **part participation**: the strain-energy shares of the parts (``energy_shares``) as bars;
* **radiated sound**: the ERP of each mode at a stated kinetic energy (:mod:`fem_squeal.fe.radiation`)
  in dB re 1 pW, the squeal index ranking the unstable modes and 1/3-octave band summaries
  (:mod:`fem_squeal.reduced.squeal_index`).

The rows of ``complex_modes`` in results.json gain ``coupling``, ``erp_w``, ``erp_db`` and
``squeal_index_db``; the CEA's results gain ``cea_coupling``, ``cea_radiation``, ``cea_squeal_ranking``
and ``cea_bands``.  Files (rank 0): cea_coupling.csv/.png, cea_part_participation.csv/.png,
cea_radiation.csv, cea_erp.png, cea_bands.csv.  Scene keys: ``analyses.cea.coupling``,
``analyses.cea.coupling_f_max_hz`` and the table ``analyses.cea.radiation`` (:data:`RADIATION`).
"""
from __future__ import annotations

import csv
import io
import math
import time
from pathlib import Path

import numpy as np

from fem_squeal.app.fields import REAL, Field, check_fields, non_negative, positive, section
from fem_squeal.app.html import escape as _e
from fem_squeal.app.html import table as _table
from fem_squeal.reduced import mode_coupling, squeal_index
from fem_squeal.util.atomic import write_atomic
from fem_squeal.util.errors import SceneError

#: the real modes of the coupling basis reach this factor times the band's upper end (by default)
COUPLING_CUT_FACTOR = 1.25


def _efficiencies(v: dict) -> str | None:
    bad = [k for k, x in v.items() if isinstance(x, bool) or not isinstance(x, (int, float)) or not x >= 0]
    return None if not bad else f"must map part names to numbers >= 0 (got {bad[0]} = {v[bad[0]]!r})"


def _names(v: list) -> str | None:
    return None if all(isinstance(x, str) for x in v) else f"must be a list of face names (got {v!r})"


RADIATION = {
    "enabled": Field(bool, True, None, "compute the ERP of every complex mode"),
    "rho_c": Field(REAL, 1.21 * 343.0, positive, "characteristic impedance of air ρc [Pa·s/m] (1.21 kg/m³ × "
                   "343 m/s)"),
    "kinetic_energy": Field(REAL, 1.0, positive, "modal kinetic energy ½∫ρ|v|²dV [J] each mode is scaled to"),
    "default_efficiency": Field(REAL, 1.0, non_negative, "radiation efficiency σ of the parts not in efficiency"),
    "efficiency": Field(dict, {}, _efficiencies, "part -> radiation efficiency σ (e.g. 0.1 for a caliper)"),
    "exclude_faces": Field(list, [], _names, "faces that do not radiate besides those a contact partner "
                           "covers (rigid plates, interface faces, the disc under the pads)"),
}


def check_radiation(v: dict) -> None:
    """analyses.cea.radiation checked against :data:`RADIATION` (raises naming the key)."""
    check_fields(v, RADIATION, "analyses.cea.radiation")


def radiation_settings(table: dict):
    """The typed ``analyses.cea.radiation`` with its defaults."""
    return section(table, RADIATION, "analyses.cea.radiation")


def check_parts(a, volumes) -> None:
    """analyses.cea.radiation.efficiency names parts of the model."""
    eff = a["radiation"].get("efficiency", {})
    for part in eff:
        if part not in volumes:
            raise SceneError(f"analyses.cea.radiation.efficiency.{part}: unknown part; parts: {sorted(volumes)}")


def compute(ctx, ops, fields, rows: list[dict], lam: np.ndarray, a, coupling=None) -> dict:
    """Coupling and radiation of the CEA's modes ``fields`` (x = xr + i xi, M-normalised): adds keys to
    ``rows`` and returns the CEA's new top-level results (module docstring).  ``coupling``: the modes'
    coefficients already known (a :class:`~fem_squeal.reduced.mode_coupling.RealModeCoefficients`, the
    projected CEA's); else, where analyses.cea.coupling asks, one real-mode solve gives them."""
    out: dict = {}
    if a["coupling"] and fields:
        t = time.perf_counter()
        if coupling is None:
            ctx.say(f"[fem_squeal] coupling: the frictionless model's real modes up to {coupling_cut(a):g} Hz")
        rc = coupling if coupling is not None else _coefficients(ctx, ops, fields, a)
        out["cea_coupling"] = {**coupling_summaries(rc, rows, ctx.products.get("basis"), ops.M),
                               "seconds": time.perf_counter() - t}
        ctx.say(f"[fem_squeal] coupling: the CEA's modes on {len(rc.freqs_hz)} real modes, "
                f"{out['cea_coupling']['seconds']:.2f} s")
    rad = radiation_settings(a["radiation"])
    t_rad = time.perf_counter()
    if rad.enabled and fields:
        from fem_squeal.fe.radiation import radiated_power  # heavy: FE stack

        P, area = radiated_power(ops.V, ctx.products["mesh"], ctx.spec, ops.M, fields, rho_c=rad.rho_c,
                                 energy=rad.kinetic_energy, efficiency=rad.efficiency,
                                 default_efficiency=rad.default_efficiency, exclude_faces=rad.exclude_faces,
                                 contacts=ops.contacts)
        L = squeal_index.level_db(P)
        SI = squeal_index.squeal_index(lam.real, L)
        unstable = np.array([r["unstable"] for r in rows], bool)
        for r, p, lw, si, u in zip(rows, P, L, SI, unstable):
            r.update(erp_w=float(p), erp_db=float(lw),
                     squeal_index_db=float(si) if u and np.isfinite(si) else None)
        out["cea_radiation"] = {
            "rho_c": rad.rho_c, "kinetic_energy_j": rad.kinetic_energy, "area_m2": area,
            "default_efficiency": rad.default_efficiency, "efficiency": dict(rad.efficiency),
            "exclude_faces": list(rad.exclude_faces),
            "norm": f"each mode scaled to a modal kinetic energy ½∫ρ|v|²dV = {rad.kinetic_energy:g} J; "
                    "ERP = ½ρcσ∫|v_n|²dA [W], L_W in dB re 1 pW",
            "squeal_index": "SI = L_W + 10 log10(Re λ · 1 s) [dB], unstable modes only"}
        out["cea_squeal_ranking"] = squeal_index.ranking(SI, unstable)
        out["cea_bands"] = squeal_index.band_summary([r["freq_hz"] for r in rows], L, unstable, SI)
        ctx.say(f"[fem_squeal] radiation (ERP, squeal index): {time.perf_counter() - t_rad:.2f} s")
    return out


def coupling_cut(a) -> float:
    """The real modes' cut of the coupling [Hz]: analyses.cea.coupling_f_max_hz, else
    :data:`COUPLING_CUT_FACTOR` × the band's top."""
    return a["coupling_f_max_hz"] or COUPLING_CUT_FACTOR * a["band_hz"][1]


def _coefficients(ctx, ops, fields, a):
    """The coefficients on the real modes of the frictionless K (``ops.K``: the reduced basis's modes, so
    that a real mode has one number in the CEA's table and the sweep's, map's and operating matrix's) up
    to analyses.cea.coupling_f_max_hz.  The solve's first count: the band's pairs, grown to the cut
    (:func:`~fem_squeal.fe.projection.shifted.count_guess`): the pairs alone sent Krylov–Schur, where it
    runs, to a second solve (711k DOFs on one rank: 91, then 144, 410 s)."""
    from fem_squeal.fe.coupling import real_mode_coefficients  # heavy: FE stack
    from fem_squeal.fe.projection.shifted import count_guess  # heavy: FE stack

    f_max = coupling_cut(a)
    n_start = max(20, math.ceil(count_guess(len(fields), a["band_hz"][1], f_max)))
    return real_mode_coefficients(ops.K, ops.M, fields, f_max, frictionless=True,
                                  options=ctx.scene.solver.petsc_options, n_start=n_start)


def coupling_summaries(rc, rows: list[dict], basis=None, M=None) -> dict:
    """Each row's ``coupling`` (:func:`fem_squeal.reduced.mode_coupling.summary` of its column of
    ``rc``, a :class:`fem_squeal.reduced.mode_coupling.RealModeCoefficients`; ``pair_kind`` from the real
    modes' descriptors by ``basis``, a :class:`fem_squeal.fe.descriptors.CircumferentialBasis`, when
    given with the mass matrix ``M``) and the CEA's ``cea_coupling`` section.  Drops ``rc.Phi``."""
    p, r = mode_coupling.participation(rc.coefficients, rc.norms)
    used: set[int] = set()
    for j, row in enumerate(rows):
        row["coupling"] = mode_coupling.summary(p[:, j], r[j], rc.freqs_hz)
        used.update(row["coupling"]["real_modes"])
    described = _describe_real_modes(basis, M, rc, sorted(used))
    rc.Phi = None                       # the vectors are not kept
    for row in rows:
        pair = row["coupling"]["pair"]
        row["coupling"]["pair_kind"] = pair_kind([described.get(i) for i in pair], rc.freqs_hz[pair])
    return {"f_max_hz": rc.f_max_hz, "n_real_modes": int(len(rc.freqs_hz)), "real_freqs_hz": rc.freqs_hz,
            "real_modes": [described[i] for i in sorted(described)], "basis": rc.basis}


def _describe_real_modes(basis, M, rc, which: list[int]) -> dict[int, dict]:
    """Frequency, nodal diameter, nodal and in-plane share of the real modes ``which`` (the columns of
    ``rc.columns``), by the descriptors of the complex modes (``basis``; None: frequencies only)."""
    out = {i: {"index": i, "freq_hz": float(rc.freqs_hz[i])} for i in which}
    if basis is None or rc.Phi is None or not which:
        return out
    vecs = []
    for x in rc.columns(which).T:
        v = M.createVecRight()
        v.array[:] = x
        vecs.append(v)
    for i, d in zip(which, basis.describe_all([(v, None) for v in vecs])):
        out[i].update(nodal_diameter=d.nodal_diameter, nodal_share=d.nodal_share, in_plane_share=d.in_plane_share)
    for v in vecs:
        v.destroy()
    return out


def pair_kind(described: list[dict | None], freqs: np.ndarray, rtol: float = 1e-2) -> str:
    """"cos/sin pair, nodal diameter k" when the two real modes have one frequency (within ``rtol``)
    and one nodal diameter k ≥ 1 (the two orientations of an axisymmetric part's k-diameter mode);
    else ""."""
    if len(described) < 2 or any(d is None or "nodal_diameter" not in d for d in described):
        return ""
    k0, k1 = described[0]["nodal_diameter"], described[1]["nodal_diameter"]
    if k0 == k1 and k0 >= 1 and abs(freqs[0] - freqs[1]) <= rtol * max(abs(freqs[0]), 1.0):
        return f"cos/sin pair, nodal diameter {k0}"
    return ""


# -- files (rank 0) --------------------------------------------------------------------------------

def _csv(path: Path, head: list[str], rows: list[list]) -> None:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(head)
    w.writerows([[("" if v is None else (f"{v:.10g}" if isinstance(v, float) else v)) for v in r] for r in rows])
    write_atomic(path, lambda f: f.write(buf.getvalue()))


def write_files(work: Path, rows: list[dict], res: dict, title: str = "") -> list[str]:
    """The CSV files and plots of the coupling, parts and radiation (rank 0); returns their names."""
    from fem_squeal.app import plots  # heavy: matplotlib (plots only)

    written = []
    if any("coupling" in r for r in rows):
        _csv(work / "cea_coupling.csv", ["mode", "freq_hz", "real_part", "unstable", "real_mode", "real_freq_hz",
                                          "participation_percent", "outside_share"],
             [[r["index"], r["freq_hz"], r["real_part"], r["unstable"], i, f, q, r["coupling"]["outside"]]
              for r in rows for i, f, q in zip(r["coupling"]["real_modes"], r["coupling"]["real_freqs_hz"],
                                               r["coupling"]["percent"])])
        written.append("cea_coupling.csv")
        if plots.coupling_matrix(work / "cea_coupling.png", rows, title):
            written.append("cea_coupling.png")
    if any("energy_shares" in r for r in rows):
        parts = list(next(r["energy_shares"] for r in rows if "energy_shares" in r))
        _csv(work / "cea_part_participation.csv", ["mode", "freq_hz", "real_part", "unstable", *parts],
             [[r["index"], r["freq_hz"], r["real_part"], r["unstable"],
               *(r["energy_shares"].get(p) for p in parts)] for r in rows if "energy_shares" in r])
        written.append("cea_part_participation.csv")
        if plots.part_participation(work / "cea_part_participation.png", rows, title):
            written.append("cea_part_participation.png")
    if any("erp_w" in r for r in rows):
        rank = {j: k + 1 for k, j in enumerate(res.get("cea_squeal_ranking", []))}
        _csv(work / "cea_radiation.csv", ["mode", "freq_hz", "real_part", "unstable", "erp_w", "erp_db",
                                           "squeal_index_db", "squeal_rank"],
             [[r["index"], r["freq_hz"], r["real_part"], r["unstable"], r["erp_w"], r["erp_db"],
               r["squeal_index_db"], rank.get(r["index"])] for r in rows])
        _csv(work / "cea_bands.csv", ["band_hz", "lower_hz", "upper_hz", "n_modes", "n_unstable", "max_level_db",
                                       "max_unstable_level_db", "max_squeal_index_db"],
             [[b[k] for k in ("band_hz", "lower_hz", "upper_hz", "n_modes", "n_unstable", "max_level_db",
                              "max_unstable_level_db", "max_squeal_index_db")] for b in res.get("cea_bands", [])])
        plots.erp_levels(work / "cea_erp.png", rows, res.get("cea_bands", []), title)
        written += ["cea_radiation.csv", "cea_bands.csv", "cea_erp.png"]
    return written


# -- report ----------------------------------------------------------------------------------------

def _coupling_text(c: dict) -> str:
    kind = f" ({c['pair_kind']})" if c.get("pair_kind") else ""
    return f"{c['label']}{kind}; outside {100 * c['outside']:.1f} %"


def _parts_text(shares: dict | None, n: int = 3) -> str:
    if not shares:
        return ""
    top = sorted(shares.items(), key=lambda kv: -kv[1])[:n]
    return ", ".join(f"{k} {100 * v:.0f} %" for k, v in top)


def report_html(res: dict) -> str:
    """The CEA report's NVH part: the unstable modes ranked by squeal index (or by growth rate without
    radiation), each with its coupling pair, parts and ERP; the 1/3-octave bands; the definitions."""
    cm = res.get("complex_modes", [])
    if not cm or not any("coupling" in c or "erp_db" in c for c in cm):
        return ""
    ranking = res.get("cea_squeal_ranking") or sorted((c["index"] for c in cm if c["unstable"]),
                                                     key=lambda j: -cm[j]["real_part"])
    rows = [[k + 1, cm[j]["index"], cm[j]["freq_hz"], cm[j]["real_part"], cm[j].get("erp_db"),
             cm[j].get("squeal_index_db"), _coupling_text(cm[j]["coupling"]) if "coupling" in cm[j] else "",
             _parts_text(cm[j].get("energy_shares"))] for k, j in enumerate(ranking)]
    html = ["<h3>Unstable modes ranked by the squeal index</h3>",
            _table(["rank", "#", "f [Hz]", "Re λ [1/s]", "ERP [dB re 1 pW]", "squeal index [dB]",
                    "coupling (real modes)", "parts (strain energy)"], rows)]
    rad, cp = res.get("cea_radiation"), res.get("cea_coupling")
    notes = []
    if cp:
        basis = _e(cp.get("basis", "")).split(" and M", 1)[0] or "real modes"
        notes.append(f"Coupling: the participation p_i = |c_i|²/Σ|c_j|² of the {basis} "
                     f"({cp['n_real_modes']} modes up to {cp['f_max_hz']:.0f} Hz, numbered from 0 by frequency) "
                     "in each complex mode, c = ΦᵀMx; 'outside' is the share 1 − Σ|c_j|²/x^HMx of the mode's "
                     "M-norm that these real modes do not represent.")
    if rad:
        notes.append(f"ERP = ½ρcσ∫|v_n|²dA over the outer surface ({rad['area_m2']:.4g} m², ρc = "
                     f"{rad['rho_c']:.4g} Pa·s/m), {_e(rad['norm'])}. Squeal index: {_e(rad['squeal_index'])}: "
                     "a ranking number, not a sound level.")
    html.append("".join(f"<p>{n}</p>" for n in notes))
    if rad and res.get("cea_bands"):
        bands = [[b["band_hz"], b["n_modes"], b["n_unstable"], b["max_level_db"], b["max_unstable_level_db"],
                  b["max_squeal_index_db"]] for b in res["cea_bands"] if b["n_modes"]]
        if bands:
            html += ["<h3>1/3-octave bands (1-16 kHz)</h3>",
                     _table(["band [Hz]", "modes", "unstable", "max ERP [dB]", "max ERP unstable [dB]",
                             "max squeal index [dB]"], bands)]
    return "".join(html)
