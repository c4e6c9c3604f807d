"""Sweep throughput: parameter points per second, vmapped vs looped vs chunked vs sharded.

Model: the chapter-4 nebula box of :func:`jaxcoag.fit.nebula_box` (Brownian + Ormel & Cuzzi
2007 turbulence + radial drift, compact 1 micron grains at 3 AU, dust-to-gas 0.01, two-bin
scheme on 32 bins, Tsit5, rtol 1e-6), outputs at 5e9 and 1e10 s; per member the output is
ln m_peak(1e10 s) [ln g] and the solver status. Grids alpha x rho_g (alpha 3e-5 .. 3e-4,
rho_g within a factor 2 of the ch4_disk value) of n x n points:

* ``vmap``: :func:`jaxcoag.sweep.sweep` - one vmapped program over all members;
* ``chunked``: the same with ``chunk=`` (``lax.map`` over vmapped batches of that size);
* ``loop``: a Python loop of a jitted single-point solve;
* a scan of the chunk size on the largest grid (all members at once, 256, 64, 16);
* ``sharded``: ``sweep(..., devices=jax.devices())`` over 4 emulated host devices
  (``XLA_FLAGS=--xla_force_host_platform_device_count=4``), run in a subprocess because the
  device count is fixed when JAX starts. On a CPU host the "devices" share the same cores.

Each mode is timed after its compilation (the compile-including first call is reported too);
the vmapped result is compared with the loop member by member. Prints a table, writes JSON
(+ PNG) to benchmarks/results/sweep_throughput[_quick].json.

    python benchmarks/sweep_throughput.py [--quick] [--sizes 8 32] [--no-sharded]

References: JAX vmap / lax.map / shard_map; jaxcoag.sweep module docstring.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import jax

jax.config.update("jax_enable_x64", True)
import diffrax
import jax.numpy as jnp
import numpy as np

from benchmarks import _common as C
from jaxcoag import fit
from jaxcoag.sweep import parameter_points, sweep

OUT = C.RESULTS
N_SHARD_DEVICES = 4


def make_problem():
    """(box function of (alpha, rho_g) -> dict, reference gas density [g cm^-3])."""
    model = fit.nebula_box(bins_per_decade=4, decades=8, ts=(5e9, 1e10), rtol=1e-6, atol=1e-10)
    adj = diffrax.RecursiveCheckpointAdjoint()

    def box(alpha, rho_g):
        """ln m_peak at 1e10 s [ln g] and the solver status, for alpha [-] and rho_g [g cm^-3]."""
        sol = model.solve({"alpha": alpha, "rho_g": rho_g}, adjoint=adj)
        return {"ln_mpeak": jnp.log(sol.mass_peak()[-1]), "result": sol.status}

    return box, float(model.rho_g), model.grid.nbins


def grid_params(n, rho0):
    return {"alpha": np.logspace(np.log10(3e-5), np.log10(3e-4), n), "rho_g": rho0 * np.logspace(-0.3, 0.3, n)}


def _timed(f):
    t0 = time.perf_counter()
    out = f()
    return out, time.perf_counter() - t0


def run_size(box, rho0, n, chunk, loop_max):
    """Time vmap / chunked / loop on an n x n grid; returns (row dict, vmapped dataset)."""
    params = grid_params(n, rho0)
    npts = n * n
    ds, t_vmap_first = _timed(lambda: sweep(box, params))
    ds2, t_vmap = _timed(lambda: sweep(box, params))
    _, t_chunk_first = _timed(lambda: sweep(box, params, chunk=chunk))
    dsc, t_chunk = _timed(lambda: sweep(box, params, chunk=chunk))
    one = jax.jit(box)
    pts, _ = parameter_points(params)
    _, t_loop_compile = _timed(lambda: jax.block_until_ready(one(pts["alpha"][0], pts["rho_g"][0])))
    idx = np.arange(npts) if npts <= loop_max else np.linspace(0, npts - 1, loop_max).round().astype(int)
    t0 = time.perf_counter()
    loop = np.array([float(one(pts["alpha"][i], pts["rho_g"][i])["ln_mpeak"]) for i in idx])
    t_loop = time.perf_counter() - t0
    vm = ds["ln_mpeak"].values.ravel()
    row = dict(grid=f"{n}x{n}", points=npts, chunk=chunk, failed=int(ds.attrs["n_failed"]),
               vmap_pts_per_s=npts / t_vmap, vmap_first_call_s=t_vmap_first,
               chunked_pts_per_s=npts / t_chunk, chunked_first_call_s=t_chunk_first,
               loop_pts_per_s=idx.size / t_loop, loop_points_timed=int(idx.size), loop_compile_s=t_loop_compile,
               vmap_over_loop=(npts / t_vmap) / (idx.size / t_loop),
               max_abs_diff_vmap_loop=float(np.max(np.abs(vm[idx] - loop))),
               max_abs_diff_chunked_vmap=float(np.max(np.abs(dsc["ln_mpeak"].values.ravel() - vm))),
               repeat_identical=bool(np.array_equal(ds2["ln_mpeak"].values, ds["ln_mpeak"].values)),
               ln_mpeak_range=[float(vm.min()), float(vm.max())])
    return row, ds


def chunk_scan(box, rho0, n, chunks=(None, 256, 64, 16), reps=2):
    """Points/s (best of ``reps`` after compile) of an n x n sweep for several chunk sizes."""
    params = grid_params(n, rho0)
    out = []
    for c in chunks:
        sweep(box, params, chunk=c)
        best = min(_timed(lambda: sweep(box, params, chunk=c))[1] for _ in range(reps))
        out.append(dict(grid=f"{n}x{n}", chunk="all" if c is None else c, pts_per_s=n * n / best))
    return out


# ------------------------------------------------------------------------------ sharded (subprocess)
def _child(sizes):
    """Runs inside the subprocess (XLA_FLAGS set before JAX started): sharded vs unsharded."""
    box, rho0, _ = make_problem()
    rows = []
    for n in sizes:
        params = grid_params(n, rho0)
        _, t_first = _timed(lambda: sweep(box, params, devices=jax.devices()))
        ds, t = _timed(lambda: sweep(box, params, devices=jax.devices()))
        _, t_plain_first = _timed(lambda: sweep(box, params))
        plain, t_plain = _timed(lambda: sweep(box, params))
        rows.append(dict(grid=f"{n}x{n}", points=n * n, n_devices=len(jax.devices()),
                         sharded_pts_per_s=n * n / t, sharded_first_call_s=t_first,
                         unsharded_pts_per_s=n * n / t_plain, unsharded_first_call_s=t_plain_first,
                         max_abs_diff_sharded_unsharded=float(np.max(np.abs(ds["ln_mpeak"].values
                                                                             - plain["ln_mpeak"].values))),
                         same_status=bool(np.array_equal(ds["status"].values, plain["status"].values))))
    print("RESULT" + json.dumps(rows), flush=True)


def run_sharded(sizes, timeout=1800):
    env = dict(os.environ, JAX_PLATFORMS="cpu",
               XLA_FLAGS=(os.environ.get("XLA_FLAGS", "")
                          + f" --xla_force_host_platform_device_count={N_SHARD_DEVICES}").strip())
    cmd = [sys.executable, str(pathlib.Path(__file__).resolve()), "--_child", *map(str, sizes)]
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout, cwd=str(ROOT))
    if r.returncode != 0:
        raise RuntimeError(f"sharded subprocess failed:\n{r.stderr[-3000:]}")
    line = [x for x in r.stdout.splitlines() if x.startswith("RESULT")][-1]
    return json.loads(line[len("RESULT"):])


def _plot(rows, shard_rows, path):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # pragma: no cover
        return None
    fig, ax = plt.subplots(figsize=(6.0, 4.0))
    x = [r["points"] for r in rows]
    for key, lab in (("vmap_pts_per_s", "vmap (sweep)"), ("chunked_pts_per_s", "chunked vmap"),
                     ("loop_pts_per_s", "loop of jitted solves")):
        ax.plot(x, [r[key] for r in rows], marker="o", label=lab)
    if shard_rows:
        ax.plot([r["points"] for r in shard_rows], [r["sharded_pts_per_s"] for r in shard_rows], marker="s",
                label=f"sharded, {shard_rows[0]['n_devices']} host devices")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("parameter points")
    ax.set_ylabel("points / s (after compile)")
    ax.set_title("sweep throughput, nebula box (32 bins)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="a 4 x 4 grid only")
    ap.add_argument("--sizes", type=int, nargs="+", default=None, help="grid sizes n (n x n; default 8 32)")
    ap.add_argument("--chunk", type=int, default=16, help="chunk size of the chunked mode (default 16)")
    ap.add_argument("--loop-max", type=int, default=256, help="time the loop on at most this many points")
    ap.add_argument("--no-sharded", action="store_true", help="skip the 4-device subprocess")
    ap.add_argument("--no-chunk-scan", action="store_true", help="skip the chunk-size scan on the largest grid")
    ap.add_argument("--out", default=None, help="JSON path")
    ap.add_argument("--_child", type=int, nargs="+", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args._child:
        _child(args._child)
        return {}
    sizes = args.sizes or ([4] if args.quick else [8, 32])
    box, rho0, nbins = make_problem()
    rows = []
    for n in sizes:
        chunk = args.chunk if n * n > args.chunk else max(1, n * n // 4)  # always a real lax.map
        row, _ = run_size(box, rho0, n, chunk, args.loop_max)
        rows.append(row)
        print(f"  done {row['grid']}: vmap {row['vmap_pts_per_s']:.3g} pts/s, loop {row['loop_pts_per_s']:.3g} pts/s",
              flush=True)
    C.print_table(rows, ["grid", "points", "failed", "vmap_pts_per_s", "chunk", "chunked_pts_per_s", "loop_pts_per_s",
                         "vmap_over_loop", "vmap_first_call_s", "max_abs_diff_vmap_loop"],
                  title=f"sweep throughput (nebula box, {nbins} bins; points/s after compile)")
    scan = []
    if not args.quick and not args.no_chunk_scan:
        scan = chunk_scan(box, rho0, max(sizes))
        C.print_table(scan, ["grid", "chunk", "pts_per_s"], title="chunk size scan (best of 2 after compile)")
    shard_rows = []
    if not args.no_sharded:
        shard_rows = run_sharded(sizes)
        C.print_table(shard_rows, ["grid", "points", "n_devices", "sharded_pts_per_s", "unsharded_pts_per_s",
                                   "sharded_first_call_s", "max_abs_diff_sharded_unsharded", "same_status"],
                      title=f"sharded over {N_SHARD_DEVICES} emulated host devices (same CPU cores)")
    out = pathlib.Path(args.out) if args.out else OUT / ("sweep_throughput" + ("_quick" if args.quick else "") + ".json")
    payload = dict(description="parameter points per second of jaxcoag.sweep.sweep (vmap, chunked), a Python loop "
                               "of jitted solves, and sweep sharded over emulated host devices; nebula_box "
                               f"({nbins} bins), output ln m_peak(1e10 s)",
                   note=C.NOISE_NOTE, machine=C.machine_info(), results=rows, chunk_scan=scan, sharded=shard_rows)
    C.write_json(out, payload)
    png = _plot(rows, shard_rows, out.with_suffix(".png"))
    print(f"wrote {out}" + (f" and {png}" if png else ""))
    return dict(results=rows, chunk_scan=scan, sharded=shard_rows, json=str(out))


if __name__ == "__main__":
    main()
