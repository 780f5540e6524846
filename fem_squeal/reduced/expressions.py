"""Operators as expressions of named matrices and parameters, compiled to their affine form
(:class:`fem_squeal.reduced.affine.AffineOperator`), parsed and never evaluated as Python.

    C = "D1 + W*DG + (1/W - 1)*DR + D4/(2*pi*1600)"   →   C(W) = 1·D1 + W·DG + (1/W − 1)·DR + (1/(2π·1600))·D4
    K = "K1 + KR + (W**2 - 1)*KGEO"

The text is read by Python's :mod:`ast` and accepted only if every node is on a whitelist: numbers,
the named matrices and parameters, ``pi``, unary and binary ``+ - * / **``, and the functions
:data:`FUNCTIONS` of parameters (``sqrt exp log sin cos``).  The operator must be linear in the
matrices: a matrix may be multiplied or divided by a scalar expression, matrices add, and nothing
else (a matrix times a matrix, a matrix in a denominator, in a power or in a function, a number added
to a matrix) is refused.  Each refusal is an :class:`~fem_squeal.util.errors.ExpressionError` whose
``kind`` names it and whose message names the operator and the construct.  A coefficient is kept as
the (whitelisted) syntax tree of a scalar expression and evaluated by :func:`evaluate_scalar`, a walk
over those nodes with NumPy (numbers or arrays of points).
"""
from __future__ import annotations

import ast
import math
from collections.abc import Callable, Collection, Mapping
from typing import Any

import numpy as np

from fem_squeal.reduced.affine import AffineOperator, AffineTerm
from fem_squeal.util.errors import ExpressionError

#: the functions an expression may call, of parameters only (one argument each)
FUNCTIONS: dict[str, Callable] = {"sqrt": np.sqrt, "exp": np.exp, "log": np.log, "sin": np.sin, "cos": np.cos}
#: the named constants
CONSTANTS: dict[str, float] = {"pi": math.pi}
#: names a matrix or parameter cannot take
RESERVED = frozenset(FUNCTIONS) | frozenset(CONSTANTS)
#: the longest expression read [characters]
MAX_LENGTH = 4000
_BINARY = {ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply, ast.Div: np.divide, ast.Pow: np.power}
_UNARY = {ast.UAdd: np.positive, ast.USub: np.negative}
_ONE = ast.Constant(1.0)
_CONSTRUCTS = {ast.Attribute: ("attribute", "attribute access is"), ast.Subscript: ("subscript", "a subscript is")}


def _refuse(op: str, kind: str, what: str, node: ast.AST | None = None, text: str = "") -> ExpressionError:
    where = f" ({ast.get_source_segment(text, node)!r})" if node is not None and text else ""
    return ExpressionError(f"{op}: {what}{where}", kind)


class _Compiler:
    """One expression's walk: each node becomes a scalar (a syntax tree of numbers, parameters and
    functions) or a linear combination of matrices ({matrix: coefficient tree})."""

    def __init__(self, op: str, text: str, matrices: Collection[str], parameters: Collection[str]):
        self.op, self.text, self.matrices, self.parameters = op, text, set(matrices), set(parameters)

    def fail(self, kind: str, what: str, node: ast.AST | None = None) -> ExpressionError:
        return _refuse(self.op, kind, what, node, self.text)

    def walk(self, node: ast.AST) -> ast.expr | dict[str, ast.expr]:
        if isinstance(node, ast.Constant):
            if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
                kind = type(node.value).__name__
                raise self.fail("number", f"only real numbers are constants, not {kind}", node)
            value = float(node.value) if abs(node.value) < 1e308 else math.inf
            if not math.isfinite(value):
                raise self.fail("number", "a number too large for a float", node)
            return ast.Constant(value)
        if isinstance(node, ast.Name):
            return self.name(node)
        if isinstance(node, ast.UnaryOp):
            if type(node.op) not in _UNARY:
                what = type(node.op).__name__
                raise self.fail("operator", f"the operator {what} is not allowed (+ - * / ** are)", node)
            x = self.walk(node.operand)
            if isinstance(x, dict):
                return {k: (c if isinstance(node.op, ast.UAdd) else _neg(c)) for k, c in x.items()}
            return ast.UnaryOp(node.op, x)
        if isinstance(node, ast.BinOp):
            return self.binary(node)
        if isinstance(node, ast.Call):
            return self.call(node)
        kind, what = _CONSTRUCTS.get(type(node), ("construct", f"a {type(node).__name__} expression is"))
        raise self.fail(kind, f"{what} not allowed", node)

    def name(self, node: ast.Name) -> ast.expr | dict[str, ast.expr]:
        n = node.id
        if n.startswith("_"):
            raise self.fail("name", f"the name {n!r} is refused (names starting with '_' are never read)", node)
        if n in self.matrices:
            return {n: _ONE}
        if n in self.parameters or n in CONSTANTS:
            return ast.Name(n, ast.Load())
        if n in FUNCTIONS:
            raise self.fail("name", f"the function {n!r} must be called", node)
        raise self.fail("name", f"unknown name {n!r}; matrices: {sorted(self.matrices)}, parameters: "
                        f"{sorted(self.parameters)}, constants: {sorted(CONSTANTS)}", node)

    def call(self, node: ast.Call) -> ast.expr:
        f = node.func
        if not isinstance(f, ast.Name) or f.id not in FUNCTIONS:
            called = ast.get_source_segment(self.text, f) or type(f).__name__
            raise self.fail("call", f"calls other than {sorted(FUNCTIONS)} are not allowed (got {called})", node)
        if node.keywords or len(node.args) != 1 or isinstance(node.args[0], ast.Starred):
            raise self.fail("call", f"{f.id} takes one argument", node)
        arg = self.walk(node.args[0])
        if isinstance(arg, dict):
            raise self.fail("matrix_argument", f"{f.id} of a matrix is not allowed (functions of parameters only)",
                            node)
        return ast.Call(ast.Name(f.id, ast.Load()), [arg], [])

    def binary(self, node: ast.BinOp) -> ast.expr | dict[str, ast.expr]:
        op = node.op
        if type(op) not in _BINARY:
            raise self.fail("operator", f"the operator {type(op).__name__} is not allowed (+ - * / ** are)", node)
        a, b = self.walk(node.left), self.walk(node.right)
        la, lb = isinstance(a, dict), isinstance(b, dict)
        if not (la or lb):
            return ast.BinOp(a, op, b)
        if isinstance(op, (ast.Add, ast.Sub)):
            if not (la and lb):
                raise self.fail("matrix_plus_number", "a number or parameter added to a matrix (write it as a "
                                "coefficient of a matrix)", node)
            out = dict(a)
            for k, c in b.items():
                c = c if isinstance(op, ast.Add) else _neg(c)
                out[k] = ast.BinOp(out[k], ast.Add(), c) if k in out else c
            return out
        if isinstance(op, ast.Mult):
            if la and lb:
                raise self.fail("matrix_product", "a matrix times a matrix is not allowed (the operator must be "
                                "linear in the matrices)", node)
            lin, s = (a, b) if la else (b, a)
            return {k: _times(s, c) for k, c in lin.items()}
        if isinstance(op, ast.Div):
            if lb:
                raise self.fail("matrix_denominator", "a matrix in a denominator is not allowed", node)
            return {k: ast.BinOp(c, ast.Div(), b) for k, c in a.items()}
        raise self.fail("matrix_power", "a matrix in a power (base or exponent) is not allowed", node)


def _neg(c: ast.expr) -> ast.expr:
    if isinstance(c, ast.UnaryOp) and isinstance(c.op, ast.USub):
        return c.operand
    return ast.UnaryOp(ast.USub(), c)


def _times(s: ast.expr, c: ast.expr) -> ast.expr:
    return s if c is _ONE else ast.BinOp(s, ast.Mult(), c)


def _names(tree: ast.expr) -> frozenset[str]:
    return frozenset(n.id for n in ast.walk(tree) if isinstance(n, ast.Name) and n.id not in CONSTANTS
                     and n.id not in FUNCTIONS)


def evaluate_scalar(tree: ast.expr, values: Mapping[str, Any]):
    """The value of a scalar tree made by :func:`compile_operator` at parameter ``values`` (numbers or
    arrays of points, NumPy semantics: 1/0 is inf, log(−1) nan; the caller checks finiteness)."""
    if isinstance(tree, ast.Constant):
        return tree.value
    if isinstance(tree, ast.Name):
        return CONSTANTS[tree.id] if tree.id in CONSTANTS else np.asarray(values[tree.id], float)
    if isinstance(tree, ast.UnaryOp):
        return _UNARY[type(tree.op)](evaluate_scalar(tree.operand, values))
    if isinstance(tree, ast.BinOp):
        return _BINARY[type(tree.op)](evaluate_scalar(tree.left, values), evaluate_scalar(tree.right, values))
    if isinstance(tree, ast.Call):
        return FUNCTIONS[tree.func.id](evaluate_scalar(tree.args[0], values))
    raise ExpressionError(f"not a compiled coefficient: {type(tree).__name__}", "construct")


#: d f(u)/du of the functions, as functions of u
_DERIVATIVES: dict[str, Callable] = {"sqrt": lambda u: 0.5 / np.sqrt(u), "exp": np.exp, "log": lambda u: 1.0 / u,
                                     "sin": np.cos, "cos": lambda u: -np.sin(u)}


def derivative_scalar(tree: ast.expr, values: Mapping[str, Any], name: str) -> tuple[Any, Any]:
    """(c, ∂c/∂p) of a scalar tree made by :func:`compile_operator` at parameter ``values``, p the
    parameter ``name``: forward-mode differentiation over the same nodes (sum, product and quotient rules,
    d(u^v) = v u^(v−1) du + u^v ln(u) dv, the chain rule through :data:`FUNCTIONS`), exact to rounding."""
    if isinstance(tree, ast.Constant):
        return tree.value, 0.0
    if isinstance(tree, ast.Name):
        if tree.id in CONSTANTS:
            return CONSTANTS[tree.id], 0.0
        return np.asarray(values[tree.id], float), (1.0 if tree.id == name else 0.0)
    if isinstance(tree, ast.UnaryOp):
        u, du = derivative_scalar(tree.operand, values, name)
        f = _UNARY[type(tree.op)]
        return f(u), f(du)
    if isinstance(tree, ast.BinOp):
        (u, du), (v, dv) = derivative_scalar(tree.left, values, name), derivative_scalar(tree.right, values, name)
        op = type(tree.op)
        if op in (ast.Add, ast.Sub):
            f = _BINARY[op]
            return f(u, v), f(du, dv)
        if op is ast.Mult:
            return u * v, du * v + u * dv
        if op is ast.Div:
            return u / v, (du * v - u * dv) / (v * v)
        w = np.power(u, v)
        dw = v * np.power(u, v - 1.0) * du
        if np.any(dv != 0):
            dw = dw + w * np.log(u) * dv
        return w, dw
    if isinstance(tree, ast.Call):
        u, du = derivative_scalar(tree.args[0], values, name)
        return FUNCTIONS[tree.func.id](u), _DERIVATIVES[tree.func.id](u) * du
    raise ExpressionError(f"not a compiled coefficient: {type(tree).__name__}", "construct")


def _term(matrix: str, tree: ast.expr) -> AffineTerm:
    tree = ast.fix_missing_locations(ast.Expression(tree)).body
    return AffineTerm(matrix, lambda values, tree=tree: evaluate_scalar(tree, values), _names(tree),
                      ast.unparse(tree) if tree is not _ONE else "1",
                      lambda values, name, tree=tree: derivative_scalar(tree, values, name)[1])


def compile_operator(name: str, text: str, matrices: Collection[str],
                     parameters: Collection[str]) -> AffineOperator:
    """The affine form Σ_k c_k(p) A_k of the expression ``text`` of operator ``name`` (for messages:
    ``"K"``, ``"matrices.K"``) over the named ``matrices`` and ``parameters`` (module docstring); one
    term per matrix, in the order the matrices first appear.  Raises :class:`ExpressionError`."""
    if not isinstance(text, str) or not text.strip():
        raise ExpressionError(f"{name}: must be a non-empty expression of the named matrices", "syntax")
    if len(text) > MAX_LENGTH:
        raise ExpressionError(f"{name}: longer than {MAX_LENGTH} characters", "syntax")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as e:
        raise ExpressionError(f"{name}: not an expression ({e.msg} at column {e.offset})", "syntax") from None
    except (ValueError, RecursionError, MemoryError):
        raise ExpressionError(f"{name}: not an expression (too deeply nested or a null character)",
                              "syntax") from None
    try:
        out = _Compiler(name, text.strip(), matrices, parameters).walk(tree.body)
    except RecursionError:
        raise ExpressionError(f"{name}: nested too deeply", "syntax") from None
    if not isinstance(out, dict):
        raise ExpressionError(f"{name}: names no matrix (an operator is a combination of the named matrices: "
                              f"{sorted(matrices)})", "no_matrix")
    return AffineOperator(name, tuple(_term(k, c) for k, c in out.items()))
