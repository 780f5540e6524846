"""The stage cache: one folder per computed stage, whose files are checked before any of them is used.

An entry ``<root>/<stage>-<key>/`` holds the stage's files and ``entry.json``: the stage's sections
of results.json, its timings, and a **manifest** of its files (size and SHA-256 of each), the whole
index sealed by the SHA-256 of its own canonical JSON (``seal``).  An entry is

- written into a temporary folder and renamed into place only when complete (:meth:`Cache.writing`),
  so an interrupted run leaves no entry;
- **verified** before it counts as cached (:meth:`Cache.verify`): the index parses, its seal matches,
  and every file of the manifest exists with its size and digest.  Anything else (a truncated, edited
  or deleted file, a cut or bit-flipped index) is a *miss* for that entry alone, with the reason: the
  stage is recomputed and its new entry replaces the bad one.  Nothing unverified reaches an output
  folder (:func:`fem_squeal.app.outputs.publish` checks the copies' digests again).

Rank 0 owns every cache read and write; the other ranks receive its verdicts (the plan is broadcast).
Two runs on one cache at once are safe: each computes into its own temporary folder, and the second
to finish keeps the first one's verified entry (a pure function of the key) unless it was forced.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any, NamedTuple

from mpi4py import MPI

from fem_squeal.util.atomic import jsonable, write_json_atomic
from fem_squeal.util.errors import PipelineError
from fem_squeal.util.storage import digest, storage_errors

INDEX = "entry.json"
#: a leftover temporary folder of an interrupted run older than this [s] is removed by ``cache --verify``
STALE_TEMPORARY_S = 3600.0


def seal(entry: dict) -> str:
    """SHA-256 of the canonical JSON of ``entry`` without its ``seal`` key."""
    body = {k: v for k, v in entry.items() if k != "seal"}
    return hashlib.sha256(json.dumps(jsonable(body), sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def manifest(folder: Path) -> dict[str, dict[str, Any]]:
    """``{relative path: {"size", "sha256"}}`` of every file under ``folder`` but the index."""
    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_file() and p.name != INDEX:
            size, sha = digest(p)
            out[str(p.relative_to(folder))] = {"size": size, "sha256": sha}
    return out


def file_problem(path: Path, rec: dict[str, Any], rel: str) -> str:
    """'' when ``path`` has the size and SHA-256 of its manifest record ``rec``, else why not (the
    file named ``rel``).  The size is compared first: a truncated file is not hashed."""
    try:
        size = path.stat().st_size
    except OSError:
        return f"{rel} is missing"
    if size != rec["size"]:
        return f"{rel} has {size} bytes, {rec['size']} recorded (truncated or rewritten)"
    if digest(path)[1] != rec["sha256"]:
        return f"{rel} does not match its recorded SHA-256 (corrupted or edited)"
    return ""


class Verdict(NamedTuple):
    """What :meth:`Cache.verify` found: ``state`` "ok", "absent" or "bad" (then ``reason`` says why)."""
    state: str
    reason: str = ""


class Cache:
    """Stage entries ``<root>/<stage>-<key>/`` holding ``entry.json`` and the stage's files."""

    def __init__(self, root: str | os.PathLike):
        self.root = Path(root)
        self._verified: dict[Path, tuple[int, int]] = {}   # entry -> (mtime_ns, size) of its index when verified

    def entry(self, stage: str, key: str) -> Path:
        return self.root / f"{stage}-{key}"

    def verify(self, stage: str, key: str) -> Verdict:
        """Check the entry's index (parses, sealed) and every file of its manifest (size, SHA-256)."""
        return self.verify_folder(self.entry(stage, key))

    def verify_folder(self, folder: Path) -> Verdict:
        index = folder / INDEX
        if not folder.is_dir():
            return Verdict("absent")
        try:
            entry = json.loads(index.read_text())
        except FileNotFoundError:
            return Verdict("bad", "no entry.json")
        except (OSError, ValueError) as e:
            return Verdict("bad", f"entry.json unreadable ({e})")
        if not isinstance(entry, dict) or "seal" not in entry or "files" not in entry:
            return Verdict("bad", "entry.json has no manifest (written by an older fem_squeal)")
        if entry["seal"] != seal(entry):
            return Verdict("bad", "entry.json does not match its seal (edited or corrupted)")
        for rel, rec in entry["files"].items():
            if why := file_problem(folder / rel, rec, rel):
                return Verdict("bad", why)
        st = index.stat()
        self._verified[folder] = (st.st_mtime_ns, st.st_size)
        return Verdict("ok")

    def has(self, stage: str, key: str) -> bool:
        """True when the entry exists and verifies."""
        return self.verify(stage, key).state == "ok"

    def load(self, stage: str, key: str) -> dict:
        """The index of a verified entry (verified again if its index changed since)."""
        folder = self.entry(stage, key)
        try:
            st = (folder / INDEX).stat()
        except OSError:
            st = None
        if st is None or self._verified.get(folder) != (st.st_mtime_ns, st.st_size):
            v = self.verify_folder(folder)
            if v.state != "ok":
                raise PipelineError(f"cache entry {folder}: {v.reason or 'absent'}; it changed during the run: "
                                    "run again (the entry is recomputed)")
        return json.loads((folder / INDEX).read_text())

    @contextmanager
    def writing(self, comm, stage: str, key: str, *, replace: bool = False):
        """Yield a temporary folder (the same on every rank) for the stage's files and a dict to fill
        with the index (``entry``); on success rank 0 writes the index with the manifest and its seal
        and renames the folder to the entry (atomic), on failure removes it.  An entry that another
        run committed meanwhile and that verifies is kept unless ``replace`` (a forced stage)."""
        tmp = None
        if comm.rank == 0:
            with storage_errors("creating a cache entry", self.root):
                self.root.mkdir(parents=True, exist_ok=True)
                tmp = tempfile.mkdtemp(prefix=f".{stage}-{key}.", dir=self.root)
        tmp = Path(comm.bcast(tmp, root=0))
        entry: dict[str, Any] = {}
        ok = False
        try:
            yield tmp, entry
            ok = True
        finally:
            ok = comm.allreduce(ok, op=MPI.LAND)
            error = None
            if comm.rank == 0:
                try:
                    if ok:
                        self._commit(tmp, self.entry(stage, key), entry, replace)
                except BaseException as e:          # noqa: BLE001 (raised on every rank below)
                    error = e
                finally:
                    shutil.rmtree(tmp, ignore_errors=True)
            error = comm.bcast(error, root=0)
            if error is not None and ok:
                raise error

    def _commit(self, tmp: Path, final: Path, entry: dict, replace: bool) -> None:
        with storage_errors("committing a cache entry", tmp):
            entry = {**entry, "files": manifest(tmp)}
            entry["seal"] = seal(entry)
            write_json_atomic(tmp / INDEX, entry)
            if final.exists():
                if not replace and self.verify_folder(final).state == "ok":
                    return                              # another run's entry for the same key
                old = Path(tempfile.mkdtemp(prefix=f".old-{final.name}.", dir=self.root))
                os.replace(final, old / "entry")
                os.replace(tmp, final)
                shutil.rmtree(old, ignore_errors=True)
            else:
                os.replace(tmp, final)
        st = (final / INDEX).stat()
        self._verified[final] = (st.st_mtime_ns, st.st_size)

    def entries(self) -> list[Path]:
        return sorted(p for p in self.root.glob("*-*") if p.is_dir() and not p.name.startswith("."))

    def temporaries(self) -> list[Path]:
        """Leftover temporary folders (of runs in progress, or of runs killed before they cleaned up)."""
        return sorted(p for p in self.root.glob(".*") if p.is_dir()) if self.root.is_dir() else []

    def check_all(self, remove: bool = False) -> list[tuple[Path, Verdict]]:
        """Verify every entry; with ``remove``, delete the bad ones and the temporary folders older
        than :data:`STALE_TEMPORARY_S` (a run in progress keeps its own).  Returns (entry, verdict)."""
        found = [(p, self.verify_folder(p)) for p in self.entries()]
        if remove:
            for p, v in found:
                if v.state == "bad":
                    shutil.rmtree(p, ignore_errors=True)
            now = time.time()
            for p in self.temporaries():
                if now - p.stat().st_mtime > STALE_TEMPORARY_S:
                    shutil.rmtree(p, ignore_errors=True)
        return found

    def clean(self) -> int:
        """Remove every entry (and leftovers of interrupted runs); returns the number removed."""
        if not self.root.exists():
            return 0
        n = 0
        for p in self.root.iterdir():
            if p.is_dir():
                shutil.rmtree(p, ignore_errors=True)
                n += 1
        shutil.rmtree(self.root, ignore_errors=True)
        return n
