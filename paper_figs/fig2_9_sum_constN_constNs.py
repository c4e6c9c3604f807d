"""Thesis Fig. 2.9: sum kernel K = (m_i+m_j)/2, (a) constant-N vs (b) constant-Ns ungrouped Monte Carlo.

(a) ``volume=ConstantNumber()``, ungrouped: Np fixed; fails once the analytic peak e^t exceeds the total simulated
    mass Np e^{t/2} (t > 2 ln Np; thesis: Np = 2e5, crossing at t ~ 24).
(b) ``volume=ConstantSpecies(SpeciesController())``, ungrouped: duplications (2 per event while
    Ns < Ns*) keep the number of *species* near Ns*; Np then grows (thesis 2e4 -> > 1e6) and the run
    follows the Golovin solution much longer, at a higher cost (freeze-down).
Output t = 1, 10, 20, 30 (Table-5.1 units) vs the Golovin (1963) solution; both run with
``jaxcoag.evolve(kernel, jaxcoag.MonteCarlo(...), jaxcoag.Monodisperse(1, 1), t_out, key=...)``.
Check points (thesis Fig. 2.9a/b): E_mass(b) < E_mass(a) at t = 20 and 30 (run means); (a) at t = 30 obeys the
deterministic bound M_tot,sim < e^{30}; (b) ends with Np > initial Np (growth factor printed) and
|ln(m_p/e^t)| of (b) at t = 20 is smaller than that of (a).

Run:   python paper_figs/fig2_9_sum_constN_constNs.py --quick  ((a) Np = 1000; (b) Np0 = 1000, Ns* = 150;
                                                                 3 runs each, ~1-2 min on 2 busy cores)
Full:  python paper_figs/fig2_9_sum_constN_constNs.py          (thesis: (a) Np = 2e5, (b) Ns* = 2e4 with
       Np0 = 2e4, 10 runs: (a) ~3e6 events/run, (b) Np > 1e6 -- days on this machine, not run here).
       Intermediate: --np 10000 --ns 1000 --runs 4.
"""

import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402
from fig2_8_constN_constant import tv_error  # noqa: E402
from fig5_3_sum_fixedNp import TIMES, in_range, simulate_const_n_sum  # noqa: E402


def _extra(p):
    p.add_argument("--np", type=int, default=None, help="(a) particles / (b) initial particles (2e5 / 2e4; quick 1000)")
    p.add_argument("--ns", type=int, default=None, help="(b) target species number Ns* (2e4; quick 150)")
    p.add_argument("--runs", type=int, default=None, help="ensemble size (default 10; quick 3)")
    p.add_argument("--seed", type=int, default=2009)


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
    n_a = args.np or (1000 if args.quick else 200000)
    n_b0 = args.np or (1000 if args.quick else 20000)
    ns = args.ns or (150 if args.quick else 20000)
    runs = args.runs or (3 if args.quick else 10)
    print(f"Fig 2.9: sum kernel; (a) const-N Np = {n_a}; (b) const-Ns Ns* = {ns}, Np0 = {n_b0}; {runs} runs")
    ra = simulate_const_n_sum(n_a, runs, args.seed)
    keys = jax.random.split(jax.random.key(args.seed + 1), runs)
    eng_b = jaxcoag.MonteCarlo(volume=mc.ConstantSpecies(mc.SpeciesController()), n_particles=n_b0, ns_target=ns,
                               capacity=4 * ns + 8)
    rb = jax.vmap(lambda k: jaxcoag.evolve(K.Sum(0.5), eng_b, jaxcoag.Monodisperse(1.0, 1.0), jnp.asarray(TIMES),
                                           key=k, throw=False))(keys)
    edges = 2.0 ** np.arange(0, 50)
    mc_ = np.sqrt(edges[:-1] * edges[1:])
    dm = edges[1:] - edges[:-1]
    ck = _common.Checks(f"Fig 2.9 (sum kernel, (a) const-N {n_a}, (b) const-Ns {ns})")
    bad = [s for r in (ra, rb) for s in jaxcoag.status_names(r.status) if s != "successful"]
    ck.add("runs not successful (a and b)", float(len(bad)), 0.0, 0.0, absolute=True)
    fig, axs = plt.subplots(1, 2, figsize=(10.5, 4.3), sharey=True)
    err = {}
    lnp = {}
    for lab, res, ax in (("a", ra, axs[0]), ("b", rb, axs[1])):
        rho = np.asarray(res.mass_per_bin(jnp.asarray(edges)))
        lmp = np.asarray(res.log_moments(2.0) - res.log_moments(1.0))
        log_np = np.asarray(res.log_moments(0.0) + res.logV)   # ln Np
        for it, t in enumerate(TIMES):
            rho_a = analytic.mass_per_bin("sum", edges, t, coeff=0.5)
            e = tv_error(rho[:, it], rho_a)
            err[lab, t] = float(e.mean())
            lnp[lab, t] = float(np.mean(lmp[:, it] - t))
            print(f"({lab}) t={t:>4g}: E_mass {e.mean():.3f}; ln(m_p/e^t) {lnp[lab, t]:+.3f}; "
                  f"Np {np.exp(log_np[:, it]).mean():.4g}; Ns {np.asarray(res.n_species)[:, it].mean():.0f}; "
                  f"events {np.asarray(res.n_events_snap)[:, it].mean():.3g}")
            y = rho[:, it] * mc_ / dm
            c = f"C{it}"
            ax.loglog(mc_, np.where(y.mean(0) > 0, y.mean(0), np.nan), "o", color=c, ms=3, label=f"t = {t:g}")
            ax.loglog(mc_, rho_a * mc_ / dm, "-", color=c, lw=1.0)
            v = float(np.exp(np.asarray(res.logV)[:, it]).mean())
            ax.loglog(mc_, mc_ * mc_ / v / dm, ":", color=c, lw=0.8)
        ax.set_xlabel("m")
        ax.set_ylim(1e-8, 2.0)
        ax.legend(fontsize=7)
        if lab == "b":
            growth = float(np.exp(log_np[:, -1]).mean() / n_b0)
    axs[0].set_ylabel(r"$m^2 f(m)$")
    axs[0].set_title(f"(a) constant N = {n_a}", fontsize=9)
    axs[1].set_title(f"(b) constant Ns* = {ns} (Np0 = {n_b0})", fontsize=9)
    fig.suptitle("Ormel 2008 Fig. 2.9: sum kernel; lines Golovin, dotted one particle per bin", fontsize=10)
    for t in (20.0, 30.0):
        in_range(ck, f"E_mass(b)/E_mass(a) t={t:g} (<1)", err["b", t] / err["a", t], 0.0, 1.0)
    in_range(ck, "|ln mp/mpA|(b) - |ln mp/mpA|(a) t=20 (<0)", abs(lnp["b", 20.0]) - abs(lnp["a", 20.0]), -50.0, 0.0)
    in_range(ck, "(a) max M_tot,sim/e^30 (<1)", float(np.max(np.asarray(ra.M_tot)[:, -1])) / math.exp(30.0), 0.0, 1.0)
    in_range(ck, "(b) Np(t=30)/Np0 (>1: Np grows)", growth, 1.0, 1e12)
    png = _common.savefig(fig, args, "fig2_9_sum_constN_constNs")
    ck.print()
    print(f"wrote {png}")
    return ck.result(png, errors={f"{k[0]}@{k[1]:g}": v for k, v in err.items()})


if __name__ == "__main__":
    main()
