"""Richardson (1995) Fig. 3: model (i), spheres with a constant coagulation kernel, against Smoluchowski.

Model (i) of R95 Table I: 1000 spheres of radius 0.1 in a periodic box of side 10, constant speed v0, a
merged pair becomes one sphere of radius 0.1 at the mass-weighted centre moving at v0 along the summed
momentum. The kernel is then constant, alpha = pi (2R)^2 (4/3) v0 / L^3 (R95 §3), and the coagulation
equation (R29) gives N(t) = N0 / (1 + alpha N0 t / 2) (R30) and n_k = N0 f^2 (1 - f)^(k-1), f = N/N0 (R31).
R95 does not print v0; its t_1/2 suggests v0 ~ 13 (spec A8), used here, so T = 8.2 is tau = alpha N0 T / 2 = 8.9.

Panels: (a) N(t) (mean and standard deviation of the mean over the seeds) with (R30), N_C (dotted), N_C1
(dashed) and the long-dashed lines crossing at (t_1/2, N0/2); (b) maximum mass / m0; (c, d) mass spectra at
t = 1.6 and 8.2 with (R31). Checks: N(1.6), N(8.2) within 3 sigma + 1 % of (R30), where sigma is the
Marcus-Lushnikov spread of the spec (2000 realisations of N0 = 1000, mean of 3 runs) scaled to this N0 and
number of seeds; N + N_C = N0 and N_C = N_C1 exactly (R95 Fig. 3a); the chi^2 p-value of the spectra.
Full mode: N0 = 1000, seeds 1-3 (the paper's setting); quick mode: N0 = 200, seed 1.
Run: python paper_figs/figR03_model_i.py [--quick] [--out DIR]
"""

import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402

# sigma / N_th of the mean of 3 runs of N0 = 1000 (spec A9, 2000 Marcus-Lushnikov realisations)
_ML_TAU = (0.25, 0.5, 1.0, 2.0, 4.0, 9.0)
_ML_SIG = (0.008, 0.011, 0.014, 0.018, 0.024, 0.033)


def _chi2_p(obs, exp):
    """p-value of chi^2 over k = 1..8 and the pooled tail (sparse tail bins pooled until E >= 5)."""
    import numpy as np
    from scipy import stats

    o = np.concatenate([obs[:8], [obs[8:].sum()]]).astype(float)
    e = np.concatenate([exp[:8], [exp[8:].sum()]])
    while len(e) > 2 and e[-1] < 5:
        o, e = np.concatenate([o[:-2], [o[-2:].sum()]]), np.concatenate([e[:-2], [e[-2:].sum()]])
    e = e * o.sum() / e.sum()
    return float(stats.chi2.sf(np.sum((o - e) ** 2 / e), max(len(o) - 2, 1)))


def main(argv=None):
    args = _common.parse_args(argv, __doc__)
    jax = _common.enable_x64()
    import jax.numpy as jnp
    import numpy as np

    from jaxcoag import analytic
    from jaxcoag.aggregates import rigid

    plt = _common.pyplot()
    n0, seeds = (200, (1,)) if args.quick else (1000, (1, 2, 3))
    v0, T = 13.0, 8.2
    t_out = np.unique(np.concatenate([np.linspace(0.41, T, 20), [1.6, T]]))
    runs = []
    for s in seeds:
        box = rigid.box_model("i", n0=n0, v0=v0, key=jax.random.key(s))
        runs.append(rigid.run(box, jnp.asarray(t_out)))
    alpha = box.alpha
    N = np.array([np.asarray(r.n_aggregates) for r in runs], float)
    NC = np.array([np.asarray(r.n_collisions) for r in runs])
    mm = np.array([np.asarray(r.max_mass) for r in runs])
    ns = len(seeds)
    Nbar = N.mean(0)
    Nerr = N.std(0, ddof=1) / math.sqrt(ns) if ns > 1 else np.zeros_like(Nbar)
    Nth = n0 / (1 + 0.5 * alpha * n0 * t_out)
    tau = 0.5 * alpha * n0 * t_out

    def sig(t):  # sigma of the mean of `ns` runs of N0 = n0, relative to N_th
        return float(np.interp(0.5 * alpha * n0 * t, _ML_TAU, _ML_SIG)) * math.sqrt(1000.0 / n0 * 3.0 / ns)

    ck = _common.Checks(f"R95 Fig. 3 (model i, N0 = {n0}, {ns} seed{'s' * (ns > 1)}, v0 = {v0:g})")
    ck.add("t_1/2 = 2/(alpha N0) [R95: 11.937/v0]", 2.0 / (alpha * n0) * n0 / 1000.0, 11.937 / v0, 1e-4, counts=False)
    spectra = {}
    for tt in (1.6, T):
        i = int(np.argmin(np.abs(t_out - tt)))
        ck.add(f"N(t={tt:g}) / N_R30 (tol 3 sigma + 1%)", Nbar[i] / Nth[i], 1.0, 3 * sig(tt) + 0.01)
        obs = sum(np.asarray(r.mass_spectrum(kmax=n0))[i] for r in runs).astype(float)
        f = Nbar[i] / n0
        k = np.arange(1, n0 + 1)
        exp = ns * n0 * f**2 * (1 - f) ** (k - 1)
        spectra[tt] = (obs / ns, exp / ns, f)
        ck.add(f"chi^2 p-value of n_k vs R31 at t={tt:g} (> 1e-3)", min(_chi2_p(obs, exp), 1e-3), 1e-3, 0.0,
               absolute=True)
    ck.add("max |N + N_C - N0| (R95 Fig. 3a)", np.max(np.abs(N + NC[..., 0] - n0)), 0.0, 0.0, absolute=True)
    ck.add("max |N_C - N_C1| (coagulation only)", np.max(np.abs(NC[..., 0] - NC[..., 1])), 0.0, 0.0, absolute=True)
    ck.add("(R31) = jaxcoag.analytic constant kernel, k = 3, t = 1.6",
           math.exp(float(analytic.log_nk("constant", 3, 1.6, coeff=alpha, n0=n0))),
           n0 * (1 / (1 + 0.8 * alpha * n0)) ** 2 * (1 - 1 / (1 + 0.8 * alpha * n0)) ** 2, 1e-12)
    ck.add(f"max mass / m0 at T (info; tau = {tau[-1]:.2f})", float(mm.mean(0)[-1]), float(mm.mean(0)[-1]), 0.0,
           counts=False)

    fig, ax = plt.subplots(2, 2, figsize=(10, 8))
    a = ax[0, 0]
    a.errorbar(t_out, Nbar, yerr=Nerr, fmt="o", color="k", ms=3, label="N (mean of seeds)")
    a.plot(t_out, NC[..., 0].mean(0), "k:", label="$N_C$")
    a.plot(t_out, NC[..., 1].mean(0), "k--", lw=0.8, label="$N_{C1}$")
    tt = np.linspace(0, T, 200)
    a.plot(tt, n0 / (1 + 0.5 * alpha * n0 * tt), "k-", label="(R30)")
    th = 2 / (alpha * n0)
    if th <= T:
        a.axvline(th, ls=(0, (8, 4)), color="gray")
    a.axhline(n0 / 2, ls=(0, (8, 4)), color="gray")
    a.set_xlabel("t")
    a.set_ylabel("N")
    a.legend(fontsize=8)
    a.set_title("(a) particles and collisions", fontsize=10)
    b = ax[0, 1]
    b.plot(t_out, mm.mean(0), "ko-", ms=3)
    b.set_xlabel("t")
    b.set_ylabel("maximum mass / $m_0$")
    b.set_title("(b) maximum mass", fontsize=10)
    for axx, tt_ in zip((ax[1, 0], ax[1, 1]), (1.6, T)):
        obs, exp, f = spectra[tt_]
        kk = np.arange(1, len(obs) + 1)
        kmax = int(max(np.max(np.nonzero(obs)[0]) + 2, 10))
        axx.bar(kk[:kmax], obs[:kmax], width=1.0, color="0.8", edgecolor="k")
        axx.plot(kk[:kmax], exp[:kmax], "k-", label=f"(R31), f = {f:.3f}")
        axx.set_yscale("log")
        axx.set_xlabel("m / $m_0$")
        axx.set_ylabel("$n_k$")
        axx.legend(fontsize=8)
        axx.set_title(f"({'c' if tt_ == 1.6 else 'd'}) spectrum at t = {tt_:g}", fontsize=10)
    fig.suptitle(f"Richardson (1995) Fig. 3: model (i), N0 = {n0}, v0 = {v0:g}", fontsize=11)
    fig.tight_layout()
    png = _common.savefig(fig, args, "figR03_model_i")
    ck.print()
    print(f"N(t) mean: {np.array2string(Nbar, precision=1)}")
    print(f"R30     : {np.array2string(Nth, precision=1)}")
    print(f"wrote {png}")
    return ck.result(png, n=Nbar, n_th=Nth, t=t_out)


if __name__ == "__main__":
    main()
