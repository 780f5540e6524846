"""geometry.gmsh_io.search_meshes: the (Algorithm3D, RandomSeed) search that both the brake builder and
the generic builders use to avoid slivers and curved elements inverted by their boundary nodes.

The logic is tested on a unit box with the quality measure replaced by a table per attempt, so each
branch (accept the first good one, keep the best when none is good, skip attempts already judged, a
last attempt that fails to mesh, no judging) is reached on purpose.  The real measure is exercised by
tests/unit/fe/test_stress_extremes.py (a ring whose default mesh has a zero-Jacobian curved element).
"""
from __future__ import annotations

import gmsh
import pytest

import geometry.gmsh_io as gio


@pytest.fixture
def box(monkeypatch):
    """A meshable unit box, a quality table by attempt and a log of the meshing calls."""
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add("box")
    gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
    gmsh.model.occ.synchronize()
    gmsh.option.setNumber("Mesh.MeshSizeMax", 0.5)
    table: dict[tuple[int, int], float] = {}
    calls: list[tuple[int, int]] = []
    fail: set[tuple[int, int]] = set()

    def current() -> tuple[int, int]:
        return int(gmsh.option.getNumber("Mesh.Algorithm3D")), int(gmsh.option.getNumber("Mesh.RandomSeed"))

    mesh_with = gio.mesh_with

    def logged(model, attempt):
        calls.append(attempt)
        return False if attempt in fail else mesh_with(model, attempt)

    monkeypatch.setattr(gio, "min_sicn", lambda model: table[current()])
    monkeypatch.setattr(gio, "mesh_with", logged)
    yield gmsh.model, table, calls, fail, current
    gmsh.finalize()


A, B, C = (1, 1), (1, 2), (10, 1)


def _order(model) -> int:
    types = model.mesh.getElementTypes(3)
    return {4: 1, 11: 2}[int(types[0])]


def test_first_good_attempt_is_taken_and_left_at_order_one(box):
    model, table, calls, _, current = box
    table.update({A: 0.05, B: 0.4, C: 0.9})
    accepted, quality = gio.search_meshes(model, [A, B, C], 2)
    assert accepted == B and quality == {A: 0.05, B: 0.4} and calls == [A, B]
    assert current() == B and _order(model) == 1


def test_best_is_remeshed_when_none_is_good(box):
    model, table, calls, _, current = box
    table.update({A: 0.05, B: 0.08, C: 0.02})
    accepted, quality = gio.search_meshes(model, [A, B, C], 2)
    assert accepted is None and quality == {A: 0.05, B: 0.08, C: 0.02}
    assert calls == [A, B, C, B] and current() == B


def test_best_last_attempt_is_not_remeshed(box):
    model, table, calls, _, current = box
    table.update({A: 0.05, B: 0.02, C: 0.08})
    assert gio.search_meshes(model, [A, B, C], 2)[0] is None
    assert calls == [A, B, C] and current() == C


def test_failed_last_attempt_leads_back_to_the_best(box):
    """The model then holds the failed attempt's mesh, even when the best is the previous one."""
    model, table, calls, fail, current = box
    table.update({A: 0.05, B: 0.08})
    fail.add(C)
    accepted, quality = gio.search_meshes(model, [A, B, C], 2)
    assert accepted is None and quality == {A: 0.05, B: 0.08} and calls == [A, B, C, B]


def test_judged_attempts_are_skipped_and_nothing_meshed_gives_no_quality(box):
    model, table, calls, fail, _ = box
    table.update({B: 0.5})
    assert gio.search_meshes(model, [A, B], 2, quality={A: 0.01}) == (B, {A: 0.01, B: 0.5})
    assert calls == [B]
    fail.update({A, B})
    assert gio.search_meshes(model, [A, B], 2) == (None, {})


def test_without_judging_the_first_mesh_is_taken(box):
    model, table, calls, fail, current = box     # an empty table: min_sicn would raise KeyError
    fail.add(A)
    assert gio.search_meshes(model, [A, B, C], 1, judge=False) == (B, {})
    assert calls == [A, B] and current() == B
