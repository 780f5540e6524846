"""Operators as expressions of named matrices (fem_squeal.reduced.expressions, .matrix_model): the
affine form of TU Berlin's operators, and a named refusal, never an evaluation, of everything else."""
from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.sparse as sp

from fem_squeal.reduced.expressions import compile_operator
from fem_squeal.reduced.matrix_model import matrix_model
from fem_squeal.util.errors import ExpressionError, ModelError, UnknownNameError

MATRICES = ["M", "D1", "DG", "DR", "D4", "K1", "KR", "KGEO"]
C_TEXT = "D1 + W*DG + (1/W - 1)*DR + D4/(2*pi*1600)"
K_TEXT = "K1 + KR + (W**2 - 1)*KGEO"


def test_tu_berlin_operators_affine_form():
    C = compile_operator("C", C_TEXT, MATRICES, ["W"])
    assert C.matrices == ("D1", "DG", "DR", "D4")
    assert C.parameters == {"W"}
    for W in (0.5, 1.0, 3.0):
        assert np.allclose(C.coefficients({"W": W}), [1.0, W, 1 / W - 1, 1 / (2 * math.pi * 1600)], rtol=1e-15)
    K = compile_operator("K", K_TEXT, MATRICES, ["W"])
    assert np.allclose(K.coefficients({"W": np.array([1.0, 2.0])})[2], [0.0, 3.0])     # arrays of points


def test_linear_combinations_and_functions():
    op = compile_operator("K", "-(K1 - 2*KR)/sqrt(W) + K1 + exp(0)*log(W)*cos(0)*sin(pi/2)*KGEO", MATRICES,
                          ["W"])
    W = 4.0
    got = dict(zip(op.matrices, op.coefficients({"W": W})))
    assert got == pytest.approx({"K1": 1 - 1 / 2, "KR": 2 / 2, "KGEO": math.log(W)}, rel=1e-15)
    rng = np.random.default_rng(0)
    mats = {m: sp.random(5, 5, density=0.5, random_state=rng, format="csr") for m in MATRICES}
    ref = (-(mats["K1"] - 2 * mats["KR"]) / 2 + mats["K1"] + math.log(W) * mats["KGEO"]).toarray()
    assert np.allclose(op.evaluate({"W": W}, mats).toarray(), ref, rtol=1e-14, atol=1e-15)


REFUSED = [
    ("K1.T", "attribute", "attribute access"),
    ("K1.__class__", "attribute", "attribute access"),
    ("K1[0]", "subscript", "subscript"),
    ("abs(W)*K1", "call", "calls other than"),
    ("__import__('os')*K1", "call", "calls other than"),
    ("(lambda: 1)()*K1", "call", "calls other than"),
    ("sqrt(W, W)*K1", "call", "sqrt takes one argument"),
    ("sqrt(x=W)*K1", "call", "sqrt takes one argument"),
    ("__builtins__*K1", "name", "names starting with '_'"),
    ("foo*K1", "name", "unknown name 'foo'"),
    ("sqrt*K1", "name", "must be called"),
    ("K1*KR", "matrix_product", "a matrix times a matrix"),
    ("W/K1", "matrix_denominator", "denominator"),
    ("K1/(W*KR)", "matrix_denominator", "denominator"),
    ("K1**2", "matrix_power", "power"),
    ("W**K1", "matrix_power", "power"),
    ("exp(K1)", "matrix_argument", "of a matrix"),
    ("K1 + 1", "matrix_plus_number", "added to a matrix"),
    ("W - K1", "matrix_plus_number", "added to a matrix"),
    ("K1 // 2", "operator", "FloorDiv"),
    ("K1 % 2", "operator", "Mod"),
    ("W @ K1", "operator", "MatMult"),
    ("~K1", "operator", "Invert"),
    ("K1 if W else KR", "construct", "IfExp"),
    ("W < 1 and K1", "construct", "BoolOp"),
    ("[K1][0]", "subscript", "subscript"),
    ("'a'*K1", "number", "not str"),
    ("True*K1", "number", "not bool"),
    ("1j*K1", "number", "not complex"),
    ("1e999*K1", "number", "too large"),
    ("K1 +", "syntax", "not an expression"),
    ("", "syntax", "non-empty"),
    ("import os", "syntax", "not an expression"),
    ("2*W", "no_matrix", "names no matrix"),
]


@pytest.mark.parametrize("text,kind,message", REFUSED, ids=[r[0] or "empty" for r in REFUSED])
def test_refused_construct_is_named(text, kind, message):
    with pytest.raises(ExpressionError) as e:
        compile_operator("matrices.K", text, MATRICES, ["W"])
    assert e.value.kind == kind
    assert str(e.value).startswith("matrices.K: ") and message in str(e.value)


def test_matrix_model_point_checks():
    m = matrix_model({"M": "M", "C": C_TEXT, "K": K_TEXT}, MATRICES, {"W": 1.0}, {"W": (0.5, 4.0)}, "matrices.")
    assert m.damped and m.matrices[0] == "M" and m.parameters == ["W"]
    with pytest.raises(UnknownNameError, match="V: not a parameter of this matrix model"):
        m.point({"V": 2.0})
    with pytest.raises(ModelError, match=r"matrices.C: the coefficient 1.0 / W - 1.0 of DR is not a finite number "
                                         r"at W = 0.0"):
        m.operators["C"].coefficients(m.point({"W": 0.0}))
    with pytest.raises(ModelError, match=r"matrices.parameters.W: the value 5.0 is outside its range"):
        matrix_model({"M": "M", "K": K_TEXT}, MATRICES, {"W": 5.0}, {"W": (0.5, 4.0)}, "matrices.")
    with pytest.raises(ModelError, match="matrices.K: required"):
        matrix_model({"M": "M"}, MATRICES, {}, where="matrices.")


def test_coefficient_derivatives_are_exact():
    """∂c/∂p of every construct (sum, product, quotient, powers with a parameter in base and exponent,
    the five functions) equals the closed form to rounding; a term that does not read p has 0."""
    op = compile_operator("K", "(W**2 - 1)*A + sqrt(W)*exp(s)/W*B + log(s)*sin(W)*C + W**s*D + cos(2*pi*W)*E - F",
                          list("ABCDEF"), ["W", "s"])
    W, s = 1.3, 0.7
    dW = {"A": 2 * W, "B": math.exp(s) * (-0.5) * W ** -1.5, "C": math.log(s) * math.cos(W),
          "D": s * W ** (s - 1), "E": -2 * math.pi * math.sin(2 * math.pi * W), "F": 0.0}
    ds = {"A": 0.0, "B": math.sqrt(W) * math.exp(s) / W, "C": math.sin(W) / s, "D": W ** s * math.log(W),
          "E": 0.0, "F": 0.0}
    for name, ref in (("W", dW), ("s", ds)):
        got = dict(zip(op.matrices, op.derivatives({"W": W, "s": s}, name)))
        for m, v in ref.items():
            assert abs(float(got[m]) - v) <= 1e-14 * max(1.0, abs(v)), (name, m)
    with pytest.raises(ModelError, match="derivative of the coefficient"):
        compile_operator("K", "log(W)*A", ["A"], ["W"]).derivatives({"W": 0.0}, "W")
