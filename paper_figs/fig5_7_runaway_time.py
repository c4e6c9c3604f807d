"""Thesis Fig. 5.7: runaway time t_R against log N for K = (m_i m_j)^nu, nu = 2 and 3 (N up to 1e160).

Constant-V, distribution zoom (``grouping="distribution"``), monodisperse start, Table-5.1 units (K00 = 1).
t_R = first time with M_L1/M_L2 >= 1e4 (M_L2 = second-largest *particle*), or the time a single particle is
left (spec §4.7 F5.7, §6.12). The engine has no stop predicate, so t_R is found from snapshots in two passes
with the *same* keys (a trajectory is a function of the key only, spec §3.9): pass 1 on a log grid around
the merger-model estimate, pass 2 on a fine grid inside the bracketing interval of pass 1 (resolution
~0.3 %). N values are vmapped together with the runs (one compilation per nu).
Expected: t_R decreases with N; local slopes d ln t_R / d ln ln N decline towards 1 - nu (Malyshkin &
Goodman 2001, eq. 5.19 t_R ~ (ln N)^{1-nu}).
Check points: t_R(N) strictly decreasing over the N grid (means over runs); the slope over the largest-N
interval is more negative than over the smallest; at N <= 1e5 the ensemble mean agrees with the exact
ungrouped-DSMC anchors of spec §4.7 (nu = 2: 0.268, 0.194, 0.143, 0.1198 at N = 300, 1e3, 1e4, 1e5;
nu = 3: 0.0817, 0.0553, 0.0358, 0.0247) within 3 combined s.e. + 5 % (+ the documented f_eps bias
allowance in quick mode, see below).

Parameters: thesis Ng* = 6e4 (nu = 2), 3e5 (nu = 3), f_eps = 1e-3, 100 -> 10 runs. Quick: Ng* = 200, f_eps = 1e-2,
N in {300, 1e3, 1e4, 1e6} (nu = 2) / {300, 1e3, 1e4} (nu = 3), 4 runs per N, event cap 1e4 (a grid reaching
N = 1e10 with Ng* = 300 did not finish within 4 min on this machine). Large N
needs a large Ng*: the monomer self-collision time t_11 ~ 1/w0 ~ 1/Ng* must be << t_R (thesis §5.3.3); with
Ng* = 100 a quick try gave no event before t_R at N = 1e160 (nu = 2) / 1e20 (nu = 3) and hit the event cap at
N = 1e20 (nu = 2). The slope-steepening check is made only in full mode: the exact anchors themselves give
local slopes -1.69 (300 -> 1e3) and -0.79 (1e4 -> 1e5) for nu = 2, i.e. the slope first *flattens*, so
"last slope < first slope" can only hold on the thesis grid reaching 1e160. (the larger f_eps coarsens the heavy-body accretion; the
larger Ng*/smaller f_eps of the full mode cost ~1e5-1e6 events per run at N = 1e160).

Run:   python paper_figs/fig5_7_runaway_time.py --quick  (~2-4 min on 2 busy cores)
Full:  python paper_figs/fig5_7_runaway_time.py          (Ng* = 6e4 / 3e5 and f_eps = 1e-3, 10 runs, thesis N grid:
       far beyond this 2-core machine -- days; not run here). Intermediate: --ng 2000 --feps 1e-3 --runs 10.
"""

import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402
from fig5_3_sum_fixedNp import in_range  # noqa: E402
from fig5_6_runaway_stats import largest_two  # noqa: E402

ANCHORS = {  # spec §4.7 F5.7: exact ungrouped DSMC, 40 runs, mean and s.e.
    2: {300: (0.268, 0.006), 1e3: (0.194, 0.004), 1e4: (0.143, 0.002), 1e5: (0.1198, 0.0013)},
    3: {300: (0.0817, 0.0044), 1e3: (0.0553, 0.0021), 1e4: (0.0358, 0.0010), 1e5: (0.0247, 0.0006)},
}
N_THESIS = (300.0, 1e5, 1e10, 1e20, 1e80, 1e160)
N_QUICK = {2: (300.0, 1e3, 1e4, 1e6), 3: (300.0, 1e3, 1e4)}


def _extra(p):
    p.add_argument("--ng", type=int, default=None, help="Ng* (default 6e4 for nu=2, 3e5 for nu=3; quick 200)")
    p.add_argument("--runs", type=int, default=None, help="runs per N (default 10; quick 6)")
    p.add_argument("--feps", type=float, default=None, help="f_eps (default 1e-3; quick 1e-2)")
    p.add_argument("--nus", type=str, default="2,3")
    p.add_argument("--max-events", type=int, default=None, help="event cap per run (default 2e6; quick 6e4)")
    p.add_argument("--seed", type=int, default=5007)


def t_estimate(n, nu):
    """Merger-model order of magnitude t_R ~ (ln N)^{1-nu}/(nu-1) (spec §4.7; prefactor unreliable)."""
    return math.log(n) ** (1.0 - nu) / (nu - 1.0)


def runaway_index(res, max_events):
    """(R, T) -> first snapshot index with M_L1/M_L2 >= 1e4 or one particle left (-1 if none / not real)."""
    import numpy as np

    l1, l2, _ = largest_two(res)
    lg = np.asarray(res.log_g)
    one = (np.asarray(res.n_species) == 1) & (np.max(np.where(np.asarray(res.valid), lg, -np.inf), -1) < 0.1)
    with np.errstate(divide="ignore"):          # l2 = 0 when a single species is left
        hit = (l1 / l2 >= 1e4) | one
    real = np.asarray(res.n_events_snap) < max_events
    hit = hit & real
    return np.where(hit.any(-1), hit.argmax(-1), -1)


def runaway_times(nu, n_grid, ng, runs, f_eps, seed, max_events, n_t=40):
    """Mean, s.e. and per-run t_R for each N (two-pass snapshot bracketing); returns dict."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from jaxcoag import kernels as K
    from jaxcoag import mc

    kern = K.PowerProduct(1.0, float(nu))
    n_arr = np.repeat(np.asarray(n_grid, float), runs)
    keys = jax.random.split(jax.random.key(seed + nu), n_arr.size)
    cap = 2 * ng

    def one(n, tt, k):
        return mc.run(kern, n_particles=n, t_out=tt, key=k, mode="const_v", grouping="distribution",
                      ns_target=ng, f_eps=f_eps, capacity=cap, max_events=max_events)

    f = jax.vmap(one)
    est = np.array([t_estimate(n, nu) for n in n_arr])
    g1 = est[:, None] * np.logspace(-1.3, 1.3, n_t)[None, :]
    r1 = f(jnp.asarray(n_arr), jnp.asarray(g1), keys)
    k1 = runaway_index(r1, max_events)
    print(f"  nu = {nu}: pass 1 done ({int(np.asarray(r1.n_events).max())} events max)", flush=True)
    lo = np.where(k1 > 0, g1[np.arange(n_arr.size), np.maximum(k1 - 1, 0)], 0.0)
    hi = np.where(k1 >= 0, g1[np.arange(n_arr.size), np.maximum(k1, 0)], g1[:, -1])
    g2 = lo[:, None] + (hi - lo)[:, None] * (np.arange(1, n_t + 1) / n_t)[None, :]
    r2 = f(jnp.asarray(n_arr), jnp.asarray(g2), keys)
    k2 = runaway_index(r2, max_events)
    ok = (k1 >= 0) & (k2 >= 0)
    prev = np.where(k2 > 0, g2[np.arange(n_arr.size), np.maximum(k2 - 1, 0)], lo)
    t_r = np.where(ok, 0.5 * (prev + g2[np.arange(n_arr.size), np.maximum(k2, 0)]), np.nan)
    t_r = t_r.reshape(len(n_grid), runs)
    ev = np.asarray(r1.n_events).reshape(len(n_grid), runs)
    return dict(N=np.asarray(n_grid), t_runs=t_r, mean=np.nanmean(t_r, 1),
                se=np.nanstd(t_r, 1, ddof=1) / np.sqrt(np.sum(np.isfinite(t_r), 1)),
                n_missing=np.sum(~np.isfinite(t_r), 1), events=ev.max(1),
                status=np.bitwise_or.reduce(np.asarray(r1.status).reshape(len(n_grid), runs), axis=1))


def main(argv=None):
    args = _common.parse_args(argv, __doc__, _extra)
    _common.enable_x64()
    import numpy as np

    plt = _common.pyplot()
    quick = args.quick
    runs = args.runs or (4 if quick else 10)
    f_eps = args.feps or (1e-2 if quick else 1e-3)
    max_events = args.max_events or (10000 if quick else 2000000)
    nus = [int(x) for x in args.nus.split(",")]
    ck = _common.Checks(f"Fig 5.7 (runaway time vs log N, {runs} runs per N)")
    fig, ax = plt.subplots(figsize=(5.8, 4.5))
    out = {}
    for nu in nus:
        ng = args.ng or (200 if quick else (60000 if nu == 2 else 300000))
        n_grid = N_QUICK[nu] if quick else N_THESIS
        r = runaway_times(nu, n_grid, ng, runs, f_eps, args.seed, max_events)
        out[nu] = r
        print(f"nu = {nu}: Ng* = {ng}, f_eps = {f_eps:g}, runs = {runs}")
        print("      N        t_R mean     s.e.   missing  max events  status")
        for i, n in enumerate(r["N"]):
            print(f"  {n:9.3g}  {r['mean'][i]:10.5g}  {r['se'][i]:8.2g}  {r['n_missing'][i]:4d}  {r['events'][i]:9d}"
                  f"  {int(r['status'][i])}")
        ck.add(f"nu={nu}: runs without t_R", float(r["n_missing"].sum()), 0.0, 0.0, absolute=True)
        lnln = np.log(np.log(r["N"]))
        lt = np.log(r["mean"])
        slopes = np.diff(lt) / np.diff(lnln)
        print(f"  local slopes d ln t_R / d ln ln N: {np.round(slopes, 3).tolist()} (asymptote 1 - nu = {1 - nu})")
        in_range(ck, f"nu={nu}: max step ln t_R(N_k+1)/t_R(N_k) (<0: decreasing)", float(np.max(np.diff(lt))),
                 -50.0, 0.0)
        if not quick:  # needs the thesis N grid (to 1e160); see docstring
            in_range(ck, f"nu={nu}: last slope - first slope (<0)", float(slopes[-1] - slopes[0]), -50.0, 0.0)
        for i, n in enumerate(r["N"]):
            if n in ANCHORS[nu]:
                a, se_a = ANCHORS[nu][n]
                tol = 3.0 * math.hypot(se_a, r["se"][i]) + 0.05 * a
                if quick:
                    tol += 0.05 * a  # f_eps = 1e-2 coarse heavy-body accretion (quick only)
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
