"""Scene validation, --set overrides and the CLI's handling of bad input."""
from __future__ import annotations

import copy
import subprocess
import sys
import tomllib

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support.paths import ROOT
from support.processes import clean_env

from fem_squeal.app.scene import SceneError, apply_overrides, load_scene, model_spec, read_scene, validate

SCENE = ROOT / "scenes" / "ryzhik_ring.toml"


def raw():
    return tomllib.loads(SCENE.read_text())


def test_bundled_scene_validates_with_defaults():
    s = load_scene(SCENE)
    assert s["discretisation"]["degree"] == 2
    assert s["analyses"]["cea"]["method"] == "auto"
    spec = model_spec(s)
    assert {p.face for p in spec.plates} == {"top", "bottom"}
    assert all(p.sliding == 1 and p.mu == 0.3 and p.kn == 1e10 for p in spec.plates)


def test_set_overrides_nested_values():
    s = load_scene(SCENE, ["geometry.width=0.004", "interfaces.top_plate.sliding=-1",
                           "analyses.cea.band_hz=[10, 300]"])
    assert s["geometry"]["width"] == 0.004
    assert s["interfaces"]["top_plate"]["sliding"] == -1
    assert s["analyses"]["cea"]["band_hz"] == [10, 300]


@pytest.mark.parametrize("override, message", [
    ("geometry.width=-0.005", r"^geometry\.width: must be > 0 \(got -0\.005\)$"),
    ("geometry.width=0.2", r"^geometry\.width: must be < 2 \* mean_radius$"),
    ("geometry.widht=0.005", r"^geometry\.widht: unknown key; allowed: \["),
    ("materials.disc.nu=0.5", r"^materials\.disc\.nu: must be in \(-1, 0\.5\)"),
    ("materials.disc.E=high", r"^materials\.disc\.E: must be int or float \(got 'high'\)$"),
    ("materials.disc.E1=8e9", r"^materials\.disc\.E1, E2, E3, nu12, nu13, nu23, G12, G13, G23: give all nine"),
    ("materials.disc.D=[1e9, 2e9, 1e9, 0, 0, 1e9, 1e9, 1e9, 1e9]",
     r"^materials\.disc\.D: the constants give a stiffness that is not positive definite"),
    ("materials.disc.D=[1e9, 2e9]", r"^materials\.disc\.D: must be 9 or 21 numbers"),
    ("materials.disc.orientation={system='polar', a=[0, 0, 0], b=[0, 0, 1]}",
     r"^materials\.disc\.orientation: system: must be 'rectangular' or 'cylindrical'"),
    ("materials.disc.orientation={system='cylindrical', a=[0, 0, 0], b=[0, 0, 1]}",
     r"^materials\.disc\.orientation: only for an orthotropic or anisotropic material"),
    ("interfaces.top_plate.face=rim", r"^interfaces\.top_plate\.face: unknown face 'rim'; faces: \["),
    ("interfaces.top_plate.sliding=2", r"^interfaces\.top_plate\.sliding: must be one of \[-1, 0, 1\]"),
    ("analyses.cea.band_hz=[5000, 100]", r"^analyses\.cea\.band_hz: must be increasing"),
    ("analyses.cea.method=qz", r"^analyses\.cea\.method: must be one of"),
    ("analyses.hbm.n=3", r"^analyses\.hbm: unknown analysis; available:"),
    ("boundary.clamped=['rim']", r"^boundary\.clamped\[0\]: unknown face 'rim'"),
    ("geometry.builder=brake", r"^geometry\.builder: must be one of"),
])
def test_bad_values_name_the_key_and_the_reason(override, message):
    with pytest.raises(SceneError, match=message):
        load_scene(SCENE, [override])


BRAKE = ROOT / "scenes" / "brake_corner_cea.toml"


@pytest.mark.parametrize("override, message", [
    ("geometry.disc_thickness=-0.02", r"^geometry\.disc_thickness: "),
    ("geometry.lining_outer_radius=0.2", r"^geometry\.lining_outer_radius: "),
    ("geometry.matching=1", r"^geometry\.matching: must be bool"),
    ("interfaces.pad_inner.master=rim", r"^interfaces\.pad_inner\.master: unknown face 'rim'; faces: \["),
    ("interfaces.pad_inner.master=lining_inner_contact", r"^interfaces\.pad_inner\.master: must differ"),
    ("interfaces.pad_inner.kn=0", r"^interfaces\.pad_inner\.kn: must be > 0"),
    ("interfaces.pad_inner.type=glue", r"^interfaces\.pad_inner\.type: must be one of"),
    ("interfaces.piston_pad.mu=0.3", r"^interfaces\.piston_pad\.mu: unknown key"),
    ("boundary.ground_springs.guide_pins={face='caliper_guide'}",
     r"^boundary\.ground_springs\.guide_pins: k_axial and"),
    ("loads.pressure.piston.face=rim", r"^loads\.pressure\.piston\.face: unknown face 'rim'"),
    ("loads.pressure={}", r"^loads\.pressure: required for preload\.mode = 'nonlinear'"),
    ("preload.mode=linear", r"^preload\.mode: must be one of"),
    ("materials.lining_inner.E_axial=3e9", r"^materials\.lining_inner\.E_axial, nu_axial, G_axial: give all"),
    ("analyses.cea.describe_part=rotor", r"^analyses\.cea\.describe_part: unknown part 'rotor'"),
    ("analyses.sweep.parameter=E.rotor", r"^analyses\.sweep\.parameter: must be 'mu', 'speed' or 'E\.<part>'"),
    ("analyses.sweep.range=[1.0, -1.0]", r"^analyses\.sweep\.range: must be increasing"),
    ("analyses.map.part=rotor", r"^analyses\.map\.part: unknown part 'rotor'"),
    ("analyses.map.E_range=[2e11, 1e11]", r"^analyses\.map\.E_range: must be increasing"),
    ("analyses.map.n_E=1", r"^analyses\.map\.n_E: must be >= 2"),
    ("analyses.reduced.cut_factors=[0.9, 2.0]", r"^analyses\.reduced\.cut_factors: must be > 1"),
    ("interfaces.pad_outer.mu=0.5", None),
    ("analyses.masa.patches=[8]", r"^analyses\.masa\.patches: must be \[\] or \[n_radial, n_angular\]"),
    ("analyses.masa.attachments=[4, 0]", r"^analyses\.masa\.attachments: must be \[\] or"),
    ("analyses.masa.cubic_share=1.5", r"^analyses\.masa\.cubic_share: must be in \[0, 1\]"),
    ("analyses.masa.amplitude_unit=mm", r"^analyses\.masa\.amplitude_unit: must be one of"),
    ("analyses.masa.contact_damping=[100.0]", r"^analyses\.masa\.contact_damping: must be \[\] or"),
    ("analyses.masa.n_samples=4", r"^analyses\.masa\.n_samples: must be >= 8"),
])
def test_bad_brake_values_name_the_key_and_the_reason(override, message):
    overrides = (["analyses.map.n_E=3"] if message is None or "analyses" in message else []) + [override]
    if "masa" in override:
        overrides = overrides[:-1] + ["analyses.masa.n_amplitudes=10", override]
    if message is None:  # different μ per pad: a reduced model scales one common μ
        with pytest.raises(SceneError, match=r"^interfaces: frictional interfaces have different mu"):
            load_scene(BRAKE, overrides)
        return
    with pytest.raises(SceneError, match=message):
        load_scene(BRAKE, overrides)


def test_brake_scene_builds_its_model_spec():
    ti = ["materials.lining_inner.E_axial=3e9", "materials.lining_inner.nu_axial=0.1",
          "materials.lining_inner.G_axial=1.5e9"]
    spec = model_spec(load_scene(BRAKE, ti))
    assert {i.name for i in spec.contacts} == {"pad_inner", "pad_outer"}
    assert spec.materials["lining_inner"].transversely_isotropic
    assert not spec.materials["lining_outer"].transversely_isotropic
    assert len(spec.pressures) == 2 and len(spec.ground_springs) == 2


def test_missing_required_key():
    r = raw()
    del r["materials"]["disc"]["rho"]
    with pytest.raises(SceneError, match=r"^materials\.disc\.rho: required"):
        validate(r)


def test_cli_bad_value_is_one_line_and_writes_nothing(tmp_path):
    out = tmp_path / "o"
    p = subprocess.run([sys.executable, "-m", "fem_squeal.cli", "run", str(SCENE),
                        "--set", "geometry.width=-1", "-o", str(out)], capture_output=True, text=True,
                       env=clean_env())
    assert p.returncode == 2
    assert p.stderr.strip().splitlines() == ["fem-squeal: error: geometry.width: must be > 0 (got -1)"]
    assert not out.exists()


# Fuzz: random mutations of the bundled scene must give SceneError or a valid scene, never a crash.
values = st.one_of(st.integers(-5, 5), st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=5),
                   st.booleans(), st.lists(st.integers(-3, 3), max_size=3), st.none())


def _paths(d, prefix=()):
    for k, v in d.items():
        yield prefix + (k,)
        if isinstance(v, dict):
            yield from _paths(v, prefix + (k,))


BUNDLED = sorted((ROOT / "scenes").glob("*.toml"))


def _check_valid(s: dict) -> None:
    """A valid scene must also give a model and a plan without error."""
    from fem_squeal.app.pipeline import required, stage_keys

    if "geometry" in s:
        model_spec(s)
    stage_keys(s, required(s), version="fuzz")


@pytest.mark.parametrize("scene", BUNDLED, ids=[p.stem for p in BUNDLED])
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_fuzzed_scenes_give_clear_errors(scene, data):
    base = read_scene(scene)
    paths = sorted(_paths(base))
    mutation = st.tuples(st.sampled_from(paths), values, st.booleans())
    mutations = data.draw(st.lists(mutation, min_size=1, max_size=4))
    r = copy.deepcopy(base)
    for path, value, delete in mutations:
        node = r
        for p in path[:-1]:
            node = node.get(p) if isinstance(node, dict) else None
        if not isinstance(node, dict):
            continue
        if delete:
            node.pop(path[-1], None)
        elif value is None:
            node[path[-1]] = {}
        else:
            node[path[-1]] = value
    try:
        s = validate(r)
    except SceneError as e:
        assert str(e).split(":")[0], e
        assert "\n" not in str(e)
    else:
        _check_valid(s)


# random scenes: arbitrary TOML-like trees over the known section names
keys = st.sampled_from(["title", "geometry", "materials", "analyses", "interfaces", "segmented_pad", "cea",
                        "transient", "speeds", "builder", "disc", "E", "x", "preload", "solver", "extends"])
trees = st.recursive(values, lambda inner: st.dictionaries(keys, inner, max_size=4), max_leaves=12)


@settings(max_examples=300, deadline=None)
@given(tree=st.dictionaries(keys, trees, max_size=5))
def test_random_scenes_give_clear_errors(tree):
    try:
        s = validate(tree)
    except SceneError as e:
        assert "\n" not in str(e) and str(e).split(":")[0]
    else:
        _check_valid(s)


def test_scene_files_that_cannot_be_read(tmp_path):
    (tmp_path / "a.toml").write_text('extends = "b.toml"\n')
    (tmp_path / "b.toml").write_text('extends = "a.toml"\n')
    with pytest.raises(SceneError, match="extended in a cycle"):
        load_scene(tmp_path / "a.toml")
    (tmp_path / "c.toml").write_text("analyses = [")
    with pytest.raises(SceneError, match=r"c\.toml: not valid TOML"):
        load_scene(tmp_path / "c.toml")
    (tmp_path / "d.toml").write_bytes(b"\xff\xfe\x00")
    with pytest.raises(SceneError, match=r"d\.toml: not a text file"):
        load_scene(tmp_path / "d.toml")
    with pytest.raises(SceneError, match=r"e\.toml: no such scene file"):
        load_scene(tmp_path / "e.toml")


@pytest.mark.parametrize("override, message", [
    ("analyses.segmented_pad.speeds=[0.1, 0.05]", r"^analyses\.segmented_pad\.speeds: must be increasing"),
    ("analyses.segmented_pad.velocity_pairs=[[0.01, 0.001]]",
     r"^analyses\.segmented_pad\.velocity_pairs\[0\]: must satisfy 0 < v_s < v_d"),
    ("analyses.segmented_pad.v_d=0.0005", r"^analyses\.segmented_pad\.v_d: must be > v_s"),
    ("analyses.segmented_pad.n_side=0", r"^analyses\.segmented_pad\.n_side: must be >= 1"),
    ("analyses.segmented_pad.dt=1.0", r"^analyses\.segmented_pad\.dt: must be < t_end"),
    ("geometry.builder=annular_disc", r"^geometry\.mean_radius: required"),
])
def test_bad_segmented_pad_values(override, message):
    with pytest.raises(SceneError, match=message):
        load_scene(ROOT / "scenes" / "segmented_pad.toml", [override])


@pytest.mark.parametrize("override, message", [
    ("analyses.transient.dt=1.0", r"^analyses\.transient\.dt: must be < t_end"),
    ("analyses.transient.alpha=-0.5", r"^analyses\.transient\.alpha: must be in \[-1/3, 0\]"),
    ("analyses.transient.friction=viscous", r"^analyses\.transient\.friction: must be one of"),
    ("analyses.transient.patches=[8]", r"^analyses\.transient\.patches: must be \[\] or"),
    ("preload.mode=all_closed", r"^analyses\.transient: needs preload\.mode = 'nonlinear'"),
])
def test_bad_transient_values(override, message):
    with pytest.raises(SceneError, match=message):
        load_scene(ROOT / "scenes" / "brake_transient.toml", [override])


def test_limit_cycle_needs_the_transient():
    with pytest.raises(SceneError, match=r"^analyses\.limit_cycle: needs analyses\.transient"):
        r = read_scene(ROOT / "scenes" / "brake_transient.toml")
        del r["analyses"]["transient"]
        validate(r)


def test_override_syntax_errors():
    with pytest.raises(SceneError, match="expected key.path=value"):
        apply_overrides(raw(), ["geometry.width"])
    with pytest.raises(SceneError, match="is not a table"):
        apply_overrides(raw(), ["title.x=1"])


def test_masa_needs_a_nonlinear_preload():
    with pytest.raises(SceneError, match=r"^analyses\.masa: needs preload\.mode = 'nonlinear'"):
        load_scene(BRAKE, ["analyses.masa.n_amplitudes=10", "preload.mode=all_closed"])


def test_scene_is_typed_frozen_and_hashes_its_plain_content():
    """validate returns frozen typed sections: attribute and key access give the same value, nothing
    can be changed after validation, "not set" reads None (also in the older spelling 0), and the
    cache key and results.json see exactly the plain tables (json of the section == json of the dict)."""
    import dataclasses
    import json

    from fem_squeal.app.fields import Section, plain

    raw = read_scene(ROOT / "scenes" / "ryzhik_ring.toml")
    s = validate(copy.deepcopy(raw))
    assert isinstance(s, Section) and isinstance(s.preload, Section)
    assert s.preload.tol == s["preload"]["tol"] == 1e-9
    assert s.interfaces["top_plate"].mu == raw["interfaces"]["top_plate"]["mu"]
    assert s.discretisation.quadrature_degree is None
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.preload.tol = 1.0
    with pytest.raises(TypeError):
        s.preload["tol"] = 1.0
    assert s.preload.replace(tol=1e-6).tol == 1e-6 and s.preload.tol == 1e-9
    legacy = validate(apply_overrides(raw, ["discretisation.quadrature_degree=0"]))
    assert legacy.discretisation.quadrature_degree is None
    six = validate(apply_overrides(raw, ["discretisation.quadrature_degree=6"]))
    assert six.discretisation.quadrature_degree == 6
    with pytest.raises(SceneError, match=r"^discretisation\.quadrature_degree: must be > 0 \(got -1\)"):
        validate(apply_overrides(raw, ["discretisation.quadrature_degree=-1"]))
    p = plain(s)
    assert type(p) is dict and type(p["preload"]) is dict and p["preload"] == dict(s.preload)
    # the cache key hashes the tables' content, never a repr of the section objects
    from fem_squeal.app.pipeline import _canonical
    assert _canonical(s) == json.dumps(p, sort_keys=True, separators=(",", ":"))
    assert "Preload(" not in _canonical({"inputs": s.preload})
    assert "geometry" in s and "geometry" not in validate({"analyses": {"segmented_pad": {}}})


def test_model_spec_is_built_once_by_the_validation(monkeypatch):
    """The validation pass builds the scene's model description; the cache keys read that one (no
    second build per run), and a scene changed with replace gets its own."""
    import fem_squeal.app.scene.validation as validation
    from fem_squeal.app.pipeline import required, stage_keys

    s = load_scene(SCENE)
    spec = s.spec
    assert spec is not None and model_spec(s) is spec

    def refuse(*a, **k):
        raise AssertionError("model_spec built again")

    monkeypatch.setattr(validation, "build_model_spec", refuse)
    assert stage_keys(s, required(s), version="once") and model_spec(s) is spec
    with pytest.raises(AssertionError, match="built again"):
        model_spec(s.replace(title="changed"))
    monkeypatch.undo()
    changed = s.replace(title="changed")
    assert model_spec(changed) == spec and model_spec(changed) is model_spec(changed)
