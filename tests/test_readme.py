"""Every ```python block of README.md runs as pasted, each in a fresh namespace and a temporary
working directory, and the numbers its comments show are what the code returns.

Comment forms checked on an expression line (``expr  # ...``):

* ``# 0.5257729 ...`` - a number: the value rounds to the printed significant digits
  (|value - shown| <= half a unit of the last printed digit);
* ``# ~1e-16 ...`` - an order of magnitude: |value| <= 10 x shown;
* ``# 200 x 200 ...`` - a shape;
* ``# [] ...`` - a Python literal the value must equal.

Other comments are prose and not checked. A block that shows no number is still run (it must not
raise).
"""

import ast
import os
import re
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def python_blocks(text):
    """(first line number, source) of every ```python fenced block."""
    out = []
    for m in re.finditer(r"^```python[ \t]*\n(.*?)^```", text, re.S | re.M):
        out.append((text.count("\n", 0, m.start()) + 2, m.group(1)))
    return out


def claims(src):
    """(line number within the block, expression source, kind, expected) for each checked comment."""
    lines = src.splitlines()
    tree = ast.parse(src)
    out = []
    for node in tree.body:
        if not isinstance(node, ast.Expr):
            continue
        line = lines[node.end_lineno - 1]
        if "#" not in line:
            continue
        comment = line.split("#", 1)[1].strip()
        expr = ast.get_source_segment(src, node)
        if m := re.match(rf"(\d+)\s+x\s+(\d+)\b", comment):
            out.append((node.lineno, expr, "shape", (int(m.group(1)), int(m.group(2)))))
        elif m := re.match(rf"~\s*({_NUM})", comment):
            out.append((node.lineno, expr, "order", float(m.group(1))))
        elif m := re.match(rf"({_NUM})(?![\w.])", comment):
            out.append((node.lineno, expr, "digits", m.group(1)))
        elif m := re.match(r"(\[[^\]]*\])", comment):
            out.append((node.lineno, expr, "literal", ast.literal_eval(m.group(1))))
    return out


def _check(value, kind, expected, where):
    if kind == "shape":
        assert tuple(np.shape(value)) == expected, f"{where}: shape {np.shape(value)} != {expected}"
    elif kind == "order":
        assert abs(float(value)) <= 10 * expected, f"{where}: |{float(value)!r}| is not ~{expected:g}"
    elif kind == "digits":
        d = Decimal(expected)
        half = Decimal(5) * Decimal(10) ** (d.as_tuple().exponent - 1)
        assert abs(Decimal(repr(float(value))) - d) <= half, f"{where}: {float(value)!r} does not round to {expected}"
    else:
        assert value == expected, f"{where}: {value!r} != {expected!r}"


BLOCKS = python_blocks(README.read_text())


def test_readme_has_checked_numbers():
    """The parser finds the README's blocks and the numbers they show (guards against a silent no-op)."""
    assert len(BLOCKS) >= 4
    found = [c for _, src in BLOCKS for c in claims(src)]
    kinds = {c[2] for c in found}
    assert {"digits", "shape", "order"} <= kinds and len(found) >= 6
    shown = {c[3] for c in found if c[2] == "digits"}
    assert {"0.5257729", "8.5627879", "1.5"} <= shown


# Blocks run only with `-m slow` (default-suite budget), named by a string unique to each, with the
# default tests that cover the same code: the DG sum-kernel accuracy and gradient block (35 s on 2 cores)
# <- tests/test_binned_dg.py (DG against the analytic sum-kernel solution, mass to round-off) and
# tests/test_binned_gradients.py::test_reverse_and_forward_vs_fd (gradients through the solve); the one-verb block
# with both engines on the constant kernel (26 s) <- tests/test_one_api.py::
# test_both_engines_match_the_constant_kernel_solution (the same engines, kernel and start against the exact moments
# and spectrum).
SLOW_BLOCKS = ("jax.grad(log_peak)", "rm = jc.evolve(kernel, mc, start, t_out, key=key)")


def _param(start, src):
    marks = [pytest.mark.slow] if any(k in src for k in SLOW_BLOCKS) else []
    return pytest.param(start, src, id=f"README.md:{start}", marks=marks)


def test_slow_blocks_exist():
    """Every SLOW_BLOCKS key names exactly one README block (a renamed block must not silently drop out)."""
    for k in SLOW_BLOCKS:
        assert sum(k in src for _, src in BLOCKS) == 1, k


@pytest.mark.parametrize("start,src", [_param(s, src) for s, src in BLOCKS])
def test_readme_block_runs_and_numbers_match(start, src, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    checks = {line: (kind, exp) for line, _, kind, exp in claims(src)}
    ns = {"__name__": "__readme__"}
    tree = ast.parse(src)
    for node in tree.body:
        where = f"README.md:{start + node.lineno - 1}"
        if isinstance(node, ast.Expr):
            value = eval(compile(ast.Expression(node.value), where, "eval"), ns)
            if node.lineno in checks:
                _check(value, *checks[node.lineno], where)
        else:
            exec(compile(ast.Module([node], type_ignores=[]), where, "exec"), ns)
    assert os.listdir(tmp_path) == [], "a README block wrote files into the working directory"
