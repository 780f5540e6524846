"""Meshes from files: read, map, check, distribute, convert and export.

Verification: the gmsh brake written to an Abaqus deck (in mm) and to a Nastran bulk file, read back
through the scene mapping, gives the real and complex modes of the native mesh.  The files hold the
same nodes to 17 (Abaqus) and 11-12 (Nastran GRID*) significant digits, so the eigenvalues agree to
the eigen-solver tolerance: 1e-8 relative is the bound (measured 1e-10 and below).

Every bad input has its test: a missing set, an unsupported element, an inverted or degenerate
element, overlapping faces, elements in no part, an assembly deck, and a mm mesh without the scale
factor (a warning).
"""
from __future__ import annotations

import functools
import json
import subprocess
import sys
import warnings

import meshio
import numpy as np
import pytest
from mpi4py import MPI
from support.paths import ROOT
from support.processes import clean_env

from fem_squeal.app.convert import write_geometry, write_mesh_file
from fem_squeal.app.run import run_scene
from fem_squeal.app.scene import SceneError, load_scene
from geometry import annular_disc_model, write_msh
from geometry.mesh_file import MeshImportError, map_sets, prepare, read_mesh_file, transform_points

COMM = MPI.COMM_WORLD
RING = dict(mean_radius=0.05, width=0.01, thickness=0.004, mesh_size=0.003)   # 0.004: a sliver that P2 inverts


@functools.cache
def ring_msh(tmp: str, order: int = 2) -> str:
    path = f"{tmp}/ring{order}.msh"
    write_msh(COMM, annular_disc_model(**RING, order=order), path)
    return path


@pytest.fixture(scope="module")
def ring(tmp_path_factory):
    """The gmsh ring (P2) as a MeshFile: parts 'disc', faces top/bottom/inner/outer."""
    tmp = tmp_path_factory.mktemp("ring")
    return tmp, read_mesh_file(ring_msh(str(tmp)))


def test_every_format_round_trips_the_sets(ring):
    tmp, mf = ring
    for ext in ("inp", "bdf", "vtu", "msh"):
        assert write_mesh_file(mf, tmp / f"r.{ext}") == []
        back = read_mesh_file(tmp / f"r.{ext}")
        # 17 digits in .inp/.msh/.vtu; GRID* prints 11-12: 1e-10 of the largest coordinate
        assert np.abs(back.points - mf.points).max() < 1e-10 * np.abs(mf.points).max(), ext
        assert np.array_equal(back.cells, mf.cells), ext
        assert np.array_equal(back.cell_sets["disc"], mf.cell_sets["disc"]), ext
        for face in ("top", "bottom", "inner", "outer"):
            assert sorted(map(tuple, back.surfaces[face])) == sorted(map(tuple, mf.surfaces[face])), (ext, face)


def test_quadratic_geometry_is_kept(ring):
    """The imported P2 ring has the volume of the native (curved) one, to round-off; straight-sided
    tetrahedra on the same nodes would miss the curvature by O((h/R)²) ~ 1e-3."""
    import ufl
    from dolfinx import fem

    from geometry import annular_disc_mesh

    tmp, mf = ring
    write_mesh_file(mf, tmp / "r.inp")
    from geometry.mesh_file import mesh_file_mesh

    imported = mesh_file_mesh(COMM, file=str(tmp / "r.inp"), parts={"disc": ["disc"]},
                              faces={f: [f] for f in ("top", "bottom", "inner", "outer")})
    native = annular_disc_mesh(COMM, **RING)

    def volume(md):
        one = fem.Constant(md.mesh, 1.0)
        return COMM.allreduce(fem.assemble_scalar(fem.form(one * ufl.dx(domain=md.mesh))), op=MPI.SUM)

    exact = np.pi * 2 * RING["mean_radius"] * RING["width"] * RING["thickness"]
    assert volume(imported) == pytest.approx(volume(native), rel=1e-12)
    assert volume(imported) == pytest.approx(exact, rel=1e-5)
    assert imported.mesh.geometry.cmap.degree == 2
    assert imported.info["quality"]["min_jacobian_ratio"] > 0


def test_node_sets_select_the_same_faces_as_surfaces(ring):
    tmp, mf = ring
    top_nodes = np.unique(np.concatenate([mf.cells[c, :4][[0, 1, 2, 3]] for c, _ in mf.surfaces["top"]]))
    z = mf.points[:, 2]
    top_nodes = top_nodes[np.isclose(z[top_nodes], z.max())]
    mf.node_sets["TOP_NODES"] = top_nodes
    try:
        write_mesh_file(mf, tmp / "n.inp")
    finally:
        del mf.node_sets["TOP_NODES"]
    back = read_mesh_file(tmp / "n.inp")
    by_surface = map_sets(back, {"disc": ["DISC"]}, {"top": ["top"]})       # Abaqus names: any case
    by_nodes = map_sets(back, {"disc": ["disc"]}, {"top": ["top_nodes"]})
    assert sorted(map(tuple, by_nodes.facets)) == sorted(map(tuple, by_surface.facets))
    assert len(by_nodes.facets) == len(mf.surfaces["top"])


def test_missing_and_empty_sets_list_the_available_ones(ring):
    _, mf = ring
    with pytest.raises(MeshImportError, match=r"geometry.parts.disc: no element set 'rotor'.*available: "
                                              r"\['1', 'disc'\]"):
        map_sets(mf, {"disc": ["rotor"]}, {})
    with pytest.raises(MeshImportError, match=r"geometry.faces.clamp: no surface or node set 'bolts'.*available: "
                                              r"\[.*'top'\]"):
        map_sets(mf, {"disc": ["disc"]}, {"clamp": ["bolts"]})
    half = dict(mf.cell_sets)
    mf.cell_sets["half"] = mf.cell_sets["disc"][::2]
    try:
        with pytest.raises(MeshImportError, match=r"geometry.parts: \d+ elements belong to no part"):
            map_sets(mf, {"disc": ["half"]}, {})
    finally:
        mf.cell_sets.clear()
        mf.cell_sets.update(half)
    with pytest.raises(MeshImportError, match=r"geometry.faces.b: shares boundary faces with 'a'"):
        map_sets(mf, {"disc": ["disc"]}, {"a": ["top"], "b": ["top", "bottom"]})


def test_unsupported_elements_are_named(tmp_path):
    """Hexahedra, wedges and pyramids are split into tetrahedra (tests/unit/geometry/test_mesh_hex.py); what is
    still refused is named with its count and the supported list."""
    cube = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
                    float)
    meshio.write(tmp_path / "hex.inp", meshio.Mesh(cube, [("hexahedron", [list(range(8))])]))
    assert len(read_mesh_file(tmp_path / "hex.inp").cells) in (5, 6)       # split, no longer refused
    pts = np.vstack([cube[:6], 0.5 * (cube[:6] + cube[[1, 2, 0, 4, 5, 3]]), 0.5 * (cube[:3] + cube[3:6])])
    pts = np.vstack([pts, pts[6:9] + [0, 0, 0.5]])
    meshio.write(tmp_path / "wedge18.vtu", meshio.Mesh(pts, [("wedge18", [list(range(18))])]))
    with pytest.raises(MeshImportError, match=r"unsupported volume elements: wedge18 \(1 elements\); "
                                              r"supported: linear and quadratic tetrahedra, hexahedra, wedges"):
        read_mesh_file(tmp_path / "wedge18.vtu")
    (tmp_path / "x.stl").write_text("solid x\nendsolid x\n")
    with pytest.raises(MeshImportError, match=r"unknown mesh format '.stl'"):
        read_mesh_file(tmp_path / "x.stl")


def _with_cell(mf, i, nodes):
    cells = mf.cells.copy()
    cells[i] = nodes
    return type(mf)(mf.points, cells, mf.cell_ids, mf.cell_sets, mf.surfaces, mf.node_sets, mf.format)


def test_inverted_and_degenerate_elements_are_errors_with_their_ids(ring):
    tmp, mf = ring
    c = mf.cells[5]
    # swap corners 1 and 2 (and the mid-edge nodes with them): the element turns inside out
    flipped = c[[0, 2, 1, 3, 6, 5, 4, 7, 9, 8]]
    write_mesh_file(_with_cell(mf, 5, flipped), tmp / "inv.inp")
    mapping = dict(parts={"disc": ["disc"]}, faces={})
    with pytest.raises(MeshImportError, match=r"geometry.file: 1 inverted \(det J <= 0\) elements: \[6\]"):
        prepare(tmp / "inv.inp", **mapping)
    # a curved element whose mid-edge node is pulled past the opposite face: corners fine, det J < 0 inside
    bent = mf.points.copy()
    a, b, mid = c[0], c[1], c[4]
    opposite = mf.points[c[[2, 3]]].mean(axis=0)
    bent[mid] = mf.points[mid] + 1.5 * (opposite - 0.5 * (mf.points[a] + mf.points[b]))
    m2 = type(mf)(bent, mf.cells, mf.cell_ids, mf.cell_sets, mf.surfaces, mf.node_sets, mf.format)
    write_mesh_file(m2, tmp / "bent.inp")
    with pytest.raises(MeshImportError, match=r"inverted \(det J <= 0\) elements: \[.*6.*\]"):
        prepare(tmp / "bent.inp", **mapping)
    # a linear mesh of a good tetrahedron and a flat one (corner 4 on the plane of 1-2-3)
    from geometry.mesh_file import MeshFile

    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [2, 0, 0], [3, 0, 0], [2, 1, 0], [2.3, 0.3, 0]],
                   float)
    two = MeshFile(pts, np.array([[0, 1, 2, 3], [4, 5, 6, 7]]), np.array([1, 2]),
                   {"all": np.array([0, 1])}, {}, {}, "abaqus")
    write_mesh_file(two, tmp / "flat.inp")
    with pytest.raises(MeshImportError,
                       match=r"1 degenerate \(zero volume or aspect ratio > 1e4\) elements: \[2\]"):
        prepare(tmp / "flat.inp", parts={"p": ["all"]}, faces={})


def test_poor_elements_and_mm_meshes_warn(ring):
    tmp, mf = ring
    write_mesh_file(mf, tmp / "r.inp")
    _, info = prepare(tmp / "r.inp", parts={"disc": ["disc"]}, faces={}, max_aspect_ratio=1.5)
    assert any(w.startswith("geometry.max_aspect_ratio:") for w in info["warnings"])
    mm = type(mf)(mf.points * 1000, mf.cells, mf.cell_ids, mf.cell_sets, mf.surfaces, mf.node_sets, mf.format)
    write_mesh_file(mm, tmp / "mm.inp")
    _, info = prepare(tmp / "mm.inp", parts={"disc": ["disc"]}, faces={})
    assert any("millimetres: set geometry.scale = 0.001" in w for w in info["warnings"])
    _, info = prepare(tmp / "mm.inp", parts={"disc": ["disc"]}, faces={}, scale=1e-3)
    assert info["warnings"] == []
    from geometry.mesh_file import mesh_file_mesh

    with pytest.warns(UserWarning, match="millimetres") if COMM.rank == 0 else warnings.catch_warnings():
        mesh_file_mesh(COMM, file=str(tmp / "mm.inp"), parts={"disc": ["disc"]}, faces={})


def test_abaqus_assemblies_are_refused(ring):
    tmp, mf = ring
    write_mesh_file(mf, tmp / "r.inp")
    text = (tmp / "r.inp").read_text()
    (tmp / "asm.inp").write_text(text.replace("*NODE", "*PART, NAME=A\n*NODE", 1) + "*NODE\n99999, 0, 0, 0\n")
    with pytest.raises(MeshImportError, match="Abaqus assembly .2 \\*NODE blocks"):
        read_mesh_file(tmp / "asm.inp")


def test_axis_and_scale_turn_the_mesh_onto_z():
    x = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.3, -0.2, 0.7]])
    y = transform_points(x, 2.0, [0.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    assert np.allclose(y[0], [0, 0, 2]) and np.allclose(np.linalg.norm(y, axis=1), 2 * np.linalg.norm(x, axis=1))
    assert np.allclose(transform_points(x, 1.0, [0, 0, 0], [0, 0, -1])[2], [0, 0, -1])
    assert np.allclose(transform_points(x, 1.0, [1, 0, 0], [0, 0, 1]), x - [1, 0, 0])


def test_convert_cli_keeps_the_sets_and_bad_files_exit_2(ring, tmp_path):
    tmp, mf = ring
    write_mesh_file(mf, tmp / "r.inp")
    cli = [sys.executable, "-m", "fem_squeal.cli"]
    p = subprocess.run(cli + ["convert", str(tmp / "r.inp"), str(tmp_path / "r.bdf"), "--scale", "1000"],
                       capture_output=True, text=True, env=clean_env())
    assert p.returncode == 0, p.stderr
    back = read_mesh_file(tmp_path / "r.bdf")
    assert {"disc", "top", "bottom", "inner", "outer"} <= set(back.cell_sets) | set(back.surfaces)
    # GRID* prints 11-12 significant digits: 1e-10 of the largest coordinate bounds the difference
    assert np.abs(back.points - 1000 * mf.points).max() < 1e-10 * np.abs(1000 * mf.points).max()
    (tmp_path / "bad.inp").write_text("*NODE\n1, 0, 0, 0\n*ELEMENT, TYPE=C3D4\n1, 1, 2\n")
    p = subprocess.run(cli + ["convert", str(tmp_path / "bad.inp"), str(tmp_path / "bad.vtu")],
                       capture_output=True, text=True, env=clean_env())
    assert p.returncode == 2 and p.stderr.startswith("fem-squeal: error: geometry.file: cannot read bad.inp")
    assert p.stderr.count("\n") == 1 and not (tmp_path / "bad.vtu").exists()


def test_scene_errors_for_mesh_files(ring, tmp_path):
    tmp, mf = ring
    write_mesh_file(mf, tmp / "r.inp")
    scene = tmp_path / "s.toml"
    scene.write_text(f"""
[geometry]
builder = "mesh_file"
file = "{tmp / 'r.inp'}"
parts = {{ disc = "rotor" }}
faces = {{ top = ["top"] }}
[materials.disc]
E = 3e9
nu = 0.4
rho = 1400
[interfaces.top]
face = "top"
kn = 1e10
[analyses.real_modes]
n_modes = 4
""")
    cli = [sys.executable, "-m", "fem_squeal.cli", "--cache-dir", str(tmp_path / "c"), "run", str(scene),
           "-o", str(tmp_path / "out")]
    p = subprocess.run(cli, capture_output=True, text=True, env=clean_env())
    assert p.returncode == 2, p.stdout + p.stderr
    assert "fem-squeal: error: geometry.parts.disc: no element set 'rotor' in the file; available: ['disc']" \
        in p.stderr
    for override, message in [
        ("geometry.file=nope.inp", "geometry.file: .*nope.inp does not exist"),
        (f"geometry.file={scene}", "geometry.file: unknown mesh format '.toml'"),
        ("materials.rotor.E=1", "materials.rotor: unknown part; parts of mesh_file: \\['disc'\\]"),
        ("interfaces.top.face=bottom", "interfaces.top.face: unknown face 'bottom'; faces: \\['top'\\]"),
        ("geometry.axis=[0, 0, 0]", "geometry.axis: must not be zero"),
        ("geometry.parts.disc=[]", "geometry.parts.disc: must be a set name or number"),
        ("geometry.faces.disc=['top']", "geometry.faces.disc: also a part name"),
    ]:
        with pytest.raises(SceneError, match=message):
            load_scene(scene, [override])


# --- verification: the gmsh brake through Abaqus and Nastran files --------------------------------
BRAKE = ROOT / "scenes" / "brake_corner_cea.toml"
IMPORT = ROOT / "scenes" / "brake_import_abaqus.toml"
ANALYSES = ["geometry.mesh_size=0.016", "analyses.cea.band_hz=[0.0, 6000.0]", "analyses.cea.n_modes=30",
            "analyses.real_modes.n_modes=12"]


class _BrakeRuns(dict):
    """The native brake run and its Abaqus and Nastran round trips, each computed when first asked
    for (the Nastran one only by the slow test): format -> results."""

    def __init__(self, base):
        super().__init__()
        self.base = base
        self.quiet = dict(log=lambda *a: None, write_fields=False, report=False)
        self.native_scene = load_scene(BRAKE, ANALYSES)
        self.physics = ANALYSES[1:] + ["analyses.real_modes.n_modes=12"]

    def __missing__(self, fmt):
        from geometry.nastran import hypermesh_names

        base, quiet, native = self.base, self.quiet, self.native_scene
        if fmt == "native":
            scene = native
        elif fmt == "abaqus":
            write_geometry(COMM, native["geometry"], base / "brake_mm.inp", scale=1000.0)
            scene = load_scene(IMPORT, [f"geometry.file={base / 'brake_mm.inp'}", *self.physics])
        else:
            write_geometry(COMM, native["geometry"], base / "brake.bdf")
            pids = {name: pid for pid, name in hypermesh_names(base / "brake.bdf").items()}
            by_number = [f"geometry.{kind}.{n}=[{pids[n]}]" for kind, names in
                         (("parts", native["materials"]), ("faces", load_scene(IMPORT)["geometry"]["faces"]))
                         for n in names]
            scene = load_scene(IMPORT, [f"geometry.file={base / 'brake.bdf'}", "geometry.scale=1.0", *by_number,
                                        *self.physics])
        self[fmt] = run_scene(scene, base / fmt, COMM, cache=base / "cache", **quiet)
        return self[fmt]


@pytest.fixture(scope="module")
def brake_runs(tmp_path_factory):
    return _BrakeRuns(tmp_path_factory.mktemp("brake_import"))


def _lam(r):
    return np.array([complex(m["real_part"], 2 * np.pi * m["freq_hz"]) for m in r["complex_modes"]])


# Behind the slow marker: two coarse-brake runs per format (87 s of one worker of the default suite,
# the largest item).  The default suite keeps the brake through a deck in the 2-rank import demo
# (its CEA against the native brake's, 1e-8) and every writer and reader in the ring round trip above.
@pytest.mark.slow
@pytest.mark.parametrize("fmt", ["abaqus", "nastran"])
def test_round_trip_gives_the_native_real_and_complex_modes(brake_runs, fmt):
    native, other = brake_runs["native"], brake_runs[fmt]
    strip = lambda m: {k: v for k, v in m.items() if k != "penalty"}  # noqa: E731
    assert strip(other["model"]) == strip(native["model"])
    # penalty ratios: medians of element sizes, equal up to the coordinates' round trip
    assert [p["name"] for p in other["model"]["penalty"]] == [p["name"] for p in native["model"]["penalty"]]
    for p, q in zip(native["model"]["penalty"], other["model"]["penalty"]):
        assert q["ratio"] == pytest.approx(p["ratio"], rel=1e-6)
    assert other["mesh"]["import"]["format"] == fmt and other["mesh"]["import"]["warnings"] == []
    f0 = np.array([m["freq_hz"] for m in native["real_modes"]])
    f1 = np.array([m["freq_hz"] for m in other["real_modes"]])
    assert len(f0) == 12 and np.max(np.abs(f1 - f0) / f0) < 1e-8
    a, b = _lam(native), _lam(other)
    assert len(a) == len(b) and any(m["unstable"] for m in native["complex_modes"])
    assert np.max(np.abs(a - b) / np.abs(a)) < 1e-8
    for face, v in native["preload"]["interfaces"].items():
        assert other["preload"]["interfaces"][face]["normal_force"] == pytest.approx(v["normal_force"], rel=1e-8)


# serial behind the slow marker: the 2-rank run makes the same self-checks (deck = native mesh), and the
# round trip above compares the deck's modes with the native ones; it saves 36 s of the default suite
@pytest.mark.parametrize("ranks", [pytest.param(1, marks=pytest.mark.slow), 2])
def test_import_demo_runs_and_checks_itself(ranks, mpirun, tmp_path):
    cmd = [sys.executable, str(ROOT / "demos" / "import_abaqus_mesh.py"), str(tmp_path),
           # 13 eigenvalues of the deck against the native brake's (1e-8; measured 2.2e-13): the deck's
           # check is the mesh, which any band shows; 0-3 kHz instead of 0-5 kHz: 41.5 -> 34.8 s on 2 ranks
           "--set=analyses.cea.band_hz=[0.0, 3000.0]", "--set=analyses.cea.n_modes=12",
           # nor the CEA's coupling (a real-mode solve in each of the two runs; tested in test_brake.py)
           "--set=analyses.cea.coupling=false"]
    if ranks == 2:
        cmd = mpirun + cmd
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=clean_env())
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    assert p.stdout.count("checks passed") == 1
    res = json.loads((tmp_path / "imported" / "results.json").read_text())
    vtu = meshio.read(tmp_path / "imported" / "complex_modes.vtu")
    assert vtu.cells[0].type == "tetra10" and len(vtu.points) == res["mesh"]["import"]["nodes"]
    assert np.allclose(vtu.field_data["freq_hz"], [m["freq_hz"] for m in res["complex_modes"]])


# --- export: fields on the mesh nodes through meshio ---------------------------------------------
def test_vtu_fields_and_snapshots_are_the_functions_at_the_nodes(tmp_path, ring_mesh):
    """Quadratic fields are exact in P2, so the VTU values at the (curved) P2 nodes equal the
    formulas to round-off; snapshots Φ q from the stored basis (float32: 1e-7 relative) likewise."""
    from dolfinx import fem

    from fem_squeal.fe.output import write_basis_field, write_vtu
    from fem_squeal.util.vtu import write_snapshots

    md = ring_mesh()
    V = fem.VectorFunctionSpace(md.mesh, ("Lagrange", 2))
    S = fem.FunctionSpace(md.mesh, ("Lagrange", 2))
    u = fem.Function(V)
    u.interpolate(lambda x: np.vstack([x[0] * x[1], x[2], x[0]]))
    p = fem.Function(S)
    p.interpolate(lambda x: x[0] + x[1] ** 2)
    path = tmp_path / "f.vtu"
    write_vtu(COMM, path, V, {"u": u.vector}, {"freq_hz": [1.5, 2.5]}, scalars={"p": p})
    cols = []
    zero = np.zeros_like
    for f in (lambda x: np.vstack([x[0], zero(x[0]), zero(x[0])]),
              lambda x: np.vstack([zero(x[0]), x[1] * x[2], zero(x[0])])):
        g = fem.Function(V)
        g.interpolate(f)
        cols.append(g.x.array[: V.dofmap.index_map.size_local * 3].copy())
    write_basis_field(COMM, tmp_path / "basis_field.npz", V, np.column_stack(cols))
    if COMM.rank == 0:
        m = meshio.read(path)
        x = m.points
        assert m.cells[0].type == "tetra10" and len(x) == md.mesh.geometry.index_map().size_global
        assert np.abs(m.point_data["u"] - np.column_stack([x[:, 0] * x[:, 1], x[:, 2], x[:, 0]])).max() < 1e-14
        assert np.abs(m.point_data["p"] - (x[:, 0] + x[:, 1] ** 2)).max() < 1e-14
        assert list(m.field_data["freq_hz"]) == [1.5, 2.5]
        with np.load(tmp_path / "basis_field.npz") as f:
            field = {k: f[k] for k in f.files}
        write_snapshots(tmp_path / "snap", field, np.array([0.1, 0.2]), np.array([[3.0, 4.0], [1.0, 5.0]]),
                        np.array([1.0, 1.0]))
        s = meshio.read(tmp_path / "snap.vtu")
        y = s.points
        want = np.column_stack([2 * y[:, 0], 3 * y[:, 1] * y[:, 2], 0 * y[:, 0]])
        assert np.abs(s.point_data["u_0"] - want).max() < 1e-6 * np.abs(want).max()
        assert list(s.field_data["time"]) == [0.1, 0.2]
        with meshio.xdmf.TimeSeriesReader(tmp_path / "snap.xdmf") as r:
            r.read_points_cells()
            t, pd, _ = r.read_data(1)
        assert t == 0.2 and np.allclose(pd["u"][:, 1], 4 * y[:, 1] * y[:, 2], atol=1e-6 * np.abs(want).max())


def test_skin_triangles_must_be_boundary_faces(ring):
    from geometry.mesh_file import TET_FACES, _FaceIndex

    _, mf = ring
    index = _FaceIndex(mf.cells)
    faces = mf.cells[:, :4][:, TET_FACES].reshape(-1, 3)
    boundary = {tuple(sorted(f)) for f in index.boundary}
    inner = next(f for f in faces if tuple(sorted(f)) not in boundary)
    outer = next(f for f in faces if tuple(sorted(f)) in boundary)
    assert index.locate(np.array([outer]), "s").shape == (1, 2)
    with pytest.raises(MeshImportError, match="surface 's': 1 triangles lie between two tetrahedra"):
        index.locate(np.array([outer, inner]), "s")
    with pytest.raises(MeshImportError, match="surface 's': 1 triangles are not faces of any tetrahedron"):
        index.locate(np.array([[0, 1, len(mf.points) - 1]]), "s")
