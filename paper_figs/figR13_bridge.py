"""Richardson (1995) box against coagulation: the "bridge to coagulation" (R95 §3, eqs. 29-31).

Model (i) (spheres of fixed radius, constant speed v0): the box, the binned engine of this package
(``jaxcoag.evolve`` with ``jaxcoag.Binned`` and ``kernels.Constant(alpha V)``) and the discrete coagulation
equation over k-mers (R29, exact for integer masses) with the constant kernel alpha = sigma<v>/V =
pi (2R)^2 (4/3) v0 / L^3, side by side with (R30) N(t) = N0/(1 + alpha N0 t/2) and (R31)
n_k = N0 f^2 (1-f)^(k-1). The kernel measured from the box's own collision log (K_ij = V c_ij / int N_i N_j dt,
one class per number of member spheres) must equal alpha V for every class pair within its Poisson error.
Models (iii) (rigid sticking aggregates) and (iv) (threshold sticking / bouncing; full mode only): the
kernel measured from the box's log over the classes 1, 2, 3-4, 5-8, ... m0, then the k-mer equation and
the binned engine (a ``ClassKernel``: piecewise constant over the classes) started from the box's spectrum.
The measured kernel is a time average over the run (the aggregate models may cool as they grow), hence the
loose band of their checks.

Panels, one row per model: N(t) of box, binned, k-mer equation and (R30) (models iii/iv: (R30) with the
measured monomer rate a_11); the spectrum (model i: n_k at the last output: box histogram, k-mer equation,
(R31), binned engine as its number per bin divided by the integers in the bin; iii/iv: particles per mass
class at T/4 and T); the measured kernel over class pairs (model i: K_ij / (alpha V) with 1-sigma Poisson
bars; iii/iv: K_ij / K_11 for the classes i of k = 1, 2, 3-4).

Checks: measured K_11, K_12, K_22 within 3 Poisson sigma of alpha V (sigma = alpha V / sqrt(mu), mu = alpha E
the expected count over the measured exposure E); binned and k-mer N(t) vs (R30) to 1e-6 and the k-mer
n_k vs (R31) (k <= 10) to 1e-6 N0; the box N(T) within 3 sigma + 1 % of (R30) (figR03's
Marcus-Lushnikov sigma); the chi^2 p-value of the box spectrum at T against (R31); the trapezoidal exposure
on the outputs within its error bound of the exact one; models iii/iv: N of the k-mer equation with the
measured kernel within 3 sqrt(N_C)/N + 5 % of the box at the first output with N <= N0/2 (tolerance: the
Poisson spread of the number of coagulations plus the piecewise-constant class approximation), the binned
engine (20 bins/decade) within 2 % of the k-mer equation at that time and its mass drift below 1e-12. At T the
binned engine differs from the k-mer equation by ~1 % in model iv but ~15 % in model iii at any resolution
(the runaway tail: with the measured kernel growing with mass, the k-mer equation has lost 34 % of the mass
beyond its cut k = N0 by T in model iii, the binned engine keeps it up to 2 N0 m0); printed as info, as is the
lost mass fraction.
Quick mode: model (i), N0 = 200, seed 1; full mode: N0 = 1000 (model i) and models (iii), (iv) with
N0 = 500 (``--n-agg``; box side 10 (N0/1000)^(1/3) keeps R95's number density), seed 1, v0 = 13, T = 8.2.
Run: python paper_figs/figR13_bridge.py [--quick] [--out DIR] [--n-agg N] [--n-i N]
"""

import math
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402
from figR03_model_i import _ML_SIG, _ML_TAU, _chi2_p  # noqa: E402  (R95 Fig. 3's spread table and chi^2 test)


def _binned_per_k(edges, n_bin):
    """Binned numbers per bin divided by the integers k in each bin [lo, hi): (k centres, n per k)."""
    import numpy as np

    lo, hi = np.ceil(edges[:-1] - 1e-9), np.ceil(edges[1:] - 1e-9)
    nint = hi - lo
    ok = nint > 0
    kc = np.sqrt(np.maximum(lo, 1) * np.maximum(hi - 1, 1))
    return kc[ok], n_bin[ok] / nint[ok]


def main(argv=None):
    def extra(p):
        p.add_argument("--n-agg", type=int, default=500, help="N0 of models iii/iv in full mode (default 500)")
        p.add_argument("--n-i", type=int, default=1000, help="N0 of model i in full mode (default 1000)")

    args = _common.parse_args(argv, __doc__, extra=extra)
    jax = _common.enable_x64()
    import jax.numpy as jnp
    import numpy as np

    from jaxcoag.aggregates import rigid
    from jaxcoag.aggregates.rigid import bridge

    plt = _common.pyplot()
    v0, T, seed = 13.0, 8.2, 1
    n0 = 200 if args.quick else int(args.n_i)
    t_out = np.linspace(0.0, T, 42 if args.quick else 83)
    wall = {}
    ck = _common.Checks(f"R95 box vs coagulation (model i N0 = {n0}"
                        f"{'' if args.quick else f', models iii/iv N0 = {args.n_agg}'})")

    # ---------------------------------------------------------------- model (i): constant kernel
    w0 = time.time()
    box = rigid.box_model("i", n0=n0, v0=v0, key=jax.random.key(seed))
    res = rigid.run(box, jnp.asarray(t_out))
    wall["box i"] = time.time() - w0
    alpha, V = box.alpha, float(box.L) ** 3
    w0 = time.time()
    c = bridge.compare_model_i(res, kmax=min(n0, 300))
    mk = bridge.measured_kernel(res)
    mo = bridge.measured_kernel(res, mk.edges, method="outputs")
    wall["bridge i"] = time.time() - w0
    for i, j in ((0, 0), (0, 1), (1, 1)):
        cnt, mu = int(mk.counts[i, j]), float(alpha * mk.exposure[i, j])  # observed and expected (K = alpha V)
        ck.add(f"model i: K_{i + 1}{j + 1} / (alpha V) (c = {cnt}, mu = {mu:.1f}; tol 3/sqrt(mu))",
               mk.K[i, j] / (alpha * V), 1.0, 3.0 / math.sqrt(max(mu, 1.0)))
    ck.add("model i: max |N_binned / N_R30 - 1|", np.max(np.abs(c["N_binned"] / c["N_R30"] - 1)), 0.0, 1e-6,
           absolute=True)
    ck.add("model i: max |N_kmer / N_R30 - 1|", np.max(np.abs(c["N_smol"] / c["N_R30"] - 1)), 0.0, 1e-6,
           absolute=True)
    ck.add("model i: max |n_k(kmer) - n_k(R31)| / N0, k <= 10",
           np.max(np.abs(c["n_smol"][:, :10] - c["n_R31"][:, :10])) / n0, 0.0, 1e-6, absolute=True)
    tau = 0.5 * alpha * n0 * T
    sig = float(np.interp(tau, _ML_TAU, _ML_SIG)) * math.sqrt(1000.0 / n0 * 3.0)
    ck.add(f"model i: N_box(T) / N_R30(T) (tol 3 sigma + 1 %, tau = {tau:.2f})", c["N_box"][-1] / c["N_R30"][-1], 1.0,
           3 * sig + 0.01)
    kk = min(n0, 300)
    p31 = _chi2_p(c["n_box"][-1], c["n_R31"][-1][:kk])
    ck.add(f"model i: chi^2 p of box n_k(T) vs R31 = {p31:.3g} (> 1e-3)", min(p31, 1e-3), 1e-3, 0.0, absolute=True)
    de = np.abs(mo.exposure - mk.exposure)[:2, :2]
    excess = max(float(np.max(de - mo.exposure_err[:2, :2])), 0.0)
    ck.add("model i: excess of |E_trap - E_exact| over its bound, k <= 2", excess, 0.0, 0.0, absolute=True)
    ck.add("model i: trapezoid vs exact exposure E_11 (info)", mo.exposure[0, 0] / mk.exposure[0, 0], 1.0, 0.05,
           counts=False)
    rows = [("i", res, c, mk)]

    # ---------------------------------------------------------------- models (iii), (iv): measured kernel
    if not args.quick:
        n1 = int(args.n_agg)
        L1 = 10.0 * (n1 / 1000.0) ** (1.0 / 3.0)
        eng = rigid.RigidBox(cell_capacity=64, neighbors=64)
        for model in ("iii", "iv"):
            w0 = time.time()
            b = rigid.box_model(model, n0=n1, box=L1, v0=v0, key=jax.random.key(seed))
            r = rigid.run(b, jnp.asarray(t_out), engine=eng)
            wall[f"box {model}"] = time.time() - w0
            w0 = time.time()
            cm = bridge.compare_measured(r, kmax=n1, bins_per_decade=20.0)
            wall[f"bridge {model}"] = time.time() - w0
            h = int(np.argmax(cm["N_box"] <= 0.5 * n1))  # first output with N <= N0/2
            nh = cm["N_box"][h]
            ck.add(f"model {model}: N_kmer / N_box at t = {cm['t'][h]:.2f} (N_box <= N0/2; tol 3 sqrt(N_C)/N + 5 %)",
                   cm["N_smol"][h] / nh, 1.0, 3 * math.sqrt(n1 - nh) / nh + 0.05)
            ck.add(f"model {model}: N_kmer(T) / N_box(T) (info)", cm["N_smol"][-1] / cm["N_box"][-1], 1.0,
                   3 * math.sqrt(n1 - cm["N_box"][-1]) / cm["N_box"][-1] + 0.05, counts=False)
            # binned (20 bins/decade) vs k-mer equation: N(T) ratio 1.055, 1.033, 1.008, 0.9995 at 5, 10, 20, 40
            # bins/decade in model iv; in model iii equal to 1 % up to t ~ 4 but 0.85 at T at any resolution
            # (the runaway tail: the k-mer equation loses 34 % of the mass beyond its cut k = N0 by T in model iii,
            # the binned engine keeps it up to 2 N0 m0)
            ck.add(f"model {model}: N_binned / N_kmer at t = {cm['t'][h]:.2f} (20 bins/decade)",
                   cm["N_binned"][h] / cm["N_smol"][h], 1.0, 0.02)
            ck.add(f"model {model}: N_binned(T) / N_kmer(T) (info)", cm["N_binned"][-1] / cm["N_smol"][-1], 1.0, 0.2,
                   counts=False)
            ck.add(f"model {model}: binned engine max |mass drift|", float(np.max(np.abs(cm["binned"]["mass_drift"]))),
                   0.0, 1e-12, absolute=True)
            ck.add(f"model {model}: k-mer mass fraction beyond k = N0 at T (info)", float(cm["smol"]["lost"][-1]), 0.0,
                   1.0, absolute=True, counts=False)
            ck.add(f"model {model}: measured K_11 / (sigma<v>: alpha V of v0) (info)",
                   cm["mk"].K[0, 0] / (b.alpha * L1**3), 1.0, 1.0, counts=False)
            rows.append((model, r, cm, cm["mk"]))

    # ---------------------------------------------------------------- figure
    fig, ax = plt.subplots(len(rows), 3, figsize=(14, 4.0 * len(rows)), squeeze=False)
    for row, (model, r, cc, m) in enumerate(rows):
        a = ax[row, 0]
        a.plot(cc["t"], cc["N_box"], "ko", ms=3, label="box")
        if np.all(np.isfinite(cc["N_binned"])):
            a.plot(cc["t"], cc["N_binned"], "C0-", lw=2, alpha=0.6, label="binned engine")
        a.plot(cc["t"], cc["N_smol"], "C1--", label="k-mer equation (R29)")
        a.plot(cc["t"], cc["N_R30"], "k:", label="(R30)" + (" with measured $a_{11}$" if model != "i" else ""))
        a.set_xlabel("t")
        a.set_ylabel("N")
        a.legend(fontsize=8)
        a.set_title(f"({model}) number of particles", fontsize=10)
        b = ax[row, 1]
        if model == "i":
            nb = cc["n_box"][-1]
            kmx = int(max(np.max(np.nonzero(nb)[0]) + 2, 10))
            k = np.arange(1, kmx + 1)
            b.bar(k, nb[:kmx], width=1.0, color="0.8", edgecolor="k", label="box")
            b.plot(k, cc["n_smol"][-1][:kmx], "C1-", label="k-mer equation")
            b.plot(k, cc["n_R31"][-1][:kmx], "k:", label="(R31)")
            kc, nk = _binned_per_k(cc["edges"], cc["bin_binned"][-1])
            sel = kc <= kmx
            b.plot(kc[sel], nk[sel], "C0s", ms=4, label="binned / integers in bin")
            b.set_yscale("log")
            b.set_ylim(0.3 * min(1.0, float(np.min(nb[nb > 0]))), None)
            b.set_xlabel("m / $m_0$")
            b.set_ylabel("$n_k$")
            b.set_title(f"({model}) spectrum at t = {cc['t'][-1]:g}", fontsize=10)
        else:  # particles per class 1, 2, 3-4, 5-8, ... (sparse at late times)
            ce = m.edges
            kk = np.arange(1, cc["n_box"].shape[1] + 1)
            cls = np.clip(np.searchsorted(ce, kk, side="right") - 1, 0, ce.size - 2)
            lo = ce[:-1] + 0.5
            for it, sty in ((len(cc["t"]) // 4, "C2"), (len(cc["t"]) - 1, "C3")):
                nbx = np.bincount(cls, weights=cc["n_box"][it], minlength=ce.size - 1)
                nsm = np.bincount(cls, weights=cc["n_smol"][it], minlength=ce.size - 1)
                b.plot(lo, nbx, sty + "o", ms=5, label=f"box, t = {cc['t'][it]:.2f}")
                b.plot(lo, nsm, sty + "-", label="k-mer equation")
            b.set_xscale("log")
            b.set_yscale("symlog", linthresh=0.1)
            b.set_ylim(0.0, None)
            b.set_xlabel("class (lowest k: 1, 2, 3-4, 5-8, ...)")
            b.set_ylabel("particles per class")
            b.set_title(f"({model}) spectrum in mass classes", fontsize=10)
        b.legend(fontsize=8)
        d = ax[row, 2]
        C = min(m.K.shape[0], 8)
        if model == "i":
            x, y, e, lab = [], [], [], []
            for i in range(min(C, 4)):
                for j in range(i, min(C, 4)):
                    if m.counts[i, j] >= 3:
                        x.append(len(x))
                        y.append(m.K[i, j] / (alpha * V))
                        e.append(m.sigma[i, j] / (alpha * V))
                        lab.append(f"{i + 1},{j + 1}")
            d.errorbar(x, y, yerr=e, fmt="ko", ms=4)
            d.axhline(1.0, color="k", ls=":")
            d.set_xticks(x, lab)
            d.set_xlabel("class pair (k_i, k_j)")
            d.set_ylabel(r"$K_{ij} / (\alpha V)$")
        else:
            lo = m.edges[:-1] + 0.5
            for i in range(min(3, C)):
                ok = m.counts[i, :C] >= 1
                hi = int(m.edges[i + 1] - 0.5)
                lab = f"i: k = {int(lo[i])}" + (f"-{hi}" if hi > int(lo[i]) else "")
                d.errorbar(lo[:C][ok], m.K[i, :C][ok] / m.K[0, 0], yerr=m.sigma[i, :C][ok] / m.K[0, 0], fmt="o-", ms=4,
                           label=lab)
            d.set_xscale("log")
            d.set_yscale("log")
            d.set_xlabel("class j (lowest k)")
            d.set_ylabel(r"$K_{ij} / K_{11}$")
            d.legend(fontsize=8)
        d.set_title(f"({model}) kernel measured from the collision log", fontsize=10)
    fig.suptitle(f"Richardson (1995) box vs coagulation equation, v0 = {v0:g}", fontsize=11)
    fig.tight_layout()
    png = _common.savefig(fig, args, "figR13_bridge")
    ck.print()
    for model, r, cc, m in rows:
        idx = np.unique(np.linspace(0, len(cc["t"]) - 1, 5).astype(int))
        print(f"model {model}: t      {np.array2string(cc['t'][idx], precision=2)}")
        print(f"model {model}: N box  {np.array2string(cc['N_box'][idx], precision=1)}")
        print(f"model {model}: binned {np.array2string(cc['N_binned'][idx], precision=3)}")
        print(f"model {model}: k-mer  {np.array2string(cc['N_smol'][idx], precision=3)}")
        print(f"model {model}: R30    {np.array2string(cc['N_R30'][idx], precision=3)}")
        print(f"model {model}: n_k(T) box   k=1..8 {np.array2string(cc['n_box'][-1][:8], precision=1)}")
        print(f"model {model}: n_k(T) k-mer k=1..8 {np.array2string(cc['n_smol'][-1][:8], precision=2)}")
        if model == "i":
            print(f"model {model}: n_k(T) R31   k=1..8 {np.array2string(cc['n_R31'][-1][:8], precision=2)}")
        C = min(m.K.shape[0], 4)
        print(f"model {model}: counts c_ij (first {C} classes)\n{m.counts[:C, :C]}")
        print(f"model {model}: K_ij / (alpha V of model i) \n{np.array2string(m.K[:C, :C] / (alpha * V), precision=3)}")
        print(f"model {model}: sigma_ij / (alpha V)\n{np.array2string(m.sigma[:C, :C] / (alpha * V), precision=3)}")
    print("wall times [s] (incl. compilation): " + ", ".join(f"{k} {v:.1f}" for k, v in wall.items()))
    print(f"wrote {png}")
    return ck.result(png, t=c["t"], N_box=c["N_box"], N_binned=c["N_binned"], N_smol=c["N_smol"], N_R30=c["N_R30"],
                     K=mk.K, sigma=mk.sigma, counts=mk.counts, wall=wall)


if __name__ == "__main__":
    main()
