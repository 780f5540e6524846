"""Nastran bulk data, as far as a mesh file needs it: the cards (small, large and free fields with
continuations), ``SET1`` node sets, HyperMesh's ``$HMNAME`` component names, and the cards that change
the model (refused by name).  The elements and grids themselves are read by meshio
(:mod:`geometry.mesh_file`)."""
from __future__ import annotations

import re
from pathlib import Path


class NastranError(ValueError):
    """A bulk data file that cannot be taken as a mesh (its file and line named)."""


UNSUPPORTED = {
    "RBE2": "a rigid element", "RBE3": "an interpolation element", "RBAR": "a rigid bar", "RROD": "a rigid rod",
    "MPC": "multi-point constraints", "MPCADD": "multi-point constraints", "CBAR": "a bar element",
    "CBEAM": "a beam element", "CROD": "a rod element", "CONROD": "a rod element", "CBUSH": "a bush element",
    "CELAS1": "a spring element", "CELAS2": "a spring element", "CONM2": "a point mass", "CONM1": "a point mass",
    "CQUADR": "a shell element", "CTRIAR": "a shell element", "CSHEAR": "a shear panel",
}


def cards(path: Path):
    """(card name, fields, line number) of the bulk data: small, large (``*``) and free (comma) fields,
    continuations starting with ``+``, ``*`` or a blank first field."""
    card = None
    bulk = False
    with open(path, errors="replace") as f:
        for no, line in enumerate(f, 1):
            line = line.rstrip("\n")
            if not bulk:
                bulk = line.strip().upper().startswith("BEGIN BULK")
                continue
            if line.startswith("$") or not line.strip():
                continue
            if line.upper().startswith("ENDDATA"):
                break
            if "," in line:
                fields = [v.strip() for v in line.split(",")]
            elif line[:8].rstrip().endswith("*") or line.startswith("*"):
                fields = [line[:8].strip()] + [line[i:i + 16].strip() for i in range(8, min(len(line), 72), 16)]
            else:
                fields = [line[i:i + 8].strip() for i in range(0, min(len(line), 72), 8)]
            head = fields[0]
            if card is not None and (head == "" or head.startswith("+") or head == "*" or
                                     (head.startswith("*") and not head[1:2].isalpha())):
                card[1].extend(fields[1:])
                continue
            if card is not None:
                yield card
            card = (head.rstrip("*").upper(), fields[1:], no)
    if card is not None:
        yield card


def scan(path: Path) -> dict[str, tuple[list[int], str]]:
    """``SET1`` node sets (name = set number) of a bulk data file; refuses the cards that change the
    model (rigid and structural elements, MPCs, GRID displacement systems)."""
    sets: dict[str, tuple[list[int], str]] = {}
    for name, fields, no in cards(path):
        if name in UNSUPPORTED:
            raise NastranError(f"{path.name} line {no}: {name} ({UNSUPPORTED[name]}) "
                                  "is not supported: it changes the model")
        if name == "GRID" and len(fields) > 5 and fields[5] not in ("", "0"):
            raise NastranError(f"{path.name} line {no}: GRID {fields[0]} uses displacement "
                                  f"coordinate system {fields[5]} (CD field); only the basic system is supported")
        if name == "SET1":
            vals = [v for v in fields[1:] if v]
            grids: list[int] = []
            i = 0
            try:
                while i < len(vals):
                    if vals[i].upper() == "THRU":
                        grids += list(range(grids[-1] + 1, int(vals[i + 1]) + 1))
                        i += 2
                    elif vals[i].upper() == "SKIN":
                        i += 1
                    else:
                        grids.append(int(vals[i]))
                        i += 1
            except (ValueError, IndexError):
                raise NastranError(f"{path.name} line {no}: cannot read SET1 "
                                      f"{fields[:1]}") from None
            old = sets.get(fields[0], ([], ""))[0]
            sets[fields[0]] = (old + grids, f"line {no}")
    return sets


def hypermesh_names(path: Path) -> dict[str, str]:
    """``$HMNAME COMP <id> "name"`` comments (HyperMesh, and fem-squeal convert): property ID -> name."""
    names = {}
    pattern = re.compile(r'^\$HMNAME\s+(?:COMP|PROP)\s+(\d+)\s*"([^"]+)"')
    with open(path, errors="replace") as f:
        for line in f:
            if line.startswith("$"):
                mt = pattern.match(line)
                if mt:
                    names[mt.group(1)] = mt.group(2)
    return names
