"""MPI helpers for work done on rank 0 only."""
from __future__ import annotations

import pickle
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")


def on_root(comm, fn: Callable[[], T]) -> T:
    """Run ``fn()`` on rank 0 and broadcast its result.  An exception there is raised on every rank
    (the same exception where it pickles, else a RuntimeError with its text): a rank-0 section that
    raised would otherwise leave the other ranks waiting in the next collective call."""
    result, error = None, None
    if comm.rank == 0:
        try:
            result = fn()
        except Exception as e:
            error = e
    if comm.rank == 0:
        try:
            payload = pickle.dumps(error)
            pickle.loads(payload)
        except Exception:
            payload = pickle.dumps(RuntimeError(f"{type(error).__name__}: {error}"))
    else:
        payload = None
    payload = comm.bcast(payload, root=0)
    if comm.rank == 0 and error is not None:
        raise error
    remote = pickle.loads(payload)
    if remote is not None:
        raise remote
    return comm.bcast(result, root=0)
