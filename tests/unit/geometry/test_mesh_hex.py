"""Hexahedra, wedges and pyramids (linear and quadratic) split into conforming tetrahedra.

Verification: the split tables (every combination of face diagonals) are positive, conforming
triangulations that respect the diagonals; a box of hexahedra, wedges, pyramids and tetrahedra with
shuffled node numbers and moved interior nodes splits into a conforming mesh (every inner triangle
shared by two tetrahedra, the boundary on the box, the volume of the box); through an Abaqus deck
and dolfinx its free-free stiffness has exactly 6 zero modes and a linear displacement field is
reproduced to round-off (patch test) across hex-hex, hex-wedge, hex-pyramid and hex-tet faces, P1
and P2, also with the interior node of a cyclic diagonal combination.  Sets, surfaces (S1-S6, node
surfaces, quadrilateral skins), includes, and the named errors of bad decks.
"""
from __future__ import annotations

import itertools
import re

import meshio
import numpy as np
import pytest
from mpi4py import MPI

from geometry.hex_decks import mixed_block, quadratic, write_inp
from geometry.mesh_file import MeshImportError, _teach_meshio, map_sets, prepare, read_mesh_file
from geometry.split import FACES, REF, _conforming, _signed6v, local_split, quad_faces, split_mesh

COMM = MPI.COMM_WORLD
_teach_meshio()             # meshio 5.0 cannot build wedge15/pyramid13 blocks without it
MIXED = dict(wedges=[(1, 0, 0)], pyramids=[(1, 1, 1)], tets=[(2, 1, 0)])
BOX_FACES = ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")


def _box_nsets(points, size, n_file_nodes):
    out = {}
    for axis, name in enumerate("xyz"):
        for end, tag in ((0.0, "min"), (size[axis], "max")):
            out[f"{name}{tag}"] = np.flatnonzero(np.isclose(points[:n_file_nodes, axis], end))
    return out


def _deck(tmp_path, order=1, name="mixed.inp", **kw):
    pts, blocks, cells, size = mixed_block(**{**MIXED, **kw}, order=order)
    total = sum(len(c) for _, c in blocks)
    write_inp(tmp_path / name, pts, blocks, elsets={"ALL": np.arange(total)},
              nsets=_box_nsets(pts, size, len(pts)))
    return tmp_path / name, pts, blocks, size


# --- the local splits ------------------------------------------------------------------------------
@pytest.mark.parametrize("kind,nq", [("hexahedron", 6), ("wedge", 3), ("pyramid", 1)])
def test_split_tables_are_conforming_positive_and_respect_the_diagonals(kind, nq):
    ref = np.vstack([REF[kind], REF[kind].mean(axis=0)])
    counts = {}
    for d in itertools.product((0, 1), repeat=nq):
        tets = local_split(kind, d)
        centred = any(len(REF[kind]) in t for t in tets)
        counts[len(tets)] = counts.get(len(tets), 0) + 1
        vols = [_signed6v(ref[list(t)]) for t in tets]
        assert min(vols) > 0
        edges = {frozenset(e) for t in tets for e in itertools.combinations(t, 2)}
        for q, di in zip(quad_faces(kind), d):
            assert frozenset((q[di], q[di + 2])) in edges and frozenset((q[1 - di], q[3 - di])) not in edges
        if not centred:
            assert _conforming(kind, tets)
    # 18 of the 64 hexahedron combinations and the 2 cyclic wedge ones have no split on the corners
    assert {"hexahedron": {5: 2, 6: 44, 12: 18}, "wedge": {3: 6, 8: 2}, "pyramid": {2: 2}}[kind] == counts


def test_the_smallest_node_rule_never_needs_a_centre_node():
    """Dompierre et al.: diagonals through the smallest node never form a cycle (every 7th of the 8!
    numberings of a hexahedron, all 6! of a wedge)."""
    for perm in itertools.islice(itertools.permutations(range(8)), 0, None, 7):
        d = tuple(int(np.argmin([perm[v] for v in q]) % 2) for q in quad_faces("hexahedron"))
        assert len(local_split("hexahedron", d)) <= 6
    for perm in itertools.permutations(range(6)):
        d = tuple(int(np.argmin([perm[v] for v in q]) % 2) for q in quad_faces("wedge"))
        assert len(local_split("wedge", d)) == 3


@pytest.mark.slow
def test_split_tables_are_the_search_results():
    from geometry.split import search_split

    for kind, nq in (("hexahedron", 6), ("wedge", 3), ("pyramid", 1)):
        for d in itertools.product((0, 1), repeat=nq):
            assert search_split(kind, d) == local_split(kind, d)


# --- conformity of the split mesh --------------------------------------------------------------------
def _volumes(points, cells):
    x = points[cells[:, :4]]
    return np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0]) / 6


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_mixed_block_splits_into_a_conforming_mesh(order, seed):
    pts, blocks, _, size = mixed_block(**MIXED, order=order, seed=seed)
    sp = split_mesh(pts, blocks)
    v = _volumes(sp.points, sp.cells)
    assert v.min() > 0 and v.sum() == pytest.approx(np.prod(size), rel=1e-13)
    faces = np.sort(sp.cells[:, :4][:, [[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]]].reshape(-1, 3), axis=1)
    uniq, count = np.unique(faces, axis=0, return_counts=True)
    assert count.max() == 2
    outer = uniq[count == 1]
    x = sp.points[outer]                                       # (k, 3 corners, 3)
    on_box = np.zeros(len(outer), bool)
    for axis in range(3):
        for end in (0.0, size[axis]):
            on_box |= np.all(np.isclose(x[:, :, axis], end), axis=1)
    assert on_box.all()                                        # no crack: one-sided faces only on the box
    if order == 2:
        # straight element edges keep their mid-nodes; a new node on a face diagonal is the bilinear
        # face's centre (the mean of its corners: the element map at the parametric mid-point)
        c, x = sp.cells, sp.points
        for (a, b), m in {(0, 1): 4, (1, 2): 5, (0, 2): 6, (0, 3): 7, (1, 3): 8, (2, 3): 9}.items():
            old = c[:, m] < len(pts)
            assert np.allclose(x[c[old, m]], 0.5 * (x[c[old, a]] + x[c[old, b]]), atol=1e-14)
        assert sp.stats["new_nodes"] == sp.stats["face_nodes"] + sp.stats["interior_nodes"] > 0


# --- through a deck and dolfinx: rigid-body modes and the patch test ----------------------------------------
def _elasticity(md, degree):
    import ufl
    from dolfinx import fem
    from dolfinx.fem.petsc import assemble_matrix

    V = fem.VectorFunctionSpace(md.mesh, ("Lagrange", degree))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    lam, mu = 1.0, 1.0

    def eps(w):
        return ufl.sym(ufl.grad(w))

    a = (2 * mu * ufl.inner(eps(u), eps(v)) + lam * ufl.div(u) * ufl.div(v)) * ufl.dx
    K = assemble_matrix(fem.form(a))
    K.assemble()
    M = assemble_matrix(fem.form(ufl.inner(u, v) * ufl.dx))
    M.assemble()
    return V, a, K, M


def _rigid_modes(K, M) -> int:
    import scipy.linalg

    k, m = K.convert("dense").getDenseArray(), M.convert("dense").getDenseArray()
    w = scipy.linalg.eigh(k, m, eigvals_only=True)
    return int(np.sum(np.abs(w) < 1e-8 * w.max())), w


def _patch(md, degree, size):
    import ufl
    from dolfinx import fem
    from dolfinx.fem.petsc import LinearProblem

    V, a, _, _ = _elasticity(md, degree)
    A = np.array([[0.3, -0.2, 0.5], [0.1, 0.7, -0.4], [-0.6, 0.2, 0.25]])
    b = np.array([0.1, -0.3, 0.2])

    def exact(x):
        return A @ x + b[:, None]

    g = fem.Function(V)
    g.interpolate(exact)
    dofs = fem.locate_dofs_geometrical(V, lambda x: np.any([np.isclose(x[i], 0) | np.isclose(x[i], size[i])
                                                            for i in range(3)], axis=0))
    bc = fem.dirichletbc(g, dofs)
    zero = fem.Constant(md.mesh, np.zeros(3))
    L = ufl.inner(zero, ufl.TestFunction(V)) * ufl.dx
    uh = LinearProblem(a, L, bcs=[bc], petsc_options={"ksp_type": "preonly", "pc_type": "lu"}).solve()
    n_inner = len(V.tabulate_dof_coordinates()) - len(dofs)
    return np.abs(uh.x.array - g.x.array).max(), n_inner


@pytest.mark.parametrize("order", [1, 2])
def test_rigid_body_modes_and_patch_test_through_an_abaqus_deck(tmp_path, order):
    from geometry.mesh_file import mesh_file_mesh

    path, pts, blocks, size = _deck(tmp_path, order)
    md = mesh_file_mesh(COMM, file=str(path), parts={"all": ["ALL"]}, faces={f: [f] for f in BOX_FACES})
    assert md.info["file_elements"] == {t: len(c) for t, c in blocks}
    _, _, K, M = _elasticity(md, order)
    n, w = _rigid_modes(K, M)
    assert n == 6, w[:8]
    err, n_inner = _patch(md, order, size)
    assert n_inner > 0 and err < 1e-12


def _caps(order):
    """One hexahedron with a tetrahedron on each half of each face, the halves cut along a cyclic
    combination of diagonals (no split on the corners: the hexahedron takes a centre node)."""
    pts = REF["hexahedron"].astype(float) / 2
    tets, extra = [], []
    for q, d in zip(quad_faces("hexahedron"), (0,) * 6):
        apex = len(pts) + len(extra)
        centre = pts[q].mean(axis=0)
        extra.append(centre + 0.5 * (centre - 0.5))
        tris = [(q[0], q[1], q[2]), (q[0], q[2], q[3])] if d == 0 else [(q[0], q[1], q[3]), (q[1], q[2], q[3])]
        tets += [[*t, apex] for t in tris]
    pts = np.vstack([pts, extra])
    tets = np.asarray(tets)
    v = _volumes(pts, tets)
    tets = np.where((v < 0)[:, None], tets[:, [0, 2, 1, 3]], tets)
    blocks = [("hexahedron", np.arange(8)[None, :]), ("tetra", tets)]
    if order == 2:
        pts, blocks = quadratic(pts, blocks)
    return pts, blocks


@pytest.mark.parametrize("order", [1, 2])
def test_cyclic_diagonals_take_a_centre_node(tmp_path, order):
    from geometry.mesh_file import mesh_file_mesh

    pts, blocks = _caps(order)
    sp = split_mesh(pts, blocks)
    assert sp.first[1] - sp.first[0] == 12 and sp.stats["centre_nodes"] == 1
    assert _volumes(sp.points, sp.cells).min() > 0
    write_inp(tmp_path / "caps.inp", pts, blocks, elsets={"ALL": np.arange(13)})
    md = mesh_file_mesh(COMM, file=str(tmp_path / "caps.inp"), parts={"all": ["ALL"]}, faces={})
    _, _, K, M = _elasticity(md, order)
    assert _rigid_modes(K, M)[0] == 6


# --- formats, sets and surfaces ----------------------------------------------------------------------------
def test_vtu_gmsh_and_nastran_give_the_split_of_the_abaqus_deck(tmp_path):
    path, pts, blocks, size = _deck(tmp_path, 2)
    ref = read_mesh_file(path)
    meshio.write(tmp_path / "m.vtu", meshio.Mesh(pts, blocks, cell_data={"part": [np.full(len(c), 7)
                                                                                 for _, c in blocks]}))
    meshio.write(tmp_path / "m.msh", meshio.Mesh(pts, blocks, cell_data={
        "gmsh:physical": [np.full(len(c), 7) for _, c in blocks],
        "gmsh:geometrical": [np.full(len(c), 7) for _, c in blocks]}), file_format="gmsh22", binary=False)
    for f in ("m.vtu", "m.msh"):
        mf = read_mesh_file(tmp_path / f)
        assert len(mf.cells) == len(ref.cells) and np.array_equal(mf.cells, ref.cells), f
        assert np.allclose(mf.points, ref.points, atol=1e-14) and len(mf.cell_sets["7"]) == len(mf.cells)
    # a Nastran deck (CHEXA 20, CPENTA 15, CPYRAM 13, CTETRA 10) written by hand
    perm = {"hexahedron20": [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 16, 17, 18, 19, 12, 13, 14, 15],
            "wedge15": [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 13, 14, 9, 10, 11]}
    card = {"hexahedron20": "CHEXA", "wedge15": "CPENTA", "pyramid13": "CPYRAM", "tetra10": "CTETRA"}
    lines = ["BEGIN BULK"] + [f"GRID,{i + 1},,{x!r},{y!r},{z!r}" for i, (x, y, z) in enumerate(pts.tolist())]
    eid = 0
    for t, c in blocks:
        for row in c:
            eid += 1
            nodes = [v + 1 for v in row[perm.get(t, range(len(row)))]]
            fields = [eid, 7, *nodes]                     # small fields, "+" continuation lines
            lines.append(f"{card[t]:<8}" + "".join(f"{v:>8}" for v in fields[:8]))
            for i in range(8, len(fields), 8):
                lines.append("+       " + "".join(f"{v:>8}" for v in fields[i:i + 8]))
    xmin = _box_nsets(pts, size, len(pts))["xmin"] + 1
    lines += [f"SET1,55,{xmin[0]},THRU,{xmin[0]}", "SET1,55," + ",".join(map(str, xmin[1:])), "ENDDATA"]
    (tmp_path / "m.bdf").write_text("\n".join(lines) + "\n")
    mf = read_mesh_file(tmp_path / "m.bdf")
    assert np.array_equal(mf.cells, ref.cells) and set(mf.cell_ids.tolist()) == set(range(1, eid + 1))
    assert sorted(mf.node_sets["55"].tolist()) == sorted((xmin - 1).tolist())
    a = map_sets(mf, {"p": ["7"]}, {"x": ["55"]})
    b = map_sets(ref, {"p": ["ALL"]}, {"x": ["xmin"]})
    assert sorted(map(tuple, a.facets)) == sorted(map(tuple, b.facets))
    text = (tmp_path / "m.bdf").read_text().replace("ENDDATA", "RBE2,900,1,123456,2,3\nENDDATA")
    (tmp_path / "r.bdf").write_text(text)
    n = text.splitlines().index("RBE2,900,1,123456,2,3") + 1
    with pytest.raises(MeshImportError, match=rf"r.bdf line {n}: RBE2 \(a rigid element\) is not supported"):
        read_mesh_file(tmp_path / "r.bdf")


def test_abaqus_sets_surfaces_includes_and_node_surfaces(tmp_path):
    pts, blocks, cells, size = mixed_block(**MIXED, order=2)
    hexes = blocks[0][1]
    n_hex = len(hexes)
    total = sum(len(c) for _, c in blocks)
    # S1 of the hexahedra at z = 0 and S3 of the wedges at y = 0, as element surfaces
    rows = []
    k = 0
    for t, c in blocks:
        kind = {"hexahedron20": "hexahedron", "wedge15": "wedge", "pyramid13": "pyramid", "tetra10": "tetra"}[t]
        for row in c:
            for f, face in enumerate(FACES[kind]):
                if np.allclose(pts[row[face], 2], 0.0):
                    rows.append((k, f"S{f + 1}"))
            k += 1
    write_inp(tmp_path / "mesh.inp", pts, blocks, surfaces={"BOTTOM": rows})
    nodes_z0 = np.flatnonzero(np.isclose(pts[:, 2], 0.0)) + 1
    half = total // 2
    (tmp_path / "main.inp").write_text(
        "*HEADING\n*INCLUDE, INPUT=mesh.inp\n"
        f"*ELSET, ELSET=Body\n{', '.join(map(str, range(1, half + 1)))}\n"
        "*ELSET, ELSET=body, GENERATE\n" + f"{half + 1}, {total}, 1\n"
        "*NSET, NSET=Z0\n" + "\n".join(map(str, nodes_z0)) + "\n"
        "*SURFACE, NAME=BOTTOM_NODES, TYPE=NODE\nZ0\n"
        "*MATERIAL, NAME=STEEL\n*ELASTIC\n210000., 0.3\n*SOLID SECTION, ELSET=BODY, MATERIAL=STEEL\n")
    mf = read_mesh_file(tmp_path / "main.inp")
    assert len(mf.cell_sets["Body"]) == len(mf.cells)                 # one set over two blocks
    by_faces = map_sets(mf, {"b": ["BODY"]}, {"bottom": ["bottom"]})
    by_nodes = map_sets(mf, {"b": ["BODY"]}, {"bottom": ["bottom_nodes"]})
    assert sorted(map(tuple, by_faces.facets)) == sorted(map(tuple, by_nodes.facets))
    tri = by_faces.facets
    # z = 0: 4 hexahedron faces (2 triangles each), 2 wedge triangles, 2 tetrahedron faces
    assert np.allclose(mf.points[tri][:, :, 2], 0.0) and len(tri) == 4 * 2 + 2 + 2
    _, info = prepare(tmp_path / "main.inp", parts={"b": ["body"]}, faces={"bottom": ["BOTTOM"]})
    assert info["file_elements"] == {t: len(c) for t, c in blocks}
    assert info["split"]["tetrahedra"] == len(mf.cells) and info["elements"] == len(mf.cells)
    assert info["faces"] == {"bottom": 12}
    # quadrilateral skins (a gmsh physical surface of quad8) name the same faces of the hexahedra
    quads = np.array([r[[0, 1, 2, 3, 8, 9, 10, 11]] for r in hexes if np.allclose(pts[r[:4], 2], 0.0)])
    assert len(quads) == 4 and n_hex > 4
    ones = [np.full(len(c), 1) for _, c in blocks] + [np.full(len(quads), 2)]
    msh = meshio.Mesh(pts, blocks + [("quad8", quads)],
                      cell_data={"gmsh:physical": ones, "gmsh:geometrical": ones},
                      field_data={"body": np.array([1, 3]), "bottom": np.array([2, 2])})
    meshio.write(tmp_path / "q.msh", msh, file_format="gmsh22", binary=False)
    g = read_mesh_file(tmp_path / "q.msh")
    skin = map_sets(g, {"b": ["body"]}, {"bottom": ["bottom"]}).facets
    assert len(skin) == 8 and set(map(tuple, skin)) <= set(map(tuple, tri))


def _bad(tmp_path, text: str, name="bad.inp") -> str:
    (tmp_path / name).write_text(text)
    with pytest.raises(MeshImportError) as e:
        prepare(tmp_path / name, parts={"a": ["ALL"]}, faces={})
    return str(e.value)


def test_bad_decks_are_named_errors_with_element_numbers_and_lines(tmp_path):
    path, pts, blocks, size = _deck(tmp_path, 1)
    text = path.read_text()
    hex_line = text.splitlines().index("*ELEMENT, TYPE=C3D8") + 2           # 1-based line of element 1
    first = text.splitlines()[hex_line - 1].split(", ")
    # inside out: top and bottom swapped
    flipped = ", ".join([first[0], *first[5:9], *first[1:5]])
    msg = _bad(tmp_path, text.replace(", ".join(first), flipped, 1))
    assert "geometry.file: 1 inverted (det J <= 0) elements: [1] (the file's element numbers" in msg
    # collapsed: a hexahedron with a repeated node
    collapsed = ", ".join([*first[:4], first[3], *first[5:]])
    msg = _bad(tmp_path, text.replace(", ".join(first), collapsed, 1))
    assert "1 hexahedron elements have repeated corner nodes" in msg and "elements [1]" in msg
    # a keyword that changes the model, shells, an unknown element set, an include that is missing
    for extra, want in [("*ORIENTATION, NAME=ORI\n1., 0., 0., 0., 1., 0.\n", r"line \d+: \*ORIENTATION .a local"),
                        ("*TRANSFORM, NSET=XMIN\n1., 0., 0., 0., 1., 0.\n", r"\*TRANSFORM"),
                        ("*TIE, NAME=T\nA, B\n", r"\*TIE .a tie constraint"),
                        ("*MPC\nBEAM, 1, 2\n", r"\*MPC"),
                        ("*ELEMENT, TYPE=S4R\n9001, 1, 2, 3, 4\n", r"TYPE=S4R: shell elements are not supported"),
                        ("*ELEMENT, TYPE=B31\n9001, 1, 2\n", r"TYPE=B31: beam elements"),
                        ("*INCLUDE, INPUT=nowhere.inp\n", r"\*INCLUDE, INPUT=nowhere.inp: no such file"),
                        ("*SURFACE, NAME=S\nNOPE, S1\n", r"unknown element set 'NOPE'")]:
        msg = _bad(tmp_path, text + extra)
        n = len(text.splitlines()) + 1
        assert f"bad.inp line {n}" in msg or f"bad.inp line {n + 1}" in msg, (extra, msg)
        assert re.search(want, msg), (extra, msg)
    # a face label a wedge does not have
    msg = _bad(tmp_path, text + "*SURFACE, NAME=W\n10, S6\n")
    assert "face label 'S6'; wedge elements have S1-S5" in msg


def test_elements_that_do_not_match_are_named(tmp_path):
    pts, blocks, _, size = mixed_block(shape=(2, 1, 1), size=(2.0, 1.0, 1.0), order=2, seed=None, jiggle=0)
    conn = blocks[0][1].copy()
    # the second hexahedron gets its own mid-node on an edge it shares with the first
    shared = [i for i in range(8, 20) if conn[1, i] in conn[0]][0]
    pts = np.vstack([pts, pts[conn[1, shared]] + 0.01])
    conn[1, shared] = len(pts) - 1
    write_inp(tmp_path / "m.inp", pts, [("hexahedron20", conn)], elsets={"ALL": [0, 1]},
              elem_ids=np.array([11, 12]))
    with pytest.raises(MeshImportError, match=r"edges have different mid-nodes .*elements \[11, 12\]"):
        read_mesh_file(tmp_path / "m.inp")
    # tetrahedra that cut a hexahedron's face along both diagonals (they overlap)
    pts, blocks = _caps(1)
    tets = blocks[1][1]
    extra = np.array([[0, 1, 3, 8], [1, 2, 3, 8]])   # face S1 (0, 1, 2, 3): caps along 0-2, these along 1-3
    bad = [("hexahedron", blocks[0][1]), ("tetra", np.vstack([tets, extra]))]
    write_inp(tmp_path / "o.inp", pts, bad, elsets={"ALL": np.arange(15)})
    with pytest.raises(MeshImportError, match=r"meet triangles cut along both diagonals.*elements \[1\]"):
        read_mesh_file(tmp_path / "o.inp")


def test_convert_writes_the_split_mesh_with_its_sets(tmp_path):
    from fem_squeal.app.convert import convert

    path, pts, blocks, size = _deck(tmp_path, 2)
    mf, warns = convert(path, tmp_path / "split.vtu")
    back = read_mesh_file(tmp_path / "split.vtu")
    assert back.cells.shape == mf.cells.shape and back.split["file_elements"] == {"tetra10": len(mf.cells)}
    assert {"ALL", "xmin"} <= set(back.cell_sets) | set(back.surfaces)
    m = meshio.read(tmp_path / "split.vtu")
    assert {b.type for b in m.cells} <= {"tetra10", "triangle6"}
