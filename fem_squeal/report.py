"""``report.html``: a self-contained summary of a scene run (the PNG plots are embedded as data URIs,
so the file can be mailed or archived on its own).

It shows the model and the stages (computed or cached, with their time), the preload, the unstable
complex modes, the reduced model and its checks, the sweep's critical values, the map, MASA's
stationary amplitudes, the transient and its limit cycle, the segmented-pad regimes, and every
plot of the output folder.  On load, a script writes the number of images that decoded into
``data-images-loaded`` / ``data-images-total`` of ``<body>`` (checked by the tests in headless
Chromium).
"""
from __future__ import annotations

import base64
import html
from pathlib import Path
from typing import Any

from fem_squeal.output import _write_atomic

CSS = """body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1.2em}td,th{border:1px solid #bbb;padding:2px 8px;font-size:90%}
th{background:#eee}tr.unstable td{background:#fde2e2}img{max-width:100%;border:1px solid #ddd}
figure{margin:1em 0}figcaption{font-size:85%;color:#555}code{background:#f4f4f4}"""

ONLOAD = """<script>window.addEventListener('load',function(){var im=document.images,n=0;
for(var i=0;i<im.length;i++){if(im[i].complete&&im[i].naturalWidth>0)n++;}
document.body.setAttribute('data-images-loaded',n);document.body.setAttribute('data-images-total',im.length);});
</script>"""


def _e(x: Any) -> str:
    return html.escape(str(x))


def _num(x: Any, fmt: str = ".4g") -> str:
    if isinstance(x, bool) or x is None:
        return _e(x)
    if isinstance(x, (int, float)):
        return format(x, fmt)
    return _e(x)


def _table(head: list[str], rows: list[list[Any]], classes: list[str] | None = None) -> str:
    out = ["<table><tr>" + "".join(f"<th>{_e(h)}</th>" for h in head) + "</tr>"]
    for i, r in enumerate(rows):
        cls = f' class="{classes[i]}"' if classes and classes[i] else ""
        out.append(f"<tr{cls}>" + "".join(f"<td>{_num(v)}</td>" for v in r) + "</tr>")
    return "".join(out) + "</table>"


def _sections(res: dict) -> list[str]:
    out = []
    if "model" in res:
        m = res["model"]
        out.append(f"<h2>Model</h2><p>{m['cells']} cells, {m['dofs']} DOFs (P{m['degree']}), "
                   f"{m['ranks']} rank(s)</p>")
    if res.get("preload", {}).get("interfaces"):
        rows = [[k, v["normal_force"], v["friction_force"], v["contact_area"] * 1e4, 100 * v["closed_share"],
                 v["peak_pressure"] / 1e6] for k, v in res["preload"]["interfaces"].items()]
        out.append("<h2>Preload</h2>" + _table(
            ["interface", "normal force [N]", "friction force [N]", "contact area [cm²]", "closed [%]",
             "peak pressure [MPa]"], rows))
    if "complex_modes" in res:
        cm = res["complex_modes"]
        rows = [[c["index"], c["freq_hz"], c["real_part"], c["damping_ratio"], c.get("nodal_diameter", ""),
                 c.get("travelling_direction", ""), c["residual"]] for c in cm]
        out.append(f"<h2>Complex eigenvalue analysis</h2><p><b>{res['n_unstable']}</b> unstable of {len(cm)} "
                   f"modes ({_e(res.get('cea_method', ''))}); unstable rows are shaded.</p>" + _table(
                       ["#", "f [Hz]", "Re λ [1/s]", "ζ", "nodal diameter", "travelling", "residual"], rows,
                       ["unstable" if c["unstable"] else "" for c in cm]))
    if "real_modes" in res:
        rows = [[i, r["freq_hz"], r["nodal_diameter"], r["in_plane_share"], r["residual"]]
                for i, r in enumerate(res["real_modes"])]
        out.append("<h2>Real modes</h2>" + _table(["#", "f [Hz]", "nodal diameter", "in-plane share",
                                                  "residual"], rows))
    if "reduced" in res:
        r = res["reduced"]
        txt = (f"<h2>Reduced model</h2><p>{r['size']} vectors, parameters {_e(r['parameters'])}, estimated "
               f"error {_num(r.get('estimated_error'))} (tol {_num(r['tol'])}), "
               f"converged {_e(r.get('converged'))}.</p>")
        if r.get("verification"):
            txt += _table(["point", "max rel. error", "unstable full", "unstable reduced"],
                          [[v["point"], v["max_rel_error"], v["n_unstable_full"], v["n_unstable_reduced"]]
                           for v in r["verification"]])
        out.append(txt)
    if "sweep" in res:
        s = res["sweep"]
        out.append(f"<h2>Sweep of {_e(s['parameter'])}</h2><p>{len(s['values'])} values, {s['solves']} reduced "
                   "solves.</p>" + _table(["value", "f [Hz]", "kind", "branches"],
                                          [[c["value"], c["freq_hz"], c["kind"], c.get("labels", "")]
                                           for c in s["critical"]]))
    if "map" in res:
        m = res["map"]
        out.append(f"<h2>Stability map</h2><p>{m['points']} points of (sign(v)μ, {_e(m['parameter'])}) in "
                   f"{_num(m['seconds'])} s; at most "
                   f"{_num(max(max(r) for r in m['total']) if m.get('total') else 0)} "
                   "unstable modes.</p>")
    if "masa" in res:
        rows = [[c["mu"], i["freq_hz"], i["real_part"],
                 ", ".join(f"{v:.3g}" for v in i["stationary_in_unit"]) or "–",
                 i["broke_at"]] for c in res["masa"]["cases"] for i in c["instabilities"]]
        out.append("<h2>MASA</h2>" + _table(["μ", "f [Hz]", "Re λ at 0 [1/s]", "stationary amplitudes",
                                            "sweep broke at"], rows))
    if "transient" in res:
        t = res["transient"]
        out.append(f"<h2>Transient</h2><p>{t['steps']} steps of {_num(t['dt'])} s on {t['basis']} vectors and "
                   f"{t['contact_elements']} contact elements in {_num(t['wall_s'])} s ({_num(t['ms_per_step'])} "
                   f"ms/step); energy balance {_num(t['energy_leak'])}; unstable at steady sliding: "
                   + (", ".join(f"{u['freq_hz']:.0f} Hz ({u['real_part']:.0f}/s)"
                                for u in t["steady_sliding_unstable"]) or "none") + "</p>")
    if "limit_cycle" in res:
        lc = res["limit_cycle"]
        c = lc["limit_cycle"]
        txt = (f"<h2>Limit cycle</h2><p>saturated: <b>{_e(c['saturated'])}</b>, {_num(c['frequency_hz'])} Hz, "
               f"amplitude {_num(c['amplitude'] * 1e6)} µm.</p>")
        txt += _table(["SVD shape", "energy share", "best CEA mode [Hz]", "share in its plane", "MAC"],
                      [[b["shape"], lc["svd_energy"][b["shape"] - 1], b["freq_hz"], b["plane_share"], b["mac"]]
                       for b in lc["svd_best_mac"]])
        if lc["energy_shares"]:
            txt += _table(["component", "strain-energy share"], [[k, v] for k, v in lc["energy_shares"].items()])
        if lc["mode_cycles"]:
            txt += _table(["α", "friction work [J]", "mean torque [N m]", "pseudo Re λ min", "max"],
                          [[m["alpha"], m["friction_work"], m["torque_mean"], m["pseudo_real_part_min"],
                            m["pseudo_real_part_max"]] for m in lc["mode_cycles"]])
        out.append(txt)
    if "segmented_pad" in res:
        rows = [[r["speed"] * 1e3, r["v_s"] * 1e3, r["v_d"] * 1e3, r["regime"], r["steps"]]
                for r in res["segmented_pad"]["runs"]]
        out.append("<h2>Segmented pad</h2>" + _table(["V [mm/s]", "v_s [mm/s]", "v_d [mm/s]", "regime", "steps"],
                                                     rows))
    return out


def render(res: dict, figures: list[tuple[str, bytes]]) -> str:
    """The report of results ``res`` with ``figures`` [(caption, PNG bytes)]."""
    title = res.get("scene", {}).get("title") or "fem_squeal run"
    stages = _table(["stage", "status", "seconds", "key"],
                    [[s["stage"], s["status"], s["seconds"], s["key"]] for s in res.get("stages", [])])
    figs = "".join(f'<figure><img alt="{_e(c)}" src="data:image/png;base64,{base64.b64encode(b).decode()}">'
                   f"<figcaption>{_e(c)}</figcaption></figure>" for c, b in figures)
    body = "".join(_sections(res))
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{_e(title)}</title><style>{CSS}</style>"
            f"{ONLOAD}</head><body><h1>{_e(title)}</h1><h2>Stages</h2>{stages}{body}<h2>Plots</h2>{figs}"
            "</body></html>")


def write_report(outdir: Path, res: dict) -> Path:
    """Write ``outdir/report.html`` atomically (rank 0) with every PNG under ``outdir``."""
    outdir = Path(outdir)
    figures = [(str(p.relative_to(outdir)), p.read_bytes()) for p in sorted(outdir.rglob("*.png"))]
    path = outdir / "report.html"
    _write_atomic(path, lambda f: f.write(render(res, figures).encode()), "wb")
    return path
