"""A vmapped ensemble of radial disks over (alpha, v_frag), sharded over accelerators where there are several.

Shows: jaxcoag.sweep.sweep over DustPy's disk model (jaxcoag.disk, split mode) on an alpha x v_frag grid in one
compiled program - every member its own adaptive step sequence inside the batched lax.while_loop - returning an
xarray Dataset labelled by alpha and v_frag with the dust mass left, the mass-weighted size a_mean(r) and Sigma_d(r);
the same sweep sharded over the local devices (jax.shard_map via ``devices=``); and the same numbers from a Python
loop over one jitted solve, with the throughput (members/s) of each.

The sweep and the loop run the same steps with different round-off (batched against single LAPACK solves), and
DustPy's step rule (a minimum over cells and bins) turns round-off into other step sequences over a few hundred steps.
What then differs is the time discretisation's own error: in the full run (1e4 yr) the dust masses agree to ~1e-7, but
a_mean in the two innermost cells differs by up to ~1e-2, as much as between step factors cfl = 0.1 and 0.099 of one
member (1.2e-2) or between the split and the parity step (1.5e-2); further out it agrees to <= 3e-3 (measured;
``docs/design_notes.md``, radial disk). The quick run is short enough to keep one step sequence (1e-14).

Sharding is for accelerators. Several *CPU* devices of one host (XLA_FLAGS=--xla_force_host_platform_device_count)
deadlock here: each device thread blocks inside jaxlib's batched LAPACK LU (lapack_dgetrf_ffi -> ParallelBatchMap)
waiting for tasks queued on the host thread pool its peers occupy (jax 0.10.2; seen in gdb), so ``jaxcoag.sweep``
refuses such a mesh with an error before running. On a CPU host use the vmapped sweep; this example shards only over
one CPU device or over GPUs/TPUs.

    python examples/07_disk_ensemble.py [--quick]

Reference: Stammler & Birnstiel (2022) ApJ 935, 35 (DustPy); Birnstiel, Klahr & Ercolano (2012) A&A 539, A148.
"""

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np

from jaxcoag import disk
from jaxcoag.sweep import sweep

C = disk.gas.DUSTPY_CONSTANTS


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="2 x 2 members, 10 cells, 1000 yr (full: 4 x 4, 30 cells, "
                                                         "1e4 yr)")
    args = ap.parse_args(argv)
    if args.quick:
        n, grid, t_yr = 2, dict(nr=10, r_min=3.0 * C["au"], r_max=30.0 * C["au"], m_max=10.0, bins_per_decade=4), \
            [0.0, 1e3]
    else:
        n, grid, t_yr = 4, dict(nr=30, m_max=1e2), [0.0, 1e3, 1e4]
    t_out = np.asarray(t_yr) * C["year"]
    params = {"alpha": np.geomspace(3e-4, 3e-3, n), "v_frag": np.geomspace(50.0, 200.0, n)}

    def member(alpha, v_frag):
        """Dust mass [g], a_mean(r) [cm] and Sigma_d(r) [g cm^-2] at the output times, and the run's status."""
        res = disk.solve(disk.dustpy_default(**grid, alpha=alpha, v_frag=v_frag), t_out, mode=disk.Split(),
                         throw=False)
        return {"dust_mass": res.dust_mass, "a_mean": res.a_mean(), "sigma_dust": res.sigma_dust_total,
                "steps": res.n_steps, "result": res.status}

    attrs = {"model": "DustPy default (Stammler & Birnstiel 2022)", "mode": "split", "t_yr": list(t_yr)}
    r_au = np.asarray(disk.dustpy_default(**grid).r) / C["au"]

    dims = {"dust_mass": "t", "a_mean": ("t", "r"), "sigma_dust": ("t", "r"), "steps": "t"}

    def label(ds):
        """t_yr and r_au coordinates on the t and r axes."""
        return ds.assign_coords(t_yr=("t", np.asarray(t_yr)), r_au=("r", r_au))

    t0 = time.perf_counter()
    ds = label(sweep(member, params, attrs=attrs, dims=dims))
    t_vmap_first = time.perf_counter() - t0
    t0 = time.perf_counter()
    sweep(member, params, dims=dims)  # the same function and shapes: the compiled program is reused
    t_vmap = time.perf_counter() - t0

    devices = jax.devices()
    if len(devices) > 1 and all(d.platform == "cpu" for d in devices):
        devices = devices[:1]  # jaxcoag.sweep refuses several CPU devices for a program with LAPACK factorisations
        print("several CPU devices: sharding over one (jaxlib's batched LAPACK deadlocks across CPU devices)")
    t0 = time.perf_counter()
    sharded = label(sweep(member, params, devices=devices, dims=dims))
    t_shard_first = time.perf_counter() - t0

    one = jax.jit(member)
    pts = [(a, v) for a in params["alpha"] for v in params["v_frag"]]
    jax.block_until_ready(one(*pts[0]))  # compile once
    t0 = time.perf_counter()
    loop = [jax.tree.map(np.asarray, one(a, v)) for a, v in pts]
    t_loop = time.perf_counter() - t0

    looped = np.stack([o["a_mean"] for o in loop]).reshape(ds["a_mean"].shape)
    rel_loop = float(np.max(np.abs(ds["a_mean"].values / looped - 1.0)))
    mass_loop = np.stack([o["dust_mass"] for o in loop]).reshape(ds["dust_mass"].shape)
    rel_mass = float(np.max(np.abs(ds["dust_mass"].values / mass_loop - 1.0)))
    steps_loop = np.stack([o["steps"] for o in loop]).reshape(ds["steps"].shape)
    n_other_steps = int(np.sum(steps_loop[..., -1] != ds["steps"].values[..., -1]))
    rel_shard = float(np.max(np.abs(sharded["a_mean"].values / ds["a_mean"].values - 1.0)))
    n_members = n * n
    print(f"{n_members} disks ({grid['nr']} cells, {t_yr[-1]:.0e} yr, split mode); {len(devices)} device(s)")
    print(f"vmapped sweep {t_vmap:.2f} s ({n_members / t_vmap:.2f} members/s; first call incl. compile "
          f"{t_vmap_first:.1f} s), loop of jitted solves {t_loop:.2f} s ({n_members / t_loop:.2f} members/s): "
          f"throughput ratio {t_loop / t_vmap:.2f}; sharded over {sharded.attrs['n_devices']} device(s) "
          f"{t_shard_first:.1f} s incl. compile")
    print(f"max rel. difference of a_mean: sweep vs loop {rel_loop:.2e}, sharded vs unsharded {rel_shard:.2e}; "
          f"of the dust mass: sweep vs loop {rel_mass:.2e}; members whose step count differs between sweep and loop: "
          f"{n_other_steps}; failed members {int(ds.attrs['n_failed'])}")
    mass = ds["dust_mass"].values[..., -1]
    table = np.array2string(mass / C["M_sun"], formatter={"float_kind": "{:.6e}".format})
    print("dust mass left [Msun] (rows alpha, columns v_frag):\n" + table)
    print(ds)
    return dict(n_members=n_members, n_devices=len(devices), n_failed=int(ds.attrs["n_failed"]),
                rel_diff_loop=rel_loop, rel_diff_sharded=rel_shard, rel_diff_mass_loop=rel_mass,
                n_other_step_counts=n_other_steps, seconds_vmap=t_vmap, seconds_loop=t_loop,
                throughput_ratio=t_loop / t_vmap, dust_mass_last=mass.tolist(), dims=list(ds["a_mean"].dims),
                a_mean_last_inner=ds["a_mean"].values[..., -1, 1].tolist())


if __name__ == "__main__":
    main()
