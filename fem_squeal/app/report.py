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
from pathlib import Path

from fem_squeal.app.analyses import STAGES
from fem_squeal.app.html import escape as _e
from fem_squeal.app.html import table as _table
from fem_squeal.util.atomic import write_atomic

CSS = """body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1.2em}td,th{border:1px solid #bbb;padding:2px 8px;font-size:90%}
th{background:#eee}tr.unstable td{background:#fde2e2}img{max-width:100%;border:1px solid #ddd}
figure{margin:1em 0}figcaption{font-size:85%;color:#555}code{background:#f4f4f4}"""

ONLOAD = """<script>window.addEventListener('load',function(){var im=document.images,n=0;
for(var i=0;i<im.length;i++){if(im[i].complete&&im[i].naturalWidth>0)n++;}
document.body.setAttribute('data-images-loaded',n);document.body.setAttribute('data-images-total',im.length);});
</script>"""


def _sections(res: dict) -> list[str]:
    """Each stage's part of the report, in the registry's order (its ``report`` function)."""
    return [html for st in STAGES.values() if st.report is not None and (html := st.report(res))]


def render(res: dict, figures: list[tuple[str, bytes]]) -> str:
    """The report of results ``res`` with ``figures`` [(caption, PNG bytes)]."""
    title = res.get("scene", {}).get("title") or "fem_squeal run"
    stages = _table(["stage", "status", "seconds", "key"],
                    [[s["stage"], s["status"], s["seconds"], s["key"]] for s in res.get("stages", [])])
    figs = "".join(f'<figure><img alt="{_e(c)}" src="data:image/png;base64,{base64.b64encode(b).decode()}">'
                   f"<figcaption>{_e(c)}</figcaption></figure>" for c, b in figures)
    body = "".join(_sections(res))
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{_e(title)}</title><style>{CSS}</style>"
            f"{ONLOAD}</head><body><h1>{_e(title)}</h1>{_run(res)}<h2>Stages</h2>{stages}{body}"
            f"<h2>Plots</h2>{figs}</body></html>")


def _run(res: dict) -> str:
    """What produced these results: scene file, --set overrides, code version, ranks, date."""
    run = res.get("run")
    if not run:
        return ""
    rows = [["scene file", run.get("scene_file") or "(given as data)"],
            ["overrides (--set)", "; ".join(run.get("overrides", [])) or "none"],
            ["fem_squeal", f"{run.get('version', '')} (code {run.get('code_version', '')})"],
            ["MPI ranks", run.get("ranks", "")], ["started", run.get("started", "")]]
    return "<h2>Run</h2>" + _table(["", ""], rows)


def write_report(outdir: Path, res: dict, into: Path | None = None) -> Path:
    """Write ``report.html`` atomically (rank 0) with every PNG under ``outdir``.  With ``into`` (the
    staging folder of a run, :func:`fem_squeal.app.outputs.staged_outputs`), the report is written
    there and its figures are the PNGs that ``res["files"]`` lists, taken from ``into`` where this run
    copied them and from ``outdir`` where they were already there."""
    outdir = Path(outdir)
    if into is None:
        figures = [(str(p.relative_to(outdir)), p.read_bytes()) for p in sorted(outdir.rglob("*.png"))]
    else:
        pngs = sorted(f for f in res.get("files", []) if f.endswith(".png"))
        figures = [(f, ((into / f) if (into / f).is_file() else (outdir / f)).read_bytes()) for f in pngs]
    path = (into or outdir) / "report.html"
    write_atomic(path, lambda f: f.write(render(res, figures).encode()), "wb")
    return path
