"""A function y = f(x) written as text (``"log10(x)"``, ``"x**1.5"``, ``"sin(x) + 0.5*x"``), evaluated safely.

Only numbers, the variable ``x``, the constants ``pi`` and ``e``, the operators + − * / ** and the functions in
:data:`FUNCTIONS` are accepted (the text is parsed, never executed), so a synthesis file cannot run code.
"""

from __future__ import annotations

import ast
import math
from collections.abc import Callable

import numpy as np

from ..errors import SynthesisError

FUNCTIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "sin": np.sin, "cos": np.cos, "tan": np.tan, "asin": np.arcsin, "acos": np.arccos, "atan": np.arctan,
    "sinh": np.sinh, "cosh": np.cosh, "tanh": np.tanh, "exp": np.exp, "log": np.log, "ln": np.log,
    "log10": np.log10, "log2": np.log2, "sqrt": np.sqrt, "abs": np.abs,
}  # fmt: skip
CONSTANTS = {"pi": math.pi, "e": math.e}
MAX_LENGTH = 500
_BINARY = {ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply, ast.Div: np.divide, ast.Pow: np.power}


class Expression:
    """f(x) parsed from its text: callable on arrays (NaN where undefined), its ``tree`` for analysis
    (:mod:`.domain`) and its ``text``."""

    def __init__(self, tree: ast.AST, text: str) -> None:
        self.tree, self.text = tree, text

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return evaluate(self.tree, np.asarray(x, float))


def parse(text: object, entry: str = "f") -> Expression:
    """A vectorized f(x) from its text; SynthesisError naming ``entry`` for anything else than the grammar."""
    if not isinstance(text, str) or not text.strip() or len(text) > MAX_LENGTH:
        raise SynthesisError(f"{entry}: must be an expression in x of at most {MAX_LENGTH} characters", entry=entry)
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        raise SynthesisError(f"{entry}: {text!r:.80} is not an expression in x", entry=entry) from None
    _check(tree.body, entry, text)
    return Expression(tree.body, text)


def _check(node: ast.AST, entry: str, text: str, depth: int = 0) -> None:
    if depth > 50:
        raise SynthesisError(f"{entry}: the expression is nested too deeply", entry=entry)
    ok = (
        (isinstance(node, ast.Constant) and type(node.value) in (int, float) and _finite(node.value))
        or (isinstance(node, ast.Name) and (node.id == "x" or node.id in CONSTANTS))
        or (isinstance(node, ast.BinOp) and type(node.op) in _BINARY)
        or (isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)))
        or (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Name)
            and node.func.id in FUNCTIONS
            and len(node.args) == 1
            and not node.keywords
        )
    )
    if not ok:
        what = ast.unparse(node)[:40] if hasattr(ast, "unparse") else type(node).__name__
        raise SynthesisError(
            f"{entry}: {what!r} is not allowed in {text!r:.60} (numbers, x, pi, e, + - * / **, and "
            f"{', '.join(FUNCTIONS)})",
            entry=entry,
        )
    children = [node.func] if isinstance(node, ast.Call) else []
    for child in ast.iter_child_nodes(node):
        if child not in children and not isinstance(child, (ast.operator, ast.unaryop, ast.expr_context)):
            _check(child, entry, text, depth + 1)


def _finite(value: float) -> bool:
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False


def evaluate(node: ast.AST, x: np.ndarray) -> np.ndarray:
    """The expression tree's values at x (NaN or ±inf where it is undefined)."""
    with np.errstate(all="ignore"):
        if isinstance(node, ast.Constant):
            return np.full_like(x, float(node.value))
        if isinstance(node, ast.Name):
            return x if node.id == "x" else np.full_like(x, CONSTANTS[node.id])
        if isinstance(node, ast.BinOp):
            return _BINARY[type(node.op)](evaluate(node.left, x), evaluate(node.right, x))
        if isinstance(node, ast.UnaryOp):
            v = evaluate(node.operand, x)
            return -v if isinstance(node.op, ast.USub) else v
        assert isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
        return FUNCTIONS[node.func.id](evaluate(node.args[0], x))
