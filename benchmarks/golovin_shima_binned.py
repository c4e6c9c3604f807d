"""Binned engine vs DustPy on the Golovin box of Shima et al. (2009), side by side in one run.

K = b (m1 + m2) with b = 1500 cm^3 s^-1 g^-1 (1500 s^-1 on volumes, water), n0 = 2^23 m^-3,
exponential start with mean radius 30.531 um, outputs at 1200/2400/3600 s; grid 1e-10..1e3 g.
Metric: relative L1 of mass per bin at 3600 s against the exact Golovin solution on each code's
own bins (DustPy: its notebook bin edges; ours: log edges at the same bins/decade).

Reports, as ratios, the error at equal bins/decade and the wall time at equal error. DustPy is
run at its notebook defaults and with the pitfalls listed in docs/design_notes.md fixed (1/2 on the diagonal,
fresh first step), at cfl 0.1 and 0.001. Writes benchmarks/results/golovin_shima_binned[_quick].json
and a PNG.

    python benchmarks/golovin_shima_binned.py [--quick] [--no-peers]
"""

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
import numpy as np

import jaxcoag
from benchmarks import _common as C
from benchmarks.peers import dustpy_boxes as DP
from jaxcoag import kernels

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")


def run_ours(scheme, order, bpd, p, rtol=1e-8):
    grid = jaxcoag.MassGrid.log(p["mmin"], p["mmax"], bpd)
    f0 = jaxcoag.binned.exponential(p["m0"], p["n0"])
    ts = jnp.array((0.0,) + tuple(p["t_out"]))
    kern = kernels.Sum(p["coeff"])
    sch = jaxcoag.binned.TwoBinScheme() if scheme == "twobin" else jaxcoag.binned.DGScheme(order=order)
    solve = lambda: jaxcoag.evolve(kern, jaxcoag.Binned(grid, scheme=sch, rtol=rtol), f0, ts)
    t0 = time.perf_counter()
    jax.block_until_ready(solve().rho)
    compile_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    sol = solve()
    rho = np.asarray(jax.block_until_ready(sol.mass_per_bin()))
    wall = time.perf_counter() - t0
    ref = C.reference_mass_per_bin("sum", grid.edges, p["t_out"][-1], coeff=p["coeff"], n0=p["n0"], m0=p["m0"])
    return dict(code="jaxcoag", scheme=f"{scheme}{order if scheme == 'dg' else ''}", bins_per_decade=bpd,
                wall_s=wall, compile_s=compile_s, l1_final=C.rel_l1(rho[-1], ref),
                mass_drift_final=float(sol.mass_drift[-1]), steps=int(sol.stats["steps"]))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="8 bins/decade, DustPy 'fixed' only")
    ap.add_argument("--no-peers", action="store_true")
    args = ap.parse_args(argv)
    p = DP.problem("golovin")
    bpds = (8,) if args.quick else (4, 8, 16)
    ours = [run_ours(s, o, b, p) for b in bpds for s, o in (("twobin", 0), ("dg", 1), ("dg", 2))]
    peers = []
    if not args.no_peers:
        try:
            import dustpy  # noqa: F401
        except ImportError:
            print("dustpy not installed (pip install dustpy; needs gfortran): peer side skipped")
        else:
            variants = ("fixed",) if args.quick else ("notebook", "fixed", "fixed_cfl1e-3")
            for v in variants:
                r = DP.run_dustpy("golovin", bins_per_decade=8 if args.quick else 16, **DP.VARIANTS[v])
                peers.append(dict(code="dustpy", variant=v, bins_per_decade=r["bins_per_decade"], wall_s=r["wall_s"],
                                  l1_final=r["l1_final"], steps=r["steps"]))
    C.print_table(ours, ["scheme", "bins_per_decade", "l1_final", "wall_s", "compile_s", "steps", "mass_drift_final"],
                  title="jaxcoag on the Shima et al. (2009) Golovin box (L1 at 3600 s)")
    ratios = []
    if peers:
        C.print_table(peers, ["variant", "bins_per_decade", "l1_final", "wall_s", "steps"], title="DustPy, same box")
        for pr in peers:
            same = [o for o in ours if o["bins_per_decade"] == pr["bins_per_decade"]]
            better = [o for o in ours if o["l1_final"] <= pr["l1_final"]]
            fastest = min(better, key=lambda o: o["wall_s"]) if better else None
            ratios.append(dict(dustpy_variant=pr["variant"], bins_per_decade=pr["bins_per_decade"],
                               error_ratio_equal_bpd={o["scheme"]: pr["l1_final"] / o["l1_final"] for o in same},
                               speedup_equal_error=(pr["wall_s"] / fastest["wall_s"]) if fastest else None,
                               fastest_at_equal_error=fastest["scheme"] + f"@{fastest['bins_per_decade']}/dec" if fastest else None))
        for r in ratios:
            print(f"DustPy {r['dustpy_variant']} @{r['bins_per_decade']}/dec: error ratio (DustPy/ours) at equal "
                  f"bins/decade {', '.join(f'{k} {v:.3g}' for k, v in r['error_ratio_equal_bpd'].items())}; "
                  f"wall-time ratio at equal error {r['speedup_equal_error']:.3g} ({r['fastest_at_equal_error']})")
    payload = dict(benchmark="golovin_shima_binned", quick=args.quick, machine=C.machine_info(), problem=p,
                   ours=ours, dustpy=peers, ratios=ratios)
    path = C.write_json(os.path.join(OUT, "golovin_shima_binned" + ("_quick" if args.quick else "") + ".json"), payload)
    _plot(ours, peers, str(path).replace(".json", ".png"))
    print(f"wrote {path}")
    return payload


def _plot(ours, peers, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4.5))
    for s in sorted({o["scheme"] for o in ours}):
        rows = [o for o in ours if o["scheme"] == s]
        ax.loglog([o["wall_s"] for o in rows], [o["l1_final"] for o in rows], "o-", label=f"jaxcoag {s}")
        for o in rows:
            ax.annotate(f"{o['bins_per_decade']}", (o["wall_s"], o["l1_final"]), fontsize=7)
    for pr in peers:
        ax.loglog([pr["wall_s"]], [pr["l1_final"]], "ks")
        ax.annotate(f"DustPy {pr['variant']} {pr['bins_per_decade']}/dec", (pr["wall_s"], pr["l1_final"]), fontsize=7)
    ax.set_xlabel("wall time [s] (after compile)")
    ax.set_ylabel("relative L1 of mass per bin at 3600 s")
    ax.set_title("Golovin box (Shima et al. 2009)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
