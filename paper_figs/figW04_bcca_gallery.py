"""Wada et al. (2007) Fig. 4: 2-D BCCAs of N = 8, 32, 128, 512 and 2048 monomers, drawn as disks to scale.

Each aggregate is built by random head-on sticking of two clusters, level by level (Wada et al. 2007 §4;
``jaxcoag.aggregates.contact.bcca``), with every bond at the JKR equilibrium 2 r1 - delta_0 of ice. The panels share
one length scale (r1 units). Printed beside the drawings: the gyration radius r_g/r1 (eq. 50) of each drawn aggregate
(one realisation, information only) and the mean over an ensemble against the paper's law N = 1.37 (r_g/r1)^1.57
(eq. 53: r_g/r1 = 3.08, 7.44, 17.99, 43.5, 105.2); the law is a fit over N = 8..2e5, so the ensemble means are
compared within 10 %. Counted checks also include the tree structure: N - 1 bonds, all at 2 r1 - delta_0, and no
other pair in contact.
Run: python paper_figs/figW04_bcca_gallery.py [--quick] [--out DIR]
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402

SIZES = (8, 32, 128, 512, 2048)


def main(argv=None):
    args = _common.parse_args(argv, __doc__)
    jax = _common.enable_x64()
    import numpy as np

    from jaxcoag.physics.wada07 import wada_bcca_rg
    from jaxcoag.aggregates.contact import materials, structures

    plt = _common.pyplot()
    from matplotlib.collections import EllipseCollection

    mat = materials.ice()
    r1 = float(mat.r1)
    d0 = float(mat.delta0) / r1
    ck = _common.Checks("Wada et al. 2007 Fig. 4 (2-D BCCAs)")
    drawn = {}
    for N in SIZES:
        agg, bonds = structures.bcca(N, jax.random.key(N), dim=2, material=mat, return_bonds=True)
        x = np.asarray(agg.positions) / r1
        drawn[N] = x
        bl = np.linalg.norm(x[bonds[:, 0]] - x[bonds[:, 1]], axis=-1)
        ck.add(f"N={N}: bonds", len(bonds), N - 1, 0.0)
        ck.add(f"N={N}: max |bond - (2 - delta0/r1)|", np.max(np.abs(bl - (2.0 - d0))), 0.0, 1e-10, absolute=True)
        if N <= 512:  # all pairs: no other contact (delta = 2 r1 - |x_i - x_j| < 0)
            d = np.linalg.norm(x[:, None] - x[None], axis=-1)
            d[bonds[:, 0], bonds[:, 1]] = d[bonds[:, 1], bonds[:, 0]] = np.inf
            np.fill_diagonal(d, np.inf)
            ck.add(f"N={N}: pairs in contact besides the bonds", np.sum(d <= 2.0), 0.0, 0.0, absolute=True)
        law = float(wada_bcca_rg(N))
        rg = float(np.sqrt(np.mean(np.sum((x - x.mean(axis=0)) ** 2, axis=-1))))  # eq. 50 [r1]
        ck.add(f"N={N}: r_g/r1 drawn vs eq. 53", rg, law, 0.5, counts=False)

    count = 4 if args.quick else 64
    radii = structures.bcca_gyration_radii(max(SIZES), count, jax.random.key(4), dim=2, material=mat)
    for N in SIZES:
        g = radii[N]
        ck.add(f"N={N}: <r_g/r1> over {g.size} vs eq. 53", g.mean(), float(wada_bcca_rg(N)), 0.10)

    # disks of radius r1 to scale within each panel (each panel has its own length scale, as in the paper)
    halves = [float(np.abs(drawn[N]).max()) + 2.0 for N in SIZES]
    fig, axes = plt.subplots(1, len(SIZES), figsize=(16, 4.0), gridspec_kw=dict(wspace=0.3))
    for ax, N, half in zip(axes, SIZES, halves):
        x = drawn[N]
        ax.add_collection(EllipseCollection(2.0, 2.0, 0.0, units="xy", offsets=x, offset_transform=ax.transData,
                                            facecolors="0.35", edgecolors="k", linewidths=0.2))  # radius r1
        ax.set_xlim(-half, half)
        ax.set_ylim(-half, half)
        ax.set_aspect("equal")
        g = float(np.sqrt(np.mean(np.sum(x**2, axis=-1))))
        ax.set_title(f"N = {N}\n$r_g/r_1$ = {g:.1f}\n(eq. 53: {float(wada_bcca_rg(N)):.1f})", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.set_xlabel(r"$x/r_1$")
    axes[0].set_ylabel(r"$y/r_1$")
    fig.suptitle("Wada et al. 2007 Fig. 4: 2-D BCCAs (ice, bonds at $2r_1-\\delta_0$)", fontsize=10, y=1.06)
    png = _common.savefig(fig, args, "figW04_bcca_gallery")
    ck.print()
    print(f"wrote {png}")
    return ck.result(png)


if __name__ == "__main__":
    main()
