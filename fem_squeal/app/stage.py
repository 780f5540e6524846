"""What one stage of a run is (:class:`Stage`, declared once by its module in
:mod:`fem_squeal.app.analyses`) and what the stages of one run share (:class:`Context`).

A stage is a model stage (``mesh``, ``operators``, ``preload``: no scene section of its own) or an
analysis (a section ``analyses.<name>``).  Its declaration carries everything the rest of the
application needs: the stages it needs (the pipeline closes a scene's analyses over them), what it
reads of the scene (its cache key), its section's fields and cross-checks (the scene loader), the
function that computes it, and its part of the report.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fem_squeal.app.fields import Field
from fem_squeal.reduced.model import ReducedModel


class Context:
    """What the stages of one run share: the scene and its model description (``spec``; None for a
    lumped scene), the communicator, the in-memory products of the stages run so far
    (``products``) and the cache entries of the stages before.  ``write_fields``: whether this run
    publishes field files (stages write them into their entry either way)."""
    def __init__(self, scene: dict, spec, comm, say, write_fields: bool, cache, keys: dict[str, str]):
        self.scene, self.spec, self.comm, self.say, self.write_fields = scene, spec, comm, say, write_fields
        self.cache, self.keys = cache, keys
        self.products: dict[str, Any] = {}
        #: False while a cached stage is rebuilt in memory only (its files would be thrown away)
        self.keep_files = True

    def entry(self, stage: str) -> Path:
        """The committed cache folder of an upstream stage (its files)."""
        return self.cache.entry(stage, self.keys[stage])

    def reduced_model(self) -> ReducedModel:
        """The reduced model: this run's, or the cached ``reduced_model.npz``."""
        if "reduced" not in self.products:
            self.products["reduced"] = ReducedModel.load(self.entry("reduced") / "reduced_model.npz")
        return self.products["reduced"]


#: ``run(ctx, work, timings)``: compute, write the stage's files into ``work`` (its cache entry),
#: fill ``timings`` [s] and return its sections of results.json.
StageFunction = Callable[[Context, Path, dict], dict]


@dataclass(frozen=True)
class Stage:
    """One stage, declared by its module (see the package docstring of ``fem_squeal.app.analyses``)."""
    name: str
    needs: tuple[str, ...]
    run: StageFunction
    doc: str = ""
    #: what the stage reads, ``inputs(scene, spec)``: its part of the cache key.  None: its own section.
    inputs: Callable[[dict, Any], Any] | None = None
    #: fields of ``analyses.<name>``; None for a model stage (mesh, operators, preload)
    section: dict[str, Field] | None = None
    #: cross-checks of the validated section against the rest of the scene: ``check(scene, volumes)``
    #: raises :class:`~fem_squeal.util.errors.SceneError` naming the key
    check: Callable[[dict, Any], None] | None = None
    #: its part of report.html from the results: ``report(results)`` -> HTML ('' when it has none)
    report: Callable[[dict], str] | None = None
    memory: bool = False          # provides an in-memory product to the stages after it
    fields: bool = False          # writes field files (XDMF/VTU): cached always, published unless --no-fields
    lumped: bool = False          # needs no finite-element model (no geometry, no materials)
    pulled: bool = False          # an analysis that needs it pulls it in with its defaults
    #: its function for a model given as matrices (a scene with ``[matrices]``,
    #: :mod:`fem_squeal.app.analyses.matrices`): it then needs the ``matrices`` stage alone; None: the
    #: analysis is not available there
    on_matrices: StageFunction | None = None
    #: its section ``analyses.<name>`` on a model given as matrices, where it differs (None: :attr:`section`)
    section_on_matrices: dict[str, Field] | None = None

    def needs_of(self, scene) -> tuple[str, ...]:
        """The stages this one needs in ``scene``: ``("matrices",)`` where the model is given as matrices
        and the stage runs on them, else :attr:`needs`."""
        return ("matrices",) if "matrices" in scene and self.on_matrices is not None else self.needs

    def key_inputs(self, scene: dict, spec) -> Any:
        """The part of the validated scene that this stage reads (hashed into its cache key)."""
        return self.inputs(scene, spec) if self.inputs is not None else scene.analyses[self.name]
