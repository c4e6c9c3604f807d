"""Cost of the physics core: N x N relative-velocity and kernel matrices, and their gradients.

Prints a table and writes JSON to benchmarks/results/physics_kernel_matrix[_quick].json:
wall time (jit, after warm-up; median of repeats) of
  * the OC07 turbulent Delta v / v_g matrix with per-particle St* (N root solves),
  * the same with St* solved per pair (N^2 root solves; what a naive implementation costs),
  * the full nebula-scene kernel matrix (Brownian + OC07 + radial drift, compact spheres),
  * reverse-mode gradient of sum(K) with respect to (ln alpha, ln rho_g, ln T, ln rho_s),
for N in (50, 100, 200, 400) (quick: 50, 200).

    python benchmarks/physics_kernel_matrix.py [--quick]
"""

import argparse
import json
import os
import platform
import statistics
import time

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp

from jaxcoag import scenes
from jaxcoag.physics import gas as G
from jaxcoag.physics import turbulence as T

OUT = os.path.join(os.path.dirname(__file__), "results")


def _time(f, *args, reps=20):
    jax.block_until_ready(f(*args))
    ts = []
    for _ in range(reps):
        t0 = time.perf_counter()
        jax.block_until_ready(f(*args))
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    Ns = (50, 200) if args.quick else (50, 100, 200, 400)
    reps = 5 if args.quick else 20
    Re = 1e8

    @jax.jit
    def dv_star_once(st):
        s = T.st_star(st, Re)
        I, II = T.dv2_terms_oc07(st[:, None], st[None, :], s[:, None], s[None, :], Re)
        return jnp.sqrt(I + II)

    @jax.jit
    def dv_star_pairs(st):
        return jnp.sqrt(T.dv2_turbulent_oc07(st[:, None], st[None, :], Re))

    def kmat(lp, m):
        g = G.midplane_state(jnp.exp(lp[1]), jnp.exp(lp[2]), jnp.exp(lp[0]), 3.83e-8)
        return scenes.nebula_ch4().kernel(g, rho_s=jnp.exp(lp[3])).matrix(m)

    kmat_j = jax.jit(kmat)
    grad_j = jax.jit(jax.grad(lambda lp, m: jnp.log(jnp.sum(kmat(lp, m)))))
    lp0 = jnp.log(jnp.array([1e-4, 2.4e-11, 162.0, 3.0]))
    rows = []
    for N in Ns:
        st = jnp.logspace(-8, 3, N)
        m = jnp.logspace(-15, 9, N)
        r = dict(N=N,
                 dv_oc07_per_particle_ms=1e3 * _time(dv_star_once, st, reps=reps),
                 dv_oc07_per_pair_ms=1e3 * _time(dv_star_pairs, st, reps=reps),
                 scene_kernel_ms=1e3 * _time(kmat_j, lp0, m, reps=reps),
                 scene_kernel_grad4_ms=1e3 * _time(grad_j, lp0, m, reps=reps))
        rows.append(r)
    print(f"{'N':>5} {'dv OC07 (N roots)':>18} {'dv OC07 (N^2 roots)':>20} {'scene K':>10} {'grad K (4 params)':>18}   [ms]")
    for r in rows:
        print(f"{r['N']:5d} {r['dv_oc07_per_particle_ms']:18.3f} {r['dv_oc07_per_pair_ms']:20.3f} "
              f"{r['scene_kernel_ms']:10.3f} {r['scene_kernel_grad4_ms']:18.3f}")
    res = dict(benchmark="physics_kernel_matrix", quick=args.quick, rows=rows,
               machine=dict(platform=platform.platform(), processor=platform.processor(), cores=os.cpu_count(),
                            jax=jax.__version__, load_average=os.getloadavg()))
    os.makedirs(OUT, exist_ok=True)
    path = os.path.join(OUT, "physics_kernel_matrix" + ("_quick" if args.quick else "") + ".json")
    with open(path + ".tmp", "w") as fh:
        json.dump(res, fh, indent=1)
    os.replace(path + ".tmp", path)
    print(f"wrote {path}")
    return res


if __name__ == "__main__":
    main()
