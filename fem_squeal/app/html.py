"""Small HTML helpers of the report: escaping, numbers, tables."""
from __future__ import annotations

import html
from typing import Any


class Raw(str):
    """HTML written as it is into a table cell (a link), not escaped."""


def escape(x: Any) -> str:
    return html.escape(str(x))


def link(href: str, text: str) -> Raw:
    """``<a href>`` to an output file (relative to report.html)."""
    return Raw(f'<a href="{html.escape(href, quote=True)}">{escape(text)}</a>')


def num(x: Any, fmt: str = ".4g") -> str:
    if isinstance(x, Raw):
        return str(x)
    if isinstance(x, bool) or x is None:
        return escape(x)
    if isinstance(x, (int, float)):
        return format(x, fmt)
    return escape(x)


def table(head: list[str], rows: list[list[Any]], classes: list[str] | None = None) -> str:
    out = ["<table><tr>" + "".join(f"<th>{escape(h)}</th>" for h in head) + "</tr>"]
    for i, r in enumerate(rows):
        cls = f' class="{classes[i]}"' if classes and classes[i] else ""
        out.append(f"<tr{cls}>" + "".join(f"<td>{num(v)}</td>" for v in r) + "</tr>")
    return "".join(out) + "</table>"
