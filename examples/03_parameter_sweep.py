"""Sweep the nebula coagulation box over an alpha x rho_g grid in one vmapped program.

Shows: jaxcoag.sweep.sweep on a 2-D parameter grid (quick 4 x 4, full 32 x 32) of the
chapter-4 nebula box (jaxcoag.fit.nebula_box: 1 micron grains at 3 AU, dust-to-gas 0.01),
returning an xarray Dataset labelled by alpha and rho_g with the mass peak [g] and the mean
log-mass after 1e10 s and a per-member status; the same numbers from a Python loop over a jitted
single solve, and the throughput (points/s) of both (the sweep in chunks of 16 members).

    python examples/03_parameter_sweep.py [--quick]
"""

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)
import diffrax
import jax.numpy as jnp
import numpy as np

from jaxcoag import diagnostics, fit
from jaxcoag.sweep import sweep


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="4 x 4 grid instead of 32 x 32")
    args = ap.parse_args(argv)
    n = 4 if args.quick else 32
    model = fit.nebula_box(bins_per_decade=4, decades=8, ts=(5e9, 1e10), rtol=1e-6, atol=1e-10)
    rho0 = float(model.rho_g)
    alphas = np.logspace(np.log10(3e-5), np.log10(3e-4), n)
    rhos = rho0 * np.logspace(-0.3, 0.3, n)
    lc = jnp.asarray(model.grid.log_centers)

    def box(alpha, rho_g):
        """Mass peak [g] and mass-weighted mean ln m at t = 1e10 s for alpha [-], rho_g [g cm^-3]."""
        sol = model.solve({"alpha": alpha, "rho_g": rho_g}, adjoint=diffrax.RecursiveCheckpointAdjoint())
        rho = sol.mass_per_bin()[-1]
        return {"mass_peak": diagnostics.mass_peak(rho, model.grid),
                "mean_ln_m": jnp.sum(rho * lc) / jnp.sum(rho), "result": sol.status}

    params = {"alpha": alphas, "rho_g": rhos}
    t0 = time.perf_counter()
    # chunk=16: lax.map over vmapped batches of 16 - on CPU 3-10x faster per point than one
    # 1024-wide batch (benchmarks/sweep_throughput.py)
    ds = sweep(box, params, chunk=16, attrs={"scene": "nebula_ch4", "t_obs_s": 1e10})
    t_first = time.perf_counter() - t0
    t0 = time.perf_counter()
    sweep(box, params, chunk=16)  # same function, chunk and shapes: the compiled program is reused
    t_vmap = time.perf_counter() - t0

    one = jax.jit(box)
    one(alphas[0], rhos[0])["mass_peak"].block_until_ready()  # compile once
    stride = max(1, (n * n) // 16)  # a loop over every stride-th point, spread over the grid
    idx = np.arange(0, n * n, stride)
    nloop = idx.size
    allpts = [(a, r) for a in alphas for r in rhos]
    pts = [allpts[i] for i in idx]
    t0 = time.perf_counter()
    loop = [float(one(a, r)["mass_peak"]) for a, r in pts]
    t_loop = time.perf_counter() - t0
    vm = ds["mass_peak"].values.ravel()[idx]
    max_rel = float(np.max(np.abs(vm / np.array(loop) - 1.0)))

    print(ds)
    print(f"grid {n} x {n}: {int(ds.attrs['n_failed'])} failed members")
    print(f"mass peak at 1e10 s: {float(ds.mass_peak.min()):.3e} .. {float(ds.mass_peak.max()):.3e} g")
    print(f"vmapped sweep: {n * n / t_vmap:.2f} points/s after compile ({n * n / t_first:.2f} incl. compile); "
          f"Python loop of jitted solves: {nloop / t_loop:.2f} points/s (after compile)")
    print(f"vmap vs loop max relative difference of the mass peak: {max_rel:.2e}")
    return dict(n_points=n * n, n_failed=int(ds.attrs["n_failed"]), points_per_s_vmap=n * n / t_vmap, points_per_s_vmap_incl_compile=n * n / t_first,
                points_per_s_loop=nloop / t_loop, max_rel_diff=max_rel,
                dlnmp_dlnalpha=float(np.polyfit(np.log(alphas), np.log(ds.mass_peak.values[:, n // 2]), 1)[0]))


if __name__ == "__main__":
    main()
