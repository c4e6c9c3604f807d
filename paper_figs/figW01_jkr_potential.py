"""Wada et al. (2007) Fig. 1: the JKR normal potential U_n/(F_c delta_c) against the compression delta/delta_c.

Drawn parametrically in a/a_0 from the separation point 6^(-2/3) to 1.6 (eqs. 4 and 6), plus the curve from
``jaxcoag.aggregates.contact.jkr.normal_potential`` evaluated on a delta grid (closed-form inversion of eq. 4),
the U = 0 branch before contact (delta < 0, approaching monomers) and the marked points: equilibrium delta_0
(U = -1.4537), contact creation delta = 0 (U = -0.8466) and separation -delta_c (U = +0.0889).
Check points: the exact constants -(4/5) 6^(1/3), U(0) at a/a_0 = (2/3)^(2/3), 4/45, E_break = 1.542585, the
maximum pull-off -F_c at -0.48075 delta_c, and the agreement of the two curves (material-independent: quartz
and ice give the same dimensionless curve).
Run: python paper_figs/figW01_jkr_potential.py [--quick] [--out DIR]
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402


def main(argv=None):
    args = _common.parse_args(argv, __doc__)
    _common.enable_x64()
    import jax
    import jax.numpy as jnp
    import numpy as np

    from jaxcoag.aggregates.contact import jkr as J
    from jaxcoag.aggregates.contact import materials as M
    from jaxcoag.physics.contact import jkr_potential

    plt = _common.pyplot()
    n = 401 if args.quick else 4001
    ck = _common.Checks("Wada 2007 Fig. 1 (JKR potential, eqs. 4-6)")

    # parametric curve in x = a/a_0 (eqs. 4, 6), delta in units of delta_c
    x = np.linspace(6.0 ** (-2.0 / 3.0), 1.6, n)
    d_par = (3.0 * x**2 - 2.0 * np.sqrt(x)) * J.DELTA0_OVER_DELTAC
    u_par = np.asarray(jkr_potential(jnp.asarray(x)))

    curves = {}
    for name, mat in (("quartz", M.quartz()), ("ice", M.ice())):
        unit_U = float(mat.F_c * mat.delta_c)
        dc = float(mat.delta_c)
        d = jnp.asarray(d_par * dc)
        U = np.asarray(jax.jit(J.normal_potential)(d, mat)) / unit_U
        curves[name] = U
        ck.add(f"{name}: max |U(delta) - U(x(delta))|", float(np.max(np.abs(U - u_par))), 0.0, 1e-11, absolute=True)
        ck.add(f"{name}: U(delta_0)", float(J.normal_potential(mat.delta0, mat)) / unit_U,
               -0.8 * 6.0 ** (1.0 / 3.0), 1e-12)
        ck.add(f"{name}: U(0)", float(J.normal_potential(0.0, mat)) / unit_U,
               float(jkr_potential((2.0 / 3.0) ** (2.0 / 3.0))), 1e-12)
        ck.add(f"{name}: U(-delta_c)", float(J.normal_potential(-mat.delta_c, mat)) / unit_U, 4.0 / 45.0, 1e-10)
        ck.add(f"{name}: E_break/(F_c delta_c)", float(mat.E_break) / unit_U, 1.542585, 1e-6)
        dmax = float(J.compression(2.0 ** (-2.0 / 3.0), mat))
        ck.add(f"{name}: delta at max pull-off [delta_c]", dmax / dc, -0.48075, 1e-5, absolute=True)
        ck.add(f"{name}: F at max pull-off [F_c]", float(J.normal_force(dmax, mat) / mat.F_c), -1.0, 1e-12)
    ck.add("paper: U(delta_0) = -1.4537", J.U_AT_EQUILIBRIUM, -1.4537, 1e-4, absolute=True, counts=False)
    ck.add("paper: U(0) = -0.8466", J.U_AT_ZERO, -0.8466, 1e-4, absolute=True, counts=False)
    ck.add("paper: U(-delta_c) = +0.0889", J.U_AT_SEPARATION, 0.0889, 1e-4, absolute=True, counts=False)
    ck.add("paper: E_break ~ 1.54 F_c delta_c", J.E_BREAK_UNITS, 1.54, 3e-3, counts=False)

    fig, ax = plt.subplots(figsize=(5.6, 4.2))
    ax.plot(d_par, u_par, "k-", lw=1.8, label=r"JKR, in contact (eqs. 4, 6)")
    ax.plot(d_par[:: max(1, n // 40)], curves["quartz"][:: max(1, n // 40)], "o", mfc="none", ms=4, color="C0",
            label=r"jaxcoag normal_potential($\delta$)")
    ax.plot([-3.0, 0.0], [0.0, 0.0], "k--", lw=1.2, label=r"$U=0$ before contact")
    pts = [(J.DELTA0_OVER_DELTAC, J.U_AT_EQUILIBRIUM, r"$\delta_0$: $-1.4537$"),
           (0.0, J.U_AT_ZERO, r"$\delta=0$: $-0.8466$"),
           (-1.0, J.U_AT_SEPARATION, r"$-\delta_c$: $+0.0889$")]
    for (px, py, lab), c in zip(pts, ("C3", "C2", "C1")):
        ax.plot([px], [py], "s", color=c, ms=6, label=lab)
    ax.annotate("", xy=(0.0, J.U_AT_ZERO), xytext=(0.0, 0.0), arrowprops=dict(arrowstyle="->", color="C2"))
    ax.annotate("", xy=(-1.0, 0.0), xytext=(-1.0, J.U_AT_SEPARATION), arrowprops=dict(arrowstyle="->", color="C1"))
    ax.set_xlim(-3.0, float(d_par[-1]))
    ax.set_ylim(-2.0, 3.0)
    ax.axhline(0.0, color="0.7", lw=0.5)
    ax.set_xlabel(r"$\delta/\delta_c$")
    ax.set_ylabel(r"$U_n/(F_c\delta_c)$")
    ax.set_title("Wada et al. 2007 Fig. 1: JKR potential", fontsize=10)
    ax.legend(fontsize=7, loc="upper left")
    png = _common.savefig(fig, args, "figW01_jkr_potential")
    ck.print()
    print(f"wrote {png}")
    return ck.result(png)


if __name__ == "__main__":
    main()
