"""The scene reference of the user guide, rendered as Markdown from the schema in code.

Nothing here restates the schema: every table is produced by iterating the tables that the scene
loader checks against (:mod:`fem_squeal.app.scene`: ``GEOMETRY``, ``MATERIAL``, ``INTERFACES``,
``SECTIONS``, ``FIXED``, ``GROUND_SPRING``, ``PRESSURE``; the parts and faces of the gmsh builders
from :mod:`geometry.tags`) and the registry of analyses (:data:`fem_squeal.app.analyses.ANALYSES`:
each stage's section, doc, needs and cross-check).  A key added to the code appears in the guide at
its next build: ``docs/conf.py`` writes ``docs/reference/scene.md`` (not committed) with :func:`write`
before Sphinx reads the pages (``bash scripts/docs.sh``).  By hand::

    python -m fem_squeal.app.schema_reference docs/reference/scene.md

Importing this module imports the scene loader (and so the FE model description), not dolfinx.
"""
from __future__ import annotations

import inspect
import json
import math
import re
import sys
from pathlib import Path
from typing import Any

from fem_squeal.app import fields as F
from fem_squeal.app.analyses import ANALYSES, STAGES
from fem_squeal.app.fields import REAL, Field
from fem_squeal.app.scene import FIXED, GEOMETRY, GROUND_SPRING, INTERFACES, MATERIAL, PRESSURE, SECTIONS
from fem_squeal.app.scene.schema import MATRICES, MATRIX_FILE, MATRIX_PARAMETER
from geometry.tags import GEOMETRY_TAGS

#: the named checks of :mod:`fem_squeal.app.fields`, in words (checks built by a factory are read
#: from their closure below; any other check is a custom one, described by its error message)
_NAMED_CHECKS = {
    F.positive: "> 0",
    F.non_negative: "≥ 0",
    F.poisson: "in (−1, 0.5)",
    F.band: "[low, high] in Hz, 0 ≤ low < high",
    F.nonempty_str: "not empty",
}

#: Markdown code spans in the generated text (the code's docstrings write ``x`` and :role:`x`)
_ROLE = re.compile(r":(?:py:)?(?:func|class|mod|meth|data|attr|obj|exc):`~?([^`]+)`")


def _kind(kind: type | tuple[type, ...]) -> str:
    kinds = kind if isinstance(kind, tuple) else (kind,)
    if set(kinds) == set(REAL):
        return "real"
    names = {str: "string", int: "integer", float: "real", bool: "boolean", list: "array", dict: "table"}
    return " or ".join(names.get(k, k.__name__) for k in kinds)


def toml_value(v: Any) -> str:
    """``v`` as it is written in a scene file (TOML)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, float):
        if not math.isfinite(v):
            return str(v)
        s = repr(v)
        if "e" in s or len(s) > 10:       # 1e14, not 100000000000000.0; 1e-9, not 1e-09
            mant, exp = f"{v:.12e}".split("e")
            s = f"{mant.rstrip('0').rstrip('.')}e{int(exp)}"
        return s
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {toml_value(x)}" for k, x in v.items()) + "}"
    return repr(v)


def _default(f: Field) -> str:
    if f.default is ...:
        return "**required**"
    if f.default is None:
        return "unset"
    return f"`{toml_value(f.default)}`"


def describe_check(check) -> str:
    """A field's check in words: the named checks of :mod:`fem_squeal.app.fields`, the arguments of
    the factories (``one_of``, ``at_least``, ``increasing``) read from the closure, a named check's
    docstring, else 'custom'."""
    if check is None:
        return ""
    if check in _NAMED_CHECKS:
        return _NAMED_CHECKS[check]
    qual = getattr(check, "__qualname__", "")
    free = dict(zip(check.__code__.co_freevars, (c.cell_contents for c in check.__closure__ or ())))
    if qual.startswith("one_of.") and "choices" in free:
        return "one of " + ", ".join(f"`{toml_value(c)}`" for c in free["choices"])
    if qual.startswith("at_least.") and "n" in free:
        return f"≥ {free['n']}"
    if qual.startswith("increasing.") and "min_len" in free:
        low = free.get("low")
        text = f"increasing list of ≥ {free['min_len']} numbers"
        return text + (f", first > {low}" if low is not None else "")
    if check.__doc__:                   # a named custom check: its docstring's first sentence is the rule
        rule = _md(check.__doc__).split(". ")[0].rstrip(".")
        return rule[:1].lower() + rule[1:]
    return "custom check (its error names the rule)"


def _label(prefix: str, name: str) -> str:
    """The target label of a section of the page (``analyses-limit-cycle``): other pages link to it."""
    return f"{prefix}-{name.replace('_', '-')}"


def _codes(names, prefix: str = "") -> str:
    """``a``, ``b``: names as code spans, comma-separated."""
    return ", ".join(f"`{prefix}{n}`" for n in names)


def _ref(text: str, label: str) -> str:
    return f"{{ref}}`{text} <{label}>`"


def _cell(text: str) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def _md(text: str) -> str:
    """A code docstring as Markdown prose: roles become code spans, line breaks joined."""
    text = _ROLE.sub(lambda m: f"`{m.group(1)}`", inspect.cleandoc(text or ""))
    return text.replace("``", "`")


def field_table(fields: dict[str, Field], prefix: str = "") -> str:
    """A Markdown table of ``fields``: key, type, default, allowed values, description."""
    rows = ["| key | type | default | allowed | description |", "|---|---|---|---|---|"]
    for name, f in fields.items():
        rows.append(f"| `{prefix}{name}` | {_kind(f.kind)} | {_cell(_default(f))} | "
                    f"{_cell(describe_check(f.check))} | {_cell(_md(f.doc))} |")
    return "\n".join(rows) + "\n"


def _closure(name: str) -> list[str]:
    """The stages ``name`` needs, directly or through others, in registry (execution) order."""
    seen: set[str] = set()
    todo = [name]
    while todo:
        for dep in STAGES[todo.pop()].needs:
            if dep not in seen:
                seen.add(dep)
                todo.append(dep)
    return [n for n in STAGES if n in seen]


def _analysis(name: str) -> str:
    st = ANALYSES[name]
    doc = _md(st.doc)
    out = [f"### `analyses.{name}`\n", f"{doc[:1].upper()}{doc[1:]}.\n"]
    needs = ", ".join(f"`analyses.{d}`" if d in ANALYSES else f"`{d}`" for d in st.needs) or "nothing"
    before = _closure(name)
    if before and list(st.needs) != before:
        needs += f" (with everything before: {_codes(before)})"
    out.append(f"- **needs:** {needs}")
    if st.lumped:
        model = [s for s in ("geometry", "materials", "interfaces", *SECTIONS) if s != "solver"]
        out.append("- **lumped:** needs no finite-element model; a scene with only lumped analyses has none "
                   f"of {_codes(model)}")
    if st.pulled:
        users = [n for n in ANALYSES if name in STAGES[n].needs]
        out.append(f"- **pulled in** with its defaults by {_codes(users, 'analyses.')} "
                   f"when the scene does not give `[analyses.{name}]`")
    needed_by = [n for n in ANALYSES if name in STAGES[n].needs and not st.pulled]
    if needed_by:
        out.append(f"- **needed by** {_codes(needed_by, 'analyses.')} (the scene must give "
                   f"`[analyses.{name}]` with them)")
    module = sys.modules.get(st.run.__module__)
    if module is not None and module.__doc__:
        out.append(f"- **what it does:** {_cell(_md(module.__doc__))}")
    if st.check is not None and st.check.__doc__:
        out.append(f"- **cross-checks:** {_cell(_md(st.check.__doc__))}")
    out.append("")
    out.append(field_table(st.section, f"analyses.{name}."))
    return "\n".join(out)


def _faces_and_parts(builder: str) -> str:
    if builder not in GEOMETRY_TAGS:
        return ("Parts and faces are the scene's own: the keys of `geometry.parts` and `geometry.faces` "
                "(each mapped to sets of the file).\n")
    volumes, faces = GEOMETRY_TAGS[builder]
    return (f"Parts (for `materials.<part>`): {_codes(volumes)}.  \n"
            f"Faces (for interfaces, boundary conditions and loads): {_codes(faces)}.\n")


def render_scene_reference() -> str:
    """The whole scene reference (Markdown, MyST) from the schema tables and the analysis registry."""
    out = ["# Scene reference\n",
           "```{note}\nThis page is generated at build time by `fem_squeal.app.schema_reference` from the "
           "tables the scene loader checks against (`fem_squeal.app.scene`) and from the registry of "
           "analyses (`fem_squeal.app.analyses.ANALYSES`), so it lists exactly the keys the code accepts.\n```\n",
           "A scene is a TOML file.  Its top-level keys: `title` (free text), `extends` (another scene file, "
           "relative to this one, whose tables this one's are merged onto), "
           + ", ".join(_ref(s, s) for s in ("geometry", "materials", "interfaces", *SECTIONS))
           + " and " + _ref("analyses", "analyses") + "; or, for a model given as matrices, "
           + _ref("matrices", "matrices") + " in place of the model sections.  "
           "Each table is checked against the fields below: an unknown key, a wrong type, a non-finite "
           "number or a value outside *allowed* stops the run before anything is computed, with one line "
           "naming the key path (`analyses.sweep.n: must be >= 2 (got 1)`).  *Required* fields have no "
           "default; *unset* fields are optional and have no value unless given.  Every key can be "
           "overridden on the command line with `--set key.path=value` (the value is parsed as TOML).\n",
           "Units are SI: lengths in m, moduli and pressures in Pa, penalty stiffnesses per area in N/m³, "
           "frequencies in Hz.\n",
           "(geometry)=\n## `geometry`\n",
           "`geometry.builder` chooses the table: "
           + ", ".join(_ref(b, _label("geometry-builder", b)) for b in GEOMETRY) + ".\n"]
    for builder, flds in GEOMETRY.items():
        out.append(f"({_label('geometry-builder', builder)})=\n"
                   f"### `geometry.builder = \"{builder}\"`\n")
        out.append(_faces_and_parts(builder))
        out.append(field_table({k: f for k, f in flds.items() if k != "builder"}, "geometry."))
    out.append("(materials)=\n## `materials.<part>`\n\n"
               "One table per part of the geometry (every part needs one).\n")
    out.append(field_table(MATERIAL))
    type_default = next(iter(INTERFACES.values()))["type"].default
    out.append("(interfaces)=\n## `interfaces.<name>`\n\n`type` chooses the table: "
               + _codes(INTERFACES) + f" (default `{toml_value(type_default)}`).  "
               "Face names are those of the geometry.\n")
    for kind, flds in INTERFACES.items():
        out.append(f"### `type = \"{kind}\"`\n")
        out.append(field_table({k: f for k, f in flds.items() if k != "type"}))
    subtables = {("boundary", "fixed"): FIXED, ("boundary", "ground_springs"): GROUND_SPRING,
                 ("loads", "pressure"): PRESSURE}
    for sec, flds in SECTIONS.items():
        out.append(f"({sec})=\n## `{sec}`\n")
        out.append(field_table(flds, f"{sec}."))
        for (s, sub), sf in subtables.items():
            if s == sec and sub in flds:
                out.append(f"### `{sec}.{sub}.<name>`\n")
                out.append(field_table(sf))
    on_matrices = [n for n, st in ANALYSES.items() if st.on_matrices is not None]
    out.append("(matrices)=\n## `matrices`\n\nA model given as matrices (`fem_squeal.app.scene.matrices`): the "
               "operators of λ²M + λC + K as expressions of named matrix files and parameters.  A scene with "
               "`[matrices]` has no `geometry`, `materials`, `interfaces`, `boundary`, `loads`, `preload`, "
               "`discretisation` or `operating`; its analyses (" + _codes(on_matrices, "analyses.")
               + ") start from the `matrices` stage.  Expressions: numbers, the named matrices and parameters, "
               "`pi`, `+ - * / **` and `sqrt exp log sin cos` of parameters, linear in the matrices; anything "
               "else is refused by name.\n")
    out.append(field_table(MATRICES, "matrices."))
    out.append("### `matrices.files.<name>`\n\nA string is the file alone.\n")
    out.append(field_table(MATRIX_FILE))
    out.append("### `matrices.parameters.<name>`\n\nA number is the value alone.\n")
    out.append(field_table(MATRIX_PARAMETER))
    for name, st in ANALYSES.items():
        if st.section_on_matrices is not None:
            out.append(f"### `analyses.{name}` on a model given as matrices\n\nIn place of the section below "
                       f"(`{st.on_matrices.__module__}`).\n")
            out.append(field_table(st.section_on_matrices, f"analyses.{name}."))
    out.append("(analyses)=\n## `analyses`\n")
    out.append("One table `[analyses.<name>]` per analysis the scene asks for (at least one).  The pipeline "
               "runs the stages they need, in this order, and caches each under a hash of what it reads.\n")
    out.append("| stage | needs | what it is |\n|---|---|---|")
    for name, st in STAGES.items():
        label = (_ref(f"analyses.{name}", _label("analyses", name)) if name in ANALYSES
                 else f"`{name}` (model stage)")
        out.append(f"| {label} | {_codes(st.needs) or '—'} | {_cell(_md(st.doc))} |")
    out.append("")
    for name in ANALYSES:
        out.append(f"({_label('analyses', name)})=")
        out.append(_analysis(name))
    return "\n".join(out).rstrip() + "\n"


def write(path: str | Path) -> Path:
    """Write the reference to ``path`` (folders created); rewrites only when the text changed."""
    path = Path(path)
    text = render_scene_reference()
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.exists() or path.read_text(encoding="utf-8") != text:
        path.write_text(text, encoding="utf-8")
    return path


if __name__ == "__main__":
    target = sys.argv[1] if len(sys.argv) > 1 else "docs/reference/scene.md"
    print(write(target))
