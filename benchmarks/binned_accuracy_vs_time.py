"""What accuracy costs in the binned engine, and how it compares with DustPy on the same boxes.

For each problem (kernel + exact solution), scheme ("twobin", "dg" order 0/1/2), bins per
decade and solver tolerance, this script runs ``jaxcoag.evolve(kernel, jaxcoag.Binned(grid, scheme=...), ...)``,
records the relative L1 error of mass per bin at the final time against the analytic solution
(:mod:`benchmarks._common`), the wall time of the solve after a warm-up compile (the compile
time is reported separately) and the solver step counts. In the same run it solves the
identical problems with DustPy (``benchmarks/peers/dustpy_boxes.py``: DustPy's own
analytic-kernel notebook set-ups, at its defaults and with the known pitfalls fixed) and reports

* the error ratio at equal bins/decade: L1(DustPy) / L1(ours) (> 1: we are more accurate);
* the wall-time ratio at equal error: wall(DustPy) / wall(our cheapest configuration whose
  L1 is not larger than DustPy's) (> 1: we are faster).

Problems (cgs, exponential start f(m, 0) = n0/m0 exp(-m/m0)):

* ``constant``: K = 1 cm^3 s^-1, n0 = 1e12 cm^-3, m0 = 1e-12 g; from the exact state at
  t = 1e-9 s to 1e3 s on [1e-12, 1e5] g (DustPy notebook "constant kernel" box);
* ``sum``: K = (m1 + m2) cm^3 s^-1 g^-1, same n0, m0; t = 0.9 -> 10 s on [1e-16, 1e5] g
  (DustPy "linear" box; the grid starts below the notebook's 1e-12 g, which would cut 8.5 %
  of the initial mass and put an error floor of ~0.25-0.6 on every code);
* ``product``: K = m1 m2 cm^3 s^-1 g^-2, n0 = 1 cm^-3, m0 = 1 g; t = 0 -> 0.4 s (gel time
  0.5 s) on [1e-4, 1e6] g (no DustPy counterpart; reference from jaxcoag.analytic).

Tolerances: the controller is diffrax's PIDController with ``rtol`` and a per-entry
``atol = atol_rel * M_tot / w`` (the library default's scaling), passed as arrays so that a
tolerance sweep reuses one compiled solve. ``atol_rel = 1e-4 rtol``.

Run: ``python benchmarks/binned_accuracy_vs_time.py [--quick]`` (restrict with ``--problems``,
``--schemes``, ``--bpd``, ``--rtol``, ``--no-peers``). Writes
``benchmarks/results/binned_accuracy_vs_time[_quick].json`` and a PNG.
References: Smoluchowski (1916); Golovin (1963); Scott (1968); Stammler & Birnstiel (2022);
Lombart & Laibe (2021) (DG); docs/design_notes.md.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

from benchmarks import _common as C  # noqa: E402

SCHEMES = {"twobin": ("twobin", 0), "dg0": ("dg", 0), "dg1": ("dg", 1), "dg2": ("dg", 2)}


def scheme_object(key):
    """The binned scheme object of a SCHEMES key: ``TwoBinScheme()`` or ``DGScheme(order=k)``."""
    from jaxcoag.binned import DGScheme, TwoBinScheme

    kind, order = SCHEMES[key]
    return TwoBinScheme() if kind == "twobin" else DGScheme(order=order)


def problems():
    """Problem definitions (see module docstring); ``dustpy`` names the DustPy box or None."""
    return {
        "constant": dict(kind="constant", coeff=1.0, n0=1e12, m0=1e-12, t_start=1e-9,
                         t_out=tuple(np.geomspace(1e-7, 1e3, 6)), m_min=1e-12, m_max=1e5,
                         dustpy="constant"),
        "sum": dict(kind="sum", coeff=1.0, n0=1e12, m0=1e-12, t_start=0.9,
                    t_out=(2.0, 4.0, 7.0, 10.0), m_min=1e-16, m_max=1e5, dustpy="linear"),
        "product": dict(kind="product", coeff=1.0, n0=1.0, m0=1.0, t_start=0.0,
                        t_out=(0.1, 0.2, 0.3, 0.4), m_min=1e-4, m_max=1e6, dustpy=None),
    }


def initial_density(p):
    """Callable f(m) [cm^-3 g^-1]: the exact solution of problem ``p`` at ``t_start``."""
    kind, t, k, n0, m0 = p["kind"], p["t_start"], p["coeff"], p["n0"], p["m0"]

    def f(m):
        m = np.asarray(m, dtype=np.float64)
        if kind == "constant":
            s = 1.0 + 0.5 * k * n0 * t
            return n0 / (m0 * s * s) * np.exp(-m / (m0 * s))
        if kind == "sum":
            return C.mass_density_sum_exp(m, t, coeff=k, n0=n0, m0=m0) / m
        if t == 0.0:
            return n0 / m0 * np.exp(-m / m0)
        from jaxcoag import analytic
        return np.asarray(analytic.number_density("product", m, t, coeff=k, n0=n0, m0=m0,
                                                  initial="exponential"))

    return f


def kernel_of(p):
    """The jaxcoag kernel of problem ``p``."""
    from jaxcoag.kernels import Constant, Product, Sum
    return {"constant": Constant, "sum": Sum, "product": Product}[p["kind"]](p["coeff"])


def _controller(sch, grid, f0, rtol, atol_rel):
    import diffrax
    import jax.numpy as jnp
    y0 = sch.init(grid, f0)
    w = sch.mass_scale(y0, grid)
    M0 = sch.total_mass(y0, grid)
    return diffrax.PIDController(rtol=jnp.asarray(rtol, dtype=jnp.float64),
                                 atol=jnp.asarray(atol_rel, dtype=jnp.float64) * M0 / w)


def run_ours(name, scheme_key, bpd, rtols, *, atol_factor=1e-4):
    """Solve problem ``name`` with one scheme/grid for every tolerance in ``rtols``.

    The first tolerance is solved twice: the first call (compile + run) gives ``compile_s`` =
    its time minus the second call's. Returns a list of result dicts (one per rtol).
    """
    import jax
    import jaxcoag
    from jaxcoag import RESULT_NAMES, MassGrid

    p = problems()[name]
    grid = MassGrid.log(p["m_min"], p["m_max"], bpd)
    f0 = initial_density(p)
    ts = np.array((p["t_start"],) + tuple(p["t_out"]), dtype=np.float64)  # outputs incl. the start
    kern = kernel_of(p)
    sch = scheme_object(scheme_key)
    ref = C.reference_mass_per_bin(p["kind"], grid.edges, ts[-1], coeff=p["coeff"], n0=p["n0"],
                                   m0=p["m0"])

    def solve(rtol):
        ctrl = _controller(sch, grid, f0, rtol, atol_factor * rtol)
        sol = jaxcoag.evolve(kern, jaxcoag.Binned(grid, scheme=sch, stepsize_controller=ctrl), f0, ts,
                             t0=ts[0], throw=False)
        jax.block_until_ready(sol.rho)
        return sol

    out = []
    with C.Timer() as tfirst:
        solve(rtols[0])
    compile_s = None
    for i, rtol in enumerate(rtols):
        walls = []
        for _ in range(3):
            with C.Timer() as tm:
                sol = solve(rtol)
            walls.append(tm.seconds)
            if sum(walls) > 1.0:
                break
        if i == 0:
            compile_s = max(tfirst.seconds - walls[0], 0.0)
        ok = bool(sol.status == jaxcoag.RESULTS.successful)
        result_name = next(n for n in RESULT_NAMES if bool(sol.status == getattr(jaxcoag.RESULTS, n)))
        rho = np.asarray(sol.mass_per_bin()[-1])
        l1 = C.rel_l1(rho, ref) if ok and np.all(np.isfinite(rho)) else None
        out.append(dict(code="jaxcoag", problem=name, scheme=scheme_key, bins_per_decade=bpd,
                        nbins=grid.nbins, rtol=rtol, atol_rel=atol_factor * rtol,
                        wall_s=min(walls), compile_s=compile_s, l1_final=l1, successful=ok,
                        result=result_name,
                        steps=int(sol.stats["steps"]), rejected=int(sol.stats["rejected"]),
                        mass_drift_final=float(np.asarray(sol.mass_drift)[-1])))
    return out


def run_dustpy_side(names, bpds, variants):
    """DustPy on the boxes of ``names`` (problem keys) for each bpd and variant."""
    from benchmarks.peers import dustpy_boxes as D

    rows = []
    for name in names:
        box = problems()[name]["dustpy"]
        if box is None:
            continue
        for bpd in bpds:
            for var in variants:
                r = D.run_dustpy(box, bins_per_decade=bpd, **D.VARIANTS[var])
                rows.append(dict(code="dustpy", problem=name, scheme=f"dustpy:{var}",
                                 bins_per_decade=bpd, nbins=len(r["m"]), cfl=r["cfl"],
                                 wall_s=r["wall_s"], l1_final=r["l1_final"], steps=r["steps"],
                                 variant=var))
                print(f"  dustpy {name} {bpd}/dec {var}: L1={r['l1_final']:.4g} "
                      f"wall={r['wall_s']:.2f}s steps={r['steps']}", flush=True)
    return rows


def ratios(ours, peers):
    """Equal-bpd error ratios and equal-error wall-time ratios (see module docstring)."""
    eq_bpd, eq_err = [], []
    for d in peers:
        mine = [o for o in ours if o["problem"] == d["problem"] and o["l1_final"] is not None]
        for key in SCHEMES:
            same = [o for o in mine if o["scheme"] == key and
                    o["bins_per_decade"] == d["bins_per_decade"]]
            if same:
                best = min(same, key=lambda o: o["l1_final"])
                eq_bpd.append(dict(problem=d["problem"], bins_per_decade=d["bins_per_decade"],
                                   dustpy_variant=d["variant"], scheme=key,
                                   l1_dustpy=d["l1_final"], l1_ours=best["l1_final"],
                                   rtol_ours=best["rtol"],
                                   error_ratio=d["l1_final"] / max(best["l1_final"], 1e-300)))
            good = [o for o in mine if o["scheme"] == key and o["l1_final"] <= d["l1_final"]]
            fastest = min(good, key=lambda o: o["wall_s"]) if good else None
            eq_err.append(dict(
                problem=d["problem"], dustpy_variant=d["variant"],
                dustpy_bpd=d["bins_per_decade"], l1_dustpy=d["l1_final"],
                wall_dustpy=d["wall_s"], scheme=key,
                ours_bpd=None if fastest is None else fastest["bins_per_decade"],
                ours_rtol=None if fastest is None else fastest["rtol"],
                l1_ours=None if fastest is None else fastest["l1_final"],
                wall_ours=None if fastest is None else fastest["wall_s"],
                speedup=None if fastest is None else d["wall_s"] / fastest["wall_s"]))
    return eq_bpd, eq_err


def plot(rows, path):
    """Error vs wall time per problem: our schemes (colours) and DustPy (black)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(dict.fromkeys(r["problem"] for r in rows))
    fig, axes = plt.subplots(1, len(names), figsize=(5 * len(names), 4), squeeze=False)
    for ax, name in zip(axes[0], names):
        for key in SCHEMES:
            pts = [r for r in rows if r["problem"] == name and r["scheme"] == key
                   and r["l1_final"] is not None]
            if pts:
                ax.loglog([r["wall_s"] for r in pts], [r["l1_final"] for r in pts], "o",
                          ms=4, label=key)
        dp = [r for r in rows if r["problem"] == name and r["code"] == "dustpy"]
        for r in dp:
            ax.loglog(r["wall_s"], r["l1_final"], "ks", ms=6)
            ax.annotate(f"{r['variant']} {r['bins_per_decade']}/dec", (r["wall_s"], r["l1_final"]),
                        fontsize=6)
        ax.set_title(name)
        ax.set_xlabel("wall time [s] (after compile)")
        ax.set_ylabel("relative L1 of mass per bin (final time)")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def parse(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true",
                    help="constant+sum, twobin+dg1, 4 and 7 bins/decade, 2 tolerances")
    ap.add_argument("--problems", default=None, help="comma list of constant,sum,product")
    ap.add_argument("--schemes", default=None, help="comma list of twobin,dg0,dg1,dg2")
    ap.add_argument("--bpd", default=None, help="comma list of bins per decade")
    ap.add_argument("--rtol", default=None, help="comma list of rtol values")
    ap.add_argument("--no-peers", action="store_true", help="skip DustPy")
    ap.add_argument("--out", default=None)
    ap.add_argument("--update", action="store_true",
                    help="merge into the existing output JSON: replace only the rows of the "
                         "problems run now (ours and DustPy), recompute the ratios and the plot")
    return ap.parse_args(argv)


def main(argv=None):
    args = parse(argv)
    C.ensure_x64()
    quick = args.quick
    names = args.problems.split(",") if args.problems else (
        ["constant", "sum"] if quick else ["constant", "sum", "product"])
    schemes = args.schemes.split(",") if args.schemes else (
        ["twobin", "dg1"] if quick else list(SCHEMES))
    bpds = [int(b) for b in args.bpd.split(",")] if args.bpd else ([4, 7] if quick else [4, 7, 10])
    rtols = [float(r) for r in args.rtol.split(",")] if args.rtol else (
        [1e-3, 1e-6] if quick else [1e-3, 1e-6, 1e-9])
    rows = []
    for name in names:
        for key in schemes:
            for bpd in bpds:
                try:
                    res = run_ours(name, key, bpd, rtols)
                except Exception as exc:  # noqa: BLE001 - record and continue the sweep
                    print(f"ours {name} {key} {bpd}/dec FAILED: {type(exc).__name__}: {exc}")
                    rows.append(dict(code="jaxcoag", problem=name, scheme=key,
                                     bins_per_decade=bpd, l1_final=None,
                                     error=f"{type(exc).__name__}: {exc}"))
                    continue
                rows.extend(res)
                for r in res:
                    print(f"ours {name:8s} {key:6s} {bpd:2d}/dec rtol={r['rtol']:.0e} "
                          f"L1={r['l1_final']} wall={r['wall_s']:.3f}s "
                          f"compile={r['compile_s']:.1f}s steps={r['steps']}", flush=True)
    peers = []
    if not args.no_peers:
        dp_bpds = [7] if quick else sorted(set(bpds) | {7})
        variants = ["fixed"] if quick else ["notebook", "fixed"]
        peers = run_dustpy_side(names, dp_bpds, variants)
        if not quick and "sum" in names:
            peers += run_dustpy_side(["sum"], [7], ["fixed_cfl1e-3"])
        if not quick and "constant" in names:
            peers += run_dustpy_side(["constant"], [7], ["fixed_cfl1e-2"])
    tag = "_quick" if quick else ""
    out = pathlib.Path(args.out) if args.out else C.RESULTS / f"binned_accuracy_vs_time{tag}.json"
    updated_from = None
    if args.update and out.exists():
        old = json.loads(out.read_text())
        keep = [r for r in old.get("results", []) if r.get("problem") not in names]
        keep_peers = [r for r in old.get("dustpy", []) if r.get("problem") not in names]
        rows = keep + rows
        peers = keep_peers + peers
        rtols = sorted(set(rtols) | set(old.get("rtols", [])), reverse=True)
        updated_from = dict(previous_machine=old.get("machine"),
                            replaced_problems=names,
                            note="rows of the other problems come from the previous run")
    ok_rows = [r for r in rows if "error" not in r]
    C.print_table(ok_rows + peers, ["problem", "scheme", "bins_per_decade", "rtol", "cfl",
                                    "steps", "compile_s", "wall_s", "l1_final"],
                  title="Binned accuracy vs wall time (relative L1 of mass per bin, final time)")
    eq_bpd, eq_err = ratios(ok_rows, peers)
    if eq_bpd:
        C.print_table(eq_bpd, ["problem", "bins_per_decade", "dustpy_variant", "scheme",
                               "l1_dustpy", "l1_ours", "rtol_ours", "error_ratio"],
                      title="Error ratio at equal bins/decade: L1(DustPy) / L1(ours)")
    if eq_err:
        C.print_table(eq_err, ["problem", "dustpy_variant", "dustpy_bpd", "l1_dustpy",
                               "wall_dustpy", "scheme", "ours_bpd", "ours_rtol", "l1_ours",
                               "wall_ours", "speedup"],
                      title="Wall-time ratio at equal error: wall(DustPy) / wall(ours)")
    C.write_json(out, dict(benchmark="binned_accuracy_vs_time", quick=quick,
                           machine=C.machine_info(), updated_from=updated_from,
                           problems=problems(), rtols=rtols,
                           results=rows, dustpy=peers, ratio_equal_bpd=eq_bpd,
                           ratio_equal_error=eq_err))
    plot(ok_rows + peers, out.with_suffix(".png"))
    print(f"wrote {out}")
    return dict(results=rows, dustpy=peers, ratio_equal_bpd=eq_bpd, ratio_equal_error=eq_err)


if __name__ == "__main__":
    main()
