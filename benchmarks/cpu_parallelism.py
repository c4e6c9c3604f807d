"""What a second CPU core can give one contact-DEM collision under XLA:CPU (issue 14's two-core goals).

Issue 14 asks for LAMMPS's throughput on the same two cores (LAMMPS splits one collision over two MPI ranks) and a
256 + 256 collision to its outcome in under 30 s (662 625 steps: 11.3e6 monomer-steps/s, more than one core gives).
Both need one collision's step to run on two cores at once. XLA:CPU offers two ways to do that inside a jitted
step, and this script measures what each costs on this machine, in one invocation:

1. **Two host devices and a collective** (``--xla_force_host_platform_device_count=2``, ``jax.shard_map``): each
   device would compute the forces of half the contacts, and one all-reduce (``psum``) per step would sum them. The
   script times a loop of steps whose only work is that ``psum`` of the (n, 3) force array (n = 512 and 2048, the
   two systems), i.e. the latency L that a perfect split adds to every step. With the step's measured single-core
   time T (``dem.integrate`` on the systems of ``contact_throughput.py``, the faster of the two compilations
   below), a perfect two-way split runs a step in at best T/2 + L: the bound on its speed-up is T / (T/2 + L). It
   also reports the largest L that would let the split reach the throughput of LAMMPS on two MPI ranks
   (``--need-2d``/``--need-3d``: that ratio, from ``results/contact_throughput_peers.json``: 1/0.669 and 1/0.535).
2. **The intra-op thread pool** (XLA's ``cpu-parallel-task-assigner`` splits large loop fusions over the threads;
   on by default): ``dem.integrate`` compiled with that pass and without it, on the two systems and on 2-D and
   3-D pairs of 512 to 8192 monomers (``dem.integrate`` runs the copy without it from ``dem.ASSIGNER_OFF_FROM``
   to ``dem.ASSIGNER_FROM`` monomers), and one reduction of exp(sin(x)) over n elements for n = 4 096 ...
   1 048 576, the fusion size from which the split pays (``assigner_speedup`` and ``speedup_on_over_off``: us
   without / us with it; > 1: it helps).

Run: ``python benchmarks/cpu_parallelism.py [--steps-2d 1000] [--steps-3d 200] [--quick] [--out PATH]``
(about four minutes, most of it compiling each system's step twice; ``--quick``: the two systems only).
Writes ``benchmarks/results/cpu_parallelism.json``. This script sets ``XLA_FLAGS`` before it imports JAX (two host
devices; the single-device timings run on the first).

References: Wada, Tanaka, Suyama, Kimura & Yamamoto (2007) ApJ 661, 320, §4 (the collision set-up, dt = 0.014 t_c).
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys
import time

os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2").strip()

import numpy as np  # noqa: E402

if __package__ in (None, ""):
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
from jax.sharding import Mesh  # noqa: E402
from jax.sharding import PartitionSpec as P  # noqa: E402

from benchmarks import _common as C  # noqa: E402
from jaxcoag.aggregates.contact import dem  # noqa: E402

ASSIGNER_OFF = dem._NO_ASSIGNER
N_HALF = {2: 256, 3: 1024}
#: further (dim, monomers per aggregate, steps) for the assigner table, around dem.ASSIGNER_FROM
SIZES = ((2, 1024, 300), (2, 4096, 100), (3, 256, 1000), (3, 2048, 100), (3, 4096, 50))


def _best(f, arg, repeats=3):
    """Best wall time [s] of ``f(arg)`` after a first (compiling) call."""
    jax.block_until_ready(f(arg))
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(f(arg))
        best = min(best, time.perf_counter() - t0)
    return best


def psum_latency(n, iters=2000):
    """Wall time per loop iteration [us] of a ``psum`` of an (n, 3) float64 array over two host devices (no other
    work in the loop), and of the same loop without the collective on one device."""
    mesh = Mesh(np.array(jax.devices()[:2]), ("d",))

    def part(x):
        return jax.lax.psum(x * (jax.lax.axis_index("d") + 1.0), "d")

    summed = jax.shard_map(part, mesh=mesh, in_specs=P(), out_specs=P(), check_vma=False)

    def loop(body):
        return jax.jit(lambda x: jax.lax.fori_loop(0, iters, lambda k, y: y + 1e-9 * body(y), x))

    x = jnp.ones((n, 3))
    t_coll = _best(loop(summed), x)
    t_none = _best(loop(lambda y: y * 1.5), x)
    return dict(n=n, iters=iters, us_per_iter_psum=1e6 * t_coll / iters, us_per_iter_no_collective=1e6 * t_none / iters)


def dem_step_times(dim, n_half, steps, rounds=2):
    """us per step of ``dem.integrate`` (chunks of 1000 steps) on ``contact_throughput.py``'s head-on BCCA pair of
    2 ``n_half`` monomers, compiled with XLA's default passes (the parallel task assigner on) and without the
    assigner: the two copies ``dem._integrate_jit.large`` / ``.small`` (``dem.integrate`` runs the second from
    ``dem.ASSIGNER_OFF_FROM`` to ``dem.ASSIGNER_FROM`` monomers); ``rounds`` alternations, best of each."""
    from benchmarks.contact_throughput import DT_TC, V_IMP_V0, _pad3, make_system
    from jaxcoag.aggregates.contact import materials

    mat = materials.ice(r1=1e-5, xi_crit=2e-8)
    x, v = make_system(n_half, dim, mat, V_IMP_V0 * float(mat.v0))
    n = 2 * n_half
    st0 = dem.init_state(_pad3(x), _pad3(v), np.zeros((n, 3)), mat, dim=dim, skin=0.1)
    cfg = dem._Cfg(dim, True, False, True)
    args = (mat, jnp.asarray(DT_TC * float(mat.t_c)), jnp.asarray(0.1), cfg)
    chunk = min(steps, 1000)
    out = dict(system=f"{dim}d {n_half}+{n_half}", n=int(n), steps=steps, default_copy=(
        "small" if dem.ASSIGNER_OFF_FROM <= n < dem.ASSIGNER_FROM else "large"))
    fs = {"assigner_on": dem._integrate_jit.large, "assigner_off": dem._integrate_jit.small}
    for _ in range(rounds):   # alternately, best of each (the load of a shared machine comes in bursts)
        for name, f in fs.items():
            t = 1e6 * _best(lambda s, f=f: f(s, *args, steps // chunk, chunk)[0].x, st0, repeats=2) / steps
            out[f"us_per_step_{name}"] = min(t, out.get(f"us_per_step_{name}", np.inf))
    out["assigner_speedup"] = out["us_per_step_assigner_off"] / out["us_per_step_assigner_on"]
    return out


def fusion_split(sizes=(4096, 16384, 65536, 262144, 1048576)):
    """us of one jitted sum(exp(0.3 sin x)) over n float64 elements, with the parallel task assigner on and off."""
    rows = []
    for n in sizes:
        x = jnp.linspace(0.1, 1.0, n)
        r = dict(n=n)
        for name, opts in (("on", {}), ("off", ASSIGNER_OFF)):
            f = jax.jit(lambda y: jnp.sum(jnp.exp(0.3 * jnp.sin(y))), compiler_options=opts)
            r[f"us_assigner_{name}"] = 1e6 * _best(f, x, repeats=20)
        r["speedup_on_over_off"] = r["us_assigner_off"] / r["us_assigner_on"]
        rows.append(r)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps-2d", type=int, default=1000)
    ap.add_argument("--steps-3d", type=int, default=200)
    ap.add_argument("--need-2d", type=float, default=1 / 0.669, help="speed-up needed to reach LAMMPS on 2 MPI ranks "
                    "(2-D 256+256; results/contact_throughput_peers.json, stop 43: ours / LAMMPS 2 ranks = 0.669)")
    ap.add_argument("--need-3d", type=float, default=1 / 0.535, help="the same for 3-D 1024+1024 (0.535)")
    ap.add_argument("--quick", action="store_true", help="skip the table of further system sizes")
    ap.add_argument("--out", default=str(C.RESULTS / "cpu_parallelism.json"))
    a = ap.parse_args(argv)
    if len(jax.devices()) < 2:
        raise SystemExit("needs two host devices: XLA_FLAGS was set after JAX started (run this file as a script)")

    rows = []
    for dim, steps, need in ((2, a.steps_2d, a.need_2d), (3, a.steps_3d, a.need_3d)):
        print(f"[{dim}-D {N_HALF[dim]}+{N_HALF[dim]}] DEM step, {steps} steps ...", flush=True)
        r = dem_step_times(dim, N_HALF[dim], steps)
        lat = psum_latency(r["n"])
        T = min(r["us_per_step_assigner_on"], r["us_per_step_assigner_off"])   # the faster one-core step
        L = lat["us_per_iter_psum"]
        r.update(psum=lat, split_bound_speedup=T / (T / 2 + L), speedup_needed_for_lammps_2_ranks=need,
                 psum_latency_needed_us=T / need - T / 2)
        rows.append(r)
    C.print_table(rows, ["system", "n", "us_per_step_assigner_on", "us_per_step_assigner_off", "assigner_speedup",
                         "split_bound_speedup", "speedup_needed_for_lammps_2_ranks", "psum_latency_needed_us"],
                  "one DEM step on one core, and the bound of a perfect two-device split (T / (T/2 + L))")
    C.print_table([r["psum"] for r in rows], ["n", "us_per_iter_psum", "us_per_iter_no_collective"],
                  "psum of the (n, 3) forces over two host devices, per loop iteration")
    sizes = []
    for dim, n_half, steps in SIZES if not a.quick else ():
        print(f"[{dim}-D {n_half}+{n_half}] assigner on / off, {steps} steps ...", flush=True)
        sizes.append(dem_step_times(dim, n_half, steps))
    if sizes:
        C.print_table(sizes, ["system", "n", "us_per_step_assigner_on", "us_per_step_assigner_off", "assigner_speedup",
                              "default_copy"], "dem.integrate with and without the parallel task assigner "
                      "(default_copy: the one dem.integrate runs)")
    fus = fusion_split()
    C.print_table(fus, ["n", "us_assigner_on", "us_assigner_off", "speedup_on_over_off"],
                  "one loop fusion of n elements: the parallel task assigner on / off")
    C.write_json(a.out, dict(benchmark="cpu_parallelism", description=__doc__.split("\n\n")[0], dem=rows,
                             dem_sizes=sizes, assigner_off_for=[int(dem.ASSIGNER_OFF_FROM), int(dem.ASSIGNER_FROM)],
                             fusion=fus,
                             xla_flags=os.environ["XLA_FLAGS"], machine=C.machine_info()))
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
