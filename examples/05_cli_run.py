"""The `jaxcoag run` main job from a TOML scene file, re-plotted, and the same run from Python.

Shows: a TOML run configuration (examples/scenes/ch4_disk_3au.toml: the thesis ch. 4 disk at 3 AU,
alpha = 1e-4, 1 um silicate monomers, Maxwellian fragmentation at v_frag = 1 m/s) run through the
command line (``jaxcoag run FILE --out ...``: netCDF + figure panel + checkpoint, summary table),
``jaxcoag plot`` on the saved file, and the Python API (``jaxcoag.config`` + ``jaxcoag.runner``)
varying alpha to measure how the fragmentation-limited peak mass scales with turbulence
(Birnstiel et al. 2012: a_frag ~ v_frag^2 / (alpha c_s^2), so m_peak ~ alpha^-3 in the Epstein regime
if turbulence dominates the relative velocities).

    python examples/05_cli_run.py [--quick] [--out DIR]

Every file it writes (netCDF, figures, checkpoint) goes inside the output directory: by default
examples/out/05_cli_run/ next to this script (git-ignored), or a fresh temporary directory with
--quick; nothing is written to the current directory.

    # the same from a shell:
    jaxcoag run examples/scenes/ch4_disk_3au.toml --out jaxcoag_out/ch4_3au.nc
    jaxcoag plot jaxcoag_out/ch4_3au.nc
"""

import argparse
import os
import pathlib
import tempfile
import time

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np

from jaxcoag import cli, config, diagnostics, io, runner

HERE = pathlib.Path(__file__).resolve().parent
SCENE = HERE / "scenes" / "ch4_disk_3au.toml"
DEFAULT_OUT = HERE / "out" / "05_cli_run"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="coarse grid and few outputs (seconds)")
    ap.add_argument("--out", default=None, help=f"output directory (default: {DEFAULT_OUT}; a temporary "
                    "directory with --quick)")
    args = ap.parse_args(argv)
    out = args.out or (tempfile.mkdtemp(prefix="jaxcoag_ex05_") if args.quick else str(DEFAULT_OUT))
    os.makedirs(out, exist_ok=True)
    q = ["--quick"] if args.quick else []

    cfg = config.load(SCENE)
    print(f"scene file {SCENE.name}: {cfg['gas']['model']} at R = {cfg['gas']['R_au']} AU, alpha = "
          f"{cfg['gas']['alpha']:g}, v_frag = {cfg['fragmentation']['v_frag']:g} cm/s, t_end = "
          f"{cfg['time']['t_end_yr']:g} yr")

    # 1. the command line (what `jaxcoag run FILE --out ...` does)
    nc = os.path.join(out, "ch4_3au.nc")
    t0 = time.perf_counter()
    rc_run = cli.main(["run", str(SCENE), "--out", nc, "--no-progress"] + q)
    wall_cli = time.perf_counter() - t0
    rc_plot = cli.main(["plot", nc, "--out", os.path.join(out, "ch4_3au_replot.png")])
    ds = io.load_netcdf(nc)  # the common layout of every engine: mass_per_bin on (t, m), bin edges m_edge [g]
    kern = runner.kernel_from_dataset(ds)
    mp = np.asarray(diagnostics.mass_peak(ds["mass_per_bin"].values, ds["m_edge"].values))

    # 2. the Python API: the same configuration with stronger turbulence (the scene file's alpha is the CLI
    #    run above: a run with or without checkpoint is the same bit for bit, so its final peak is reused)
    alphas = [cfg["gas"]["alpha"], 4e-4]
    peaks = [float(mp[-1])]
    for a in alphas[1:]:
        r = runner.run(cfg.replace(**{"gas.alpha": a}), out=os.path.join(out, f"alpha_{a:g}.nc"), quick=args.quick,
                       progress=False, verbose=False, figure=False, checkpoint=False)
        peaks.append(r.numbers["m_peak"])
    slope = float(np.log(peaks[1] / peaks[0]) / np.log(alphas[1] / alphas[0]))
    st_frag = cfg["fragmentation"]["v_frag"] ** 2 / (3 * cfg["gas"]["alpha"] * float(ds.attrs["c_g"]) ** 2)
    st_peak = float(kern.particles(mp[-1]).st)
    print(f"final mass peak {mp[-1]:.4g} g (St = {st_peak:.3g}; St_frag = v_frag^2/(3 alpha c_s^2) = {st_frag:.3g}); "
          f"max |mass drift| {float(np.max(np.abs(ds['mass_drift'].values))):.2e}")
    print("m_peak(alpha): " + ", ".join(f"alpha = {a:g}: {p:.4g} g" for a, p in zip(alphas, peaks))
          + f" -> d ln m_peak / d ln alpha = {slope:.3f} "
          "(-3 for turbulence-dominated Epstein fragmentation)")
    print(f"CLI run {wall_cli:.1f} s; files in {out}")
    return dict(rc_run=rc_run, rc_plot=rc_plot, m_peak=float(mp[-1]), m_peak_first=float(mp[0]), st_peak=st_peak,
                st_frag=st_frag, max_abs_mass_drift=float(np.max(np.abs(ds["mass_drift"].values))),
                dlnm_dlnalpha=slope, n_out=int(ds.sizes["t"]), wall_cli_s=wall_cli)


if __name__ == "__main__":
    main()
