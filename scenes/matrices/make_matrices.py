"""Write the matrices of scenes/matrices_brake.toml: a lumped, reproducible stand-in for a brake model
exchanged as matrices, in TU Berlin's naming (M, D1, DG, DR, D4, K1, KR, KGEO; the disc speed ratio
W as parameter).

N masses on a ring (a disc's circumferential degrees of freedom, doublet modes), each with an
out-of-plane (w) and an in-plane (u) degree of freedom, n = 2N:

- M     masses m (1 ± 10 %, seeded)
- K1    ring springs (w: bending-like k_w, u: k_u) and ground springs: symmetric, positive definite
- KR    a pad at node 0 with friction: normal spring k_c on w, the friction force μ k_c w on u
        (one entry, non-symmetric: circulatory, the mode-coupling mechanism)
- KGEO  centrifugal stiffening of the ring springs (× (W² − 1) in K)
- D1    Rayleigh damping of the ring, DG gyroscopic coupling of w and u along the ring (skew, × W),
        DR a damper at the pad (× (1/W − 1)), D4 stiffness-proportional damping (÷ 2π·1600)

Run ``python scenes/matrices/make_matrices.py [FOLDER]`` (default: this folder); the files are Matrix
Market (M, K1, KR, KGEO, D1, D4), MATLAB (DG, DR in damping.mat) and Harwell-Boeing (M again, as
mass.rsa with symmetric storage, for the reader's test).  Same seed, same files.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import scipy.io as sio
import scipy.sparse as sp

N = 24


def matrices(n_nodes: int = N, seed: int = 7) -> dict[str, sp.csr_matrix]:
    """The named matrices of the lumped brake (module docstring), n = 2·n_nodes."""
    rng = np.random.default_rng(seed)
    n = 2 * n_nodes
    w, u = np.arange(0, n, 2), np.arange(1, n, 2)
    m = 0.05 * (1 + 0.1 * (2 * rng.random(n) - 1))
    ring = sp.diags([2.0 * np.ones(n_nodes), -np.ones(n_nodes - 1), -np.ones(n_nodes - 1)], [0, 1, -1],
                    shape=(n_nodes, n_nodes), format="lil")
    ring[0, n_nodes - 1] = ring[n_nodes - 1, 0] = -1.0
    ring = ring.tocsr()

    def on(idx, A):
        P = sp.csr_matrix((np.ones(len(idx)), (idx, np.arange(len(idx)))), shape=(n, len(idx)))
        return (P @ A @ P.T).tocsr()

    k_w, k_u, k_g = 2.0e6, 6.0e6, 4.0e5
    K1 = on(w, k_w * ring) + on(u, k_u * ring) + k_g * sp.eye(n)
    k_c, mu = 1.5e6, 0.4
    KR = sp.csr_matrix(([k_c, mu * k_c], ([0, 1], [0, 0])), shape=(n, n))
    KGEO = 0.02 * (on(w, k_w * ring) + on(u, k_u * ring))
    M = sp.diags(m, format="csr")
    D1 = (2.0 * M + 1e-6 * K1).tocsr()
    g = 3.0
    DG = sp.csr_matrix((n, n))
    for i in range(n_nodes):
        j = (i + 1) % n_nodes
        DG = DG + g * sp.csr_matrix(([1.0, -1.0], ([w[i], u[j]], [u[j], w[i]])), shape=(n, n))
    DR = sp.csr_matrix(([4.0, 1.0], ([0, 1], [0, 1])), shape=(n, n))
    D4 = (1e-3 * K1).tocsr()
    return {k: sp.csr_matrix(v) for k, v in dict(M=M, D1=D1, DG=DG, DR=DR, D4=D4, K1=K1, KR=KR, KGEO=KGEO).items()}


def write(folder: Path) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    mats = matrices()
    for name in ("M", "K1", "KR", "KGEO", "D1", "D4"):
        sio.mmwrite(str(folder / f"{name}.mtx"), sp.coo_matrix(mats[name]), precision=17,
                    comment=f"{name} of scenes/matrices/make_matrices.py")
    sio.savemat(folder / "damping.mat", {"DG": mats["DG"], "DR": mats["DR"]})
    sio.hb_write(str(folder / "mass.rsa"), sp.tril(mats["M"]).tocsc())
    lines = (folder / "mass.rsa").read_text().split("\n")
    lines[2] = lines[2].replace("RUA", "RSA", 1)
    (folder / "mass.rsa").write_text("\n".join(lines))


if __name__ == "__main__":
    write(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent)
