"""Abaqus input decks (``.inp``): nodes, solid elements, sets and surfaces, read line by line.

What a flat deck holds for a modal model is read; what changes the model and is not supported is an
error naming the keyword and its line; the rest (materials, sections, steps, loads) is left to the
scene and ignored.

- ``*INCLUDE, INPUT=file`` is followed (relative to the including file), to any depth.
- ``*NODE`` (several blocks), ``*ELEMENT`` of solid types C3D4*, C3D10*, C3D8*, C3D20*, C3D27*,
  C3D6*, C3D15*, C3D5*, C3D13* and the surface elements SFM3D3/4/6/8 (skins that name faces).
- ``*ELSET``/``*NSET`` (``GENERATE``, members by number or set name, one set over several blocks,
  ``*NSET, ELSET=``), ``ELSET=`` on ``*ELEMENT`` and ``NSET=`` on ``*NODE``.
- ``*SURFACE, TYPE=ELEMENT`` (element or element set, face label S1..S6) and ``TYPE=NODE`` (node or
  node set; read as a node set).
- Errors: assemblies (``*PART``/``*INSTANCE``/``*ASSEMBLY``), structural elements (shells,
  membranes, beams, trusses, springs, masses, connectors, rigid elements, ...), and
  :data:`MODEL_CHANGING` keywords (orientations, transforms, local systems, constraints).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: Abaqus element type prefix -> meshio type (VTK node order after :data:`PERMUTATION`).
SOLIDS = [("C3D10", "tetra10"), ("C3D4", "tetra"), ("C3D20", "hexahedron20"), ("C3D27", "hexahedron27"),
          ("C3D8", "hexahedron"), ("C3D15", "wedge15"), ("C3D6", "wedge"), ("C3D13", "pyramid13"),
          ("C3D5", "pyramid")]
#: Surface elements (no stiffness): skins whose element sets name faces.
SKINS = {"SFM3D3": "triangle", "SFM3D4": "quad", "SFM3D4R": "quad", "SFM3D6": "triangle6", "SFM3D8": "quad8",
         "SFM3D8R": "quad8"}
#: Abaqus node order -> VTK: C3D27 face nodes are S1..S6 (-z, +z, -y, +x, +y, -x), VTK's -x, +x, -y, +y, -z, +z.
PERMUTATION = {"hexahedron27": list(range(20)) + [25, 23, 22, 24, 20, 21, 26]}
NODES = {"tetra": 4, "tetra10": 10, "hexahedron": 8, "hexahedron20": 20, "hexahedron27": 27, "wedge": 6,
         "wedge15": 15, "pyramid": 5, "pyramid13": 13, "triangle": 3, "quad": 4, "triangle6": 6, "quad8": 8}
#: Element families that are structural (they add stiffness or mass this reader cannot represent).
STRUCTURAL = [("S", "shell"), ("M3D", "membrane"), ("B", "beam"), ("PIPE", "pipe"), ("T2D", "truss"),
              ("T3D", "truss"), ("SPRING", "spring"), ("DASHPOT", "dashpot"), ("MASS", "point mass"),
              ("ROTARYI", "rotary inertia"), ("CONN", "connector"), ("R3D", "rigid"), ("R2D", "rigid"),
              ("RB3D", "rigid"), ("GK", "gasket"), ("COH", "cohesive"), ("CAX", "axisymmetric"),
              ("CPE", "plane strain"), ("CPS", "plane stress"), ("SC", "continuum shell"), ("DC", "heat transfer")]
#: Keywords that change the model and are not supported: keyword -> what it does.
MODEL_CHANGING = {
    "ORIENTATION": "a local material orientation", "TRANSFORM": "a nodal transformation (local directions)",
    "SYSTEM": "a local coordinate system for nodes", "NMAP": "a mapping of nodal coordinates",
    "MPC": "multi-point constraints", "TIE": "a tie constraint", "EQUATION": "linear constraint equations",
    "COUPLING": "a coupling constraint", "KINEMATIC COUPLING": "a coupling constraint",
    "DISTRIBUTING COUPLING": "a coupling constraint", "RIGID BODY": "a rigid body", "SHELL SECTION": "shells",
    "BEAM SECTION": "beams", "MEMBRANE SECTION": "membranes", "SHELL TO SOLID COUPLING": "a coupling constraint",
    "EMBEDDED ELEMENT": "embedded elements", "NODE TRANSFORM": "a nodal transformation",
}
#: The :data:`MODEL_CHANGING` keywords that the deck translation (:mod:`geometry.abaqus_model`) supports.
MODEL_KEYWORDS = {"TIE", "ORIENTATION"}
ASSEMBLY = {"PART", "END PART", "INSTANCE", "END INSTANCE", "ASSEMBLY", "END ASSEMBLY"}


class AbaqusError(ValueError):
    """An input deck that cannot be used; the message names the file, the line and the keyword."""


class AbaqusSyntaxError(AbaqusError):
    """Data lines that cannot be read (bad numbers, incomplete elements, undefined nodes or sets)."""


@dataclass
class Deck:
    """The mesh of a flat deck: nodes, element blocks (VTK order, node indices) and sets."""

    node_ids: np.ndarray
    points: np.ndarray
    blocks: list = field(default_factory=list)          # (meshio type, connectivity, element numbers)
    element_types: list = field(default_factory=list)   # the deck's TYPE of each block (upper case: C3D20R)
    elsets: dict = field(default_factory=dict)          # name -> element numbers (file order, unique)
    nsets: dict = field(default_factory=dict)           # name -> node numbers
    surfaces: dict = field(default_factory=dict)        # name -> [(element number, label, where)]
    node_surfaces: dict = field(default_factory=dict)   # name -> node numbers (TYPE=NODE)
    names: dict = field(default_factory=dict)           # upper-case set name -> name as first written


_KEYWORD = re.compile(r"^\s*\*\s*([A-Za-z][A-Za-z ]*?)\s*(,|$)")


def _lines(path: Path, stack=()):
    """(file name, line number, text) of the deck with ``*INCLUDE`` expanded."""
    if path in stack:
        raise AbaqusError(f"{stack[-1].name}: *INCLUDE of {path.name} includes itself")
    with open(path, errors="replace") as f:
        for no, line in enumerate(f, 1):
            if line.startswith("**"):
                continue
            m = _KEYWORD.match(line)
            if m and m.group(1).strip().upper() == "INCLUDE":
                params = _params(line)
                name = params.get("INPUT", "").strip().strip('"')
                target = (path.parent / name) if name else None
                if target is None or not target.is_file():
                    raise AbaqusError(f"{path.name} line {no}: *INCLUDE, INPUT={name}: no such file "
                                      f"(looked in {path.parent})")
                yield from _lines(target, (*stack, path))
                continue
            yield path.name, no, line


def _params(line: str) -> dict[str, str]:
    out = {}
    for item in line.split(",")[1:]:
        k, _, v = item.partition("=")
        if k.strip():
            out[k.strip().upper()] = v.strip()
    return out


def _blocks(path: Path):
    """(keyword, parameters, [(data line, where)], where) of each keyword block."""
    block = None
    for fname, no, line in _lines(path):
        m = _KEYWORD.match(line)
        if m:
            if block:
                yield block
            block = (" ".join(m.group(1).upper().split()), _params(line), [], f"{fname} line {no}")
        elif block is not None and line.strip():
            block[2].append((line, f"{fname} line {no}"))
    if block:
        yield block


def _ints(lines, where: str) -> list[int]:
    try:
        return [int(v) for ln, _ in lines for v in ln.replace(",", " ").split()]
    except ValueError as e:
        raise AbaqusSyntaxError(f"{where}: {e}") from None


def _members(lines, params: dict, table: dict, kind: str, where: str) -> list[int]:
    items = [(v.strip(), w) for ln, w in lines for v in ln.split(",") if v.strip()]
    if "GENERATE" in params:
        out = []
        for ln, w in lines:
            vals = [v.strip() for v in ln.split(",") if v.strip()]
            try:
                a, b, *s = (int(v) for v in vals)
            except ValueError:
                raise AbaqusSyntaxError(f"{w}: GENERATE needs first, last[, increment]") from None
            out += list(range(a, b + 1, s[0] if s else 1))
        return out
    out = []
    for it, w in items:
        if it.lstrip("-").isdigit():
            out.append(int(it))
        elif it.upper() in table:
            out += table[it.upper()]
        else:
            raise AbaqusSyntaxError(f"{w}: unknown {kind} set {it!r}")
    return out


def read_deck(path: str | Path, model: bool = False) -> Deck:
    """Read a flat deck (see the module text); raises :class:`AbaqusError`.  ``model``: the deck's model
    keywords are translated elsewhere (:mod:`geometry.abaqus_model`), so the ones it supports
    (:data:`MODEL_KEYWORDS`: ``*TIE``, ``*ORIENTATION``) are skipped here instead of refused."""
    path = Path(path)
    node_ids: list[int] = []
    coords: list[list[float]] = []
    raw_blocks: list = []                                   # (type, flat ints, where, TYPE)
    elsets: dict[str, list[int]] = {}
    nsets: dict[str, list[int]] = {}
    surfaces: dict[str, list] = {}
    node_surfaces: dict[str, list] = {}
    names: dict[str, str] = {}
    pending_nset_elsets = []                                # (*NSET name, ELSET names, where)
    nodes_seen = 0

    def name_of(raw: str) -> str:
        names.setdefault(raw.upper(), raw)
        return raw.upper()

    assembly = ""
    for kw, params, lines, where in _blocks(path):
        if kw in ASSEMBLY:
            assembly = assembly or f"*{kw} at {where}"
            nodes_seen += kw == "NODE"
            continue
        if kw in MODEL_CHANGING and not (model and kw in MODEL_KEYWORDS):
            raise AbaqusError(f"{where}: *{kw} ({MODEL_CHANGING[kw]}) is not supported: it changes the model; "
                              "remove it or write the model without it")
        if kw == "SOLID SECTION" and "ORIENTATION" in params and not model:
            raise AbaqusError(f"{where}: *SOLID SECTION, ORIENTATION={params['ORIENTATION']}: local material "
                              "orientations are not supported")
        if kw == "NODE":
            if "SYSTEM" in params and params["SYSTEM"].upper() not in ("", "R"):
                raise AbaqusError(f"{where}: *NODE, SYSTEM={params['SYSTEM']}: only rectangular coordinates are "
                                  "supported")
            nodes_seen += 1
            new = []
            for ln, w in lines:
                vals = [v for v in ln.replace(",", " ").split()]
                try:
                    nid, xyz = int(vals[0]), [float(v) for v in vals[1:4]]
                except (ValueError, IndexError):
                    raise AbaqusSyntaxError(f"{w}: bad *NODE line {ln.strip()!r}") from None
                new.append(nid)
                coords.append(xyz + [0.0] * (3 - len(xyz)))
            node_ids += new
            if "NSET" in params:
                nsets.setdefault(name_of(params["NSET"]), []).extend(new)
        elif kw == "ELEMENT":
            etype = params.get("TYPE", "").upper()
            mtype = next((m for p, m in SOLIDS if etype.startswith(p)), None) or SKINS.get(etype)
            if mtype is None:
                family = next((f for p, f in STRUCTURAL if etype.startswith(p)), None)
                what = f"{family} elements" if family else "elements of an unknown type"
                raise AbaqusError(f"{where}: *ELEMENT, TYPE={etype}: {what} are not supported; supported: solid "
                                  "C3D4/C3D10, C3D8/C3D20/C3D27, C3D6/C3D15, C3D5/C3D13 (any suffix), "
                                  "and surface elements SFM3D*")
            values = _ints(lines, where)
            n = NODES[mtype] + 1
            if len(values) % n:
                raise AbaqusSyntaxError(f"{where}: *ELEMENT, TYPE={etype}: {len(values)} numbers is not "
                                        "a multiple of "
                                  f"{n} (element number and {n - 1} nodes)")
            flat = np.asarray(values, dtype=np.int64).reshape(-1, n)
            raw_blocks.append((mtype, flat, where, etype))
            if "ELSET" in params:
                elsets.setdefault(name_of(params["ELSET"]), []).extend(flat[:, 0].tolist())
        elif kw == "ELSET":
            if "ELSET" not in params:
                raise AbaqusSyntaxError(f"{where}: *ELSET without ELSET=name")
            elsets.setdefault(name_of(params["ELSET"]), []).extend(
                _members(lines, params, elsets, "element", where))
        elif kw == "NSET":
            if "NSET" not in params:
                raise AbaqusSyntaxError(f"{where}: *NSET without NSET=name")
            key = name_of(params["NSET"])
            if "ELSET" in params:
                pending_nset_elsets.append((key, [params["ELSET"]], where))
                nsets.setdefault(key, [])
            else:
                nsets.setdefault(key, []).extend(_members(lines, params, nsets, "node", where))
        elif kw == "SURFACE":
            name = params.get("NAME", "")
            stype = params.get("TYPE", "ELEMENT").upper()
            if stype == "NODE":
                members = []
                for ln, w in lines:
                    ref = ln.split(",")[0].strip()
                    if ref.lstrip("-").isdigit():
                        members.append(int(ref))
                    elif ref.upper() in nsets:
                        members += nsets[ref.upper()]
                    else:
                        raise AbaqusSyntaxError(f"{w}: *SURFACE {name}: unknown node set {ref!r}")
                node_surfaces.setdefault(name_of(name), []).extend(members)
            elif stype == "ELEMENT":
                rows = surfaces.setdefault(name_of(name), [])
                for ln, w in lines:
                    parts = [v.strip() for v in ln.split(",")]
                    if len(parts) < 2 or not parts[1]:
                        raise AbaqusSyntaxError(f"{w}: *SURFACE {name}: give a face label (S1..S6) "
                                                f"after {parts[0]}")
                    ref, label = parts[0], parts[1].upper()
                    if ref.lstrip("-").isdigit():
                        elems = [int(ref)]
                    elif ref.upper() in elsets:
                        elems = elsets[ref.upper()]
                    else:
                        raise AbaqusSyntaxError(f"{w}: *SURFACE {name}: unknown element set {ref!r}")
                    rows += [(e, label, w) for e in elems]
            else:
                raise AbaqusError(f"{where}: *SURFACE {name}: TYPE={stype} is not supported; use TYPE=ELEMENT, "
                                  "TYPE=NODE or a node set")
    if assembly:
        raise AbaqusError(f"{path.name} is an Abaqus assembly ({nodes_seen} *NODE blocks, {assembly}); write a "
                          "flat input file (no parts/instances)")
    if not node_ids:
        raise AbaqusSyntaxError(f"{path.name}: no *NODE block")
    ids = np.asarray(node_ids, dtype=np.int64)
    order = np.argsort(ids, kind="stable")
    sorted_ids = ids[order]
    dup = np.flatnonzero(sorted_ids[1:] == sorted_ids[:-1])
    if len(dup):
        raise AbaqusSyntaxError(f"{path.name}: node {int(sorted_ids[dup[0]])} is defined twice")

    def index_of(numbers: np.ndarray, what: str) -> np.ndarray:
        pos = np.searchsorted(sorted_ids, numbers)
        pos = np.minimum(pos, len(sorted_ids) - 1)
        bad = sorted_ids[pos] != numbers
        if np.any(bad):
            raise AbaqusSyntaxError(f"{what} {int(np.asarray(numbers)[bad].ravel()[0])} is not defined")
        return order[pos]

    deck = Deck(ids, np.asarray(coords, dtype=float))
    elem_nodes: dict[int, np.ndarray] = {}
    for mtype, flat, where, etype in raw_blocks:
        pos = np.minimum(np.searchsorted(sorted_ids, flat[:, 1:]), len(sorted_ids) - 1)
        bad = np.argwhere(sorted_ids[pos] != flat[:, 1:])
        if len(bad):
            i, j = bad[0]
            raise AbaqusSyntaxError(f"{where}: element {int(flat[i, 0])}: node {int(flat[i, 1 + j])} "
                                    "is not defined")
        conn = order[pos]
        if mtype in PERMUTATION:
            conn = conn[:, PERMUTATION[mtype]]
        deck.blocks.append((mtype, conn, flat[:, 0].copy()))
        deck.element_types.append(etype)
        if pending_nset_elsets:
            for e, row in zip(flat[:, 0].tolist(), flat[:, 1:]):
                elem_nodes[e] = row
    for key, sets, where in pending_nset_elsets:
        for s in sets:
            if s.upper() not in elsets:
                raise AbaqusSyntaxError(f"{where}: *NSET, ELSET={s}: unknown element set")
            nsets[key] += sorted({int(n) for e in elsets[s.upper()] for n in elem_nodes.get(e, [])})
    all_elems = np.concatenate([b[2] for b in deck.blocks]) if deck.blocks else np.zeros(0, np.int64)
    u, c = np.unique(all_elems, return_counts=True)
    if np.any(c > 1):
        raise AbaqusSyntaxError(f"{path.name}: element {int(u[c > 1][0])} is defined twice")
    deck.elsets = {k: list(dict.fromkeys(v)) for k, v in elsets.items()}
    deck.nsets = {k: index_of(np.asarray(list(dict.fromkeys(v)), np.int64), f"*NSET {names[k]}: node")
                  for k, v in nsets.items() if v}
    deck.node_surfaces = {k: index_of(np.asarray(list(dict.fromkeys(v)), np.int64), f"*SURFACE {names[k]}: node")
                          for k, v in node_surfaces.items() if v}
    deck.surfaces = surfaces
    deck.names = names
    return deck
