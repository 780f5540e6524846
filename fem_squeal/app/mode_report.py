"""The report's engineer-first part: a summary of the complex modes that matter (the unstable ones
ranked, with thumbnails), then one section per drawn mode (its pictures and, when the results
carry them, its part participation, mode coupling and radiated power), then the 3-D view.

Ranking: by the squeal index where every unstable mode has one (``squeal_index_db``,
:mod:`fem_squeal.reduced.squeal_index`: the larger the louder), else by the growth rate Re λ.
Blocks are shown only when their keys are present and not empty: no empty boxes.  The pictures
and the 3-D view come from the CEA's ``mode_shapes`` files (:mod:`fem_squeal.app.mode_shapes`),
published with the field files: with ``--no-fields`` the sections say so and show the rest."""
from __future__ import annotations

import base64
from typing import Any

from fem_squeal.app.html import Raw, link, num
from fem_squeal.app.html import escape as _e
from fem_squeal.app.html import table as _table
from fem_squeal.app.mode_shapes import FOLDER

#: summary columns read when present: (key, header)
EXTRA_COLUMNS = (("squeal_index_db", "squeal index [dB]"), ("erp_db", "ERP [dB re 1 pW]"))
#: the squeal index of a complex mode (fem_squeal.app.nvh; "squeal_index" read too)
INDEX_KEYS = ("squeal_index_db", "squeal_index")


def _index(m: dict) -> float | None:
    v = next((m[k] for k in INDEX_KEYS if isinstance(m.get(k), (int, float))), None)
    return float(v) if v is not None else None


def _png(data: bytes, alt: str, cls: str = "") -> str:
    c = f' class="{cls}"' if cls else ""
    return f'<img{c} alt="{_e(alt)}" src="data:image/png;base64,{base64.b64encode(data).decode()}">'


def ranked(modes: list[dict]) -> list[dict]:
    """The unstable modes, loudest first: by ``squeal_index`` where every one has it, else by Re λ."""
    bad = [m for m in modes if m.get("unstable")]
    if bad and all(_index(m) is not None for m in bad):
        return sorted(bad, key=lambda m: -_index(m))
    return sorted(bad, key=lambda m: -m["real_part"])


def _label(m: dict) -> str:
    return f"mode {m['index']}: {m['freq_hz']:.0f} Hz, Re λ = {m['real_part']:.3g} 1/s"


def _with_sections(res: dict) -> list[int]:
    """The modes that have a section: those drawn, or the unstable ones when none was drawn."""
    modes = res.get("complex_modes") or []
    indices = {m["index"] for m in modes}
    drawn = [j for j in (res.get("mode_shapes") or {}).get("modes", []) if j in indices]
    return drawn or [m["index"] for m in ranked(modes)]


def summary(res: dict, thumbs: dict[int, bytes]) -> str:
    """The summary section: counts, and the unstable modes ranked with their thumbnails."""
    modes = res.get("complex_modes")
    if not modes:
        return ""
    top = ranked(modes)
    linked = set(_with_sections(res))
    lo, hi = res.get("scene", {}).get("analyses", {}).get("cea", {}).get("band_hz", [None, None])
    band = f" in {lo:g}–{hi:g} Hz" if lo is not None else ""
    by = "squeal index" if top and _index(top[0]) is not None and all(_index(m) is not None for m in top) \
        else "growth rate Re λ"
    if not top:
        drawn = res.get("mode_shapes", {}).get("modes", [])
        text = (f"<p>No unstable mode among the {len(modes)} complex modes{band}."
                + (f" The first {len(drawn)} are drawn below." if drawn and thumbs else "") + "</p>")
        return f'<h2 id="summary">Summary</h2>{text}'
    extra = [(k, h) for k, h in EXTRA_COLUMNS if any(k in m for m in top)]
    head = ["rank", "mode", "f [Hz]", "Re λ [1/s]", "ζ", *[h for _, h in extra], "nodal diameter", "shape"]
    rows = []
    for r, m in enumerate(top, 1):
        j = m["index"]
        shape = Raw(f'<a href="#mode-{j}">{_png(thumbs[j], _label(m), "thumb")}</a>') if j in thumbs else \
            link(f"#mode-{j}", "section") if j in linked else "not drawn"
        rows.append([r, link(f"#mode-{j}", str(j)) if j in linked else j, m["freq_hz"], m["real_part"],
                     m["damping_ratio"],
                     *[m.get(k, "") for k, _ in extra], m.get("nodal_diameter", ""), shape])
    return (f'<h2 id="summary">Summary</h2><p><b>{len(top)}</b> unstable of {len(modes)} complex modes{band}, '
            f"ranked by {by} (most critical first).</p>" + _table(head, rows))


def _bars(shares: dict[str, float]) -> str:
    """A part-participation block: one bar per part, largest first."""
    items = sorted(((k, float(v)) for k, v in shares.items() if isinstance(v, (int, float))),
                   key=lambda kv: -kv[1])
    if not items:
        return ""
    rows = "".join(f'<tr><td>{_e(k)}</td><td class="num">{100 * v:.1f} %</td><td><span class="bar" '
                   f'style="width:{max(0.0, min(1.0, v)) * 240:.0f}px"></span></td></tr>' for k, v in items)
    return f'<h4>Parts (strain-energy shares)</h4><table class="bars">{rows}</table>'


def _generic(value: Any) -> str:
    """A block's value as HTML: a number, a text, a {name: value} table or a table of records."""
    if isinstance(value, (int, float, str)):
        return f"<p>{num(value)}</p>"
    if isinstance(value, dict):
        items = [[k, v] for k, v in value.items() if not isinstance(v, (dict, list))]
        return _table(["", ""], items) if items else ""
    if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        keys = list(dict.fromkeys(k for v in value for k in v if not isinstance(v[k], (dict, list))))
        return _table(keys, [[v.get(k, "") for k in keys] for v in value]) if keys else ""
    if isinstance(value, list) and value:
        return f"<p>{', '.join(num(v) for v in value)}</p>"
    return ""


def _coupling(c: Any) -> str:
    """The coupling block of :func:`fem_squeal.app.nvh` (``coupling``: label, pair kind, outside share,
    the real modes with their frequencies and percentages); anything else generically."""
    if not (isinstance(c, dict) and "label" in c and "real_modes" in c):
        return _generic(c)
    kind = f" ({_e(c['pair_kind'])})" if c.get("pair_kind") else ""
    head = f"<p>{_e(c['label'])}{kind}; outside the real modes {100 * float(c.get('outside', 0.0)):.2g} %</p>"
    rows = [[i, f, q] for i, f, q in zip(c["real_modes"], c.get("real_freqs_hz", []), c.get("percent", []))]
    return head + _table(["real mode", "f [Hz]", "participation [%]"], rows)


def _radiation(m: dict) -> str:
    rows = [[h, m[k]] for k, h in (("erp_db", "ERP [dB re 1 pW]"), ("erp_w", "ERP [W]"),
                                    ("squeal_index_db", "squeal index [dB]")) if m.get(k) is not None]
    return _table(["", ""], rows) if rows else ""


def _blocks(m: dict) -> str:
    """Part shares, coupling and radiated sound of a complex mode, each only when present."""
    out = [_bars(m["energy_shares"])] if m.get("energy_shares") else []
    if m.get("coupling") and (html := _coupling(m["coupling"])):
        out.append(f"<h4>Mode coupling (participation of the real modes)</h4>{html}")
    if (html := _radiation(m)):
        out.append(f"<h4>Radiated sound (equivalent radiated power)</h4>{html}")
    return "".join(out)


def sections(res: dict, pictures: dict[int, bytes], files: set[str]) -> str:
    """One section per drawn mode (or per unstable mode when nothing was drawn)."""
    modes = res.get("complex_modes")
    if not modes:
        return ""
    by_index = {m["index"]: m for m in modes}
    order = _with_sections(res)
    note = ""
    if (res.get("mode_shapes") or {}).get("modes") and not pictures:
        note = ("<p class='note'>The mode pictures and the 3-D view are published with the field files "
                "(this run was made with <code>--no-fields</code>).</p>")
    out = []
    for j in order:
        m = by_index[j]
        parts = [f'<section id="mode-{j}"><h3>{_e(_label(m))}'
                 + (" — unstable" if m.get("unstable") else "") + "</h3>"]
        facts = [f"ζ = {m['damping_ratio']:.3g}"]
        if m.get("nodal_diameter") not in (None, ""):
            facts.append(f"nodal diameter {m['nodal_diameter']}")
        if m.get("travelling_direction"):
            facts.append(f"travelling {_e(m['travelling_direction'])}")
        parts.append(f"<p>{', '.join(facts)}</p>")
        if j in pictures:
            csv = [f for f in (f"{FOLDER}/surface_points.csv", f"{FOLDER}/surface_triangles.csv",
                               f"{FOLDER}/mode_{j}_points.csv", f"{FOLDER}/mode_{j}_triangles.csv") if f in files]
            data = " Data: " + ", ".join(str(link(f, f.split("/")[-1])) for f in csv) + "." if csv else ""
            parts.append(f"<figure>{_png(pictures[j], _label(m))}<figcaption>Real and imaginary parts along the "
                         f"axis and obliquely; colour: normal displacement.{data}</figcaption></figure>")
        parts.append(_blocks(m))
        out.append("".join(parts) + "</section>")
    if not out:
        return ""
    return '<h2 id="modes">Modes</h2>' + note + "".join(out)


def mode_pictures(figures: list[tuple[str, bytes]]) -> tuple[dict[int, bytes], dict[int, bytes], list]:
    """Split the report's PNGs into the mode pictures {j: bytes}, the thumbnails {j: bytes} and the
    other figures."""
    pictures, thumbs, rest = {}, {}, []
    for name, data in figures:
        stem = name[len(FOLDER) + 1:-4] if name.startswith(FOLDER + "/") and name.endswith(".png") else None
        if stem and stem.startswith("mode_"):
            j = stem[5:]
            if j.endswith("_thumb") and j[:-6].isdigit():
                thumbs[int(j[:-6])] = data
                continue
            if j.isdigit():
                pictures[int(j)] = data
                continue
        rest.append((name, data))
    return pictures, thumbs, rest

