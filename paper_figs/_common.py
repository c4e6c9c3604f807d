"""Tiny shared helper for the paper-figure scripts (any chapter).

Usage in a script ``paper_figs/figN_M_name.py``::

    import os, sys
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import _common

    def main(argv=None):
        args = _common.parse_args(argv, __doc__)
        plt = _common.pyplot()
        checks = _common.Checks("Fig 3.2")
        checks.add("St*(0.3) exact", computed, 0.4302, tol=1e-3)
        ...
        png = _common.savefig(fig, args, "fig3_2_tstar")
        checks.print()
        return checks.result(png)

``--quick`` selects coarse grids (the test suite runs every script this way), ``--out DIR`` sets the
output folder (default ``paper_figs/out/``). ``result()`` returns ``{"png": path, "checks": {name:
{"computed", "reference", "rel_diff", "tol", "ok", "counts"}}, "all_ok": bool}`` for the tests.

A check that touches no simulation (published numbers against each other, a property of the chosen
parameters) is added with ``counts=False``: it is printed and returned, marked "info", but it does
not count toward ``all_ok`` - a script passes on what it computed, not on what it was given.
"""

from __future__ import annotations

import argparse
import math
import pathlib

DEFAULT_OUT = pathlib.Path(__file__).resolve().parent / "out"


def parse_args(argv=None, description: str | None = None, extra=None) -> argparse.Namespace:
    """Parse the common options ``--quick`` and ``--out DIR``.

    Arguments:
        argv: list of strings (None: sys.argv[1:]).
        description: help text (pass the script's ``__doc__``).
        extra: optional callable ``extra(parser)`` adding script-specific options.
    Returns:
        argparse.Namespace with ``quick`` (bool) and ``out`` (pathlib.Path, created).
    """
    p = argparse.ArgumentParser(description=(description or "").strip().splitlines()[0] if description else None)
    p.add_argument("--quick", action="store_true", help="coarse grids, a few seconds (used by the tests)")
    p.add_argument("--out", type=pathlib.Path, default=DEFAULT_OUT, help="output folder (default paper_figs/out/)")
    if extra is not None:
        extra(p)
    args = p.parse_args(argv)
    args.out = pathlib.Path(args.out)
    args.out.mkdir(parents=True, exist_ok=True)
    return args


def enable_x64():
    """Turn on float64 (the scripts are entry points; the library itself never flips config)."""
    import jax

    jax.config.update("jax_enable_x64", True)
    return jax


def pyplot():
    """matplotlib.pyplot with the non-interactive Agg backend."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def savefig(fig, args, name: str, dpi: int = 120) -> pathlib.Path:
    """Save ``fig`` as ``<args.out>/<name>.png``, close it, and return the path."""
    path = pathlib.Path(args.out) / f"{name}.png"
    fig.savefig(path, dpi=dpi, bbox_inches="tight")
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path


class Checks:
    """Collects (computed, reference) check points, prints them as a table and returns them."""

    def __init__(self, title: str):
        self.title = title
        self.rows: dict[str, dict] = {}

    def add(self, name: str, computed, reference, tol: float = 1e-6, *, absolute: bool = False,
            counts: bool = True):
        """Record a check point.

        Arguments:
            name: label (unique).
            computed, reference: numbers.
            tol: tolerance on the relative difference (or the absolute one if ``absolute``).
            absolute: compare |computed - reference| instead of the relative difference.
            counts: False for a check that involves no simulation output (e.g. published table
                rows against each other): reported, but not part of :attr:`all_ok`.
        """
        c, r = float(computed), float(reference)
        diff = c - r if absolute or r == 0 else (c - r) / abs(r)
        ok = bool(math.isfinite(c) and abs(diff) <= tol)
        self.rows[name] = dict(computed=c, reference=r, rel_diff=diff, tol=float(tol), ok=ok,
                               absolute=bool(absolute or r == 0), counts=bool(counts))
        return c

    def print(self):
        """Print the table: name, computed, reference, (relative) difference, tolerance, status."""
        w = max([len(k) for k in self.rows] + [10])
        print(f"== {self.title}: check points ==")
        print(f"{'check':<{w}}  {'computed':>14}  {'reference':>14}  {'diff':>10}  {'tol':>8}  ok")
        for k, v in self.rows.items():
            kind = "abs" if v["absolute"] else "rel"
            info = "" if v["counts"] else ", info: not counted"
            print(f"{k:<{w}}  {v['computed']:>14.7g}  {v['reference']:>14.7g}  {v['rel_diff']:>10.2e}  "
                  f"{v['tol']:>8.1e}  {'ok' if v['ok'] else 'FAIL'} ({kind}{info})")

    @property
    def all_ok(self) -> bool:
        """True when every counted check passed (``counts=False`` rows are informational)."""
        return all(v["ok"] for v in self.rows.values() if v["counts"])

    def result(self, png, **extra) -> dict:
        """Dictionary returned by a script's ``main``: png path, checks, all_ok (+ extra entries)."""
        out = dict(png=pathlib.Path(png), checks=self.rows, all_ok=self.all_ok)
        out.update(extra)
        return out


def log_peak(f, lo: float, hi: float, n: int = 401, zooms: int = 5):
    """Maximum of a vectorised f(x) over x in [lo, hi] by repeated zooming on a log grid.

    Arguments:
        f: callable taking a 1-D numpy/jax array of x and returning values of the same shape.
        lo, hi: search bracket (> 0).
        n: points per zoom level; zooms: number of levels.
    Returns:
        (x_max, f_max) as floats.
    """
    import numpy as np

    a, b = math.log10(lo), math.log10(hi)
    for _ in range(zooms):
        x = np.linspace(a, b, n)
        v = np.asarray(f(10.0 ** x))
        i = int(np.argmax(v))
        a, b = x[max(i - 2, 0)], x[min(i + 2, n - 1)]
    return float(10.0 ** x[i]), float(v[i])


__all__ = ["parse_args", "enable_x64", "pyplot", "savefig", "Checks", "log_peak", "DEFAULT_OUT"]
