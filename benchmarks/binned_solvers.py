"""Implicit solvers on the default ``jaxcoag run`` box: Rodas4 (the default with fragmentation) vs Kvaerno5 + chord
(a Jacobian per stage, the previous default), steps, wall time and accuracy.

Box: ``jaxcoag.config.default()`` (1 AU MMSN, Brownian + OC07 turbulence + radial drift, Maxwellian shattering at
10 m/s, two-bin scheme on 135 bins, 17 outputs to 1e4 yr) in one ``jaxcoag.evolve`` call. Error: the largest
relative L1 of the mass per bin over the outputs against Kvaerno5 + chord at rtol 1e-10 (atol 1e-14). Each
setting is timed as the best of two calls after its compiling call.

    python benchmarks/binned_solvers.py [--quick]

``--quick``: ``runner.quick_config`` (coarse grid, rtol 1e-4 and 1e-6 only). Writes
``benchmarks/results/binned_solvers[_quick].json``.

References: Hairer & Wanner (1996), Solving ODEs II, §IV.7 and §VI.4 (RODAS); Kvaerno (2004) (ESDIRK 5(4)).
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.append(str(ROOT))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
import equinox as eqx  # noqa: E402
import numpy as np  # noqa: E402

import jaxcoag  # noqa: E402
from jaxcoag import config as cfgmod  # noqa: E402
from jaxcoag import runner  # noqa: E402
from jaxcoag.binned import Rodas4  # noqa: E402
from jaxcoag.binned.solve import default_implicit_solver  # noqa: E402

from benchmarks._common import first_and_best, machine_info, print_table, write_json  # noqa: E402

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")


def solve(b, solver, rtol, atol, repeat=2):
    eng = eqx.tree_at(lambda e: (e.solver, e.rtol, e.atol), b.engine, (solver, rtol, atol),
                      is_leaf=lambda x: x is None)
    call = lambda: jaxcoag.evolve(b.kernel, eng, b.initial, b.t_out, t0=0.0, outcome=b.outcome, throw=False)  # noqa: E731
    r, first, best = first_and_best(call, repeat)
    return r, best, first


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args(argv)
    cfg = runner.quick_config(cfgmod.default()) if a.quick else cfgmod.default()
    b = cfgmod.build(cfg)
    M0 = float(b.engine.scheme.total_mass(b.engine.scheme.init(b.engine.grid, b.engine._n0(b.initial)), b.engine.grid))
    ref, _, _ = solve(b, default_implicit_solver(1e-10, 1e-3 * 1e-14 * M0), 1e-10, 1e-14, repeat=0)
    M = np.asarray(ref.mass_per_bin())
    rtols = (1e-4, 1e-6) if a.quick else (1e-4, 1e-5, 1e-6, 1e-7)
    rows = []
    for name in ("Rodas4", "Kvaerno5+chord"):
        for rt in rtols:
            s = Rodas4() if name == "Rodas4" else default_implicit_solver(rt, 1e-3 * 1e-4 * rt * M0)
            r, wall, first = solve(b, s, rt, 1e-4 * rt)
            m = np.asarray(r.mass_per_bin())
            rows.append(dict(solver=name, rtol=rt, steps=int(r.stats["steps"]), rejected=int(r.stats["rejected"]),
                             wall_s=wall, first_call_s=first,
                             l1_max=float(np.max(np.sum(np.abs(m - M), axis=1) / np.sum(M, axis=1))),
                             mass_drift=float(np.max(np.abs(np.asarray(r.mass_drift))))))
            print(rows[-1], flush=True)
    print_table(rows, ["solver", "rtol", "steps", "rejected", "wall_s", "l1_max", "mass_drift"],
                title=f"default box ({b.grid.nbins} bins), one evolve call, error vs Kvaerno5 rtol 1e-10")
    out = os.path.join(OUT, "binned_solvers" + ("_quick" if a.quick else "") + ".json")
    write_json(out, dict(benchmark="binned_solvers", quick=a.quick, nbins=b.grid.nbins, rows=rows,
                         reference="Kvaerno5 + chord, rtol 1e-10, atol 1e-14", machine=machine_info()))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
