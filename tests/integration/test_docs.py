"""The user guide builds (``bash scripts/docs.sh``: Sphinx with warnings as errors) and its scene
reference is generated from the schema in code: every analysis of the registry, every interface
type and every key of their sections appears in it, and the generated page is exactly what
:mod:`fem_squeal.app.schema_reference` renders now (nothing hand-copied, nothing stale)."""
from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import time

import pytest
from support.paths import ROOT
from support.processes import clean_env

from fem_squeal.app.analyses import ANALYSES
from fem_squeal.app.scene import GEOMETRY, INTERFACES, MATERIAL, SECTIONS
from fem_squeal.app.schema_reference import render_scene_reference


def _can_build() -> str | None:
    """None when scripts/docs.sh can build, else why not (skip reason)."""
    if importlib.util.find_spec("sphinx") and importlib.util.find_spec("myst_parser"):
        return None
    if shutil.which("apt-get") is None or (os.geteuid() != 0 and shutil.which("sudo") is None):
        return "sphinx/myst_parser not importable and apt-get (as root or with sudo) not available to install them"
    return None


def test_user_guide_builds_with_the_generated_scene_reference():
    reason = _can_build()
    if reason:
        pytest.skip(reason)
    t = time.perf_counter()
    # -E: read every page again, so that a warning of any page (or docstring) fails the build
    p = subprocess.run(["bash", str(ROOT / "scripts" / "docs.sh"), "-E", "-q"], cwd=ROOT, capture_output=True,
                       text=True, timeout=600, env=clean_env())
    seconds = time.perf_counter() - t
    assert p.returncode == 0, f"docs build failed ({seconds:.0f} s):\n{p.stdout[-4000:]}\n{p.stderr[-6000:]}"
    html = ROOT / "docs" / "_build" / "html"
    for page in ("index", "installation", "validation", "architecture", "reference/scene", "reference/results",
                 "api/reduced", "tutorials/reduced_sweep_map"):
        assert (html / f"{page}.html").is_file(), page

    scene_md = (ROOT / "docs" / "reference" / "scene.md").read_text(encoding="utf-8")
    assert scene_md == render_scene_reference(), "docs/reference/scene.md is not the reference the code renders"
    for name, stage in ANALYSES.items():
        assert f"`analyses.{name}`" in scene_md, name
        for key in stage.section:
            assert f"`analyses.{name}.{key}`" in scene_md, f"analyses.{name}.{key}"
    assert "`analyses.sweep.n`" in scene_md and "`interfaces.<name>`" in scene_md
    for kind, fields in INTERFACES.items():
        assert f'`type = "{kind}"`' in scene_md, kind
        assert all(f"`{key}`" in scene_md for key in fields if key != "type"), kind
    for builder, fields in GEOMETRY.items():
        assert f'geometry.builder = "{builder}"' in scene_md, builder
        assert all(f"`geometry.{key}`" in scene_md for key in fields if key != "builder"), builder
    assert all(f"`{key}`" in scene_md for key in MATERIAL)
    assert all(f"`{sec}.{key}`" in scene_md for sec, fields in SECTIONS.items() for key in fields)

    scene_html = (html / "reference" / "scene.html").read_text(encoding="utf-8")
    assert "analyses.segmented_pad" in scene_html and "band_hz" in scene_html
    results_html = (html / "reference" / "results.html").read_text(encoding="utf-8")
    assert "schema_version" in results_html and "complex_modes" in results_html   # run.py's docstring
