"""Mode coupling (fem_squeal.fe.coupling) and radiation of the Ryzhik ring (seed 003): the unstable
complex modes are the k-nodal-diameter cos/sin pair of real modes, their participations sum to 100 %
in the M-norm when the real modes span them, and in-plane modes radiate less than out-of-plane ones by
the factor of thin-ring theory; the same numbers on 1 and 2 ranks."""
from __future__ import annotations

import numpy as np
import pytest
from support.ranks import two_rank_signature
from support.ring import ring_mesh, ring_operators

from fem_squeal.reduced import mode_coupling

B, H, RHO, MESH = 0.005, 0.004, 1400.0, 0.0025


def _ring_cea():
    """The ring between its plates (μ 0.3): complex modes in 100-1500 Hz (k = 2, 3) and their
    coefficients on the real modes of ½(K + Kᵀ) up to 2 kHz."""
    from fem_squeal.fe.coupling import real_mode_coefficients
    from fem_squeal.fe.eigen import solve_complex_modes
    from fem_squeal.fe.model import Material, ModelSpec, RigidPlate
    from fem_squeal.fe.radiation import radiated_power

    ops = ring_operators()
    K = ops.K_total()
    cm = solve_complex_modes(K, ops.M, None, 6, 700.0, band_hz=(100.0, 1500.0))
    fields = list(zip(cm.vectors_re, cm.vectors_im))
    rc = real_mode_coefficients(K, ops.M, fields, 2000.0)
    spec = ModelSpec({"disc": Material(3e9, 0.4, RHO)}, (RigidPlate("top", 1e10, 0.3, 1),
                                                         RigidPlate("bottom", 1e10, 0.3, 1)), (), 2)
    P, area = radiated_power(ops.V, ring_mesh(B, H, MESH), spec, ops.M, fields)
    return ops, cm, rc, P, area


def _free_ring_erp():
    """The free ring's real modes near 1 kHz: frequency, nodal diameter, in-plane share, ERP/(ρcT)."""
    from fem_squeal.fe.descriptors import CircumferentialBasis
    from fem_squeal.fe.eigen import solve_real_modes
    from fem_squeal.fe.model import Material, ModelSpec
    from fem_squeal.fe.radiation import radiated_power

    ops = ring_operators(kn=0.0)
    rm = solve_real_modes(ops.K, ops.M, 18, 1000.0)
    modes = [(v, None) for v in rm.vectors]
    spec = ModelSpec({"disc": Material(3e9, 0.4, RHO)}, (), (), 2)
    P, _ = radiated_power(ops.V, ring_mesh(B, H, MESH), spec, ops.M, modes, rho_c=1.0)
    d = CircumferentialBasis(ops.V, ops.M, ops.M_axial).describe_all(modes)
    return rm.freqs_hz, np.array([x.nodal_diameter for x in d]), np.array([x.in_plane_share for x in d]), P


@pytest.fixture(scope="module")
def ring():
    return _ring_cea()


def test_unstable_ring_modes_are_the_cos_sin_pair(ring):
    """Each complex mode (k = 2, 3) is 50/50 on the two real modes of its k-diameter pair, which have
    one frequency; less than 1e-4 of its M-norm lies outside the real modes up to 2 kHz."""
    ops, cm, rc, _, _ = ring
    p, r = mode_coupling.participation(rc.coefficients, rc.norms)
    assert np.allclose(p.sum(axis=0), 100.0, atol=1e-9)
    assert np.allclose(rc.norms, 1.0, atol=1e-10)          # x^H M x = 1 (the solver's normalisation)
    assert len(cm.eigenvalues) == 4 and np.all(r < 1e-4) and np.all(r > -1e-12)
    for j in range(4):
        s = mode_coupling.summary(p[:, j], r[j], rc.freqs_hz)
        a, b = s["pair"]
        assert s["percent"][0] + s["percent"][1] > 99.99
        assert abs(s["percent"][0] - 50) < 1.0
        assert abs(rc.freqs_hz[a] - rc.freqs_hz[b]) < 1e-3 * rc.freqs_hz[a]
        assert abs(rc.freqs_hz[a] - cm.freqs_hz[j]) < 0.02 * cm.freqs_hz[j]


def test_participation_sums_to_100_percent_when_the_real_modes_span_the_vector(ring):
    """x = Φ c for a random complex c: its coefficients are c and nothing lies outside (round-off)."""
    ops, _, rc, _, _ = ring
    from fem_squeal.fe.coupling import coefficients_on

    Phi = rc.Phi
    c = np.random.default_rng(1).standard_normal((Phi.shape[1], 2)) @ np.array([1.0, 1j])
    xr, xi = ops.M.createVecRight(), ops.M.createVecRight()
    xr.array[:], xi.array[:] = Phi @ c.real, Phi @ c.imag
    C, norms = coefficients_on(ops.M, Phi, [(xr, xi)])
    p, r = mode_coupling.participation(C, norms)
    assert np.allclose(C[:, 0], c, atol=1e-10 * np.abs(c).max())
    assert abs(r[0]) < 1e-12 and abs(p.sum() - 100.0) < 1e-10


def test_report_names_the_cos_sin_pair_of_the_unstable_ring_modes(ring):
    """The CEA report's ranking names each unstable mode's pair and says it is the k-diameter cos/sin pair."""
    import dataclasses

    from fem_squeal.app import nvh
    from fem_squeal.app.analyses.cea import report
    from fem_squeal.fe.descriptors import CircumferentialBasis
    from fem_squeal.reduced.eigensolve import unstable

    ops, cm, rc, _, _ = ring
    rows = [{"index": j, "freq_hz": f, "real_part": lam.real, "damping_ratio": 0.0, "residual": 0.0,
             "unstable": bool(unstable(lam, 1e-6))} for j, (f, lam) in enumerate(zip(cm.freqs_hz, cm.eigenvalues))]
    res = {"complex_modes": rows, "n_unstable": sum(r["unstable"] for r in rows), "cea_method": "linear",
           "cea_coupling": nvh.coupling_summaries(dataclasses.replace(rc), rows,
                                                  CircumferentialBasis(ops.V, ops.M, ops.M_axial), ops.M)}
    assert res["n_unstable"] == 2
    html = report(res)
    assert "Unstable modes ranked" in html
    for k, r in zip((2, 3), (r for r in rows if r["unstable"])):
        assert r["coupling"]["pair_kind"] == f"cos/sin pair, nodal diameter {k}"
        assert f"{r['coupling']['label']} (cos/sin pair, nodal diameter {k})" in html


def test_ring_between_plates_radiates_from_its_cylindrical_faces_only(ring):
    """The plates cover the top and bottom faces: the surface is the inner and outer cylinders."""
    *_, P, area = ring
    assert area == pytest.approx(2 * 2 * np.pi * 0.05 * H, rel=1e-5)
    assert np.all(P > 0)


def test_in_plane_modes_radiate_less_by_the_thin_ring_factor():
    """Free ring, all faces radiating, unit kinetic energy: an out-of-plane k-diameter mode (u_z uniform
    over the section) gives ERP/(ρcT) = 2/(ρh), an in-plane one (u_r on the cylinders, u_θ = u_r'/k)
    2/(ρb(1 + 1/k²)): out-of-plane/in-plane = b(1 + 1/k²)/h (1.56 for k = 2), within 3 %."""
    f, k, inplane, P = _free_ring_erp()
    checked = 0
    for kk in (2, 3, 4):
        ip = P[(k == kk) & (inplane > 0.99) & (f > 1)]
        op = P[(k == kk) & (inplane < 0.05) & (f > 1)]
        if not (len(ip) and len(op)):
            continue
        assert ip.max() == pytest.approx(2 / (RHO * B * (1 + 1 / kk ** 2)), rel=0.03)
        assert op.min() == pytest.approx(2 / (RHO * H), rel=0.03)
        assert op.min() / ip.max() == pytest.approx(B * (1 + 1 / kk ** 2) / H, rel=0.03)
        checked += 1
    assert checked >= 2


def signature() -> dict:
    """What 1 and 2 ranks must agree on: eigenvalues, ERP, the outside shares and the participations
    summed over degenerate groups (a pair's split depends on the solver's basis of its eigenspace)."""
    _, cm, rc, P, area = _ring_cea()
    p, r = mode_coupling.participation(rc.coefficients, rc.norms)
    g = mode_coupling.group_sums(p, mode_coupling.degenerate_groups(rc.freqs_hz))
    return {"lam_re": cm.eigenvalues.real.tolist(), "lam_im": cm.eigenvalues.imag.tolist(), "erp": P.tolist(),
            "area": area, "outside": r.tolist(), "groups": g.tolist(), "real_hz": rc.freqs_hz.tolist()}


@pytest.mark.mpi
@pytest.mark.slow
def test_two_ranks_give_the_same_coupling_and_erp(mpirun, tmp_path):
    one, two = signature(), two_rank_signature(mpirun, "test_coupling", tmp_path / "sig.json")
    assert np.allclose(one["real_hz"], two["real_hz"], rtol=1e-7)
    assert one["area"] == pytest.approx(two["area"], rel=1e-12)
    order1, order2 = np.argsort(one["lam_im"]), np.argsort(two["lam_im"])
    assert np.allclose(np.array(one["erp"])[order1], np.array(two["erp"])[order2], rtol=1e-6)
    assert np.allclose(np.array(one["groups"])[:, order1], np.array(two["groups"])[:, order2], atol=1e-4)
    assert np.allclose(np.array(one["outside"])[order1], np.array(two["outside"])[order2], atol=1e-7)


@pytest.mark.slow
def test_ring_scene_report_says_the_unstable_pair_is_the_cos_sin_pair(tmp_path):
    """scenes/ryzhik_ring.toml with analyses.cea.coupling = true: every unstable mode's coupling is its
    k-diameter cos/sin pair (k = 2..6) in results.json, report.html and cea_coupling.csv."""
    import json

    from mpi4py import MPI
    from support.paths import ROOT

    from fem_squeal.app.run import run_scene
    from fem_squeal.app.scene import load_scene

    scene = load_scene(ROOT / "scenes" / "ryzhik_ring.toml", ["analyses.cea.coupling=true"])
    run_scene(scene, tmp_path, MPI.COMM_SELF, cache=tmp_path / "cache", log=lambda *a: None)
    res = json.loads((tmp_path / "results.json").read_text())
    html = (tmp_path / "report.html").read_text()
    ks = []
    for m in res["complex_modes"]:
        if m["unstable"]:
            c = m["coupling"]
            assert c["pair_kind"] == f"cos/sin pair, nodal diameter {m['nodal_diameter']}"
            assert abs(c["percent"][0] - 50) < 1 and c["outside"] < 1e-4
            assert f"{c['label']} ({c['pair_kind']})" in html
            ks.append(m["nodal_diameter"])
    assert sorted(ks) == [2, 3, 4, 5, 6]
    assert res["cea_squeal_ranking"]
    assert {"cea_coupling.csv", "cea_radiation.csv", "cea_erp.png"} <= set(res["files"])
