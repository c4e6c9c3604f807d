"""Thesis Fig. 5.7: runaway time t_R against log N for K = (m_i m_j)^nu, nu = 2 and 3 (N up to 1e160).

Constant-V, distribution zoom (``grouping="distribution"``), monodisperse start, Table-5.1 units (K00 = 1).
t_R = first time with M_L1/M_L2 >= 1e4 (M_L2 = second-largest *particle*), or the time a single particle is
left (spec §4.7 F5.7, §6.12): ``mc.run(..., stop=mc.Runaway(1e4))`` stops each run there and t_R is
``result.t_stop``. All (N, run) pairs are vmapped in one call per nu.
Expected: t_R decreases with N; local slopes d ln t_R / d ln ln N decline towards 1 - nu (Malyshkin &
Goodman 2001, eq. 5.19 t_R ~ (ln N)^{1-nu}).
Check points: t_R(N) strictly decreasing over the N grid (means over runs); every run reaches t_R; at
N <= 1e5 the ensemble mean agrees with the exact ungrouped-DSMC anchors of spec §4.7 (nu = 2: 0.268, 0.194,
0.143, 0.1198 at N = 300, 1e3, 1e4, 1e5; nu = 3: 0.0817, 0.0553, 0.0358, 0.0247) within 3 combined s.e. + 5 %
(+ 5 % for f_eps = 1e-2); on a grid reaching 1e80 the last local slope is within 40 % of 1 - nu [own]. The
spec's "last slope < first slope" is printed, not asserted: the exact anchors give a first slope (300 -> 1e5)
of -1.15 for nu = 2, already below the asymptote -1, so the asymptote is approached from above.

Known limitation of the distribution method at large N (measured, nu = 2, N = 1e20, Ng* = 200, f_eps = 1e-2,
4 runs): a group event moves a quantum of 2^z identical particles, so the rare upward jumps that seed the
runaway are sampled as if each bin held ~Ng*/N_b particles instead of N: t_R = 0.091 +- 0.009 (Ng* = 2000:
0.06), so t_R falls only slowly with N beyond ~1e5 (extrapolating the exact anchors with slope ~ -0.8 gives
~0.04-0.046 at 1e20). An engine-side zoom cap of the heaviest species (``jaxcoag.mc.grouping.zoom_cap_tail``,
``mc.run(..., tail_events=64)``, ``--tail-events 64`` here) gave 0.051 +- 0.003 (64 events) / 0.0495 +- 0.002 (256), but it also made the
subcritical product-kernel M_L1 of Fig. 5.6 45x too large at t = 0.9, so it is off by default. With the cap
(64), nu = 3 on the thesis grid gave 0.0760, 0.0260, 0.00918, 0.00407, 0.0031 +- 0.0012, 0.0050 +- 0.0023 at
N = 300 ... 1e160 (4 runs): not decreasing beyond 1e20 with Ng* = 200.

Parameters: thesis Ng* = 6e4 (nu = 2), 3e5 (nu = 3), f_eps = 1e-3, 100 -> 10 runs. Quick (test suite):
Ng* = 200, f_eps = 1e-2, 4 runs, N in {300, 1e3, 1e5, 1e20} for both nu (~3 min on 2 busy cores).
Default (non-quick): the thesis N grid to 1e160 with Ng* = 200, f_eps = 1e-2, 4 runs -- far fewer groups and
runs than the thesis (stated here); ~1e4-6e4 events per run at N >= 1e80. Larger settings: --ng 2000
--feps 1e-3 --runs 10.

Run:   python paper_figs/fig5_7_runaway_time.py --quick
Full:  python paper_figs/fig5_7_runaway_time.py [--ng 60000 --feps 1e-3 --runs 10 for the thesis settings]
"""

import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402
from fig5_3_sum_fixedNp import in_range  # noqa: E402

ANCHORS = {  # spec §4.7 F5.7: exact ungrouped DSMC, 40 runs, mean and s.e.
    2: {300: (0.268, 0.006), 1e3: (0.194, 0.004), 1e4: (0.143, 0.002), 1e5: (0.1198, 0.0013)},
    3: {300: (0.0817, 0.0044), 1e3: (0.0553, 0.0021), 1e4: (0.0358, 0.0010), 1e5: (0.0247, 0.0006)},
}
N_THESIS = (300.0, 1e5, 1e10, 1e20, 1e80, 1e160)
N_QUICK = {2: (300.0, 1e3, 1e5, 1e20), 3: (300.0, 1e3, 1e5, 1e20)}
ANCHOR_SLOPES = {2: "-1.69 (300->1e3), -1.06 (1e3->1e4), -0.79 (1e4->1e5)",
                 3: "-2.04 (300->1e3), -1.51 (1e3->1e4), -1.66 (1e4->1e5)"}


def _extra(p):
    p.add_argument("--ng", type=int, default=None, help="Ng* (default 200; thesis 6e4 for nu=2, 3e5 for nu=3)")
    p.add_argument("--runs", type=int, default=None, help="runs per N (default 4; thesis 100 -> 10)")
    p.add_argument("--feps", type=float, default=None, help="f_eps (default 1e-2; thesis 1e-3)")
    p.add_argument("--nus", type=str, default="2,3")
    p.add_argument("--max-events", type=int, default=None, help="event cap per run (default 2e6; quick 1e5)")
    p.add_argument("--seed", type=int, default=5007)
    p.add_argument("--tail-events", type=float, default=0.0,
                   help="EXPERIMENTAL zoom cap of the heaviest species (mc.run tail_events; default 0 = off)")


def t_estimate(n, nu):
    """Merger-model order of magnitude t_R ~ (ln N)^{1-nu}/(nu-1) (spec §4.7; prefactor unreliable)."""
    return math.log(n) ** (1.0 - nu) / (nu - 1.0)


def runaway_times(nu, n_grid, ng, runs, f_eps, seed, max_events, tail_events=0.0):
    """Mean, s.e. and per-run t_R for each N; returns dict.

    One vmapped call over (N, run): ``mc.run(..., stop=mc.Runaway(1e4))`` stops each run at the
    first event after which M_L1/M_L2 >= 1e4 or a single particle is left; t_R = ``t_stop``.
    Runs that end otherwise (event cap) count as missing.
    """
    import jax
    import jax.numpy as jnp
    import numpy as np

    from jaxcoag import kernels as K
    from jaxcoag import mc

    kern = K.PowerProduct(1.0, float(nu))
    n_arr = np.repeat(np.asarray(n_grid, float), runs)
    keys = jax.random.split(jax.random.key(seed + nu), n_arr.size)
    t_end = jnp.array([10.0 * t_estimate(300.0, nu)])  # far beyond t_R(300); runs stop at t_R

    def one(n, k):
        return mc.run(kern, n_particles=n, t_out=t_end, key=k, mode="const_v", grouping="distribution",
                      ns_target=ng, f_eps=f_eps, capacity=2 * ng, max_events=max_events,
                      stop=mc.Runaway(1e4), tail_events=tail_events)

    r = jax.vmap(one)(jnp.asarray(n_arr), keys)
    stopped = (np.asarray(r.status) & mc.STATUS.STOPPED) != 0
    t_r = np.where(stopped, np.asarray(r.t_stop), np.nan).reshape(len(n_grid), runs)
    ev = np.asarray(r.n_events).reshape(len(n_grid), runs)
    n_ok = np.sum(np.isfinite(t_r), 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.nanmean(t_r, 1)
        se = np.nanstd(t_r, 1, ddof=1) / np.sqrt(n_ok)
    return dict(N=np.asarray(n_grid), t_runs=t_r, mean=mean, se=se, n_missing=runs - n_ok,
                events=ev.max(1), events_mean=ev.mean(1), merges=np.asarray(r.n_merge).reshape(len(n_grid), runs).max(1),
                status=np.bitwise_or.reduce(np.asarray(r.status).reshape(len(n_grid), runs), axis=1))


def main(argv=None):
    args = _common.parse_args(argv, __doc__, _extra)
    _common.enable_x64()
    import numpy as np

    plt = _common.pyplot()
    quick = args.quick
    runs = args.runs or 4
    f_eps = args.feps or 1e-2
    max_events = args.max_events or (100000 if quick else 2000000)
    nus = [int(x) for x in args.nus.split(",")]
    ck = _common.Checks(f"Fig 5.7 (runaway time vs log N, {runs} runs per N)")
    fig, ax = plt.subplots(figsize=(5.8, 4.5))
    out = {}
    for nu in nus:
        ng = args.ng or 200
        n_grid = N_QUICK[nu] if quick else N_THESIS
        r = runaway_times(nu, n_grid, ng, runs, f_eps, args.seed, max_events, args.tail_events)
        out[nu] = r
        print(f"nu = {nu}: Ng* = {ng}, f_eps = {f_eps:g}, runs = {runs}")
        print("      N        t_R mean     s.e.  missing  mean/max events   exact DSMC (spec)   merger model"
              "  (ln N)^(1-nu)/(nu-1)")
        for i, n in enumerate(r["N"]):
            a = ANCHORS[nu].get(float(n))
            a_txt = f"{a[0]:.4g} +- {a[1]:.2g}" if a else "-"
            print(f"  {n:9.3g}  {r['mean'][i]:10.5g}  {r['se'][i]:8.2g}  {r['n_missing'][i]:4d}  "
                  f"{r['events_mean'][i]:9.0f}/{r['events'][i]:<9d}  {a_txt:>17}   {t_estimate(n, nu):10.4g}")
        ck.add(f"nu={nu}: runs without t_R", float(r["n_missing"].sum()), 0.0, 0.0, absolute=True)
        lnln = np.log(np.log(r["N"]))
        lt = np.log(r["mean"])
        slopes = np.diff(lt) / np.diff(lnln)
        print(f"  local slopes d ln t_R / d ln ln N: {np.round(slopes, 3).tolist()} (asymptote 1 - nu = {1 - nu}; "
              f"exact-DSMC anchors: {ANCHOR_SLOPES[nu]})")
        in_range(ck, f"nu={nu}: max step ln t_R(N_k+1)/t_R(N_k) (<0: decreasing)", float(np.max(np.diff(lt))),
                 -50.0, 0.0)
        if r["N"][-1] >= 1e80:
            # spec §4.7 asks "last slope < first slope"; the exact anchors themselves give a first slope
            # (300 -> 1e5) of -1.15 (nu=2) below the asymptote -1, so the asymptote is approached from
            # above and that inequality is not asserted (printed only); instead the last slope must be
            # within 40 % [own tolerance] of 1 - nu.
            print(f"  last slope - first slope = {slopes[-1] - slopes[0]:.3f} (spec: < 0; see docstring)")
            in_range(ck, f"nu={nu}: last slope (N>=1e80) in (1-nu) x [0.6, 1.4]", float(slopes[-1]),
                     1.4 * (1 - nu), 0.6 * (1 - nu))
        for i, n in enumerate(r["N"]):
            if n in ANCHORS[nu]:
                a, se_a = ANCHORS[nu][n]
                tol = 3.0 * math.hypot(se_a, r["se"][i]) + 0.05 * a
                if f_eps > 2e-3:
                    tol += 0.05 * a  # f_eps = 1e-2: coarse heavy-body accretion
                ck.add(f"nu={nu}: t_R(N={n:g}) vs exact DSMC", r["mean"][i], a, tol / a)
        eb = ax.errorbar(np.log10(r["N"]), r["mean"], yerr=r["se"], fmt="o-", ms=4, capsize=2, label=rf"$\nu = {nu}$")
        an = sorted(ANCHORS[nu])
        ax.plot(np.log10(an), [ANCHORS[nu][n][0] for n in an], "k+", ms=8)
        xx = np.logspace(np.log10(np.log10(300)), np.log10(160), 50)
        ax.plot(xx, [t_estimate(10 ** x, nu) for x in xx], ":", color=eb[0].get_color(), lw=0.8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(r"$\log_{10} N$")
    ax.set_ylabel(r"$t_R$")
    ax.set_title("Ormel 2008 Fig. 5.7: runaway time, K = (m_i m_j)^nu, distribution method\n"
                 "+: exact ungrouped DSMC (spec), dotted: (ln N)^(1-nu)/(nu-1)", fontsize=9)
    ax.legend(fontsize=8)
    png = _common.savefig(fig, args, "fig5_7_runaway_time")
    ck.print()
    print(f"wrote {png}")
    return ck.result(png, runaway={nu: {"N": r["N"].tolist(), "mean": r["mean"].tolist(), "se": r["se"].tolist()}
                                   for nu, r in out.items()})


if __name__ == "__main__":
    main()
