"""No numba-compiled function in fgloc raises to a power: squares are written as products.

numba types ``x ** 2`` with a literal or a plain integer exponent depending on what the
process typed before, and the two compile to different machine code: the native matcher's
covariances would change in their last bits with the order in which a process compiles its
kernels or loads them from the on-disk cache.  A product compiles the same whatever came
before, so outputs do not depend on the cache's history."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "fgloc"


def _compiled(node: ast.FunctionDef) -> bool:
    return any(isinstance(d, ast.Call) and isinstance(d.func, ast.Name) and "jit" in d.func.id
               or isinstance(d, ast.Name) and "jit" in d.id for d in node.decorator_list)


def test_no_power_in_compiled_functions() -> None:
    found = []
    n_compiled = 0
    for path in sorted(PACKAGE.rglob("*.py")):
        text = path.read_text()
        if "jit" not in text:
            continue
        for fn in ast.parse(text, filename=str(path)).body:  # the kernels are module-level functions
            if isinstance(fn, ast.FunctionDef) and _compiled(fn):
                n_compiled += 1
                found += [f"{path.relative_to(PACKAGE.parent)}:{n.lineno} {fn.name}: {ast.unparse(n)}"
                          for n in ast.walk(fn) if isinstance(n, ast.BinOp) and isinstance(n.op, ast.Pow)]
    assert n_compiled > 20  # the walk does see the compiled kernels
    assert found == [], "write squares as products in compiled code:\n" + "\n".join(found)
