"""The stage graph of a scene run, its content-hash cache and the plan.

A scene asks for analyses; each analysis is a stage, and each stage names the stages it needs (the
stages are declared in the registry :mod:`fem_squeal.app.analyses`)::

    mesh → operators → preload → real_modes
                               → cea
                               → reduced → sweep, map, masa, transient → limit_cycle
    segmented_pad (no mesh: a lumped model)

:func:`required` closes the requested analyses over ``needs``; nothing else is built (a ring
scene with a CEA builds no reduced model, the segmented pad builds no mesh).

Cache
-----
Every stage's output (its ``results.json`` section, its timings and its files) is stored in
``<cache>/<stage>-<key>/`` (:mod:`fem_squeal.app.cache`: written atomically, every file recorded by
size and SHA-256 and verified before use).  The key hashes what the stage reads: its part of the
scene (the ``inputs`` function of its :class:`Stage`), the keys of the stages it needs, and the code
version (a hash of the package sources), so

- a re-run of an unchanged scene computes nothing;
- a change recomputes the stages whose inputs changed and those downstream of them only (a new
  ``analyses.sweep.n`` re-runs the sweep on the cached reduced model; a new μ re-runs the
  preload and everything after it, because the static state depends on μ);
- output choices (``--no-fields``, ``--no-report``) are not inputs: a stage always keeps its field
  files in its entry, and the run publishes them or not (:mod:`fem_squeal.app.outputs`);
- an entry that fails verification is a miss for that stage alone: the plan says why, and the stage
  is recomputed.

The in-memory products of ``mesh``, ``operators`` and ``preload`` (a dolfinx mesh, PETSc
matrices) are not stored: when a stage that needs them must run, they are rebuilt in memory
(the plan says ``memory``) even if their own summary is cached.  Rank 0 owns every cache write and
makes the plan; the other ranks receive it.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
from collections.abc import Iterable
from contextlib import contextmanager
from pathlib import Path
from typing import Any, NamedTuple

from fem_squeal.app.analyses import STAGES
from fem_squeal.app.cache import Cache, Verdict  # noqa: F401  (public here since the cache moved)
from fem_squeal.app.fields import plain
from fem_squeal.app.outputs import publish  # noqa: F401  (public here since publishing moved)
from fem_squeal.app.scene import model_spec
from fem_squeal.util.errors import PipelineError

CACHE_ENV = "FEM_SQUEAL_CACHE"


def required(scene: dict) -> list[str]:
    """Stages needed by the scene's analyses, in execution order."""
    want: set[str] = set()

    def pull(name: str) -> None:
        if name not in want:
            want.add(name)
            for n in STAGES[name].needs_of(scene):
                pull(n)

    for name in scene.analyses:
        pull(name)
    return [n for n in STAGES if n in want]


def downstream(names: Iterable[str], among: list[str], scene=None) -> set[str]:
    """``names`` and every stage of ``among`` that (transitively) needs one of them (in ``scene``:
    :meth:`~fem_squeal.app.stage.Stage.needs_of`)."""
    out = set(names)
    for n in among:  # ``among`` is in execution order, so one pass suffices
        if any(d in out for d in (STAGES[n].needs if scene is None else STAGES[n].needs_of(scene))):
            out.add(n)
    return out


def code_version() -> str:
    """Hash of the package sources (fem_squeal and geometry, Python and the compiled kernels' C): any
    code change invalidates the cache."""
    root = Path(__file__).resolve().parents[2]
    h = hashlib.sha256()
    for pkg in ("fem_squeal", "geometry"):
        for p in sorted(q for pattern in ("*.py", "*.c", "*.h") for q in (root / pkg).rglob(pattern)):
            h.update(str(p.relative_to(root)).encode())
            h.update(p.read_bytes())
    return h.hexdigest()[:16]


def _canonical(obj: Any) -> str:
    """JSON of what a key hashes: typed scene sections as the plain tables they hold."""
    return json.dumps(plain(obj), sort_keys=True, separators=(",", ":"), default=repr)


def stage_keys(scene: dict, stages: list[str], *, write_fields: bool = True,
               version: str | None = None) -> dict[str, str]:
    """Content key of each stage: hash of (stage, its inputs, upstream keys, code version).  A stage's
    inputs may read the scene's model description: the one its validation built
    (:func:`~fem_squeal.app.scene.model_spec`, not built again here).  ``write_fields`` is accepted for
    old callers and ignored: output choices are not inputs."""
    version = version or code_version()
    spec = model_spec(scene) if "geometry" in scene else None
    keys: dict[str, str] = {}
    for name in stages:
        st = STAGES[name]
        payload = {"stage": name, "inputs": st.key_inputs(scene, spec),
                   "upstream": [keys[n] for n in st.needs_of(scene)], "code": version}
        keys[name] = hashlib.sha256(_canonical(payload).encode()).hexdigest()[:20]
    return keys


class PlanItem(NamedTuple):
    stage: str
    key: str
    status: str       # "cached" | "run" | "memory" (rebuilt in memory only) | "forced"
    note: str = ""    # why a stage runs although an entry exists (it failed verification)


@contextmanager
def scratch(comm):
    """A temporary folder on every rank (the same path), removed afterwards: where a stage that is
    only rebuilt in memory writes the files nobody keeps."""
    tmp = comm.bcast(tempfile.mkdtemp(prefix="fem_squeal_scratch.") if comm.rank == 0 else None, root=0)
    try:
        yield Path(tmp)
    finally:
        comm.barrier()
        if comm.rank == 0:
            shutil.rmtree(tmp, ignore_errors=True)


def make_plan(scene: dict, cache: Cache, *, force: Iterable[str] = (), write_fields: bool = True,
              version: str | None = None) -> list[PlanItem]:
    """What a run would do: each required stage is cached (its entry verifies), run (absent, or
    failing verification: ``note`` says why), forced (``force`` and every stage after it), or rebuilt
    in ``memory`` for a stage after it that runs.  ``write_fields`` is ignored (output choices are
    not inputs)."""
    stages = required(scene)
    force = list(force)
    if "all" in force:
        force = list(stages)
    unknown = sorted(set(force) - set(stages))
    if unknown:
        raise PipelineError(f"--force {unknown[0]}: not a stage of this scene; its stages: {stages}")
    keys = stage_keys(scene, stages, version=version)
    forced = downstream(force, stages, scene)
    status, notes = {}, {}
    for n in stages:
        if n in forced:
            status[n] = "forced"
            continue
        v = cache.verify(n, keys[n])
        status[n] = "cached" if v.state == "ok" else "run"
        if v.state == "bad":
            notes[n] = f"cache entry {n}-{keys[n]}: {v.reason}; recomputed"
    for n in reversed(stages):   # a stage that runs needs the in-memory products of its upstream
        if status[n] in ("run", "forced", "memory"):
            for d in STAGES[n].needs_of(scene):
                if STAGES[d].memory and status[d] == "cached":
                    status[d] = "memory"
    return [PlanItem(n, keys[n], status[n], notes.get(n, "")) for n in stages]


def format_plan(plan: list[PlanItem]) -> str:
    words = {"cached": "cached  ", "run": "run     ", "forced": "forced  ", "memory": "memory  "}
    lines = [f"  {words[p.status]} {p.stage:<14} {p.key}  {STAGES[p.stage].doc}" for p in plan]
    n_run = sum(p.status != "cached" for p in plan)
    return "\n".join([f"  warning: {p.note}" for p in plan if p.note] + lines
                     + [f"  {n_run} of {len(plan)} stages to compute"
                        + (" (memory: rebuilt in memory, its cached outputs kept)"
                           if any(p.status == "memory" for p in plan) else "")])


def default_cache_dir() -> Path:
    """``$FEM_SQUEAL_CACHE`` if set, else ``$XDG_CACHE_HOME/fem_squeal`` (``~/.cache/fem_squeal``): never
    the working folder or the checkout (``--cache-dir .fem_squeal_cache`` keeps a cache there)."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV])
    xdg = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(xdg) / "fem_squeal"
