"""Wada et al. (2007) Fig. 10: number of monomers N of 2-D BCCAs against their gyration radius r_g/r1.

Mean +- 1 sigma of r_g/r1 (eq. 50) over an ensemble of BCCAs per size (``jaxcoag.aggregates.contact.bcca``, bonds at
the JKR equilibrium 2 r1 - delta_0 of ice), the paper's fit N = 1.37 (r_g/r1)^1.57 (eq. 53, from 10^4 BCCAs up to
N ~ 2e5) and our least-squares fit (log r_g regressed on log N, N = 8 and up). One pass builds ``count`` aggregates of
the largest size; the 2^l-monomer clusters met on the way are independent BCCAs of 2^l monomers, so every smaller size
has more samples. Quick: N up to 2^9, 5 aggregates of 512 (checks D = 1.57 +- 0.1, k = 1.37 +- 25 %); full: N up to
2^14, 20 of 2^14 (D +- 0.05, k +- 15 %).
Run: python paper_figs/figW10_bcca_size.py [--quick] [--out DIR]
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402


def main(argv=None):
    args = _common.parse_args(argv, __doc__)
    jax = _common.enable_x64()
    import numpy as np

    from jaxcoag.physics.wada07 import wada_bcca_rg
    from jaxcoag.aggregates.contact import analysis, materials, structures

    plt = _common.pyplot()
    n_max, count = (2**9, 5) if args.quick else (2**14, 20)
    radii = structures.bcca_gyration_radii(n_max, count, jax.random.key(10), dim=2, material=materials.ice())
    N = np.array([n for n in sorted(radii) if n >= 8])
    mean = np.array([radii[n].mean() for n in N])
    sig = np.array([radii[n].std() for n in N])
    k, D = (float(v) for v in analysis.fractal_fit(N, mean))

    ck = _common.Checks("Wada et al. 2007 Fig. 10 (2-D BCCA size law, eq. 53)")
    ck.add("fractal dimension D", D, 1.57, 0.1 if args.quick else 0.05, absolute=True)
    ck.add("prefactor k", k, 1.37, 0.25 if args.quick else 0.15)
    for n, m, s in zip(N, mean, sig):
        ck.add(f"<r_g/r1>(N={n}) [{radii[n].size} BCCAs, sigma {s:.2f}]", m, float(wada_bcca_rg(n)), 0.12)

    fig, ax = plt.subplots(figsize=(5.5, 4.5))
    ax.errorbar(mean, N, xerr=sig, fmt="o", mfc="none", color="k", ms=5, capsize=2,
                label="this code: mean $\\pm1\\sigma$")
    g = np.geomspace(1.0, mean[-1] * 1.5, 100)
    ax.plot(g, 1.37 * g**1.57, "k-", lw=1, label=r"eq. 53: $N = 1.37\,(r_g/r_1)^{1.57}$")
    ax.plot(g, k * g**D, "C3--", lw=1, label=rf"fit: $N = {k:.2f}\,(r_g/r_1)^{{{D:.3f}}}$")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(r"$r_g/r_1$")
    ax.set_ylabel(r"$N_{\rm total}$")
    ax.set_title(f"Wada et al. 2007 Fig. 10: 2-D BCCAs ({count} of N = {n_max} per pass)", fontsize=10)
    ax.legend(fontsize=8, loc="upper left")
    png = _common.savefig(fig, args, "figW10_bcca_size")
    ck.print()
    print(f"fit: N = {k:.4f} (r_g/r1)^{D:.4f}   (paper: N = 1.37 (r_g/r1)^1.57)")
    print(f"wrote {png}")
    return ck.result(png, prefactor=k, exponent=D)


if __name__ == "__main__":
    main()
