"""Throughput of a vmapped fragmentation sweep vs a loop of single solves (issue 17 goal: an 8-member vmapped
fragmentation sweep >= 4x the throughput of a loop).

Box: the default ``jaxcoag run`` configuration (1 AU MMSN, Brownian + OC07 turbulence + radial drift, Maxwellian
shattering, two-bin scheme on 135 bins, the engine's implicit default (Rodas4) with the structured Jacobian, 17
outputs to 1e4 yr).
Members: v_frag = 6 ... 14 m/s (8 values), the ``Shattering.v_frag`` leaf of the outcome. Modes, each timed
after its compile: ``loop`` (a Python loop of one jitted solve), ``vmap`` (one ``jax.vmap``-ed solve of all
members), ``workers`` (``jaxcoag.sweep.sweep(..., chunk=1, workers=W)``: each member one unbatched solve, W
host threads at once; W = ``--workers``, default the machine's core count; its first call, which compiles, is
timed apart like the others'). Also reports steps per member and that the vmapped and the threaded members equal
the looped ones.

    python benchmarks/frag_sweep_throughput.py [--quick] [--members 8] [--workers W] [--out PATH]

``--quick``: ``runner.quick_config`` (coarse grid). Writes benchmarks/results/frag_sweep_throughput[_quick].json.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.append(str(ROOT))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxcoag  # noqa: E402
from jaxcoag import config as cfgmod  # noqa: E402
from jaxcoag import runner  # noqa: E402

from benchmarks._common import machine_info, print_table, write_json  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--members", type=int, default=8)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                    help="host threads of the sweep(workers=...) mode (default: the core count)")
    ap.add_argument("--out", default=None, help="JSON path (default benchmarks/results/frag_sweep_throughput"
                    "[_quick].json)")
    a = ap.parse_args(argv)
    cfg = cfgmod.default()
    if a.quick:
        cfg = runner.quick_config(cfg)
    b = cfgmod.build(cfg)
    t_out = jnp.asarray(b.t_out)
    vf = jnp.linspace(600.0, 1400.0, a.members)  # cm/s

    def one(v):
        out = eqx.tree_at(lambda o: o.v_frag, b.outcome, v)
        r = jaxcoag.evolve(b.kernel, b.engine, b.initial, t_out, outcome=out, throw=False)
        return r.rho[-1], r.stats["steps"], r.stats["rejected"], jaxcoag.result_code(r.status)

    f1 = jax.jit(one)
    fv = jax.jit(jax.vmap(one))
    t0 = time.perf_counter()
    jax.block_until_ready(f1(vf[0]))
    c1 = time.perf_counter() - t0
    t0 = time.perf_counter()
    jax.block_until_ready(fv(vf))
    cv = time.perf_counter() - t0
    t0 = time.perf_counter()
    loop = [jax.block_until_ready(f1(v)) for v in vf]
    t_loop = time.perf_counter() - t0
    t0 = time.perf_counter()
    rv = jax.block_until_ready(fv(vf))
    t_vmap = time.perf_counter() - t0
    rho_loop = np.stack([np.asarray(x[0]) for x in loop])
    diff = float(np.max(np.abs(np.asarray(rv[0]) - rho_loop)) / np.max(np.abs(rho_loop)))

    def member(v_frag):
        rho, steps, rejected, code = one(v_frag)
        return {"rho": rho, "steps": steps, "result": code}

    from jaxcoag.sweep import sweep
    vf_np = np.asarray(vf)
    t0 = time.perf_counter()
    sweep(member, {"v_frag": vf_np}, chunk=1, workers=a.workers)
    cw = time.perf_counter() - t0
    t0 = time.perf_counter()
    dw = sweep(member, {"v_frag": vf_np}, chunk=1, workers=a.workers)
    t_work = time.perf_counter() - t0
    diff_w = float(np.max(np.abs(dw["rho"].values - rho_loop)) / np.max(np.abs(rho_loop)))
    rows = [dict(mode="loop", members=a.members, wall_s=t_loop, per_member_s=t_loop / a.members, first_call_s=c1,
                 steps=[int(x[1]) for x in loop]),
            dict(mode="vmap", members=a.members, wall_s=t_vmap, per_member_s=t_vmap / a.members, first_call_s=cv,
                 steps=[int(s) for s in np.asarray(rv[1])]),
            dict(mode=f"sweep(chunk=1, workers={a.workers})", members=a.members, wall_s=t_work,
                 per_member_s=t_work / a.members, first_call_s=cw, steps=[int(s) for s in dw["steps"].values])]
    ratio = t_loop / t_vmap
    ratio_w = t_loop / t_work
    print_table(rows, ["mode", "members", "wall_s", "per_member_s", "first_call_s", "steps"],
                f"{a.members}-member v_frag sweep of the {'quick' if a.quick else 'default'} run box")
    print(f"throughput vmap / loop = {ratio:.3g} (goal >= 4); max |vmap - loop| / max = {diff:.2e}")
    print(f"throughput sweep(workers={a.workers}) / loop = {ratio_w:.3g}; max |workers - loop| / max = {diff_w:.2e}")
    path = pathlib.Path(a.out) if a.out else (ROOT / "benchmarks" / "results" /
                                              ("frag_sweep_throughput" + ("_quick" if a.quick else "") + ".json"))
    write_json(path, dict(benchmark="frag_sweep_throughput", quick=a.quick, machine=machine_info(),
                          device=dict(backend=jax.default_backend(), device=str(jax.devices()[0].device_kind)),
                          v_frag_cm_s=np.asarray(vf), rows=rows, throughput_ratio_vmap_over_loop=ratio,
                          max_rel_diff_vmap_loop=diff, workers=a.workers, throughput_ratio_workers_over_loop=ratio_w,
                          max_rel_diff_workers_loop=diff_w, status_codes=[int(x[3]) for x in loop]))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
