"""A model given as matrices: the quadratic eigenproblem (λ²M(p) + λC(p) + K(p))x = 0 of named
matrices, each operator an expression of the matrices and the parameters p compiled to its affine form
(:func:`fem_squeal.reduced.expressions.compile_operator`):

    M(p) = Σ_k m_k(p) A_k,   C(p) = Σ_k c_k(p) A_k (none: undamped),   K(p) = Σ_k k_k(p) A_k

(TU Berlin's brake, for example: M, C = D1 + W DG + (1/W − 1) DR + D4/(2π·1600),
K = K1 + KR + (W² − 1) KGEO with the disc speed ratio W).  :class:`MatrixModel` holds the operators
and the parameters (nominal values and ranges), not the matrices: :meth:`MatrixModel.assemble` forms
the operators of any matrices given by name (SciPy CSR, the rows of one rank, dense arrays)."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from fem_squeal.reduced.affine import AffineOperator, check_names
from fem_squeal.reduced.expressions import compile_operator
from fem_squeal.util.errors import ModelError

#: the operators of the quadratic eigenproblem, in the order λ², λ, 1
OPERATORS = ("M", "C", "K")


@dataclass(frozen=True)
class MatrixModel:
    """λ²M(p) + λC(p) + K(p) of named matrices (module docstring): ``operators`` "M", "K" and, damped,
    "C"; ``nominal`` the value of every parameter, ``ranges`` [low, high] of those that have one."""

    operators: dict[str, AffineOperator]
    nominal: dict[str, float] = field(default_factory=dict)
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)

    @property
    def parameters(self) -> list[str]:
        return list(self.nominal)

    @property
    def matrices(self) -> list[str]:
        """The matrices the operators use, in order of first use (M, C, K)."""
        out: list[str] = []
        for op in self.operators.values():
            out += [m for m in op.matrices if m not in out]
        return out

    @property
    def damped(self) -> bool:
        return "C" in self.operators

    def point(self, given: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """The value of every parameter: ``given`` over the nominal ones (names checked)."""
        given = dict(given or {})
        check_names(given, self.parameters, " of this matrix model")
        return {**self.nominal, **given}

    def assemble(self, matrices: Mapping[str, Any], given: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """{"M", "C" (damped only), "K"}: each operator Σ_k c_k(p) A_k at the point ``given`` (nominal
        where not given) of the named ``matrices``."""
        values = self.point(given)
        return {name: op.evaluate(values, matrices) for name, op in self.operators.items()}


def matrix_model(expressions: Mapping[str, str | None], matrices: list[str], nominal: Mapping[str, float],
                 ranges: Mapping[str, tuple[float, float]] | None = None, where: str = "") -> MatrixModel:
    """The model of the operator ``expressions`` ("M", "K" and optionally "C": None or missing = undamped)
    over the named ``matrices`` and parameters ``nominal`` (their values); ``where`` prefixes the
    operator names in messages (``"matrices."``).  Raises ExpressionError / ModelError."""
    if "M" not in expressions or "K" not in expressions:
        raise ModelError(f"{where}{'M' if 'M' not in expressions else 'K'}: required (an expression of the "
                         "named matrices)")
    ops = {name: compile_operator(f"{where}{name}", expressions[name], matrices, list(nominal))
           for name in OPERATORS if expressions.get(name) is not None}
    ranges = {k: (float(lo), float(hi)) for k, (lo, hi) in (ranges or {}).items()}
    for k, (lo, hi) in ranges.items():
        if not lo <= nominal[k] <= hi:
            raise ModelError(f"{where}parameters.{k}: the value {nominal[k]} is outside its range [{lo}, {hi}]")
    model = MatrixModel(ops, {k: float(v) for k, v in nominal.items()}, ranges)
    for op in ops.values():     # every coefficient finite at the nominal point
        op.coefficients(model.point())
    return model
