"""Thesis Fig. 5.5: product kernel K = m_i m_j, constant-V equal-mass grouping, N = 1e20, m* = N/Ns*.

Output t = 0.4, 0.7, 0.95, 1.0, 1.05, 1.3, 2.0 (Table-5.1 units; gel point t = 1) against the Flory /
Trubnikov sol distribution n_k = k^{k-2} t^{k-1} e^{-kt}/k! (Trubnikov 1971; Ernst, Ziff & Hendriks 1984; valid for the sol after
t = 1). The runaway (gel) body of mass ~ beta(t) N is excluded from the sol comparison: sol := particles
with m < 10 N^{2/3}.
Check points (thesis Fig. 5.5): at t = 0.4, 0.7 the ensemble-mean |ln(M2/M2^A)| < 0.1 (M2^A = 1/(1-t)); at
t = 1.3, 2.0 the gel mass fraction (m >= 10 N^{2/3}) is within 0.05 + 3 sqrt(beta(1-beta)/(Ns* R)) of beta(t)
(beta = 0.42297, 0.79681; the second term is the granularity of swallowing ~Ns* groups whole: 0.003 at the
thesis size, 0.10/0.085 in quick mode, where 0.478 and 0.872 were measured);
at t = 0.4, 0.7, 1.3, 2.0 the sol E_mass (factor-2 bins, normalised over the sol) is <= 1.5 (quick: 2.5) x
the noise floor (2 pi Ng)^{-1/2} sum sqrt(p(1-p)) of Ng mass-weighted draws (docs/design_notes.md).

Leftover rule: ``leftover="stochastic"`` (MC hazard 3 in docs/design_notes.md) by default. With the thesis' demagnify rule
(``--leftover demagnify``) the post-gel accretion of j-group chunks by the gel (N_eps splitting) starts a
demagnification cascade: measured (quick size) Ng = 1.3e8 groups and > 1.1e5 events between t = 1.05 and
1.3, CAPACITY flag, event cap hit before t = 1.3 (gel fraction stuck at 0.30 vs beta(1.3) = 0.42).

Run:   python paper_figs/fig5_5_product.py --quick   (Ns* = 100, f_eps = 1e-2, 2 runs; a few min on 2 busy cores)
Full:  python paper_figs/fig5_5_product.py           (thesis: m* = N/1e4, 40 runs; each run is cheap in
       events (~1e5) but O(8e4)-slot rate updates make it ~1 h on this machine; not run here).
       Intermediate: --ns 2000 --runs 8.
"""

import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402
from fig2_8_constN_constant import tv_error  # noqa: E402
from fig5_4_sum_grouped import floor_mass  # noqa: E402

TIMES = (0.4, 0.7, 0.95, 1.0, 1.05, 1.3, 2.0)
N = 1e20


def _extra(p):
    p.add_argument("--ns", type=int, default=None, help="Ns* (m* = N/Ns*; default 1e4, quick 300)")
    p.add_argument("--runs", type=int, default=None, help="ensemble size (default 40; quick 3)")
    p.add_argument("--feps", type=float, default=None, help="f_eps (default 1e-4; quick 1e-2)")
    p.add_argument("--max-events", type=int, default=None, help="event cap per run (default 1e7; quick 1.5e5)")
    p.add_argument("--leftover", default="stochastic", choices=("stochastic", "demagnify"),
                   help="fractional-leftover rule of the engine (default stochastic; demagnify = thesis-literal)")
    p.add_argument("--seed", type=int, default=5005)


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
    ns = args.ns or (100 if args.quick else 10000)
    runs = args.runs or (2 if args.quick else 40)
    tol_e = 2.5 if args.quick else 1.5
    max_events = args.max_events or (150000 if args.quick else 10**7)
    args.feps = args.feps or (1e-2 if args.quick else 1e-4)
    print(f"Fig 5.5: K = m_i m_j, const-V equal-mass, N = {N:g}, m* = N/{ns}, f_eps = {args.feps:g}, {runs} runs, "
          f"leftover = {args.leftover}")
    keys = jax.random.split(jax.random.key(args.seed), runs)
    engine = jaxcoag.MonteCarlo(grouping=mc.EqualMass(), n_particles=N, ns_target=ns, f_eps=args.feps,
                                max_events=max_events, leftover=args.leftover)
    res = jax.vmap(lambda k: jaxcoag.evolve(K.Product(1.0), engine, jaxcoag.Monodisperse(1.0, 1.0), jnp.asarray(TIMES),
                                            key=k, throw=False))(keys)
    status = jaxcoag.status_names(res.status)
    ev = np.asarray(res.n_events_snap)
    real = np.all(ev < max_events, axis=0)          # snapshot reached by every run before the cap
    print(f"status: {sorted(set(status))}; events per run: {np.asarray(res.n_events).tolist()}")
    print(f"events at the output times (run 0): {ev[0].tolist()}")
    if not real.all():
        print(f"GAP: the event cap {max_events} was hit before t = {TIMES[int(np.argmin(real))]:g} (post-gel runaway "
              "accretion is f_eps-limited); later times are not compared (their checks fail).")
    m_cut = 10.0 * N ** (2.0 / 3.0)
    edges = 2.0 ** np.arange(0, 70)
    mc_ = np.sqrt(edges[:-1] * edges[1:])
    dm = edges[1:] - edges[:-1]
    sol = edges[1:] <= m_cut
    rho = np.asarray(res.mass_per_bin(jnp.asarray(edges)))      # mass density per bin (rho_tot = 1)
    lm2 = np.asarray(res.log_moments(2.0))
    ngr = np.asarray(res.n_groups)
    ck = _common.Checks(f"Fig 5.5 (product kernel, equal-mass m*=N/{ns}, {runs} runs)")
    ck.add("runs neither successful nor max_steps_reached (event cap)",
           float(sum(s not in ("successful", "max_steps_reached") for s in status)), 0.0, 0.0, absolute=True)
    ck.add("output times reached before the event cap", float(real.sum()), float(len(TIMES)), 0.0, absolute=True)
    fig, ax = plt.subplots(figsize=(6.2, 4.6))
    for it, t in enumerate(TIMES):
        rho_a = analytic.mass_per_bin("product", edges, t)
        gel = rho[:, it][:, ~sol].sum(axis=1)                 # mass fraction above 10 N^{2/3} (M1 = 1)
        beta = analytic.gel_fraction(t)
        line = f"t={t:>4g}: gel fraction {gel.mean():.4f} (beta {beta:.4f})"
        if t < 1:
            d2 = float(np.mean(lm2[:, it] + math.log(1 - t)))
            line += f"; ln(M2/M2A) {d2:+.4f}"
            if t in (0.4, 0.7):
                ck.add(f"mean ln(M2/M2A) t={t:g}", d2, 0.0, 0.1, absolute=True)
        if t in (0.4, 0.7, 1.3, 2.0):
            e = tv_error(rho[:, it][:, sol], rho_a[sol])
            fl = floor_mass(rho_a[sol], float(ngr[:, it].mean()))
            line += f"; sol E_mass {e.mean():.4f} (floor {fl:.4f}, Ng {ngr[:, it].mean():.0f})"
            ck.add(f"sol E_mass/E_floor t={t:g} (<={tol_e:g})", e.mean() / fl, 0.0, tol_e, absolute=True)
        if t in (1.3, 2.0):
            # granularity of the gel fraction: ~Ns* groups of mass m* are swallowed whole ->
            # s.d. sqrt(beta (1-beta)/(Ns* R)); tolerance 0.05 [own] + 3 s.d. (negligible at thesis size)
            sd = math.sqrt(beta * (1 - beta) / (ns * runs))
            ck.add(f"gel fraction t={t:g}", gel.mean(), beta, 0.05 + 3 * sd, absolute=True)
        print(line)
        y = rho[:, it] * mc_ / dm
        c = f"C{it}"
        ax.loglog(mc_, np.where(y.mean(0) > 0, y.mean(0), np.nan), "o", color=c, ms=3, label=f"t = {t:g}")
        ax.loglog(mc_[sol], (rho_a * mc_ / dm)[sol], "--" if t > 1 else "-", color=c, lw=1.0)
    ax.axvline(m_cut, color="k", lw=0.6, ls=":")
    ax.set_ylim(1e-6, 2)
    ax.set_xlabel("m")
    ax.set_ylabel(r"$m^2 f(m)$")
    ax.set_title(f"Ormel 2008 Fig. 5.5: product kernel, equal-mass (N = 1e20, m* = N/{ns}, {runs} runs)\n"
                 "lines: pre-gel solution, dashed: Flory sol (t > 1); dotted: 10 N^(2/3)", fontsize=9)
    ax.legend(fontsize=7, ncol=2)
    png = _common.savefig(fig, args, "fig5_5_product")
    ck.print()
    print(f"wrote {png}")
    return ck.result(png)


if __name__ == "__main__":
    main()
