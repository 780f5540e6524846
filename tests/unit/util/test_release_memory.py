"""fem_squeal.util.memory: the heap's free pages go back to the system."""
from __future__ import annotations

import ctypes


def _rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return float(line.split()[1]) / 1e3
    raise AssertionError("no VmRSS")


def test_freed_heap_blocks_go_back_to_the_system():
    """What a factorisation leaves: 1 MiB blocks from the heap (glibc's mmap threshold raised by one
    large block freed, as MUMPS's first factorisation raises it), all freed but the last, which pins
    the heap's top: the 399 MiB stay in RSS until :func:`release_freed_memory`, then leave it (the
    bound, half of them, fails only if nothing was returned: RSS moves by a few MiB otherwise)."""
    from fem_squeal.util.memory import release_freed_memory

    libc = ctypes.CDLL(None)
    libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
    libc.free.argtypes = [ctypes.c_void_p]
    libc.memset.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_size_t]
    big = libc.malloc(30 << 20)
    libc.memset(big, 1, 30 << 20)
    libc.free(big)
    blocks = [libc.malloc(1 << 20) for _ in range(400)]
    for b in blocks:
        libc.memset(b, 1, 1 << 20)
    for b in blocks[:-1]:
        libc.free(b)
    held = _rss_mb()
    assert release_freed_memory()
    assert held - _rss_mb() >= 200
    libc.free(blocks[-1])
