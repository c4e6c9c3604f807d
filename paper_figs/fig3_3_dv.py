"""Thesis Fig. 3.3 (OC07 Fig. 3): Delta v_12/v_g against St_1 at Re = 1e8 (exact y*), log-log.

Solid: t_1 >> t_2 (St_2 = 0, clamped to 1e-30); dashed: identical particles (zero for St_1 < 6.25e-5,
omitted on the log axis). Dotted: limits eq. 3.24 (Re^1/4 St_1, St_1 < r), eq. 3.25 (sqrt(2.969 St_1),
sqrt(1.969 St_1), r < St_1 < 1) and eq. 3.26 (sqrt(1 + 1/(1+St_1)), sqrt(2/(1+St_1)), St_1 > 1).
Check points: independent float64 values of eqs. 3.14/3.15 and the peak (1.226468 at St_1 = 0.964145;
identical 1.009725 at 0.915010) -- the curves peak slightly below St_1 = 1.
Run: python paper_figs/fig3_3_dv.py [--quick] [--out DIR]
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402

FIG33 = [  # St1, identical, St2 -> 0 (independent float64 reference values)
    (1e-6, 0.0, 9.949869e-5), (1e-5, 0.0, 9.534101e-4), (1e-4, 9.847625e-3, 1.212294e-2),
    (1e-3, 4.416624e-2, 5.346727e-2), (1e-2, 1.399818e-1, 1.714552e-1), (0.1, 4.325908e-1, 5.272040e-1),
    (0.3, 7.119773e-1, 8.588253e-1), (1, 1.000000, 1.224704), (3, 7.071068e-1, 1.117989),
    (10, 4.264014e-1, 1.044418), (100, 1.407195e-1, 1.004889),
]


def main(argv=None):
    args = _common.parse_args(argv, __doc__)
    jax = _common.enable_x64()
    import jax.numpy as jnp
    import numpy as np

    from jaxcoag.physics import turbulence as T

    plt = _common.pyplot()
    RE = 1e8
    r = RE ** -0.5
    dv_solid = jax.jit(lambda s: jnp.sqrt(T.dv2_turbulent_oc07(s, 0.0, RE)))
    dv_ident = jax.jit(lambda s: jnp.sqrt(T.dv2_turbulent_oc07(s, s, RE)))

    st = np.logspace(-6, 2, 161 if args.quick else 1601)
    solid = np.asarray(dv_solid(jnp.asarray(st)))
    ident = np.asarray(dv_ident(jnp.asarray(st)))

    ck = _common.Checks("Fig 3.3 (Delta v/v_g vs St_1, Re = 1e8)")
    pts = jnp.asarray([p[0] for p in FIG33])
    vs = np.asarray(dv_solid(pts))
    vi = np.asarray(dv_ident(pts))
    for (s1, ri, rs), cs, ci in zip(FIG33, vs, vi):
        ck.add(f"St2->0, St1={s1:g}", cs, rs, 1e-6)
        if ri == 0.0:
            ck.add(f"identical, St1={s1:g}", ci, 0.0, 0.0, absolute=True)
        else:
            ck.add(f"identical, St1={s1:g}", ci, ri, 1e-6)
    x, v = _common.log_peak(lambda s: dv_solid(jnp.asarray(s)), 0.1, 10.0, n=201 if args.quick else 801)
    ck.add("peak St1 (St2->0)", x, 0.964145, 1e-5)
    ck.add("peak value (St2->0)", v, 1.226468, 1e-6)
    x, v = _common.log_peak(lambda s: dv_ident(jnp.asarray(s)), 0.1, 10.0, n=201 if args.quick else 801)
    ck.add("peak St1 (identical)", x, 0.915010, 1e-5)
    ck.add("peak value (identical)", v, 1.009725, 1e-6)

    fig, ax = plt.subplots(figsize=(5.5, 4.3))
    ax.loglog(st, solid, "k-", lw=1.6, label=r"$t_1 \gg t_2$")
    pos = ident > 0
    ax.loglog(st[pos], ident[pos], "k--", lw=1.6, label="identical")
    s24 = st[st < r]
    ax.loglog(s24, np.sqrt(np.asarray(T.dv2_small_eq324(jnp.asarray(s24), 0.0, RE))), "C0:", lw=1.2,
              label="eq. 3.24")
    s25 = st[(st > r) & (st < 1)]
    for eps, c in [(0.0, "C1"), (1.0, "C2")]:
        ax.loglog(s25, np.sqrt(np.asarray(T.dv2_intermediate_eq325(jnp.asarray(s25), eps, 1.6))), c + ":",
                  lw=1.2, label=f"eq. 3.25, $\\epsilon={eps:g}$")
    s26 = st[st > 1]
    ax.loglog(s26, np.sqrt(np.asarray(T.dv2_heavy_eq326(jnp.asarray(s26), 0.0))), "C3:", lw=1.2,
              label=r"eq. 3.26, $t_2\to0$")
    ax.loglog(s26, np.sqrt(np.asarray(T.dv2_heavy_eq326(jnp.asarray(s26), jnp.asarray(s26)))), "C4:", lw=1.2,
              label="eq. 3.26, identical")
    ax.plot([p[0] for p in FIG33], vs, "o", color="C3", ms=3, mfc="none")
    ax.set_xlim(1e-6, 1e2)
    ax.set_ylim(1e-5, 3)
    ax.set_xlabel(r"St$_1 = t_1/t_L$")
    ax.set_ylabel(r"$\Delta v_{12}/v_g$")
    ax.set_title(r"Ormel 2008 Fig. 3.3 (OC07 Fig. 3), Re $=10^8$", fontsize=10)
    ax.legend(fontsize=7, loc="lower right")
    png = _common.savefig(fig, args, "fig3_3_dv")
    ck.print()
    print(f"wrote {png}")
    return ck.result(png)


if __name__ == "__main__":
    main()
