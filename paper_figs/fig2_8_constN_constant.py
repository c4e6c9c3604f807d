"""Thesis Fig. 2.8: constant kernel K = 1, constant-N Monte Carlo (Smith & Matsoukas 1998) to t = 1e8.

Ungrouped species DSMC (``jaxcoag.MonteCarlo(grouping=None, volume=jaxcoag.mc.ConstantNumber())``, run with
``jaxcoag.evolve``) from a monodisperse start, Table-5.1 units (m0 = n0 = rho_d = 1). Plotted: m^2 f(m) in factor-2 bins (ensemble mean; run-to-run band)
against the Smoluchowski solution n_k = f^2 (1-f)^(k-1), f = 1/(1+t/2) (Smoluchowski 1916),
and the "one particle per bin" line m/V.
Check points (thesis Fig. 2.8): at every output time the ensemble mean of ln(M0/M0^A) and
ln(m_p/m_p^A) (m_p = M2/M1; M0^A = 1/(1+t/2), m_p^A = 1+t) are within a statistical tolerance
4 sqrt((1 + ln GF)/(Np R)) (Smith-Matsoukas error grows like ln GF; capped below by 0.05
at the full size), and the run-mean mass-distribution error E_mass (total variation over factor-2
bins, docs/design_notes.md) is <= 1.5x the noise floor of Np number-weighted draws from the exact n_k for GF <= 100
([own] tolerance) and <= 2x beyond: the constant-N duplication error grows ~ ln GF (Smith & Matsoukas 1998);
measured with the quick size (Np = 1000, 4 runs): 0.65 (t = 1), 1.16 (t = 1e2), 1.55 (t = 1e4).

Run:   python paper_figs/fig2_8_constN_constant.py --quick      (Np = 1000, 4 runs, t <= 1e4; ~30 s
                                                                  incl. ~20 s compile on 2 busy cores)
Full:  python paper_figs/fig2_8_constN_constant.py              (thesis: Np = 2e4, 10 runs,
       t = 1, 1e2, 1e4, 1e6, 1e8: kappa ~ Np ln GF ~ 3.5e5 events per run with O(S) = O(4e4) work each;
       ~1 h on this 2-core machine -- not run here). Intermediate: --np 4000 --runs 6 --tmax 1e6.
"""

import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402


def _extra(p):
    p.add_argument("--np", type=int, default=None, help="number of simulated particles (default 2e4; quick 1000)")
    p.add_argument("--runs", type=int, default=None, help="ensemble size (default 10; quick 4)")
    p.add_argument("--tmax", type=float, default=None, help="last output time (default 1e8; quick 1e4)")
    p.add_argument("--seed", type=int, default=2008)


def noise_floor(n_bin, rho_bin, n_draw, rng, n_rep=200, return_sd=False):
    """E_mass of n_draw number-weighted particle draws from the exact distribution (noise floor, docs/design_notes.md).

    Counts per factor-2 bin are multinomial with the exact number fractions; each drawn particle
    carries the bin's exact mean mass (within-bin mass scatter neglected). With ``return_sd`` also
    the standard deviation of one draw's E_mass (the sampling spread of a single ideal run: about
    0.4 of the floor for 1000 particles), for tolerances on the mean of a few runs.
    """
    import numpy as np

    q = n_bin / n_bin.sum()
    mbar = np.where(n_bin > 0, rho_bin / np.where(n_bin > 0, n_bin, 1.0), 0.0)
    pa = rho_bin / rho_bin.sum()
    cnt = rng.multinomial(n_draw, q, size=n_rep)
    r = cnt * mbar[None, :]
    p = r / r.sum(axis=1, keepdims=True)
    e = 0.5 * np.abs(p - pa[None, :]).sum(axis=1)
    return (float(np.mean(e)), float(np.std(e))) if return_sd else float(np.mean(e))


def tv_error(rho_sim, rho_a):
    """Total-variation mass-distribution error E_mass (docs/design_notes.md) of one run (last axis = bins)."""
    import numpy as np

    p = rho_sim / rho_sim.sum(axis=-1, keepdims=True)
    return 0.5 * np.abs(p - rho_a / rho_a.sum()).sum(axis=-1)


def main(argv=None):
    args = _common.parse_args(argv, __doc__, _extra)
    jax = _common.enable_x64()
    import jax.numpy as jnp
    import numpy as np

    import jaxcoag
    from jaxcoag import analytic
    from jaxcoag import kernels as K
    from jaxcoag import mc

    plt = _common.pyplot()
    n_p = args.np or (1000 if args.quick else 20000)
    runs = args.runs or (4 if args.quick else 10)
    tmax = args.tmax or (1e4 if args.quick else 1e8)
    times = np.array([t for t in (1.0, 1e2, 1e4, 1e6, 1e8) if t <= tmax * (1 + 1e-12)])
    print(f"Fig 2.8: K = 1, const-N ungrouped, Np = {n_p}, {runs} runs, t = {times.tolist()}")

    keys = jax.random.split(jax.random.key(args.seed), runs)
    engine = jaxcoag.MonteCarlo(volume=mc.ConstantNumber(), n_particles=n_p, capacity=n_p + 8)
    run1 = lambda k: jaxcoag.evolve(K.Constant(1.0), engine, jaxcoag.Monodisperse(1.0, 1.0),  # noqa: E731
                                    jnp.asarray(times), key=k, throw=False)
    res = jax.vmap(run1)(keys)
    status = jaxcoag.status_names(res.status)
    lm0 = np.asarray(res.log_moments(0.0))              # (R, T)
    lmp = np.asarray(res.log_moments(2.0) - res.log_moments(1.0))
    edges = 2.0 ** np.arange(0, int(math.log2(times[-1] * 40)) + 2)
    rho = np.asarray(res.mass_per_bin(jnp.asarray(edges)))   # (R, T, nb)
    print(f"status: {sorted(set(status))}; events per run: {np.asarray(res.n_events).tolist()}; "
          f"species at t_end: {np.asarray(res.n_species)[:, -1].tolist()}")

    ck = _common.Checks(f"Fig 2.8 (K=1, const-N, Np={n_p}, {runs} runs)")
    ck.add("runs not successful", float(sum(s != "successful" for s in status)), 0.0, 0.0, absolute=True)
    rng = np.random.default_rng(args.seed)
    fig, ax = plt.subplots(figsize=(6.0, 4.5))
    mc_ = np.sqrt(edges[:-1] * edges[1:])
    dm = edges[1:] - edges[:-1]
    for it, t in enumerate(times):
        m0a = analytic.moments("constant", t, 0)
        mpa = analytic.moments("constant", t, 2)
        gf = 1.0 + t / 2
        tol = max(4.0 * math.sqrt((1.0 + math.log(gf)) / (n_p * runs)), 0.05 if n_p >= 20000 else 0.0)
        d0 = lm0[:, it] - math.log(m0a)
        dp = lmp[:, it] - math.log(mpa)
        ck.add(f"mean ln(M0/M0A) t={t:g}", d0.mean(), 0.0, tol, absolute=True)
        ck.add(f"mean ln(mp/mpA) t={t:g}", dp.mean(), 0.0, tol, absolute=True)
        rho_a = analytic.mass_per_bin("constant", edges, t)
        n_a = analytic.number_per_bin("constant", edges, t)
        e_runs = tv_error(rho[:, it], rho_a)
        floor = noise_floor(n_a, rho_a, n_p, rng)
        etol = 1.5 if gf <= 100 else 2.0
        ck.add(f"E_mass/E_floor t={t:g} (<={etol:g})", e_runs.mean() / floor, 0.0, etol, absolute=True)
        print(f"t={t:>8g}: M0 sim {np.exp(lm0[:, it]).mean():.5g} vs {m0a:.5g}; m_p sim {np.exp(lmp[:, it]).mean():.5g}"
              f" vs {mpa:.5g}; E_mass {e_runs.mean():.4f} (floor {floor:.4f})")
        y = rho[:, it] * mc_ / dm          # m^2 f = m * (rho per unit mass)
        c = f"C{it}"
        ax.loglog(mc_, y.mean(0), "o", color=c, ms=3.5, label=f"t = {t:g}")
        ax.fill_between(mc_, y.min(0), y.max(0), color=c, alpha=0.2, lw=0)
        ax.loglog(mc_, rho_a * mc_ / dm, "-", color=c, lw=1.0)
        v = float(np.exp(np.asarray(res.logV)[:, it]).mean())
        ax.loglog(mc_, mc_ / v / dm * mc_, ":", color=c, lw=0.8)
    ax.set_ylim(1e-6, 2.0)
    ax.set_xlabel("m")
    ax.set_ylabel(r"$m^2 f(m)$")
    ax.set_title(f"Ormel 2008 Fig. 2.8: K=1, constant-N (Np={n_p}, {runs} runs)\n"
                 "symbols: MC mean (band: min-max), lines: exact, dotted: one particle per bin", fontsize=9)
    ax.legend(fontsize=7)
    png = _common.savefig(fig, args, "fig2_8_constN_constant")
    ck.print()
    print(f"wrote {png}")
    return ck.result(png, n_particles=n_p, runs=runs)


if __name__ == "__main__":
    main()
