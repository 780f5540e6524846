"""Abaqus/CalculiX squeal decks: the model reader (geometry.abaqus_model), its translation into a scene
(fem_squeal.app.deck) and ``fem-squeal convert model.inp scene.toml`` / ``fem-squeal run model.inp``."""
from __future__ import annotations

import math
import tomllib

import pytest

from geometry.abaqus import AbaqusError
from geometry.abaqus_model import read_model, rigid_sets, rotation

# a pad (PAD, elements 1-2), a backplate tied to it (BACK, element 3) and a rigid plate under the pad (PLATE,
# element 4, every node prescribed); the plate is pressed in step 1 and turned by θ = +1e-4 about z in step 2
R0, R1 = 0.04, 0.06


def _hex(e: int, n0: int, z0: float, z1: float, r0=R0, r1=R1, t0=0.0, t1=0.2) -> tuple[list[str], list[str]]:
    nodes, k = [], n0
    for z in (z0, z1):
        for r, t in ((r0, t0), (r1, t0), (r1, t1), (r0, t1)):
            nodes.append(f"{k}, {r * math.cos(t):.12g}, {r * math.sin(t):.12g}, {z:.12g}")
            k += 1
    return nodes, [f"{e}, " + ", ".join(str(n0 + i) for i in range(8))]


def _mesh() -> str:
    lines = ["*NODE"]
    elems = {}
    for e, n0, z0, z1, t0, t1 in ((1, 1, 0.0, 0.01, 0.0, 0.1), (2, 9, 0.0, 0.01, 0.1, 0.2),
                                  (3, 17, 0.01, 0.02, 0.0, 0.2),
                                  (4, 25, -0.002, 0.0, 0.0, 0.2)):
        n, el = _hex(e, n0, z0, z1, t0=t0, t1=t1)
        lines += n
        elems[e] = el
    lines += ["*ELEMENT, TYPE=C3D8, ELSET=PAD", *elems[1], *elems[2], "*ELEMENT, TYPE=C3D8, ELSET=BACK", *elems[3],
              "*ELEMENT, TYPE=C3D8, ELSET=PLATE", *elems[4],
              "*NSET, NSET=NPLATE, GENERATE", "25, 32, 1", "*NSET, NSET=NBACK", "18, 19, 22, 23",
              "*SURFACE, NAME=PADBOT, TYPE=ELEMENT", "PAD, S1", "*SURFACE, NAME=PADTOP, TYPE=ELEMENT", "PAD, S2",
              "*SURFACE, NAME=BACKBOT, TYPE=ELEMENT", "BACK, S1",
              "*SURFACE, NAME=BACKTOP, TYPE=ELEMENT", "BACK, S2",
              "*SURFACE, NAME=PLATETOP, TYPE=ELEMENT", "PLATE, S2"]
    return "\n".join(lines) + "\n"


def _turn(theta: float) -> list[str]:
    out = []
    for i in range(8):
        t = 0.0 if i % 4 in (0, 1) else 0.2
        r = R0 if i % 4 in (0, 3) else R1
        x, y = r * math.cos(t), r * math.sin(t)
        out += [f"{25 + i}, 1, 1, {-theta * y:.12g}", f"{25 + i}, 2, 2, {theta * x:.12g}"]
    return out


MODEL = """*HEADING
a squeal deck of every supported keyword
*INCLUDE, INPUT=mesh/parts.inp
*MATERIAL, NAME=LINING
*ELASTIC, TYPE=ENGINEERING CONSTANTS
8e9, 8e9, 2e9, 0.25, 0.1, 0.1,
3.2e9, 1e9, 1e9
*DENSITY
2500.
*DAMPING, ALPHA=1.5, BETA=2e-7
*MATERIAL, NAME=STEEL
*ELASTIC
2.1e11, 0.3
*DENSITY
7850.
*SOLID SECTION, ELSET=PAD, MATERIAL=LINING
*SOLID SECTION, ELSET=BACK, MATERIAL=STEEL
*SOLID SECTION, ELSET=PLATE, MATERIAL=STEEL
*TIE, NAME=glue
PADTOP, BACKBOT
*SURFACE INTERACTION, NAME=SI
*SURFACE BEHAVIOR, PRESSURE-OVERCLOSURE=LINEAR
1e12, 100.
*FRICTION
0.4004, 1e11
*CONTACT PAIR, INTERACTION=SI, TYPE=NODE TO SURFACE
PADBOT, PLATETOP
*BOUNDARY
NPLATE, 1, 2
NBACK, 1, 2
*STEP
*STATIC
0.5, 1.
*BOUNDARY
NPLATE, 3, 3, 1e-8
*DLOAD
BACKTOP, P, 2e5
*NODE PRINT, NSET=NBACK
U
*END STEP
*STEP
*STATIC
*BOUNDARY
{turn}
*END STEP
*STEP, PERTURBATION
*CHANGE FRICTION, INTERACTION=SI
*FRICTION
0.4, 1e11
*FREQUENCY
6
*EL FILE
S
*END STEP
"""


@pytest.fixture(scope="module")
def deck(tmp_path_factory):
    d = tmp_path_factory.mktemp("deck")
    (d / "mesh").mkdir()
    (d / "mesh" / "parts.inp").write_text(_mesh())
    (d / "model.inp").write_text(MODEL.format(turn="\n".join(_turn(1e-4))))
    return d / "model.inp"


def test_reader_reads_every_supported_keyword(deck):
    m = read_model(deck)
    lining = m.materials["LINING"]
    assert lining["E"].value == 8e9 and lining["E_axial"].value == 2e9 and lining["G_axial"].value == 1e9
    assert lining["nu_axial"].value == pytest.approx(0.1 * 2e9 / 8e9)
    assert (lining["rho"].value, lining["rayleigh_alpha"].value,
            lining["rayleigh_beta"].value) == (2500, 1.5, 2e-7)
    assert lining["E"].where == "model.inp line 5"
    assert m.sections["PAD"].value == "LINING" and m.ties == [("glue", "PADTOP", "BACKBOT", "model.inp line 20")]
    si = m.interactions["SI"]
    assert (si.kn.value, si.sigma_inf, si.mu.value, si.stick.value) == (1e12, 100.0, 0.4004, 1e11)
    assert m.pairs == [("SI", "PADBOT", "PLATETOP", "model.inp line 27")]
    assert [s.procedure for s in m.steps] == ["STATIC", "STATIC", "FREQUENCY"]
    assert m.steps[2].perturbation and m.steps[2].data == [6.0] and m.steps[2].friction["SI"][0].value == 0.4
    assert m.steps[0].dload == [("BACKTOP", "P", 2e5, "model.inp line 37")]
    assert any("*NODE PRINT" in n and "ignored" in n for n in m.notes)
    assert set(rigid_sets(m)) == {"PLATE"}
    (theta, where), = rotation(m, m.elset_nodes("PLATE"))
    assert theta == pytest.approx(1e-4) and where.startswith("model.inp line")


def test_deck_scene_round_trip(deck):
    from fem_squeal.app.deck import deck_scene, write_scene
    from fem_squeal.app.scene import load_scene

    raw = deck_scene(deck).raw
    geo = raw["geometry"]
    assert geo["parts"] == {"PAD": ["PAD"], "BACK": ["BACK"]} and geo["skip_sets"] == ["PLATE"] and geo["deck"]
    pad = raw["materials"]["PAD"]
    assert pad["E_axial"] == 2e9 and pad["rayleigh_beta"] == 2e-7
    plate = raw["interfaces"]["PADBOT_PLATETOP"]
    assert plate["type"] == "rigid_plate" and plate["face"] == "PADBOT" and plate["sliding"] == 1
    assert plate["kn"] == 1e12 and plate["mu"] == 0.4 and plate["kt"] == pytest.approx(1e11 * 0.4 / 0.4004)
    assert raw["interfaces"]["glue"] == {"type": "bonded", "slave": "PADTOP", "master": "BACKBOT"}
    assert raw["boundary"]["fixed"]["NBACK"] == {"face": "NBACK", "components": ["x", "y"]}
    assert raw["loads"]["pressure"]["BACKTOP"] == {"face": "BACKTOP", "p": 2e5}
    assert raw["preload"]["mode"] == "all_closed" and raw["analyses"] == {
        "cea": {"n_modes": 6, "target_hz": 1.0, "band_hz": [0.0, 1e9]}}
    out = deck.parent / "scenes" / "scene.toml"
    write_scene(deck, out)
    text = out.read_text()
    assert "[boundary.fixed.NBACK]    # model.inp line 30: *BOUNDARY" in text
    assert "kt = " in text and "model.inp line 63: *FRICTION stick slope" in text
    assert tomllib.loads(text)["geometry"]["file"] == "../model.inp"      # relative to the scene's folder
    scene = load_scene(out)
    assert scene.interfaces["PADBOT_PLATETOP"].kt == pytest.approx(plate["kt"])
    assert scene.materials["PAD"].E_axial == 2e9 and list(scene.geometry.skip_sets) == ["PLATE"]


def test_frequency_and_complex_frequency_steps(deck):
    """Abaqus's pair of steps: *FREQUENCY -> real_modes, *COMPLEX FREQUENCY (n, f_min, f_max) -> cea; a
    second step of one kind is refused."""
    from fem_squeal.app.deck import deck_scene
    from fem_squeal.util.errors import MeshError

    two = deck.parent / "two.inp"
    text = deck.read_text().replace("*FREQUENCY\n6\n", "*FREQUENCY\n6\n*END STEP\n*STEP, PERTURBATION\n"
                                    "*COMPLEX FREQUENCY\n4, 100., 5000.\n")
    two.write_text(text)
    assert deck_scene(two).raw["analyses"] == {
        "real_modes": {"n_modes": 6, "target_hz": 1.0},
        "cea": {"n_modes": 4, "target_hz": 2550.0, "band_hz": [100.0, 5000.0]}}
    two.write_text(text.replace("*COMPLEX FREQUENCY", "*FREQUENCY"))
    with pytest.raises(MeshError, match=r"two.inp line 69: \*FREQUENCY: a second one"):
        deck_scene(two)


@pytest.mark.parametrize("edit, message", [
    (("*DENSITY\n2500.", "*DENSITY\n2500.\n*PLASTIC\n1e8, 0."), "model.inp line 10: *PLASTIC: not supported"),
    (("*STEP, PERTURBATION", "*CLOAD\n999, 3, 1.\n*STEP, PERTURBATION"),
     "model.inp line 62: *CLOAD: no node set or node '999'"),
    (("*STEP, PERTURBATION", "*CLOAD\nNBACK, 4, 1.\n*STEP, PERTURBATION"), "line 62: *CLOAD, 4: only forces"),
    (("PRESSURE-OVERCLOSURE=LINEAR", "PRESSURE-OVERCLOSURE=EXPONENTIAL"),
     "line 22: *SURFACE BEHAVIOR, PRESSURE-OVERCLOSURE=EXPONENTIAL: only LINEAR"),
    (("0.25, 0.1, 0.1,", "0.25, 0.1, 4.0,"),
     "line 5: *ELASTIC of *MATERIAL LINING: nu12, nu13, nu23: the constants give a stiffness that is not"),
    (("*SOLID SECTION, ELSET=PAD, MATERIAL=LINING", "*SOLID SECTION, ELSET=PAD, MATERIAL=LINING, ORIENTATION=OR"),
     "line 16: *SOLID SECTION, ORIENTATION=OR: no such *ORIENTATION"),
    (("*SOLID SECTION, ELSET=PAD,",
      "*ORIENTATION, NAME=OR, SYSTEM=SPHERICAL\n0,0,0,0,0,1\n*SOLID SECTION, ELSET=PAD,"),
     "line 16: *ORIENTATION, SYSTEM=SPHERICAL: only RECTANGULAR and CYLINDRICAL"),
    (("*STATIC\n*BOUNDARY", "*STATIC\n*MOTION, TRANSLATION, TYPE=VELOCITY\nNPLATE, 1, 1, 1.\n*BOUNDARY"),
     "*MOTION, TRANSLATION: parameter not supported"),
    (("BACKTOP, P, 2e5", "PAD, P2, 2e5"), "line 37: *DLOAD PAD, P2: element-face pressure"),
    (("NBACK, 1, 2", "NBACK, 1, 2, 1e-6"), "line 30: *BOUNDARY NBACK, 1, 2, 1e-06: a nonzero prescribed"),
    (("*FREQUENCY\n6", "*COMPLEX FREQUENCY, FRICTION DAMPING=YES\n6"),
     "line 65: *COMPLEX FREQUENCY, FRICTION DAMPING: parameter not supported"),
    (("NPLATE, 3, 3, 1e-8", "NPLATE, 3, 3, 1e-8\n*BOUNDARY, OP=NEW\nNPLATE, 3, 3, 1e-8"),
     "*BOUNDARY, OP=NEW: only OP=MOD"),
    (("*EL FILE", "*MODAL DAMPING\n1, 6, 0.01\n*EL FILE"), "line 67: *MODAL DAMPING: not supported"),
    (("INPUT=mesh/parts.inp", "INPUT=parts.inp"), "model.inp line 3: *INCLUDE, INPUT=parts.inp: no such file"),
])
def test_refused_constructs_name_keyword_file_and_line(deck, edit, message):
    from fem_squeal.app.deck import deck_scene
    from fem_squeal.util.errors import MeshError

    bad = deck.parent / "bad.inp"
    text = deck.read_text()
    assert edit[0] in text
    bad.write_text(text.replace(edit[0], edit[1], 1))
    with pytest.raises(MeshError) as e:
        deck_scene(bad)
    msg = str(e.value).replace("bad.inp", "model.inp")
    assert message in msg and "\n" not in msg


def test_include_is_relative_to_the_including_file(tmp_path):
    (tmp_path / "a" / "b").mkdir(parents=True)
    (tmp_path / "a" / "b" / "nodes.inp").write_text("*NODE\n1, 0, 0, 0\n2, 1, 0, 0\n3, 0, 1, 0\n4, 0, 0, 1\n")
    (tmp_path / "a" / "mesh.inp").write_text("*INCLUDE, INPUT=b/nodes.inp\n"
                                             "*ELEMENT, TYPE=C3D4, ELSET=S\n1, 1, 2, 3, 4\n")
    (tmp_path / "top.inp").write_text("*INCLUDE, INPUT=a/mesh.inp\n*MATERIAL, NAME=M\n*ELASTIC\n1e9, 0.3\n")
    m = read_model(tmp_path / "top.inp")
    assert len(m.mesh.points) == 4 and m.materials["M"]["E"].where == "top.inp line 3"
    (tmp_path / "a" / "mesh.inp").write_text("*INCLUDE, INPUT=nodes.inp\n")
    with pytest.raises(AbaqusError, match=r"mesh.inp line 1: \*INCLUDE, INPUT=nodes.inp: no such file"):
        read_model(tmp_path / "top.inp")


@pytest.mark.slow
def test_run_deck_as_it_is(deck, tmp_path):
    """``fem-squeal run model.inp``: the deck converted in memory runs (native hexahedra, the rigid plate left
    out of the mesh, the tie, the pressure, the fixed node set) and gives its modes; a refused keyword exits 2.
    Slow: 44 s on the shared machine (the hexahedral forms compile cold); benchmarks/cea_calculix.py --deck runs
    the target deck."""
    import json

    from fem_squeal.app.cli import main

    out = tmp_path / "out"
    assert main(["--cache-dir", str(tmp_path / "cache"), "--log-level", "warning", "run", str(deck),
                 "-o", str(out), "--no-fields", "--no-report"]) == 0
    res = json.loads((out / "results.json").read_text())
    assert res["mesh"]["import"]["elements"] == 3 and res["mesh"]["import"]["hexahedra"]["path"] == "native"
    assert len(res["complex_modes"]) >= 6
    bad = deck.parent / "bad_run.inp"
    bad.write_text(deck.read_text().replace("*EL FILE", "*MODAL DAMPING\n1, 6, 0.01\n*EL FILE"))
    assert main(["--cache-dir", str(tmp_path / "cache"), "run", str(bad), "-o", str(tmp_path / "o2")]) == 2


def test_orientation_cload_and_motion(deck):
    """Orthotropic constants in a cylindrical *ORIENTATION, a *CLOAD and the disc's *MOTION become an editable
    scene: materials.PAD.E1 … G23 with its orientation, loads.point.n<node> (components summed), and the
    sliding direction of the rotation rate, the same as the prescribed rotation of equal sign gives."""
    from fem_squeal.app.deck import deck_scene, write_scene
    from fem_squeal.app.scene import load_scene

    text = deck.read_text().replace("3.2e9, 1e9, 1e9", "3.1e9, 1e9, 0.9e9").replace(
        "*SOLID SECTION, ELSET=PAD, MATERIAL=LINING",
        "*ORIENTATION, NAME=CYL, SYSTEM=CYLINDRICAL\n0, 0, 0, 0, 0, 1\n"
        "*SOLID SECTION, ELSET=PAD, MATERIAL=LINING, ORIENTATION=cyl").replace(
        "*DLOAD\n", "*CLOAD\nNBACK, 3, -10.\n18, 1, 2.\n*DLOAD\n")
    turn = text[text.index("*STATIC\n*BOUNDARY\n25, 1"):text.index("*END STEP\n*STEP, PERTURBATION")]
    motion = deck.parent / "motion.inp"
    for omega, sign in ((50.0, 1), (-50.0, -1)):
        motion.write_text(text.replace(turn, f"*STATIC\n*MOTION, ROTATION, TYPE=VELOCITY\nNPLATE, {omega}, "
                                             "0., 0., 0., 0., 0., 1.\n"))
        ds = deck_scene(motion)
        assert ds.raw["interfaces"]["PADBOT_PLATETOP"]["sliding"] == sign
        assert "*MOTION, ROTATION" in ds.origin["interfaces.PADBOT_PLATETOP.sliding"]
    pad = ds.raw["materials"]["PAD"]
    assert (pad["E1"], pad["E3"], pad["nu23"], pad["G23"]) == (8e9, 2e9, 0.1, 0.9e9) and "E" not in pad
    assert pad["orientation"] == {"system": "cylindrical", "a": [0.0, 0.0, 0.0], "b": [0.0, 0.0, 1.0],
                                  "c": [0.0, 0.0, 0.0]}
    assert ds.raw["loads"]["point"]["n18"]["force"] == [2.0, 0.0, -10.0]
    assert ds.raw["loads"]["point"]["n19"]["force"] == [0.0, 0.0, -10.0]
    write_scene(motion, deck.parent / "motion.toml")
    scene = load_scene(deck.parent / "motion.toml")
    from fem_squeal.app.scene.validation import model_spec

    spec = model_spec(scene)
    mat = spec.materials["PAD"]
    assert scene.materials["PAD"].orientation["system"] == "cylindrical"
    assert mat.anisotropic and mat.orientation.system == "cylindrical" and mat.E == pytest.approx(8e9)
    assert {p.name: p.force for p in spec.point_loads}["n18"] == (2.0, 0.0, -10.0)
    motion.write_text(text.replace(turn, "*STATIC\n*MOTION, ROTATION, TYPE=VELOCITY\nNPLATE, 50., 0., 0., 0., "
                                         "1., 0., 0.\n"))
    from fem_squeal.util.errors import MeshError

    with pytest.raises(MeshError, match=r"motion.inp line \d+: \*MOTION, ROTATION: the axis must be the z axis"):
        deck_scene(motion)


def _transport_decks(deck, omega: float) -> dict:
    """The fixture's disc rotation (the second static step) as a *MOTION rate in a *STATIC step and as a
    *TRANSPORT VELOCITY in a *STEADY STATE TRANSPORT step, same ω about +z: {"motion": text, "transport": text}."""
    text = deck.read_text()
    turn = text[text.index("*STATIC\n*BOUNDARY\n25, 1"):text.index("*END STEP\n*STEP, PERTURBATION")]
    return {"motion": text.replace(turn, f"*STATIC\n*MOTION, ROTATION, TYPE=VELOCITY\nNPLATE, {omega}, "
                                         "0., 0., 0., 0., 0., 1.\n"),
            "transport": text.replace(turn, f"*STEADY STATE TRANSPORT, ELSET=PLATE\n0.1, 1.\n*TRANSPORT VELOCITY\n"
                                            f"NPLATE, {omega}\n")}


def test_transport_velocity_gives_the_scene_of_the_motion(deck):
    """*TRANSPORT VELOCITY in a *STEADY STATE TRANSPORT step (Abaqus: node set, ω about the disc axis) gives
    the scene the equivalent *MOTION deck gives (hence the same run): the sliding direction of ω's sign, the
    steady-state step as the preload; convert writes it with the keyword and line it came from."""
    from fem_squeal.app.deck import deck_scene, write_scene
    from fem_squeal.app.scene import load_scene

    for omega, sign in ((50.0, 1), (-50.0, -1)):
        scenes = {}
        for kind, text in _transport_decks(deck, omega).items():
            (deck.parent / f"{kind}.inp").write_text(text)
            scenes[kind] = deck_scene(deck.parent / f"{kind}.inp")
        same = [{**ds.raw, "title": "", "geometry": {**ds.raw["geometry"], "file": ""}} for ds in scenes.values()]
        assert same[0] == same[1]       # all but the deck's name
        assert scenes["transport"].raw["interfaces"]["PADBOT_PLATETOP"]["sliding"] == sign
        assert scenes["transport"].raw["preload"] == {"mode": "all_closed"}
    ds = scenes["transport"]
    where = ds.origin["interfaces.PADBOT_PLATETOP.sliding"]
    assert where.startswith("transport.inp line 45:") and "*TRANSPORT VELOCITY, ω = -50 rad/s about z" in where
    for kind in scenes:
        write_scene(deck.parent / f"{kind}.inp", deck.parent / f"{kind}.toml")
    text = (deck.parent / "transport.toml").read_text()
    assert "*TRANSPORT VELOCITY, ω = -50 rad/s" in text
    a, b = (load_scene(deck.parent / f"{k}.toml") for k in ("transport", "motion"))
    assert a.interfaces == b.interfaces and a.preload == b.preload and a.analyses == b.analyses


@pytest.mark.parametrize("edit, message", [
    (("*STEADY STATE TRANSPORT, ELSET=PLATE", "*STATIC"),
     r"transport.inp line 45: \*TRANSPORT VELOCITY: only in a \*STEADY STATE TRANSPORT step"),
    (("NPLATE, 50.0\n", "NPLATE, 50.0\n*MOTION, ROTATION, TYPE=VELOCITY\nNPLATE, 1., 0, 0, 0, 0, 0, 1\n"),
     r"transport.inp line 47: \*MOTION in a \*STEADY STATE TRANSPORT step .* is not supported"),
    (("TRANSPORT, ELSET=PLATE", "TRANSPORT, ELSET=PLATE, INERTIA=YES"),
     r"transport.inp line 42: \*STEADY STATE TRANSPORT, INERTIA=YES: not supported"),
    (("TRANSPORT, ELSET=PLATE", "TRANSPORT, ELSET=PAD"),
     r"transport.inp line 45: \*TRANSPORT VELOCITY NPLATE: nodes outside the Eulerian element set ELSET=PAD"),
    (("TRANSPORT, ELSET=PLATE", "TRANSPORT, ELSET=DISC"),
     r"transport.inp line 42: \*STEADY STATE TRANSPORT, ELSET=DISC: no such element set"),
    (("*TRANSPORT VELOCITY", "*TRANSPORT VELOCITY, AMPLITUDE=RAMP"),
     r"transport.inp line 44: \*TRANSPORT VELOCITY, AMPLITUDE: parameter not supported"),
    (("NPLATE, 50.0", "NPLATE, 50.0, 0., 0., 0., 0., 0., 1."),
     r"transport.inp line 45: \*TRANSPORT VELOCITY: expected node set or node, ω \(the axis is \*SYMMETRIC MODEL "
     "GENERATION"),
    (("NPLATE, 50.0", "NOPE, 50.0"), r"transport.inp line 45: \*TRANSPORT VELOCITY: no node set or node 'NOPE'"),
    (("*STEP, PERTURBATION\n", "*STEP, PERTURBATION\n*STEADY STATE TRANSPORT\n*END STEP\n*STEP, PERTURBATION\n"),
     r"transport.inp line 48: \*STEADY STATE TRANSPORT: a static perturbation step is not supported"),
])
def test_transport_velocity_refused_combinations(deck, edit, message):
    from fem_squeal.app.deck import deck_scene
    from fem_squeal.util.errors import MeshError

    text = _transport_decks(deck, 50.0)["transport"]
    assert edit[0] in text
    bad = deck.parent / "transport.inp"
    bad.write_text(text.replace(edit[0], edit[1], 1))
    with pytest.raises(MeshError, match=message) as e:
        deck_scene(bad)
    assert "\n" not in str(e.value)
