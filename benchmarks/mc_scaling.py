"""Wall time of the Monte Carlo engine (``jaxcoag.evolve`` with ``jaxcoag.MonteCarlo``) vs Ns* and vs simulated
time; events per second.

Sum kernel K = (m1 + m2)/2, const-V, equal-mass grouping, N = 1e30 monomers, f_eps = 1e-3.
Each configuration is timed on its second call (the first compiles; reported separately).
Writes benchmarks/results/mc_scaling[_quick].json and prints a table.

    python benchmarks/mc_scaling.py [--quick]
"""

import argparse
import json
import os
import platform
import time

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp

import jaxcoag
from jaxcoag import kernels as K
from jaxcoag import mc

OUT = os.path.join(os.path.dirname(__file__), "results")


def timed(ns, tend, rates="incremental", seed=1):
    engine = jaxcoag.MonteCarlo(grouping=mc.EqualMass(), n_particles=1e30, ns_target=ns, f_eps=1e-3,
                                rates={"incremental": mc.IncrementalRates(), "full": mc.FullRates()}[rates])
    run = lambda key: jaxcoag.evolve(K.Sum(0.5), engine, jaxcoag.Monodisperse(1.0, 1.0),  # noqa: E731
                                     jnp.array([0.0, tend]), key=key, throw=False)
    t0 = time.perf_counter()
    r = run(jax.random.key(0))
    jax.block_until_ready(r.m)
    tc = time.perf_counter() - t0
    t0 = time.perf_counter()
    r = run(jax.random.key(seed))
    jax.block_until_ready(r.m)
    tw = time.perf_counter() - t0
    ev = int(r.n_events)
    return dict(ns=ns, t=tend, rates=rates, first_call_s=tc, wall_s=tw, events=ev, ev_per_s=ev / tw,
                status=next(n for n in jaxcoag.RESULT_NAMES if bool(r.status == getattr(jaxcoag.RESULTS, n))),
                Ns_end=int(r.n_species[-1]))


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    grid_ns = (50, 100) if args.quick else (50, 100, 200, 400)
    grid_t = (2.0,) if args.quick else (2.0, 10.0)
    rows = [timed(ns, 5.0) for ns in grid_ns] + [timed(100, t) for t in grid_t]
    if not args.quick:
        rows.append(timed(100, 5.0, rates="full"))
    print(f"{'Ns*':>5} {'t':>5} {'rates':>12} {'events':>8} {'wall [s]':>9} {'events/s':>9} {'compile+run [s]':>16} {'Ns_end':>7} status")
    for r in rows:
        print(f"{r['ns']:5d} {r['t']:5.1f} {r['rates']:>12} {r['events']:8d} {r['wall_s']:9.3f} {r['ev_per_s']:9.0f} "
              f"{r['first_call_s']:16.2f} {r['Ns_end']:7d} {r['status']}")
    res = dict(benchmark="mc_scaling", quick=args.quick, rows=rows,
               machine=dict(platform=platform.platform(), cores=os.cpu_count(), jax=jax.__version__,
                            load_average=os.getloadavg()))
    os.makedirs(OUT, exist_ok=True)
    path = os.path.join(OUT, "mc_scaling" + ("_quick" if args.quick else "") + ".json")
    with open(path + ".tmp", "w") as fh:
        json.dump(res, fh, indent=1, default=str)
    os.replace(path + ".tmp", path)
    print(f"wrote {path}")
    return res


if __name__ == "__main__":
    main()
