"""Thesis Fig. 3.4 (OC07 Fig. 4): contours of Delta v_12/v_g over (St_1, St_2), both log axes.

Panels: (a) the Markiewicz et al. 1991 numerics are not reproducible from closed forms; it is replaced
by the App. 3.A ``accurate=True`` variant (exact y*, Re = 1e8) and labelled so. (b) t* = 1.6 tau_f with
Re -> inf (Re = 1e30); (c) exact y*, Re = 1e8; (d) CH03 k*, Re = 1e8. Levels {1, 3} x 10^i, 0.8, 1.15.
Check points (independent float64 values of eqs. 3.14/3.15): maxima along the St_2 -> 0 edge at Re = 1e8: exact 1.2265 at St_1 = 0.964,
ya 1.2709 at 0.625, ch03 1.1059 at 1.84; the 2-D maximum lies on that edge; Delta v = 0 on the diagonal
for St < 6.25e-5 (Re = 1e8).
Run: python paper_figs/fig3_4_contours.py [--quick] [--out DIR]
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402

PANELS = [  # (label, method, Re, accurate)
    ("(a) App. 3.A accurate form (substitute for MMV91), Re=1e8", "exact", 1e8, True),
    ("(b) $t^*=1.6\\,\\tau_f$, Re$\\to\\infty$ (1e30)", "ya", 1e30, False),
    ("(c) exact $y^*$, Re=1e8", "exact", 1e8, False),
    ("(d) CH03 $k^*$, Re=1e8", "ch03", 1e8, False),
]


def main(argv=None):
    args = _common.parse_args(argv, __doc__)
    jax = _common.enable_x64()
    import jax.numpy as jnp
    import numpy as np

    from jaxcoag.physics import turbulence as T

    plt = _common.pyplot()
    n = 61 if args.quick else 301
    st = np.logspace(-6, 2, n)
    levels = sorted({c * 10.0 ** i for i in range(-6, 1) for c in (1, 3)} | {0.8, 1.15})

    ck = _common.Checks("Fig 3.4 (Delta v/v_g contours)")
    for method, ref_x, ref_v in [("exact", 0.964145, 1.226468), ("ya", 0.625, 1.270938), ("ch03", 1.843996, 1.105917)]:
        f = jax.jit(lambda s, m=method: jnp.sqrt(T.dv2_turbulent_oc07(s, 0.0, 1e8, method=m)))
        x, v = _common.log_peak(lambda s: f(jnp.asarray(s)), 0.1, 10.0, n=201 if args.quick else 801)
        ck.add(f"max along St2->0, {method}: St1", x, ref_x, 1e-3)
        ck.add(f"max along St2->0, {method}: value", v, ref_v, 1e-4)

    fig, axes = plt.subplots(2, 2, figsize=(9, 8.4), sharex=True, sharey=True)
    S1, S2 = np.meshgrid(st, st, indexing="xy")
    for ax, (label, method, re, acc) in zip(axes.ravel(), PANELS):
        grid = np.asarray(T.dv_turbulent_oc07(jnp.asarray(S1), jnp.asarray(S2), re, method=method, accurate=acc))
        cs = ax.contour(S1, S2, grid, levels=levels, colors="k", linewidths=0.8)
        ax.clabel(cs, fontsize=6, fmt="%g", inline=False)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_aspect("equal")
        ax.set_title(label, fontsize=8)
        if method == "exact" and re == 1e8 and not acc:
            # the 2-D maximum of the grid sits on the St_2 -> 0 edge (smallest St_2 row) and is symmetric
            i, j = np.unravel_index(np.argmax(grid), grid.shape)
            ck.add("(c) 2-D grid max on the St2 edge (row index)", float(min(i, j)), 0.0, 0.0, absolute=True)
            ck.add("(c) symmetry max|dv - dv^T|", float(np.max(np.abs(grid - grid.T))), 0.0, 1e-15, absolute=True)
            diag = np.diag(grid)[st < 6.2e-5]
            ck.add("(c) diagonal dv for St < 6.25e-5", float(np.max(diag)), 0.0, 0.0, absolute=True)
        if method == "ch03":
            ck.add("(d) grid max < 1.15 (no 1.15 contour)", float(np.max(grid)), 1.105917, 2e-3)
    for ax in axes[1]:
        ax.set_xlabel(r"St$_1$")
    for ax in axes[:, 0]:
        ax.set_ylabel(r"St$_2$")
    fig.suptitle(r"Ormel 2008 Fig. 3.4 (OC07 Fig. 4): $\Delta v_{12}/v_g$", fontsize=11)
    png = _common.savefig(fig, args, "fig3_4_contours")
    ck.print()
    print(f"wrote {png}")
    return ck.result(png)


if __name__ == "__main__":
    main()
