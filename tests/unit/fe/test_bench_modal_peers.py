"""fem_squeal, CalculiX and scikit-fem agree on the same mesh (short version of
benchmarks/modal_peers.py: the clamped steel disc on its coarsest, 20 mm mesh, ~7k free DOFs, 6 modes).

Tolerances, from what separates the codes (measured values: the benchmark, this mesh):
- fem_squeal (default quadrature: degree 7 for the mass, 5 for the stiffness) against scikit-fem with
  ``intorder`` 7 / 5.  ρ u·v det J is a polynomial of degree 7 on the curved P2 geometry, so both
  integrate the mass exactly; the stiffness has 1/det J on the curved elements at the two cylinders
  and the codes use different degree-5 rules (basix's 14 points, scikit-fem's own).  That is the only
  difference: 1e-7 measured; eigen-solves at tol 1e-10 add ~1e-16.  Tolerance 1e-6.
- fem_squeal with the 4-point rule against scikit-fem ``intorder`` 2: the same points and weights, so
  round-off only: 3e-13 measured.  Tolerance 1e-10.
- CalculiX (C3D10: 4 points for stiffness and mass) against fem_squeal with the 4-point rule: ccx's
  .dat prints 7 significant digits (0.1170078E+09), i.e. rounds λ by up to 4e-7 and f by up to 2.5e-7
  (1.8e-7 measured); its ARPACK tol 1e-2 (fixed) costs nothing here (scipy's ARPACK at the same tol and
  ncv: 1e-15).  Tolerance 1e-6.
- The 4-point mass quadrature itself moves the frequencies by 1.5e-4 on this mesh, so a difference
  at the 1e-5 level between the codes (the benchmark's "same frequencies") would fail these tests.

fem_squeal runs in a child process: the 4-point case patches fem_squeal.fe.assembly._compile (its
quadrature_degree is ignored by FFCx 0.5), which must not leak into the other tests.
"""
from __future__ import annotations

import shutil
import sys

import numpy as np
import pytest
from support.paths import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))
import modal_peers as mp  # noqa: E402

H, N = 0.02, 6


@pytest.fixture(scope="module")
def disc(tmp_path_factory):
    from mpi4py import MPI

    if MPI.COMM_WORLD.size > 1:
        pytest.skip("serial (the codes run in child processes)")
    d = tmp_path_factory.mktemp("modal_peers")
    mesh = mp.spawn(["mesh", H, d, N])
    fem = {q: mp.fem_case(d, mesh["stem"], N, q, 1) for q in (mp.AUTO, mp.FOUR_POINT)}
    for r in fem.values():
        assert len(r["freqs"]) == N and r["max_residual"] < 1e-8
        assert r["free_dofs"] == mesh["free_dofs"]
    return d, mesh, fem


def needs(*modules: str) -> None:
    """Skip unless the peers' modules are installed: looked up, never imported here (getfem links a
    sequential MUMPS whose symbols, once loaded into the test process, break PETSc's parallel MUMPS
    in later tests: the process exited with status 49 in a later CEA)."""
    missing = [m for m in modules if not mp.have_module(m)]
    if missing:
        pytest.skip(f"not installed: {', '.join(missing)}")


def skfem_run(d, mesh, orders):
    needs("skfem")
    r = mp.spawn(["skfem", d / f"{mesh['stem']}.msh", N, *orders])
    assert r["free_dofs"] == mesh["free_dofs"] and r["max_residual"] < 1e-8
    return r


def test_quadrature_matters_at_the_tested_level(disc):
    _, _, fem = disc
    assert mp.rel_diff(fem[mp.AUTO]["freqs"], fem[mp.FOUR_POINT]["freqs"]) > 2e-5


def test_skfem_same_quadrature_as_fem_default(disc):
    d, mesh, fem = disc
    r = skfem_run(d, mesh, mp.SKFEM_AUTO)
    assert mp.rel_diff(r["freqs"], fem[mp.AUTO]["freqs"]) < 1e-6


def test_skfem_four_point_is_fem_four_point(disc):
    d, mesh, fem = disc
    r = skfem_run(d, mesh, mp.SKFEM_4PT)
    assert mp.rel_diff(r["freqs"], fem[mp.FOUR_POINT]["freqs"]) < 1e-10


def test_getfem_agrees_with_fem_default(disc):
    """GetFEM: mass with IM_TETRAHEDRON(8) (exact, as fem_squeal's degree 7), stiffness with its
    own degree-5 rule: the same kind of difference as scikit-fem's (1e-7 measured).  Tolerance 1e-6."""
    needs("getfem", "sksparse")
    d, mesh, fem = disc
    r = mp.spawn(["getfem", d / f"{mesh['stem']}.msh", N, mp.SPEED_TOL])
    assert r["free_dofs"] == mesh["free_dofs"] and r["max_residual"] < 1e-8
    assert mp.rel_diff(r["freqs"], fem[mp.AUTO]["freqs"]) < 1e-6


def test_skfem_cholmod_is_skfem_superlu(disc):
    """scikit-fem with the CHOLMOD factor (the --speed peer) solves the same problem as with SuperLU:
    both at eigsh tol 1e-10, so the frequencies agree to round-off (1e-12 is 1e4 × eps)."""
    needs("sksparse")
    d, mesh, _ = disc
    a, b = (skfem_run(d, mesh, (*mp.SKFEM_AUTO, mp.EIG_TOL, f)) for f in ("cholmod", "superlu"))
    assert a["solver"] == "cholmod + eigsh" and b["solver"] == "superlu + eigsh"
    assert mp.rel_diff(a["freqs"], b["freqs"]) < 1e-12


def test_calculix_is_fem_with_its_quadrature(disc):
    d, mesh, fem = disc
    if shutil.which("ccx") is None:
        pytest.skip("CalculiX (ccx) not installed")
    r = mp.run_ccx(d, mesh["stem"], N, 1)
    assert r["free_dofs"] == mesh["free_dofs"]
    assert len(r["freqs"]) == N and np.all(np.diff(r["freqs"]) >= 0)
    assert mp.rel_diff(r["freqs"], fem[mp.FOUR_POINT]["freqs"]) < 1e-6
