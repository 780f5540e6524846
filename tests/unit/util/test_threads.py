"""Threads of the numerical libraries (fem_squeal.util.blas): the OpenMP guard around CHOLMOD's
factorisation switches parallel regions off inside its block and restores the previous setting
after it, also on an exception and when nested (that the factor is the same to the bit with and
without it: tests/unit/fe/test_cholmod.py); the one-BLAS-thread block of the transients likewise."""
from __future__ import annotations

import pytest

from fem_squeal.fe import cholmod
from fem_squeal.util import blas

pytestmark = pytest.mark.skipif(not cholmod.available(), reason="libcholmod (SuiteSparse 5) not found")


def _gomp():
    cholmod._lib()                  # libcholmod links libgomp: loaded with it
    lib = blas._gomp()
    if lib is None:
        pytest.skip("libgomp is not loaded in this process")
    return lib


def test_serial_openmp_switches_regions_off_and_restores():
    lib = _gomp()
    before = lib.omp_get_max_active_levels()
    with blas.serial_openmp():
        assert lib.omp_get_max_active_levels() == 0
        with blas.serial_openmp():
            assert lib.omp_get_max_active_levels() == 0
        assert lib.omp_get_max_active_levels() == 0        # the inner block restored the outer's 0
    assert lib.omp_get_max_active_levels() == before
    with pytest.raises(RuntimeError), blas.serial_openmp():
        raise RuntimeError("inside")
    assert lib.omp_get_max_active_levels() == before


def test_single_threaded_sets_one_blas_thread_and_restores():
    import numpy  # noqa: F401  (loads the BLAS)

    before = blas.blas_threads()
    if before is None:
        pytest.skip("no BLAS is loaded in this process")
    with pytest.raises(RuntimeError), blas.single_threaded():
        assert blas.blas_threads() == 1
        raise RuntimeError("inside")
    assert blas.blas_threads() == before
