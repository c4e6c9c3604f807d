"""Cost per event of the Monte Carlo engine (``jaxcoag.evolve`` with ``jaxcoag.MonteCarlo``) vs Ns* and vs
capacity, a baseline revision run side by side, the issue-17 goal run and a vmapped seed ensemble.

Box: sum kernel K = (m1 + m2)/2, constant volume, equal-mass grouping, N = 1e30 monomers of 1 g,
f_eps = 1e-3; the goal run uses the thesis' Fig. 5.4a set-up (constant Ns, n_particles = Ns*). Every configuration
is timed after a first call that compiles (reported apart as ``compile_s``; short runs: the best of up to 3 timed
calls).

Tables:
  * ``ns``: events/s vs Ns* at the default capacity (4 Ns*), to t = 5, with the species count at 11
    output times (max and end, and max/Ns*);
  * ``capacity``: Ns* = 100 at capacities 150 ... 51 200, to t = 20 (t = 2 with ``--quick``): the cost per event
    should not follow the capacity. From t ~ 5 on the run merges species every ~90 events (887 maintenances in
    78 035 events), so the table also carries the cost of the maintenance (merge, rezoom, refresh);
  * ``goal``: Fig. 5.4a set-up, Ns* = 2000 to t = 20 (issue 17: under 60 s after compile);
  * ``ensemble``: 8 seeds, one ``jax.vmap``-ed call vs a Python loop of 8 jitted calls, at Ns* = 100 and 400
    (on CPU the engine runs the members of a vmapped batch one after another: ``mc.engine._simulate_members``).
``--baseline PATH`` runs the ``ns`` and ``capacity`` tables with the jaxcoag checkout at PATH (a
subprocess with ``PYTHONPATH=PATH``, same machine, same invocation) and reports new/baseline ratios of
events/s; with ``--baseline-goal`` also the goal run (ratio of wall times).

    python benchmarks/mc_scaling.py [--quick] [--baseline /path/to/old/checkout [--baseline-goal]]
        [--skip tables,goal,ensemble] [--out PATH]

Writes benchmarks/results/mc_scaling[_quick].json (or ``--out``).
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

sys.path.append(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxcoag  # noqa: E402
from jaxcoag import kernels as K  # noqa: E402
from jaxcoag import mc  # noqa: E402

from benchmarks._common import machine_info, print_table, write_json  # noqa: E402
from jaxcoag.sweep import sweep  # noqa: E402

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")


def _status(r):
    return next(n for n in jaxcoag.RESULT_NAMES if bool(np.all(np.asarray(r.status == getattr(jaxcoag.RESULTS, n)))))


def timed(ns, tend, capacity=None, seed=1, n_out=11, const_ns=False):
    """One configuration: a compile call (key 0, the output times scaled by 1e-6: the same program, no events;
    ``compile_s``), then the timed call (key ``seed``; calls under 2 s together are repeated up to 3 times and
    the fastest is reported, ``timed_calls``). ``const_ns``: the thesis Fig. 5.4a set-up (constant Ns,
    mass controller, n_particles = Ns*; m_p grows as e^t)."""
    vol = mc.ConstantSpecies() if const_ns else mc.ConstantVolume()
    engine = jaxcoag.MonteCarlo(grouping=mc.EqualMass(), volume=vol, n_particles=float(ns) if const_ns else 1e30,
                                ns_target=ns, f_eps=1e-3, capacity=capacity)
    t_out = jnp.linspace(0.0, tend, n_out)
    run = lambda key, t: jaxcoag.evolve(K.Sum(0.5), engine, jaxcoag.Monodisperse(1.0, 1.0), t,  # noqa: E731
                                        key=key, throw=False)
    t0 = time.perf_counter()
    r = run(jax.random.key(0), t_out * 1e-6)
    jax.block_until_ready(r.m)
    tc = time.perf_counter() - t0
    times = []
    while len(times) < 3 and sum(times) < 2.0:   # short calls: the best of up to 3 (single calls varied by ~50 %)
        t0 = time.perf_counter()
        r = run(jax.random.key(seed), t_out)
        jax.block_until_ready(r.m)
        times.append(time.perf_counter() - t0)
    tw = min(times)
    ev = int(r.n_events)
    nsp = np.asarray(r.n_species)
    return dict(ns=ns, t=tend, volume="const_ns" if const_ns else "const_v", capacity=int(r.m.shape[-1]), compile_s=tc,
                wall_s=tw, timed_calls=len(times), events=ev, ev_per_s=ev / tw,
                us_per_event=1e6 * tw / max(ev, 1), status=_status(r), Ns_end=int(nsp[-1]), Ns_max=int(nsp.max()),
                Ns_max_over_target=float(nsp.max()) / ns, merges=int(r.n_merge))


def ensemble(ns=100, tend=5.0, n_seeds=8, workers=None, chunk=1):
    """8 seeds: one vmapped call, and ``jaxcoag.sweep.sweep`` over the seeds with ``workers`` host threads
    (chunk=1: each seed one single run; default workers = the core count), vs a loop of jitted single calls (all
    after compile; the same keys in every mode)."""
    workers = workers or os.cpu_count() or 1
    engine = jaxcoag.MonteCarlo(grouping=mc.EqualMass(), n_particles=1e30, ns_target=ns, f_eps=1e-3)
    t_out = jnp.array([0.0, tend])
    keys = jax.random.split(jax.random.key(3), n_seeds)

    def run(key):
        return jaxcoag.evolve(K.Sum(0.5), engine, jaxcoag.Monodisperse(1.0, 1.0), t_out, key=key, throw=False)

    one = jax.jit(run)
    many = jax.jit(jax.vmap(run))

    def member(seed):
        r = run(keys[seed.astype(jnp.int32)])
        return {"n_events": r.n_events, "M2": r.moments(2)[-1], "result": r.status}

    jax.block_until_ready(one(keys[0]).m)
    jax.block_until_ready(many(keys).m)
    seeds = np.arange(n_seeds, dtype=np.float64)
    t0 = time.perf_counter()
    sweep(member, {"seed": seeds}, chunk=chunk, workers=workers)
    compile_workers = time.perf_counter() - t0
    t0 = time.perf_counter()
    ev_loop = 0
    finals = []
    for k in keys:
        r = one(k)
        jax.block_until_ready(r.m)
        ev_loop += int(r.n_events)
        finals.append(r)
    t_loop = time.perf_counter() - t0
    m2_loop = [float(r.moments(2)[-1]) for r in finals]   # (outside the timed loop)
    t0 = time.perf_counter()
    rv = many(keys)
    jax.block_until_ready(rv.m)
    t_vmap = time.perf_counter() - t0
    ev_vmap = int(np.sum(np.asarray(rv.n_events)))
    t0 = time.perf_counter()
    dw = sweep(member, {"seed": seeds}, chunk=chunk, workers=workers)
    t_work = time.perf_counter() - t0
    ev_work = int(np.sum(dw["n_events"].values))
    return dict(ns=ns, t=tend, seeds=n_seeds, loop_s=t_loop, vmap_s=t_vmap, events_loop=ev_loop, events_vmap=ev_vmap,
                throughput_ratio_vmap_over_loop=(ev_vmap / t_vmap) / (ev_loop / t_loop), workers=workers,
                workers_s=t_work, workers_first_call_s=compile_workers, events_workers=ev_work,
                throughput_ratio_workers_over_loop=(ev_work / t_work) / (ev_loop / t_loop),
                workers_equal_loop=bool(np.array_equal(dw["M2"].values, np.asarray(m2_loop))))


def tables(quick, max_ns=None):
    ns_grid = (50, 100) if quick else (50, 100, 200, 400, 1000, 2000, 20000)
    ns_grid = tuple(n for n in ns_grid if max_ns is None or n <= max_ns)
    caps = (150, 800) if quick else (150, 800, 3200, 12800, 51200)
    return dict(ns=[timed(ns, 2.0 if quick else 5.0) for ns in ns_grid],
                capacity=[timed(100, 2.0 if quick else 20.0, capacity=c) for c in caps])


def run_baseline(path, quick, max_ns, goal=False):
    """The ``ns`` and ``capacity`` tables (and the goal run if ``goal``) with the checkout at ``path`` (subprocess,
    PYTHONPATH)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "rows.json")
        env = dict(os.environ, PYTHONPATH=os.path.abspath(path))
        cmd = [sys.executable, os.path.abspath(__file__), "--tables-only", out, "--baseline-max-ns", str(max_ns)] + \
            (["--quick"] if quick else []) + (["--baseline-goal"] if goal else [])
        subprocess.run(cmd, env=env, check=True)
        with open(out) as fh:
            return json.load(fh)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--baseline", default=None, help="jaxcoag checkout to run side by side (PYTHONPATH)")
    ap.add_argument("--skip", default="", help="comma list of tables to skip: tables (the Ns and capacity tables), "
                    "goal, ensemble")
    ap.add_argument("--out", default=None, help="JSON path (default benchmarks/results/mc_scaling[_quick].json)")
    ap.add_argument("--baseline-max-ns", type=int, default=1000,
                    help="largest Ns* of the baseline's Ns table (the old O(capacity) engine is slow beyond)")
    ap.add_argument("--baseline-goal", action="store_true",
                    help="also run the goal run with the --baseline checkout (the old engine took ~400 s)")
    ap.add_argument("--tables-only", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.tables_only:
        rows = dict(tables(args.quick, args.baseline_max_ns), jaxcoag_file=jaxcoag.__file__)
        if args.baseline_goal:
            rows["goal"] = [timed(2000, 20.0, const_ns=True)]
        with open(args.tables_only, "w") as fh:
            json.dump(rows, fh, default=str)
        return None
    skip = set(filter(None, args.skip.split(",")))
    do_tables = "tables" not in skip
    base_goal = args.baseline_goal and not args.quick and "goal" not in skip
    base = (run_baseline(args.baseline, args.quick, args.baseline_max_ns, base_goal)
            if args.baseline and do_tables else None)
    res = dict(benchmark="mc_scaling", quick=args.quick, machine=machine_info(),
               **(tables(args.quick) if do_tables else {}))
    cols = ["ns", "t", "volume", "capacity", "events", "wall_s", "ev_per_s", "us_per_event", "compile_s", "Ns_max",
            "Ns_end", "Ns_max_over_target", "merges", "status"]
    if base is not None:
        res["baseline"] = base
        for name in ("ns", "capacity"):
            for r, b in zip(res[name], base[name]):   # baseline rows are a prefix (Ns* <= --baseline-max-ns)
                r["baseline_ev_per_s"] = b["ev_per_s"]
                r["speedup_vs_baseline"] = r["ev_per_s"] / b["ev_per_s"]
        cols += ["baseline_ev_per_s", "speedup_vs_baseline"]
    if do_tables:
        print_table(res["ns"], cols, "events/s vs Ns* (capacity 4 Ns*, t = 5)")
        print_table(res["capacity"], cols, f"events/s vs capacity (Ns* = 100, t = {res['capacity'][0]['t']:g})")
    if not args.quick and "goal" not in skip:
        res["goal"] = [timed(2000, 20.0, const_ns=True)]
        if base is not None and "goal" in base:
            g, b = res["goal"][0], base["goal"][0]
            g["baseline_ev_per_s"], g["baseline_wall_s"] = b["ev_per_s"], b["wall_s"]
            g["speedup_vs_baseline"] = b["wall_s"] / g["wall_s"]
        print_table(res["goal"], cols if "speedup_vs_baseline" in res["goal"][0] else
                    [c for c in cols if c not in ("baseline_ev_per_s", "speedup_vs_baseline")],
                    "goal: Fig. 5.4a set-up (const-Ns, equal mass), Ns* = 2000 to t = 20 (issue 17: < 60 s after compile)")
    if "ensemble" not in skip:
        res["ensemble"] = [ensemble(ns=ns, tend=2.0 if args.quick else 5.0)
                           for ns in ((100,) if args.quick else (100, 400))]
        print_table(res["ensemble"], list(res["ensemble"][0]), "8-seed ensemble: vmap vs loop")
    path = args.out or os.path.join(OUT, "mc_scaling" + ("_quick" if args.quick else "") + ".json")
    write_json(path, res)
    print(f"wrote {path}")
    return res


if __name__ == "__main__":
    main()
