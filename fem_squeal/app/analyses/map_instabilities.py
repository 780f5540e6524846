"""A stability map's instabilities as the engineer reads them (issue 38): each region of the map where one
mode is unstable (:func:`fem_squeal.reduced.stability_map.instabilities`), with the real modes that couple
in it where it grows fastest, as a table in the report, stability_map_instabilities.csv and, for a map of
two axes, stability_map_coupling.png.  Shared by the map of the FE model (:mod:`.stability_map`) and of a
model given as matrices (:mod:`.matrix_studies`)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from fem_squeal.app import plots
from fem_squeal.app.html import table as _table
from fem_squeal.app.stage import Context
from fem_squeal.reduced.stability_map import Instability, instabilities, instability_couplings
from fem_squeal.reduced.sweep import SweepResult
from fem_squeal.util.atomic import columns_of, write_csv_atomic


def label(x: Instability) -> str:
    """"7.51–7.62 kHz: real modes 43 (48 %) and 44 (41 %)" for an instability (no coupling: its band only)."""
    f = f"{x.freq_hz[0] / 1e3:.2f}–{x.freq_hz[1] / 1e3:.2f} kHz"
    return f + (f": {x.coupling['label']}" if x.coupling else "")


def masks(found: list[Instability], shape: tuple[int, ...]) -> np.ndarray:
    """The instabilities' masks stacked: (len(found),) + the grid's shape (stability_map.npz)."""
    return np.array([x.mask for x in found], bool).reshape((len(found), *shape))


def map_instabilities(ctx: Context, work: Path, model, res: SweepResult, band: tuple[float, float], gt: float,
                      labels: tuple[str, str], scale: float = 1.0, couple: bool = True) -> list[Instability]:
    """The instabilities of the map ``res`` (:func:`~fem_squeal.reduced.stability_map.instabilities`), each
    with its coupling where it grows fastest (``couple``: a :class:`~fem_squeal.reduced.model.ReducedModel`
    with real modes in its basis); on rank 0 stability_map_instabilities.csv and, for a map of two
    axes (the first drawn as y, × ``scale``; ``labels`` = (x, y)), stability_map_coupling.png.  The same on
    every rank: every rank holds the whole map."""
    found = instabilities(res, band, gt)
    if couple:
        instability_couplings(model, found)
    if ctx.comm.rank == 0:
        names = list(res.grid.axes)
        head = ["instability", "f_min_hz", "f_max_hz", "points", "share", "max_growth_rate",
                *[f"at_{n}" for n in names], *[f"{n}_{e}" for n in names for e in ("min", "max")], "coupling",
                "real_freqs_hz"]
        rows = [[k + 1, *x.freq_hz, x.points, x.points / x.mask.size, x.max_growth_rate, *x.at.values(),
                 *[v for r in x.ranges.values() for v in r], x.coupling["label"] if x.coupling else "",
                 " ".join(f"{f:.6g}" for f in x.coupling["real_freqs_hz"][:2]) if x.coupling else ""]
                for k, x in enumerate(found)]
        write_csv_atomic(work / "stability_map_instabilities.csv", head, columns_of(rows, len(head)))
        if len(names) == 2:
            plots.map_instabilities(work / "stability_map_coupling.png", res.grid.axes[names[1]],
                                    res.grid.axes[names[0]] * scale, [(x.growth, label(x)) for x in found],
                                    *labels, ctx.scene.title)
    return found


def instabilities_html(found: list[dict], top: int = 12) -> str:
    """The report's table of a map's instabilities (results.json ``map.instabilities``), fastest first."""
    if not found:
        return ""
    rows = [[k + 1, f"{x['freq_hz'][0]:.0f}–{x['freq_hz'][1]:.0f}", x["points"], f"{100 * x['share']:.1f} %",
             x["max_growth_rate"], ", ".join(f"{n} = {v:.4g}" for n, v in x["at"].items()),
             "; ".join(f"{n} {a:.4g}…{b:.4g}" for n, (a, b) in x["ranges"].items()),
             x["coupling"]["label"] if "coupling" in x else ""] for k, x in enumerate(found[:top])]
    more = f" The first {top} of {len(found)}; all in stability_map_instabilities.csv." if len(found) > top else ""
    return ("<h3>Instabilities of the map</h3><p>Each region of the map where one mode is unstable (its "
            "eigenvalues linked from point to neighbouring point), fastest-growing first, with the real modes "
            "of the basis that make it up where it grows fastest (stability_map_coupling.png)." + more + "</p>"
            + _table(["#", "f [Hz]", "points", "share of the map", "max Re λ [1/s]", "at", "ranges",
                      "coupling (real modes)"], rows))
