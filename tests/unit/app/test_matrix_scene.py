"""A scene whose model is given as matrices ([matrices], scenes/matrices_brake.toml): validated in one
pass before anything is computed, each bad input a one-line error naming its key (exit 2), the stages
real_modes and cea started from the ``matrices`` stage, cached by the files' content."""
from __future__ import annotations

import shutil
import tomllib

import pytest
import scipy.io as sio
import scipy.sparse as sp
from support.paths import ROOT

from fem_squeal.app.cli import main
from fem_squeal.app.pipeline import Cache, make_plan, required, stage_keys
from fem_squeal.app.scene import load_scene, validate
from fem_squeal.util.errors import ExpressionError, SceneError

SCENE = ROOT / "scenes" / "matrices_brake.toml"


@pytest.fixture
def scene_dir(tmp_path):
    """A copy of the example scene and its matrices (files may be changed)."""
    shutil.copytree(ROOT / "scenes" / "matrices", tmp_path / "matrices",
                    ignore=shutil.ignore_patterns("*.py", "__pycache__"))
    shutil.copy(SCENE, tmp_path / "scene.toml")
    return tmp_path


def _raw(folder):
    """The raw table of the example scene with its files made absolute (as read_scene does)."""
    from fem_squeal.app.scene import read_scene

    return read_scene(folder / "scene.toml")


def test_example_scene_validates():
    s = load_scene(SCENE)
    assert s.matrices.dofs == 48
    assert s.matrices.files["DG"].variable == "DG" and s.matrices.files["DR"].variable == ""
    assert s.matrices.parameters["W"].range == [0.5, 3.0]
    assert required(s) == ["matrices", "real_modes", "cea", "sweep"]
    assert "geometry" not in s and s.spec is None


def test_cache_key_follows_the_content_not_the_path(scene_dir, tmp_path):
    a = stage_keys(load_scene(SCENE), ["matrices", "cea"], version="v")
    b = stage_keys(load_scene(scene_dir / "scene.toml"), ["matrices", "cea"], version="v")
    assert a == b                               # the same files elsewhere
    K = sio.mmread(str(scene_dir / "matrices" / "KR.mtx")).tocsr() * 2.0
    sio.mmwrite(str(scene_dir / "matrices" / "KR.mtx"), K, precision=17)
    c = stage_keys(load_scene(scene_dir / "scene.toml"), ["matrices", "cea"], version="v")
    assert c["matrices"] != a["matrices"] and c["cea"] != a["cea"]
    plan = make_plan(load_scene(SCENE), Cache(tmp_path / "cache"))
    assert [(p.stage, p.status) for p in plan] == [("matrices", "run"), ("real_modes", "run"), ("cea", "run"),
                                                   ("sweep", "run")]


def _bad(folder, change):
    raw = _raw(folder)
    change(raw)
    return raw


def _wrong_size(folder):
    sio.mmwrite(str(folder / "matrices" / "small.mtx"), sp.eye(47).tocoo())
    def change(r):
        r["matrices"]["files"].update(KR=str(folder / "matrices" / "small.mtx"))
        del r["matrices"]["dofs"]
    return change


BAD = [
    ("unknown matrix", lambda r: r["matrices"].update(K="K1 + KX"), SceneError,
     r"matrices.K: unknown name 'KX'"),
    ("unknown parameter", lambda r: r["matrices"].update(C="D1 + V*DG + DR + D4"), SceneError,
     r"matrices.C: unknown name 'V'"),
    ("refused construct", lambda r: r["matrices"].update(K="K1.T + KR + KGEO"), SceneError,
     r"matrices.K: attribute access is not allowed"),
    ("import", lambda r: r["matrices"].update(K="__import__('os').system('true')*K1 + KR + KGEO"), SceneError,
     r"matrices.K: calls other than"),
    ("matrix product", lambda r: r["matrices"].update(K="K1*KR + KGEO"), SceneError,
     r"matrices.K: a matrix times a matrix"),
    ("unused matrix", lambda r: r["matrices"].update(K="K1 + KR"), SceneError,
     r"matrices.files.KGEO: not used by the operators"),
    ("missing file", lambda r: r["matrices"]["files"].update(KR="/nonexistent/KR.mtx"), SceneError,
     r"matrices.files.KR: /nonexistent/KR.mtx does not exist"),
    ("dofs", lambda r: r["matrices"].update(dofs=50), SceneError,
     r"matrices.files.M: .*mass.rsa is 48×48, but matrices.dofs = 50"),
    ("variable", lambda r: r["matrices"]["files"].update(DG={"file": r["matrices"]["files"]["DR"]["file"],
                                                             "variable": "DX"}), SceneError,
     r"matrices.files.DG: .*damping.mat: no variable 'DX'; variables: \['DG', 'DR'\]"),
    ("format", lambda r: r["matrices"]["files"]["DG"].update(format="op4"), SceneError,
     r"matrices.files.DG.format: must be one of"),
    ("reserved name", lambda r: r["matrices"]["parameters"].update(pi=3.0), SceneError,
     r"matrices.parameters.pi: the name 'pi' cannot be used"),
    ("range", lambda r: r["matrices"]["parameters"].update(W={"value": 5.0, "range": [0.5, 3.0]}), SceneError,
     r"matrices.parameters.W: the value 5.0 is outside its range"),
    ("not finite", lambda r: r["matrices"]["parameters"].update(W=0.0), SceneError,
     r"matrices.C: the coefficient 1.0 / W - 1.0 of DR is not a finite number at W = 0.0"),
    # a vectorised check over the sweep's values names the first bad one, on one line (hypothesis found the
    # whole array printed over several lines)
    ("sweep through a pole", lambda r: (r["matrices"]["parameters"].update(W=1.0),
                                        r["analyses"]["sweep"].update(range=[0.0, 1.0])), SceneError,
     r"^analyses.sweep.range: matrices.C: the coefficient 1.0 / W - 1.0 of DR is not a finite number at W = 0.0$"),
    ("geometry", lambda r: r.update(geometry={"builder": "annular_disc"}), SceneError,
     r"geometry: not used by a model given as matrices"),
    ("analysis", lambda r: r["analyses"].update(transient={}), SceneError,
     r"analyses.transient: not available for a model given as matrices; available: "
     r"\['cea', 'map', 'real_modes', 'robustness', 'sensitivity', 'sweep'\]"),
]


@pytest.mark.parametrize("what,change,error,message", BAD, ids=[b[0] for b in BAD])
def test_bad_input_is_named(scene_dir, what, change, error, message):
    with pytest.raises(error, match=message) as e:
        validate(_bad(scene_dir, change))
    assert "\n" not in str(e.value)
    if what in ("unknown matrix", "refused construct", "import", "matrix product"):
        assert isinstance(e.value.__cause__, ExpressionError)      # the parser's refusal, with its kind


def test_wrong_size_names_the_file_and_both_sizes(scene_dir):
    with pytest.raises(SceneError, match=r"^matrices.files.KR: .*small.mtx is 47×47, but matrices.files.M "
                                         r"\(mass.rsa\) is 48×48$"):
        validate(_bad(scene_dir, _wrong_size(scene_dir)))


def test_cli_exit_2_before_any_computation(scene_dir, tmp_path, capsys):
    text = (scene_dir / "scene.toml").read_text().replace('K = "K1 + KR + (W**2 - 1)*KGEO"',
                                                          'K = "K1 + KR + (W**2 - 1)*KGEO[0]"')
    (scene_dir / "bad.toml").write_text(text)
    assert tomllib.loads(text)["matrices"]["K"].endswith("[0]")
    code = main(["--cache-dir", str(tmp_path / "cache"), "run", str(scene_dir / "bad.toml"), "-o",
                  str(tmp_path / "out")])
    assert code == 2
    assert "matrices.K: a subscript is not allowed ('KGEO[0]')" in capsys.readouterr().err
    assert not (tmp_path / "out").exists() and not (tmp_path / "cache").exists()
