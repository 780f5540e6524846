"""The matrix readers (fem_squeal.util.matrix_files): each format read back as written, symmetric
storage expanded, the header's size without loading, and a named error for each refused file."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.io as sio
import scipy.sparse as sp

from fem_squeal.util.errors import MatrixFileError
from fem_squeal.util.matrix_files import matrix_shape, read_matrix, write_matrix_market


def _matrix(n=7, seed=3) -> sp.csr_matrix:
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=0.4, random_state=rng, format="csr") + sp.eye(n) * 2.0
    A.data *= np.pi         # entries that need all 17 digits
    return A.tocsr()


def _same(A, B) -> None:
    assert A.shape == B.shape
    assert abs(A - B).max() == 0.0


def test_matrix_market_round_trip_is_exact(tmp_path):
    A = _matrix()
    write_matrix_market(tmp_path / "a.mtx", A, comment="test")
    _same(read_matrix(tmp_path / "a.mtx"), A)
    assert matrix_shape(tmp_path / "a.mtx") == (7, 7)
    write_matrix_market(tmp_path / "b.mm", A)     # another extension, no .mtx appended
    assert (tmp_path / "b.mm").is_file() and not (tmp_path / "b.mm.mtx").exists()
    _same(read_matrix(tmp_path / "b.mm"), A)


def test_matrix_market_symmetric_storage_expanded(tmp_path):
    A = _matrix()
    S = (A + A.T).tocsr()
    sio.mmwrite(str(tmp_path / "s.mtx"), sp.coo_matrix(S), symmetry="symmetric", precision=17)
    assert "symmetric" in (tmp_path / "s.mtx").read_text().splitlines()[0]
    _same(read_matrix(tmp_path / "s.mtx"), S)


def test_mat_variables(tmp_path):
    A, B = _matrix(), _matrix(seed=4)
    sio.savemat(tmp_path / "m.mat", {"K1": A, "KR": B.toarray()})
    _same(read_matrix(tmp_path / "m.mat", variable="K1"), A)
    _same(read_matrix(tmp_path / "m.mat", name="KR"), B)          # the matrix's name, a dense variable
    assert matrix_shape(tmp_path / "m.mat", variable="KR") == (7, 7)
    sio.savemat(tmp_path / "one.mat", {"whatever": A})
    _same(read_matrix(tmp_path / "one.mat", name="M"), A)          # the only variable
    with pytest.raises(MatrixFileError, match=r"m.mat: no variable 'D1'; variables: \['K1', 'KR'\]"):
        read_matrix(tmp_path / "m.mat", variable="D1")
    with pytest.raises(MatrixFileError, match="m.mat: give variable"):
        read_matrix(tmp_path / "m.mat", name="M")


def test_harwell_boeing_unsymmetric_and_symmetric(tmp_path):
    A = _matrix()
    sio.hb_write(str(tmp_path / "a.rua"), A.tocsc())
    _same(read_matrix(tmp_path / "a.rua"), A)
    assert matrix_shape(tmp_path / "a.rua") == (7, 7)
    S = (A + A.T).tocsr()
    sio.hb_write(str(tmp_path / "s.hb"), sp.tril(S).tocsc())      # ANSYS HBMAT: RSA, one triangle on file
    text = (tmp_path / "s.hb").read_text().split("\n")
    text[2] = text[2].replace("RUA", "RSA", 1)
    (tmp_path / "s.hb").write_text("\n".join(text))
    _same(read_matrix(tmp_path / "s.hb"), S)


def test_refused_files_are_named(tmp_path):
    with pytest.raises(MatrixFileError, match="nope.mtx: no such file"):
        read_matrix(tmp_path / "nope.mtx")
    (tmp_path / "a.txt").write_text("1 2 3")
    with pytest.raises(MatrixFileError, match="a.txt: cannot tell the matrix format"):
        read_matrix(tmp_path / "a.txt")
    with pytest.raises(MatrixFileError, match="unknown matrix format 'op4'"):
        read_matrix(tmp_path / "a.txt", fmt="op4")
    sio.mmwrite(str(tmp_path / "c.mtx"), sp.coo_matrix(_matrix() * (1 + 1j)))
    with pytest.raises(MatrixFileError, match="c.mtx: a complex Matrix Market matrix"):
        read_matrix(tmp_path / "c.mtx")
    (tmp_path / "bad.mtx").write_text("not a matrix\n")
    with pytest.raises(MatrixFileError, match="bad.mtx: not a Matrix Market file"):
        read_matrix(tmp_path / "bad.mtx")
