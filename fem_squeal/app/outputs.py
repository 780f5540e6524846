"""The output folder of a run: the user's own files, replaced all at once or not at all.

A run's outputs (the stages' files from the cache, ``results.json``, ``report.html``) are first
written into a staging folder inside the output folder (:func:`staged_outputs`); only when all of
them are there are they renamed over the old ones.  A failure before that (a full disk, a report
section that raised) removes the staging folder and leaves every earlier output unchanged.

Stage files are **copies** of the cache's (:func:`fem_squeal.util.storage.clone_file`: a
copy-on-write clone where the file system offers one), never hard links, and each copy is checked
against the entry's manifest before it is published: a user who edits an output changes neither
the cache nor what the next run publishes, and a cache file that changed after it was verified is
never published.  An output that already holds the entry's bytes is left as it is.
"""
from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from fem_squeal.app.cache import INDEX, file_problem
from fem_squeal.util.errors import PipelineError, StorageError
from fem_squeal.util.storage import clone_file, free_bytes, mib, storage_errors

#: field files (XDMF, its HDF5, VTU) and the mode pictures drawn from them (``mode_shapes.npz`` and
#: ``mode_shapes/``: fem_squeal.app.mode_shapes): in the cache always, published only when fields are asked for
FIELD_SUFFIXES = (".xdmf", ".h5", ".vtu")
FIELD_PREFIXES = ("mode_shapes.", "mode_shapes/")
STAGING_PREFIX = ".fem_squeal-staging."
#: a staging folder older than this [s] was left by a killed run and is removed by the next one
STALE_STAGING_S = 3600.0


def is_field(rel: str) -> bool:
    return rel.endswith(FIELD_SUFFIXES) or rel.startswith(FIELD_PREFIXES)


@contextmanager
def staged_outputs(outdir: Path) -> Iterator[Path]:
    """Yield a staging folder inside ``outdir``; on success move each file in it over its name in
    ``outdir`` (``os.replace``, no space needed), on failure remove it: ``outdir`` then holds exactly
    what it held before."""
    outdir = Path(outdir)
    with storage_errors("creating the output folder", outdir):
        outdir.mkdir(parents=True, exist_ok=True)
        for old in outdir.glob(STAGING_PREFIX + "*"):          # left by a run killed while publishing
            if old.is_dir() and time.time() - old.stat().st_mtime > STALE_STAGING_S:
                shutil.rmtree(old, ignore_errors=True)
        stage = Path(tempfile.mkdtemp(prefix=STAGING_PREFIX, dir=outdir))
    try:
        yield stage
        files = sorted(p for p in stage.rglob("*") if p.is_file())
        for p in files:                                   # folders first: nothing below can fail for space
            (outdir / p.relative_to(stage)).parent.mkdir(parents=True, exist_ok=True)
        for p in files:
            os.replace(p, outdir / p.relative_to(stage))
    finally:
        shutil.rmtree(stage, ignore_errors=True)


def publish(entry: Path, outdir: Path, stage: Path, fields: bool = True) -> list[str]:
    """Copy a verified cache entry's files (field files only with ``fields``) into the staging
    folder ``stage`` of ``outdir``, checking each copy's size and SHA-256 against the manifest;
    files that ``outdir`` already holds with those bytes are not copied.  Returns the published
    names (relative to ``outdir``)."""
    files = json.loads((entry / INDEX).read_text())["files"]
    names = [rel for rel in sorted(files) if fields or not is_field(rel)]
    todo = [rel for rel in names if file_problem(outdir / rel, files[rel], rel)]
    needed = sum(files[rel]["size"] for rel in todo)
    if needed and needed > free_bytes(stage):
        raise StorageError(f"{outdir}: no space left for the outputs of {entry.name} ({mib(needed)} needed, "
                           f"{mib(free_bytes(stage))} free on that file system)")
    for rel in todo:
        dst = stage / rel
        with storage_errors(f"copying {entry.name}/{rel} into the output folder", outdir, needed):
            dst.parent.mkdir(parents=True, exist_ok=True)
            clone_file(entry / rel, dst)
        if file_problem(dst, files[rel], rel):
            raise PipelineError(f"cache entry {entry}: {rel} changed after it was verified; nothing was "
                                "published; run again (the entry is recomputed)")
    return names


def remove_stale_outputs(outdir: Path, old_files: list[str], files: list[str]) -> None:
    """Delete the files that an earlier run listed (``old_files``, from its ``results.json``) and this
    run did not write (a MASA plot of a μ no longer asked for), so the folder shows one run."""
    for name in set(old_files) - set(files):
        p = (outdir / name).resolve()
        if outdir.resolve() in p.parents and p.is_file():
            p.unlink()


def listed_outputs(outdir: Path) -> list[str]:
    """The files that ``outdir/results.json`` lists ([] when there is none or it is unreadable)."""
    try:
        return list(json.loads((outdir / "results.json").read_text()).get("files", []))
    except (OSError, ValueError, AttributeError):
        return []
