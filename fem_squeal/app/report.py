"""``report.html``: a self-contained summary of a scene run (the PNG plots are embedded as data URIs,
so the file can be mailed or archived on its own; it loads nothing from the network).

It opens with a summary of the complex modes (the unstable ones ranked, with thumbnails), one
section per drawn mode (its pictures, parts, coupling and radiated power where the results have
them) and an interactive 3-D view of the drawn modes (:mod:`fem_squeal.app.mode_report`,
:mod:`fem_squeal.app.viewer`); then the model and the stages (computed or cached, with their time),
the preload, the complex modes, the reduced model and its checks, the sweep's critical values, the
map, MASA's stationary amplitudes, the transient and its limit cycle, the segmented-pad regimes,
and every other plot of the output folder, each with a link to its data (the CSV next to it).
Every table sorts by a column when its header is clicked.  On load, a script writes the number of
images that decoded into ``data-images-loaded`` / ``data-images-total`` of ``<body>``, and the
number of script errors into ``data-script-errors`` (checked by the tests in headless Chromium).
"""
from __future__ import annotations

import base64
from pathlib import Path

from fem_squeal.app import mode_report
from fem_squeal.app.analyses import STAGES
from fem_squeal.app.html import escape as _e
from fem_squeal.app.html import link
from fem_squeal.app.html import table as _table
from fem_squeal.app.mode_shapes import NPZ, ModeShapes
from fem_squeal.app.viewer import viewer_html
from fem_squeal.util.atomic import write_atomic

CSS = """body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1.2em}td,th{border:1px solid #bbb;padding:2px 8px;font-size:90%}
th{background:#eee}tr.unstable td{background:#fde2e2}img{max-width:100%;border:1px solid #ddd}
figure{margin:1em 0}figcaption{font-size:85%;color:#555}code{background:#f4f4f4}
th{cursor:pointer}th.asc:after{content:" \\25B2"}th.desc:after{content:" \\25BC"}
img.thumb{max-width:140px;border:0}nav{font-size:90%;margin-bottom:1em}nav a{margin-right:0.8em}
section{border-top:1px solid #ddd;margin-top:1em}table.bars td{border:0}td.num{text-align:right}
span.bar{display:inline-block;height:0.8em;background:#4a7fb5}.note{color:#555;font-size:90%}
canvas{border:1px solid #ddd;touch-action:none;max-width:100%}"""

ONLOAD = """<script>var scriptErrors=0;window.addEventListener('error',function(){scriptErrors++;
if(document.body)document.body.setAttribute('data-script-errors',scriptErrors);});
window.addEventListener('load',function(){var im=document.images,n=0;
for(var i=0;i<im.length;i++){if(im[i].complete&&im[i].naturalWidth>0)n++;}
document.body.setAttribute('data-images-loaded',n);document.body.setAttribute('data-images-total',im.length);
document.body.setAttribute('data-script-errors',scriptErrors);});
</script>"""

#: click a header to sort its table by that column (numbers as numbers), again to reverse
SORT = """<script>function sortTable(th){var tr=th.parentNode,table=tr.closest('table'),
col=[].indexOf.call(tr.children,th),rows=[].slice.call(table.rows,1),dir=th.classList.contains('asc')?-1:1;
function key(r){var c=r.cells[col],t=c?c.textContent.trim():'',x=parseFloat(t);
return isNaN(x)||!/^[-+.\\d]/.test(t)?t.toLowerCase():x;}
rows.sort(function(a,b){var p=key(a),q=key(b);if(typeof p!==typeof q){p=typeof p;q=typeof q;}
return p<q?-dir:p>q?dir:0;});
[].forEach.call(tr.children,function(h){h.classList.remove('asc','desc');});th.classList.add(dir>0?'asc':'desc');
var body=rows.length?rows[0].parentNode:table;rows.forEach(function(r){body.appendChild(r);});}
document.addEventListener('click',function(ev){var th=ev.target.closest&&ev.target.closest('th');
if(th&&th.parentNode.parentNode.closest('table').rows[0]===th.parentNode)sortTable(th);});</script>"""


def _sections(res: dict) -> list[str]:
    """Each stage's part of the report, in the registry's order (its ``report`` function)."""
    return [html for st in STAGES.values() if st.report is not None and (html := st.report(res))]


def _figure(name: str, data: bytes, files: set[str]) -> str:
    """A plot with its caption and, when the output has it, the link to its CSV."""
    csv = name[:-4] + ".csv"
    data_link = f" (data: {link(csv, csv)})" if csv in files else ""
    return (f'<figure><img alt="{_e(name)}" src="data:image/png;base64,{base64.b64encode(data).decode()}">'
            f"<figcaption>{_e(name)}{data_link}</figcaption></figure>")


def render(res: dict, figures: list[tuple[str, bytes]], shapes: ModeShapes | None = None) -> str:
    """The report of results ``res`` with ``figures`` [(caption: the file name, PNG bytes)] and the
    drawn modes' surface data ``shapes`` (its 3-D view; None: none)."""
    title = res.get("scene", {}).get("title") or "fem_squeal run"
    files = set(res.get("files", []))
    stages = _table(["stage", "status", "seconds", "key"],
                    [[s["stage"], s["status"], s["seconds"], s["key"]] for s in res.get("stages", [])])
    pictures, thumbs, others = mode_report.mode_pictures(figures)
    summary = mode_report.summary(res, thumbs)
    modes = mode_report.sections(res, pictures, files)
    view = ""
    if shapes is not None and len(shapes.modes):
        by_index = {m["index"]: m for m in res.get("complex_modes", [])}
        labels = [f"mode {j}: {by_index[j]['freq_hz']:.0f} Hz" if j in by_index else f"mode {j}"
                  for j in shapes.modes.tolist()]
        view = '<h2 id="view">3-D view</h2>' + viewer_html(shapes, labels)
    figs = "".join(_figure(c, b, files) for c, b in others)
    body = "".join(_sections(res))
    nav = [(i, t) for i, t, html in (("summary", "Summary", summary), ("modes", "Modes", modes),
                                      ("view", "3-D view", view)) if html]
    nav += [("run", "Run and stages"), ("plots", "Plots")] if figs else [("run", "Run and stages")]
    links = "<nav>" + "".join(f'<a href="#{i}">{_e(t)}</a>' for i, t in nav) + "</nav>"
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{_e(title)}</title><style>{CSS}</style>"
            f"{ONLOAD}{SORT}</head><body><h1>{_e(title)}</h1>{links}{summary}{modes}{view}"
            f'<div id="run">{_run(res)}</div><h2>Stages</h2>{stages}{body}'
            f'<h2 id="plots">Plots</h2>{figs}</body></html>')


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
    where = (lambda f: (into / f) if (into / f).is_file() else (outdir / f)) if into is not None else \
        (lambda f: outdir / f)
    if into is None:
        figures = [(str(p.relative_to(outdir)), p.read_bytes()) for p in sorted(outdir.rglob("*.png"))]
        npz = outdir / NPZ if (outdir / NPZ).is_file() else None
    else:
        pngs = sorted(f for f in res.get("files", []) if f.endswith(".png"))
        figures = [(f, where(f).read_bytes()) for f in pngs]
        npz = where(NPZ) if NPZ in res.get("files", []) else None
    shapes = ModeShapes.load(npz) if npz is not None else None
    path = (into or outdir) / "report.html"
    write_atomic(path, lambda f: f.write(render(res, figures, shapes).encode()), "wb")
    return path
