"""Shard a parameter sweep over several devices with jax.sharding (Mesh + NamedSharding).

Shows: jaxcoag.sweep.sweep(..., devices=jax.devices()) splitting the members of an
alpha x rho_g sweep of the nebula box (jaxcoag.fit.nebula_box) over all local devices with
jax.shard_map, and that the result equals the unsharded sweep. Run as a script on a CPU-only
machine it emulates 4 devices by setting XLA_FLAGS=--xla_force_host_platform_device_count=4
before JAX starts (when imported by the test suite JAX is already running, so it uses whatever
devices exist - possibly one). For several hosts see the jax.distributed recipe in the
jaxcoag.sweep module docstring.

    python examples/04_sharded_sweep.py [--quick]
"""

import os
import sys

if __name__ == "__main__" and "jax" not in sys.modules and "xla_force_host_platform_device_count" not in \
        os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=4").strip()

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)
import diffrax
import numpy as np

from jaxcoag import fit
from jaxcoag.sweep import sweep


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="3 x 3 grid instead of 16 x 16")
    args = ap.parse_args(argv)
    n = 3 if args.quick else 16
    model = fit.nebula_box(bins_per_decade=4, decades=8, ts=(5e9, 1e10), rtol=1e-6, atol=1e-10)
    params = {"alpha": np.logspace(np.log10(3e-5), np.log10(3e-4), n),
              "rho_g": float(model.rho_g) * np.logspace(-0.3, 0.3, n)}

    def box(alpha, rho_g):
        """Final mass per bin [g cm^-3] and mass peak [g] at t = 1e10 s."""
        sol = model.solve({"alpha": alpha, "rho_g": rho_g}, adjoint=diffrax.RecursiveCheckpointAdjoint())
        return {"mass_per_bin": sol.mass_per_bin()[-1], "mass_peak": sol.mass_peak()[-1], "result": sol.status}

    devices = jax.devices()
    t0 = time.perf_counter()
    plain = sweep(box, params)
    t_plain = time.perf_counter() - t0
    t0 = time.perf_counter()
    sharded = sweep(box, params, devices=devices)
    t_shard = time.perf_counter() - t0
    diff = float(np.max(np.abs(plain.mass_per_bin.values - sharded.mass_per_bin.values)))
    scale = float(np.max(np.abs(plain.mass_per_bin.values)))
    same_status = bool(np.array_equal(plain.status.values, sharded.status.values))
    print(f"{len(devices)} device(s): {[str(d) for d in devices]}")
    print(f"{n * n} members: unsharded {t_plain:.2f} s, sharded over {sharded.attrs['n_devices']} device(s) "
          f"{t_shard:.2f} s (both incl. compile)")
    print(f"max |sharded - unsharded| mass per bin = {diff:.3e} g cm^-3 (scale {scale:.3e}); statuses equal: {same_status}")
    return dict(n_devices=len(devices), n_members=n * n, max_abs_diff=diff, rel_diff=diff / scale,
                same_status=same_status, seconds_unsharded=t_plain, seconds_sharded=t_shard)


if __name__ == "__main__":
    main()
