"""Thesis Fig. 5.3: sum kernel K = (m_i+m_j)/2 with a fixed number of particles (negative control).

Ungrouped constant-N DSMC (``jaxcoag.MonteCarlo(grouping=None, volume=jaxcoag.mc.ConstantNumber())`` through
``jaxcoag.evolve``), monodisperse start, Table-5.1 units,
output t = 1, 10, 20, 30, against the Golovin (1963) solution (M0 = e^{-t/2},
m_p = M2/M1 = e^t). The method is fine for t < 10, lags at t = 20 and fails at t = 30: the total
simulated mass M_tot,sim = Np <m>_sim ~ Np e^{15} lies below the analytic peak mass e^{30}
(one-particle line crossed at t ~ 2 ln Np), so m_p <= M_tot,sim < e^{30} deterministically.
Check points (thesis Figs. 2.9a, 5.3): t = 1 passes the F2.8 tolerances (ensemble-mean ln M0 and ln m_p
within 4 sqrt((1+ln GF)/(Np R)), E_mass <= 1.5x noise floor, plus 3 standard errors of
the R-run mean); at t = 30 max over runs of
M_tot,sim/e^{30} < 1 (deterministic bound) and the ensemble-mean ln(m_p/e^t) < -1 (failure shown).
The crossing time 2 ln Np < 30 is a property of the chosen Np, not of the simulation: it is printed
as an info row and does not count toward the pass flag.

Run:   python paper_figs/fig5_3_sum_fixedNp.py --quick   (Np = 1000, 3 runs: ~1.5e4 events/run; ~60 s incl.
                                                          compile on 2 busy cores)
Full:  python paper_figs/fig5_3_sum_fixedNp.py           (thesis: Np = 1e5, 40 runs: ~1.5e6 events per run
       at O(2e5) work each -- many hours on this machine, not run here). Intermediate: --np 10000 --runs 8.
"""

import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402
from fig2_8_constN_constant import noise_floor, tv_error  # noqa: E402

TIMES = (1.0, 10.0, 20.0, 30.0)


def in_range(ck, name, value, lo, hi):
    """Check lo <= value <= hi (stored as |value - mid| <= half-width, absolute)."""
    return ck.add(name, value, 0.5 * (lo + hi), 0.5 * (hi - lo), absolute=True)


def _extra(p):
    p.add_argument("--np", type=int, default=None, help="simulated particles (default 1e5; quick 1000)")
    p.add_argument("--runs", type=int, default=None, help="ensemble size (default 40; quick 3)")
    p.add_argument("--seed", type=int, default=5003)


def simulate_const_n_sum(n_p, runs, seed, times=TIMES):
    """Ensemble of ungrouped const-N runs of the sum kernel (b = 1/2); returns the vmapped MCResult."""
    import jax
    import jax.numpy as jnp

    import jaxcoag
    from jaxcoag import kernels as K
    from jaxcoag import mc

    keys = jax.random.split(jax.random.key(seed), runs)
    engine = jaxcoag.MonteCarlo(volume=mc.ConstantNumber(), n_particles=n_p, capacity=n_p + 8)
    return jax.vmap(lambda k: jaxcoag.evolve(K.Sum(0.5), engine, jaxcoag.Monodisperse(1.0, 1.0), jnp.asarray(times),
                                             key=k, throw=False))(keys)


def main(argv=None):
    args = _common.parse_args(argv, __doc__, _extra)
    _common.enable_x64()
    import jax.numpy as jnp
    import numpy as np

    import jaxcoag
    from jaxcoag import analytic

    plt = _common.pyplot()
    n_p = args.np or (1000 if args.quick else 100000)
    runs = args.runs or (3 if args.quick else 40)
    print(f"Fig 5.3: K = (m_i+m_j)/2, const-N ungrouped, Np = {n_p}, {runs} runs, t = {TIMES}")
    res = simulate_const_n_sum(n_p, runs, args.seed)
    status = jaxcoag.status_names(res.status)
    lm0 = np.asarray(res.log_moments(0.0))
    lmp = np.asarray(res.log_moments(2.0) - res.log_moments(1.0))
    mtot = np.asarray(res.M_tot)
    edges = 2.0 ** np.arange(0, 50)
    rho = np.asarray(res.mass_per_bin(jnp.asarray(edges)))
    print(f"status: {sorted(set(status))}; events per run: {np.asarray(res.n_events).tolist()}")

    ck = _common.Checks(f"Fig 5.3 (sum kernel, fixed Np={n_p}, {runs} runs)")
    ck.add("runs not successful", float(sum(s != "successful" for s in status)), 0.0, 0.0, absolute=True)
    rng = np.random.default_rng(args.seed)
    mc_ = np.sqrt(edges[:-1] * edges[1:])
    dm = edges[1:] - edges[:-1]
    fig, ax = plt.subplots(figsize=(6.0, 4.5))
    for it, t in enumerate(TIMES):
        mpa = math.exp(t)
        rho_a = analytic.mass_per_bin("sum", edges, t, coeff=0.5)
        n_a = analytic.number_per_bin("sum", edges, t, coeff=0.5)
        e_runs = tv_error(rho[:, it], rho_a)
        floor, floor_sd = noise_floor(n_a, rho_a, n_p, rng, return_sd=True)
        print(f"t={t:>4g}: M0 sim {np.exp(lm0[:, it]).mean():.5g} vs {math.exp(-t / 2):.5g}; m_p sim "
              f"{np.exp(lmp[:, it]).mean():.4g} vs {mpa:.4g} (ln ratio {np.mean(lmp[:, it] - t):+.3f}); "
              f"M_tot,sim {mtot[:, it].mean():.3g}; E_mass {e_runs.mean():.3f} (floor {floor:.3f})")
        if t == 1.0:
            tol = 4.0 * math.sqrt((1.0 + t / 2) / (n_p * runs))
            ck.add("mean ln(M0/M0A) t=1", np.mean(lm0[:, it] + t / 2), 0.0, tol, absolute=True)
            ck.add("mean ln(mp/mpA) t=1", np.mean(lmp[:, it] - t), 0.0, tol, absolute=True)
            # the thesis bound (1.5 floors) holds for the expected E_mass; the mean of `runs` runs
            # scatters about it by ~sd/sqrt(runs) (one ideal 1000-particle sample: sd ~0.4 floor), so
            # the bound gets 3 of those: the old and the new engine both gave 0.84-1.69 over 8 seeds
            # of 3 runs (mean 1.13 / 1.14), and 1.5 alone failed one seed in eight for each
            etol = 1.5 + 3.0 * floor_sd / (floor * math.sqrt(runs))
            ck.add("E_mass/E_floor t=1 (<=1.5+3sd/sqrt(R))", e_runs.mean() / floor, 0.0, etol, absolute=True)
        if t == 30.0:
            ck.add("max M_tot,sim / e^30 (<1, deterministic)", np.max(mtot[:, it]) / mpa, 0.0, 1.0, absolute=True)
            ck.add("max m_p,sim / M_tot,sim (<=1)", np.max(np.exp(lmp[:, it]) / mtot[:, it]), 0.0, 1.0, absolute=True)
            # failure shown: the ensemble-mean peak lags the analytic one by more than a factor e
            in_range(ck, "mean ln(mp/mpA) t=30 in [-50,-1] (failure)", np.mean(lmp[:, it] - t), -50.0, -1.0)
        y = rho[:, it] * mc_ / dm
        c = f"C{it}"
        ax.loglog(mc_, np.where(y.mean(0) > 0, y.mean(0), np.nan), "o", color=c, ms=3.5, label=f"t = {t:g}")
        ax.fill_between(mc_, y.min(0), y.max(0), color=c, alpha=0.2, lw=0)
        ax.loglog(mc_, rho_a * mc_ / dm, "-", color=c, lw=1.0)
        v = float(np.exp(np.asarray(res.logV)[:, it]).mean())
        ax.loglog(mc_, mc_ * mc_ / v / dm, ":", color=c, lw=0.8)
    # a property of the chosen Np (no simulation involved): reported, not counted
    ck.add("one-particle-line crossing 2 ln Np (<30)", 2 * math.log(n_p), 0.0, 30.0, absolute=True, counts=False)
    ax.set_ylim(1e-7, 2.0)
    ax.set_xlabel("m")
    ax.set_ylabel(r"$m^2 f(m)$")
    ax.set_title(f"Ormel 2008 Fig. 5.3: sum kernel, fixed Np = {n_p} ({runs} runs)\n"
                 "symbols: MC mean (band: min-max), lines: Golovin, dotted: one particle per bin", fontsize=9)
    ax.legend(fontsize=7)
    png = _common.savefig(fig, args, "fig5_3_sum_fixedNp")
    ck.print()
    print(f"wrote {png}")
    return ck.result(png, n_particles=n_p, runs=runs)


if __name__ == "__main__":
    main()
