"""Structured two-bin Jacobian vs the dense JVP Jacobian, and what it buys implicit solves.

Part 1 (one Jacobian): on the default ``jaxcoag run`` box (``jaxcoag.config.default()``: MMSN 1 AU,
Brownian + turbulence + radial drift, Maxwellian shattering + erosion at v_frag = 10 m/s) at 3, 7
and 14 bins per decade (60 / 135 / 270 bins), with the fragmentation and without it (pure growth,
gel sweep on): compiled wall time per evaluation of one right-hand side,
``jax.jacfwd`` of the plain rhs (N + 1 JVPs: the previous Jacobian), ``TwoBinScheme.jacobian``
(the scatter of the pair-rate derivatives) and ``jax.jacfwd(rhs_structured)`` (what the solvers
now call: the custom JVP rule forms J once and multiplies it by the identity), on a random
positive state; best of ``--repeat`` timed loops after compilation; the maximum relative
(Frobenius) difference of the Jacobians.

Part 2 (solves): the default box (135 bins, 17 output times to 1e4 yr, rtol 1e-6) in one
``jaxcoag.evolve`` call with Kvaerno5 + chord (the default until 2026-11-26; now Rodas4) and with the DustPy-parity
``LinearlyImplicitEuler`` (PID step control, same tolerances), before (a scheme whose
``rhs_structured`` is the plain rhs, i.e. the previous code path: Jacobians by N + 1 JVPs) and
after: accepted/rejected steps, wall time of the call minus compilation (``runner.CompileClock``),
and the maximum difference of the mass per bin between before and after, relative to the peak
(and to each bin, over bins above 1e-6 of the peak). Then ``jaxcoag.runner.run`` of the same
box (one solve per output time, as ``jaxcoag run``; nothing written): its timings and steps.

    python benchmarks/binned_jacobian.py [--quick] [--no-solves] [--no-lie-before] [--repeat 5]

``--quick``: part 1 at 3 and 7 bins per decade only, part 2 on ``runner.quick_config`` (3 bins per
decade, 8 outputs, rtol 1e-4). Writes ``benchmarks/results/binned_jacobian[_quick].json``.

References: Stammler & Birnstiel (2022) ApJ 935, 35, §3.2 (DustPy's implicit step with the
coagulation Jacobian); Brauer et al. (2008) App. A (two-bin operator); Hairer & Wanner (1996),
Solving ODEs II, §IV.7-8.
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks import _common as C  # noqa: E402


def _timeit(fn, arg, repeat, min_s=0.2):
    """Best time per call [s] of a compiled fn over ``repeat`` loops of >= min_s each."""
    import jax

    jax.block_until_ready(fn(arg))  # compile
    n = 1
    while True:
        t0 = time.perf_counter()
        for _ in range(n):
            jax.block_until_ready(fn(arg))
        dt = time.perf_counter() - t0
        if dt >= min_s or n >= 4096:
            break
        n *= 4
    best = dt / n
    for _ in range(repeat - 1):
        t0 = time.perf_counter()
        for _ in range(n):
            jax.block_until_ready(fn(arg))
        best = min(best, (time.perf_counter() - t0) / n)
    return best


def _config(bpd=None, frag=True, quick=False):
    from jaxcoag import config as cfgmod
    from jaxcoag import runner

    cfg = cfgmod.default()
    if quick:
        cfg = runner.quick_config(cfg)
    raw = cfg.raw()
    if bpd is not None:
        raw.setdefault("grid", {})["bins_per_decade"] = float(bpd)
        raw["grid"].pop("m_min", None)
    if not frag:
        raw.pop("fragmentation", None)
    return cfgmod.build(cfgmod.from_dict(raw, source="benchmarks/binned_jacobian.py"))


class _Previous:
    """Factory of the previous code path: a TwoBinScheme whose rhs_structured is the plain rhs."""

    cls = None

    @classmethod
    def make(cls, scheme):
        from jaxcoag.binned.twobin import TwoBinScheme

        if cls.cls is None:
            class PlainJacobianTwoBin(TwoBinScheme):
                def rhs_structured(self, t, y, data):
                    return self.rhs(t, y, data)
            cls.cls = PlainJacobianTwoBin
        return cls.cls(gel_sweep=scheme.gel_sweep)


def jacobian_timings(bpds, repeat):
    import jax
    import jax.numpy as jnp
    import numpy as np
    from jaxcoag.binned.engine import _fragmentation

    rows = []
    for frag in (True, False):
        for bpd in bpds:
            b = _config(bpd, frag)
            sch, grid = b.engine.scheme, b.engine.grid
            data = sch.precompute(b.kernel, grid, _fragmentation(b.outcome))
            y0 = sch.init(grid, b.initial)
            rng = np.random.default_rng(0)
            y = y0 + jnp.asarray(rng.uniform(0.0, 1.0, y0.shape)) * jnp.max(y0)
            f_rhs = jax.jit(lambda y: sch.rhs(0.0, y, data))
            f_old = jax.jit(jax.jacfwd(lambda y: sch.rhs(0.0, y, data)))
            f_new = jax.jit(lambda y: sch.jacobian(0.0, y, data))
            f_cj = jax.jit(jax.jacfwd(lambda y: sch.rhs_structured(0.0, y, data)))
            J_old, J_new, J_cj = f_old(y), f_new(y), f_cj(y)
            nrm = float(jnp.linalg.norm(J_old))
            row = dict(fragmentation=frag, bins_per_decade=bpd, nbins=grid.nbins,
                       rhs_ms=1e3 * _timeit(f_rhs, y, repeat),
                       jacfwd_plain_ms=1e3 * _timeit(f_old, y, repeat),
                       structured_ms=1e3 * _timeit(f_new, y, repeat),
                       jacfwd_structured_ms=1e3 * _timeit(f_cj, y, repeat),
                       rel_diff=max(float(jnp.linalg.norm(J_new - J_old)) / nrm,
                                    float(jnp.linalg.norm(J_cj - J_old)) / nrm))
            row["speedup"] = row["jacfwd_plain_ms"] / row["jacfwd_structured_ms"]
            rows.append(row)
            print(row, flush=True)
    return rows


def solve(built, solver_name, previous):
    import dataclasses

    import jax
    import jax.numpy as jnp
    import numpy as np
    import jaxcoag
    from jaxcoag._status import RESULT_NAMES, result_code
    from jaxcoag.binned import LinearlyImplicitEuler
    from jaxcoag.runner import CompileClock

    eng = built.engine
    changes = {}
    if previous:
        changes["scheme"] = _Previous.make(eng.scheme)
    if solver_name == "lie":
        changes["solver"] = LinearlyImplicitEuler()
    eng = dataclasses.replace(eng, **changes) if changes else eng
    t0 = time.perf_counter()
    with CompileClock() as clock:
        res = jaxcoag.evolve(built.kernel, eng, built.initial, jnp.asarray(built.t_out), outcome=built.outcome,
                             throw=False)
        jax.block_until_ready(res.y)
    wall = time.perf_counter() - t0
    rho = np.asarray(eng.scheme.mass_per_bin(res.y, eng.grid))
    return dict(solver=solver_name, path="previous (jacfwd of plain rhs)" if previous else "structured",
                status=RESULT_NAMES[int(np.asarray(result_code(res.status)))], steps=int(res.stats["steps"]), rejected=int(res.stats["rejected"]),
                wall_s=wall, compile_s=clock.compile_s, trace_lower_s=clock.trace_lower_s,
                solve_s=wall - clock.compile_s - clock.trace_lower_s), rho


def _compare(a, b):
    import numpy as np

    peak = np.max(np.abs(b), axis=-1, keepdims=True)
    big = np.abs(b) > 1e-6 * peak
    return dict(max_diff_over_peak=float(np.max(np.abs(a - b) / peak)),
                max_rel_diff_above_1em6_peak=float(np.max(np.abs(a - b)[big] / np.abs(b)[big])))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--no-solves", action="store_true", help="only part 1 (one Jacobian)")
    ap.add_argument("--no-lie-before", action="store_true",
                    help="skip the LinearlyImplicitEuler solve on the previous path (slow: one dense JVP Jacobian "
                         "per step)")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    if a.repeat < 1:
        ap.error("--repeat must be >= 1")
    out = pathlib.Path(a.out) if a.out else C.RESULTS / f"binned_jacobian{'_quick' if a.quick else ''}.json"

    import jax
    jax.config.update("jax_enable_x64", True)

    payload = dict(benchmark="binned_jacobian", quick=a.quick, machine=C.machine_info())
    bpds = (3, 7) if a.quick else (3, 7, 14)
    payload["jacobian"] = rows = jacobian_timings(bpds, a.repeat)
    C.print_table(rows, ["fragmentation", "nbins", "rhs_ms", "jacfwd_plain_ms", "structured_ms",
                         "jacfwd_structured_ms", "speedup", "rel_diff"], title="one Jacobian (compiled, per call)")
    C.write_json(out, payload)
    if not a.no_solves:
        built = _config(quick=a.quick)
        payload["box"] = dict(nbins=built.grid.nbins, n_out=len(built.t_out), rtol=float(built.engine.rtol),
                              atol=float(built.engine.atol), t_end_s=float(built.t_out[-1]))
        solves = []
        for solver_name in ("kvaerno5", "lie"):
            new, rho_new = solve(built, solver_name, previous=False)
            solves.append(new)
            print(new, flush=True)
            C.write_json(out, dict(payload, solves=solves))
            if solver_name == "lie" and a.no_lie_before:
                continue
            old, rho_old = solve(built, solver_name, previous=True)
            old.update(_compare(rho_new, rho_old))
            old["solve_speedup"] = old["solve_s"] / new["solve_s"]
            solves.append(old)
            print(old, flush=True)
            C.write_json(out, dict(payload, solves=solves))
        payload["solves"] = solves
        # the whole runner on the same box (one segment per output time, as `jaxcoag run`), structured path
        from jaxcoag import runner

        r = runner.run(None, quick=a.quick, save=False, progress=False, verbose=False)
        payload["runner"] = dict(timings=r.timings, steps=int(r.numbers["steps"]), rejected=int(r.numbers["rejected"]),
                                 result=r.numbers["result"], m_peak=float(r.numbers["m_peak"]))
        print("runner.run:", payload["runner"], flush=True)
        C.print_table(solves, ["solver", "path", "status", "steps", "rejected", "solve_s", "compile_s",
                               "solve_speedup", "max_diff_over_peak"], title="default box solve")
    C.write_json(out, payload)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
