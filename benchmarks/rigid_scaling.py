"""Cost of the rigid-aggregate box (``jaxcoag.aggregates.rigid``, Richardson 1995 model v) against the number of
spheres N at fixed number density.

Model (v) settings (R95 Table I: spheres of radius 0.033, aggregates stick below the impact-energy threshold and
bounce with the Bridges et al. 1984 law above it; Maxwellian rms speed v0 = 13) in a box of side
L = 10 (N / 9000)^(1/3), so that the number density (9 per unit volume) and the collision rate per sphere are
those of model (v) for every N. Each size is run once to t_a = 0.01 (the first call: compile plus a short run,
reported as ``first_call_s``), then continued over a window dt = max(0.01, 200 / N) (about 200 collisions, and
at least five neighbour-list rebuilds) with the compiled program; that second call is timed. Reported per size:
wall time per unit simulated time, per loop step and per collision, the step / collision / rebuild counts of
the window. The exponent b of ``wall per unit time ~ N^b`` is the least-squares slope of the logs with its
standard error (scipy.stats.linregress). Both clocks of ``RigidBox`` run side by side on the same boxes:
``clock="body"`` (per-body clocks, the default) and ``clock="global"`` (one conservative-advancement step for
the whole box), with the ratio of their wall times per size; each window is timed ``--repeat`` times (default
2) and the fastest call is reported; each (N, clock) runs in a fresh process (``--same-process`` to share
one). Writes benchmarks/results/rigid_scaling[_quick].json (``rows``: the default clock; ``clocks``: every
clock run) and prints a table; the machine record (with the load average) goes into the JSON.

    python benchmarks/rigid_scaling.py [--quick] [--sizes 1000,3000,10000,30000,100000] [--clocks body,global]
        [--repeat 2] [--same-process] [--out PATH]
"""

import argparse
import math
import multiprocessing
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402

from benchmarks import _common  # noqa: E402
from jaxcoag.aggregates import rigid  # noqa: E402

V0, T_A = 13.0, 0.01


def window(n0):
    """Simulated time of the timed window for N spheres (about 200 collisions, at least 0.01)."""
    return max(0.01, 200.0 / n0)


def timed(n0, seed=1, t_a=T_A, dt=None, clock=None, repeat=1):
    """Compile + short run to t_a, then the timed continuation over dt (default window(n0); module docstring), with
    ``RigidBox(clock=clock)`` (None: the engine's default for the backend); with ``repeat`` > 1 the same
    continuation (from the same state: the same work) is timed that many times and the fastest is reported (single
    calls on this shared machine varied up to 1.7x).
    Also reports ``setup_s``, the wall time of ``box_model`` (the random placement of n0 spheres)."""
    engine = rigid.RigidBox(clock=clock)
    L = 10.0 * (n0 / 9000.0) ** (1.0 / 3.0)
    t0 = time.perf_counter()
    box = rigid.box_model("v", n0=n0, box=L, v0=V0, key=jax.random.key(seed))
    jax.block_until_ready(box)
    setup = time.perf_counter() - t0
    t0 = time.perf_counter()
    r1 = rigid.run(box, jnp.array([t_a]), engine=engine)
    jax.block_until_ready(r1.outs)
    first = time.perf_counter() - t0
    dt = window(n0) if dt is None else dt
    walls = []
    for _ in range(max(int(repeat), 1)):
        t0 = time.perf_counter()
        r2 = rigid.run(r1, jnp.array([t_a + dt]), engine=engine)
        jax.block_until_ready(r2.outs)
        walls.append(time.perf_counter() - t0)
    wall = min(walls)
    d = {k: int(np.asarray(r2.outs[k])[-1]) - int(np.asarray(r1.outs[k])[-1])
         for k in ("n_steps", "n_c", "n_build")}
    clock = clock or ("body" if jax.default_backend() == "cpu" else "global")
    return dict(n0=n0, clock=clock, walls_s=walls, L=L, setup_s=setup, t_a=t_a, first_call_s=first, window=dt,
                wall_s=wall, steps=d["n_steps"], collisions=d["n_c"], rebuilds=d["n_build"], wall_per_time=wall / dt,
                wall_per_step_ms=1e3 * wall / max(d["n_steps"], 1), wall_per_collision_ms=1e3 * wall / max(d["n_c"], 1),
                steps_per_time=d["n_steps"] / dt, n_aggregates_end=int(np.asarray(r2.outs["n_aggregates"])[-1]),
                status=r2.status_message or "successful")


def fit(rows, key="wall_per_time"):
    """Exponent of ``key ~ N^b``: (b, standard error) by least squares on the logs."""
    if len(rows) < 3:
        if len(rows) == 2:
            a, b = rows
            return math.log(b[key] / a[key]) / math.log(b["n0"] / a["n0"]), math.nan
        return math.nan, math.nan
    lr = stats.linregress(np.log([r["n0"] for r in rows]), np.log([r[key] for r in rows]))
    return float(lr.slope), float(lr.stderr)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="N = 1000, 3000 only")
    ap.add_argument("--sizes", default=None, help="comma-separated N (default 1000,3000,10000,30000,100000)")
    ap.add_argument("--clocks", default="body,global", help="RigidBox clocks to run side by side (default both)")
    ap.add_argument("--repeat", type=int, default=2,
                    help="timed calls of each window, the fastest reported (default 2)")
    ap.add_argument("--same-process", action="store_true",
                    help="run every size and clock in this process (default: a fresh process for each)")
    ap.add_argument("--out", default=None, help="JSON path (default benchmarks/results/rigid_scaling[_quick].json)")
    args = ap.parse_args(argv)
    if args.sizes:
        try:
            sizes = [int(s) for s in args.sizes.split(",")]
        except ValueError:
            raise SystemExit(f"--sizes must be comma-separated integers >= 8; got {args.sizes!r}") from None
        if any(s < 8 for s in sizes):
            raise SystemExit(f"--sizes must be comma-separated integers >= 8; got {args.sizes!r}")
    else:
        sizes = [1000, 3000] if args.quick else [1000, 3000, 10000, 30000, 100000]
    clocks = [c.strip() for c in args.clocks.split(",") if c.strip()]
    if not clocks or any(c not in ("body", "global") for c in clocks):
        raise SystemExit(f"--clocks must be a comma-separated subset of body,global; got {args.clocks!r}")
    path = args.out or os.path.join(_common.RESULTS, "rigid_scaling" + ("_quick" if args.quick else "") + ".json")
    machine_start = _common.machine_info()
    rows = {c: [] for c in clocks}
    print(f"{'N':>7} {'clock':>6} {'window':>7} {'steps':>7} {'coll.':>6} {'rebuilds':>8} {'wall [s]':>9} "
          f"{'s / unit t':>10} {'ms/step':>8} {'ms/coll.':>9} {'first call [s]':>14} status")
    for n0 in sizes:
        for c in clocks:
            if args.same_process:
                r = timed(n0, clock=c, repeat=args.repeat)
            else:  # a fresh process per run: in one process the later runs were up to 2.5x slower (2026-11-28)
                with multiprocessing.get_context("spawn").Pool(1) as pool:
                    r = pool.apply(timed, (n0,), dict(clock=c, repeat=args.repeat))
            rows[c].append(r)
            print(f"{n0:7d} {c:>6} {r['window']:7.3f} {r['steps']:7d} {r['collisions']:6d} {r['rebuilds']:8d} "
                  f"{r['wall_s']:9.2f} {r['wall_per_time']:10.1f} {r['wall_per_step_ms']:8.3f} "
                  f"{r['wall_per_collision_ms']:9.2f} {r['first_call_s']:14.1f} {r['status']}", flush=True)
        if len(clocks) == 2:
            print(f"{'':7} global / body wall per unit time: "
                  f"{rows['global'][-1]['wall_per_time'] / rows['body'][-1]['wall_per_time']:.2f}x", flush=True)
    out = {}
    for c in clocks:
        b, be = fit(rows[c])
        bs, bse = fit(rows[c], "wall_per_step_ms")
        bn, bne = fit(rows[c], "steps_per_time")
        print(f"clock={c}: wall per unit simulated time ~ N^{b:.2f} +- {be:.2f}  (= steps per unit time "
              f"~ N^{bn:.2f} +- {bne:.2f} times wall per step ~ N^{bs:.2f} +- {bse:.2f})")
        out[c] = dict(rows=rows[c], exponent_wall_per_time=[b, be], exponent_wall_per_step=[bs, bse],
                      exponent_steps_per_time=[bn, bne])
    ratios = ([dict(n0=g["n0"], global_over_body=g["wall_per_time"] / b["wall_per_time"])
               for g, b in zip(rows["global"], rows["body"])] if len(clocks) == 2 else [])
    main_clock = clocks[0]
    res = dict(benchmark="rigid_scaling", quick=args.quick, model="v", v0=V0, number_density=9000 / 1000.0,
               default_clock=main_clock, rows=rows[main_clock],
               exponent_wall_per_time=out[main_clock]["exponent_wall_per_time"],
               exponent_wall_per_step=out[main_clock]["exponent_wall_per_step"],
               exponent_steps_per_time=out[main_clock]["exponent_steps_per_time"], clocks=out,
               global_over_body=ratios, machine_start=machine_start, machine_end=_common.machine_info(),
               note=("wall_s excludes compilation (the first call compiles); steps are loop iterations (global steps, "
                     "or pair checks + resynchronisations + outputs with per-body clocks); "
                     "load_average in machine_* is the 1/5/15-min load of the 2-core machine shared with other jobs"))
    _common.write_json(path, res)
    print(f"wrote {path}")
    return res


if __name__ == "__main__":
    main()
