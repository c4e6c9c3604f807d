"""Cost of a gradient relative to a forward solve, reverse and forward mode, end to end.

Model: the chapter-4 nebula box of :func:`jaxcoag.fit.nebula_box` (Brownian + Ormel & Cuzzi
2007 turbulence + radial drift for compact 1 micron grains at 3 AU, dust-to-gas 0.01, two-bin
scheme), without fragmentation (Tsit5) and with ``Shattering(v_frag)`` (Kvaerno5 + Newton), at
2 - 3 grid sizes. Output: y = <ln m>_M(t_end), the mass-weighted mean ln m [ln g] of the
mass distribution at t_end = 1e10 s. Parameters: x = (ln alpha, ln rho_g[, ln v_frag]).

For each case, every program is compiled ahead of time (``jax.jit(f).lower(x).compile()``,
compile time reported separately) and then timed round robin (each repeat runs all four
back to back; a repeat of a sub-50 ms program loops it for >= 50 ms) as the median of:

* ``forward``: y(x), RecursiveCheckpointAdjoint solve (what a user runs);
* ``reverse``: ``jax.grad`` with ``diffrax.RecursiveCheckpointAdjoint`` (default adjoint);
* ``jvp``: one ``jax.jvp`` (one direction) with ``diffrax.ForwardMode``;
* ``jacfwd``: the full gradient by ``jax.jacfwd`` with ``ForwardMode`` (one batched JVP per
  parameter: 2 or 3 tangents);

and reports the ratios to ``forward`` (medians of the per-repeat ratios). The three gradients are cross-checked against each
other and against central finite differences in x (step 1e-4).

Prints a table; writes JSON (+ PNG) to benchmarks/results/gradient_cost[_quick].json.

    python benchmarks/gradient_cost.py [--quick] [--reps N] [--bpd 3 5 8]

References: Kidger (2021) diffrax adjoints (RecursiveCheckpointAdjoint, ForwardMode);
Griewank & Walther (2008) (reverse-mode cost bound ~ 3-5 x forward); docs/design_notes.md.
"""

from __future__ import annotations

import argparse
import pathlib
import statistics
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
from jaxcoag import RESULTS

OUT = C.RESULTS


def make_objective(model, names, adjoint):
    """y(x) = <ln m>_M(t_end) [ln g], the mass-weighted mean log-mass at t_end, for
    log-parameters x (ordered as ``names``). (ln m_peak is piecewise: its gradient is 0 while
    the peak sits in the monomer bin, as it does at 1e10 s on the finer grids.)"""
    lc = jnp.asarray(model.grid.log_centers)

    def f(x):
        sol = model.solve({k: jnp.exp(x[i]) for i, k in enumerate(names)}, adjoint=adjoint)
        rho = sol.mass_per_bin()[-1]
        return jnp.sum(rho * lc) / jnp.sum(rho)

    return f


def _compile(fn, x):
    t0 = time.perf_counter()
    c = jax.jit(fn).lower(x).compile()
    return c, time.perf_counter() - t0


def _median_time(c, x, reps, min_block=0.05):
    """Median over ``reps`` blocks of the time per call [s]; a block repeats the call until it
    lasts >= min_block s, so sub-millisecond programs are not timer/dispatch noise."""
    t0 = time.perf_counter()
    jax.block_until_ready(c(x))  # warm (allocations)
    one = time.perf_counter() - t0
    inner = max(1, min(1000, int(min_block / max(one, 1e-6))))
    ts = []
    for _ in range(reps):
        t0 = time.perf_counter()
        for _ in range(inner):
            y = c(x)
        jax.block_until_ready(y)
        ts.append((time.perf_counter() - t0) / inner)
    return statistics.median(ts)


def run_case(bpd, fragmentation, reps, decades=8, t_end=1e10, v_frag=2.0):
    """Time forward / reverse / jvp / jacfwd on one nebula box; returns a dict of numbers."""
    model = fit.nebula_box(bins_per_decade=bpd, decades=decades, ts=(t_end,), fragmentation=fragmentation,
                           v_frag=v_frag, rtol=1e-6, atol=1e-10)
    names = ("alpha", "rho_g", "v_frag") if fragmentation else ("alpha", "rho_g")
    x = jnp.log(jnp.array([float(getattr(model, k)) for k in names]))
    rev = diffrax.RecursiveCheckpointAdjoint()
    fwd = diffrax.ForwardMode()
    f_rev = make_objective(model, names, rev)
    f_fwd = make_objective(model, names, fwd)
    v = jnp.zeros_like(x).at[0].set(1.0)
    progs = {
        "forward": f_rev,
        "reverse": jax.grad(f_rev),
        "jvp": lambda z: jax.jvp(f_fwd, (z,), (v,))[1],
        "jacfwd": jax.jacfwd(f_fwd),
    }
    row = dict(bins=model.grid.nbins, bpd=bpd, fragmentation=bool(fragmentation), n_params=len(names),
               solver="Kvaerno5+Newton" if fragmentation else "Tsit5")
    vals, comp = {}, {}
    for name, fn in progs.items():
        comp[name], row[f"compile_{name}_s"] = _compile(fn, x)
        vals[name] = np.asarray(comp[name](x))
    # round robin: every repeat times all four programs back to back, so a change of machine
    # load hits numerator and denominator of a ratio alike; ratios are medians of per-repeat ratios
    per = {name: [] for name in progs}
    for _ in range(reps):
        for name, c in comp.items():
            per[name].append(_median_time(c, x, 1))
    for name in progs:
        row[f"{name}_s"] = statistics.median(per[name])
    for name in ("reverse", "jvp", "jacfwd"):
        row[f"{name}_ratio"] = statistics.median([a / b for a, b in zip(per[name], per["forward"])])
    sol = model.solve({k: jnp.exp(x[i]) for i, k in enumerate(names)}, adjoint=rev)
    row["steps"] = int(sol.stats["steps"])
    row["result"] = "successful" if bool(sol.status == RESULTS.successful) else "failed"
    row["mean_ln_m"] = float(vals["forward"])
    g_rev, g_fwd = vals["reverse"], vals["jacfwd"]
    c_fd = jax.jit(f_rev)
    h = 1e-4
    g_fd = np.array([(float(c_fd(x.at[i].add(h))) - float(c_fd(x.at[i].add(-h)))) / (2 * h)
                     for i in range(len(names))])
    scale = float(np.max(np.abs(g_rev)))
    row["grad"] = dict(zip(names, g_rev.tolist()))
    row["rev_vs_fwd_max_rel"] = float(np.max(np.abs(g_rev - g_fwd)) / scale)
    row["jvp_vs_grad0_rel"] = float(abs(float(vals["jvp"]) - g_rev[0]) / scale)
    row["rev_vs_fd_max_rel"] = float(np.max(np.abs(g_rev - g_fd)) / scale)
    return row


def _plot(rows, path):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # pragma: no cover - matplotlib is a dependency of jaxcoag.plot
        return None
    fig, ax = plt.subplots(figsize=(6.0, 4.0))
    for frag, mk in ((False, "o"), (True, "s")):
        sub = [r for r in rows if r["fragmentation"] == frag]
        if not sub:
            continue
        nb = [r["bins"] for r in sub]
        for key, col in (("reverse_ratio", "C0"), ("jvp_ratio", "C1"), ("jacfwd_ratio", "C2")):
            ax.plot(nb, [r[key] for r in sub], marker=mk, color=col, ls="-" if not frag else "--",
                    label=f"{key.split('_')[0]} ({'frag.' if frag else 'coag.'})")
    ax.set_xlabel("bins")
    ax.set_ylabel("time / forward solve")
    ax.set_title("gradient cost, nebula box, y = <ln m>_M(1e10 s)")
    ax.axhline(1.0, color="k", lw=0.5)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="one small grid (3 bins/decade, 24 bins), 3 repeats")
    ap.add_argument("--bpd", type=float, nargs="+", default=None, help="bins per decade (default 3 5 8)")
    ap.add_argument("--reps", type=int, default=None, help="timing repeats (median)")
    ap.add_argument("--no-frag", action="store_true", help="skip the fragmentation cases")
    ap.add_argument("--out", default=None, help="JSON path (default benchmarks/results/gradient_cost[_quick].json)")
    args = ap.parse_args(argv)
    bpds = args.bpd or ([3] if args.quick else [3, 5, 8])
    reps = args.reps or (3 if args.quick else 7)
    rows = []
    for frag in ((False,) if args.no_frag else (False, True)):
        for bpd in bpds:
            r = run_case(bpd, frag, reps)
            rows.append(r)
            print(f"  done: {r['bins']} bins, fragmentation={frag}: forward {r['forward_s']:.3g} s", flush=True)
    C.print_table(rows, ["bins", "solver", "steps", "forward_s", "reverse_s", "jvp_s", "jacfwd_s", "reverse_ratio",
                         "jvp_ratio", "jacfwd_ratio", "compile_forward_s", "compile_reverse_s",
                         "rev_vs_fwd_max_rel", "rev_vs_fd_max_rel"],
                  title="gradient cost / forward solve (y = mass-weighted <ln m> at 1e10 s; medians after compile)")
    out = pathlib.Path(args.out) if args.out else OUT / ("gradient_cost" + ("_quick" if args.quick else "") + ".json")
    payload = dict(description="cost of d <ln m>_M / d(ln alpha, ln rho_g[, ln v_frag]) relative to the forward "
                               "solve, nebula_box (two-bin), reverse = grad with RecursiveCheckpointAdjoint, "
                               "jvp/jacfwd with ForwardMode",
                   reps=reps, note=C.NOISE_NOTE, machine=C.machine_info(), results=rows)
    C.write_json(out, payload)
    png = _plot(rows, out.with_suffix(".png"))
    print(f"wrote {out}" + (f" and {png}" if png else ""))
    return dict(results=rows, json=str(out))


if __name__ == "__main__":
    main()
