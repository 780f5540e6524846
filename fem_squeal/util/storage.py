"""Files on disk that can be trusted: content digests, copies that share nothing with their source,
and write failures (a full disk, a read-only folder) turned into one named error.

- :func:`digest`: size and SHA-256 of a file (1.2 GB/s with the CPU's SHA extensions), what a cache
  entry records of each of its files and checks before anything of it is used.
- :func:`clone_file`: ``dst`` as a file of its own with ``src``'s bytes: a copy-on-write clone where
  the file system offers one (``FICLONE``: btrfs, XFS), else an in-kernel copy.  Never a hard link: a
  tool that rewrites an output in place must not change the cache.
- :func:`storage_errors`: ``OSError`` for lack of space or permission inside the block becomes a
  :class:`~fem_squeal.util.errors.StorageError` naming the path, what was being written and, when
  known, the bytes needed.
"""
from __future__ import annotations

import errno
import fcntl
import hashlib
import os
import shutil
from contextlib import contextmanager
from pathlib import Path

from fem_squeal.util.errors import StorageError

#: errno values that mean "this file system will not take the write" (not a bug of the caller)
STORAGE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EACCES, errno.EPERM, errno.EROFS, errno.EFBIG})
_FICLONE = 0x40049409          # linux/fs.h: _IOW(0x94, 9, int)
_CHUNK = 1 << 20


def digest(path: str | os.PathLike) -> tuple[int, str]:
    """(size in bytes, SHA-256 hex) of the file ``path``."""
    h = hashlib.sha256()
    n = 0
    with open(path, "rb", buffering=0) as f:
        buf = bytearray(_CHUNK)
        view = memoryview(buf)
        while k := f.readinto(buf):
            h.update(view[:k])
            n += k
    return n, h.hexdigest()


def free_bytes(path: str | os.PathLike) -> int:
    """Bytes free to an unprivileged writer on the file system of ``path`` (or of its nearest existing
    parent folder)."""
    p = Path(path).absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    st = os.statvfs(p)
    return st.f_bavail * st.f_frsize


def mib(n: float) -> str:
    """A byte count for a message: ``12.3 MB``."""
    return f"{n / 1e6:.3g} MB" if n >= 1e5 else f"{int(n)} bytes"


def clone_file(src: str | os.PathLike, dst: str | os.PathLike) -> None:
    """Write ``dst`` (a new file) with the bytes of ``src``: a copy-on-write clone where the file system
    supports it, else ``copy_file_range``/``sendfile`` (shutil), then ``fsync``.  The two never share
    an inode, so writing into one leaves the other unchanged."""
    with open(src, "rb") as fs, open(dst, "wb") as fd:
        try:
            fcntl.ioctl(fd.fileno(), _FICLONE, fs.fileno())
        except OSError as e:
            if e.errno in (errno.ENOSPC, errno.EDQUOT):
                raise
            if not _kernel_copy(fs, fd):
                shutil.copyfileobj(fs, fd, _CHUNK)
        fd.flush()
        os.fsync(fd.fileno())


def _kernel_copy(fs, fd) -> bool:
    """Copy with ``os.copy_file_range`` (in the kernel; a reflink on file systems that do it); False
    where the call is not supported (the caller then copies through user space)."""
    size = os.fstat(fs.fileno()).st_size
    done = 0
    try:
        while done < size:
            n = os.copy_file_range(fs.fileno(), fd.fileno(), size - done)
            if n == 0:
                break
            done += n
    except OSError as e:
        if e.errno in STORAGE_ERRNOS or done:
            raise
        return False
    return done == size


@contextmanager
def storage_errors(what: str, path: str | os.PathLike, needed: int | None = None):
    """Inside the block, an ``OSError`` for space or permission (:data:`STORAGE_ERRNOS`) is raised as
    :class:`StorageError`: ``<file>: <reason> while <what> (<needed> needed, <free> free)``."""
    try:
        yield
    except OSError as e:
        if isinstance(e, StorageError) or e.errno not in STORAGE_ERRNOS:
            raise
        raise storage_error(e, what, path, needed) from e


def storage_error(e: OSError, what: str, path: str | os.PathLike, needed: int | None = None) -> StorageError:
    """The :class:`StorageError` for ``OSError`` ``e`` raised while ``what`` under ``path``."""
    where = e.filename or path
    size = f"{mib(needed)} needed, " if needed else ""
    return StorageError(f"{where}: {e.strerror or os.strerror(e.errno)} while {what} "
                        f"({size}{mib(free_bytes(path))} free on that file system)")
